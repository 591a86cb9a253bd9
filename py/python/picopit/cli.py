"""The ``picopit`` command line. Subcommands grow with the project.

Bad input (a setting out of range, an unknown parameter set, a malformed file) prints one
line naming the field and exits with status 2, without a traceback.
"""

from __future__ import annotations

import argparse
import dataclasses
import datetime as _dt
import sys
from pathlib import Path
from typing import Any, Dict, List, NoReturn, Optional

EXIT_BAD_INPUT = 2


class _Parser(argparse.ArgumentParser):
    """argparse with the same one-line, exit-2 error style as our own checks."""

    def error(self, message: str) -> NoReturn:
        self.print_usage(sys.stderr)
        self.exit(EXIT_BAD_INPUT, f"{self.prog}: error: {message}\n")


def _simulate_parser(sub) -> None:
    from .simulate import SimulateConfig

    defaults = SimulateConfig()
    p = sub.add_parser(
        "simulate",
        help="one two-vehicle rear-quarter PIT contact on the plant, with CSV and figure",
        description=(
            "Simulate a scripted rear-quarter PIT on the high-fidelity plant: the bullet "
            "chases the target on a straight 3-lane road, lines up beside its rear axle, "
            "steers a quarter turn into it, then steers back and brakes. Writes "
            "trajectory.csv, simulate.png and summary.json. Options override the TOML file."
        ),
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
    )
    p.add_argument("--config", metavar="TOML",
                   help="settings file: the option names below (with underscores) at top level "
                        "or in a [simulate] table")
    p.add_argument("--out", metavar="DIR", help="output folder (default: runs/simulate-<timestamp>)")
    p.add_argument("--params", help="parameter set: full_size, half_scale or a TOML file "
                   f"(default {defaults.params})")
    num = [
        ("--mu", "road adhesion", defaults.mu),
        ("--target-speed", "initial target speed (m/s)", defaults.target_speed),
        ("--speed-diff", "initial bullet speed minus target speed (m/s)", defaults.speed_diff),
        ("--lateral-offset", "initial bullet c.g. Y minus target c.g. Y (m); negative: bullet on "
                             "the target's right", defaults.lateral_offset),
        ("--gap", "initial gap from the bullet's front bumper to the target's rear bumper (m)",
         defaults.gap),
        ("--duration", "simulated time (s)", defaults.duration),
        ("--jitter", "initial-condition noise scale (0: nominal scenario)", defaults.jitter),
        ("--pit-steer", "road-wheel steer of the quarter turn into the target (rad)",
         defaults.pit_steer),
        ("--target-brake", "target driver's brake after the hit, fraction of its maximum",
         defaults.target_brake),
        ("--target-reaction", "target driver's reaction time after the first contact (s)",
         defaults.target_reaction),
        ("--record-hz", "trajectory sample rate (Hz, multiple of 20)", defaults.record_hz),
    ]
    for flag, text, default in num:
        p.add_argument(flag, type=float, metavar="X", help=f"{text} (default {default:g})")
    p.add_argument("--seed", type=int, metavar="N", help=f"random seed (default {defaults.seed})")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=_cmd_simulate)


def _params_parser(sub) -> None:
    p = sub.add_parser("params", help="list the built-in parameter sets or print one, validated")
    p.add_argument("name", nargs="?", help="built-in name or TOML path to validate and print")
    p.set_defaults(func=_cmd_params)


def build_parser() -> argparse.ArgumentParser:
    from . import __version__

    parser = _Parser(
        prog="picopit",
        description="picopit: automated Precision Immobilization Technique (PIT) on a Rust core.",
    )
    parser.add_argument("--version", action="version", version=f"picopit {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    sub.required = True
    _simulate_parser(sub)
    _params_parser(sub)
    return parser


def _bad_input(message: str) -> int:
    print(f"picopit: error: {message}", file=sys.stderr)
    return EXIT_BAD_INPUT


def _cmd_params(args: argparse.Namespace) -> int:
    from . import builtin_param_sets, load_params

    if args.name is None:
        for name in builtin_param_sets():
            print(name)
        return 0
    print(load_params(args.name), end="")
    return 0


def _check_params_name(name: str) -> None:
    """A friendlier message than the core's for a name that is neither built in nor a file."""
    from . import builtin_param_sets
    from .simulate import ConfigError

    if name not in builtin_param_sets() and not Path(name).exists():
        raise ConfigError(
            f"params = {name!r}: not a built-in parameter set ({', '.join(builtin_param_sets())}) "
            "nor an existing TOML file"
        )


def _cmd_simulate(args: argparse.Namespace) -> int:
    from .simulate import SimulateConfig, load_config_file, run, write_outputs

    values: Dict[str, Any] = {}
    if args.config:
        values.update(load_config_file(args.config))
    for f in dataclasses.fields(SimulateConfig):
        v = getattr(args, f.name, None)
        if v is not None:
            values[f.name] = v
    cfg = SimulateConfig.from_mapping(values, source=args.config or "options").validate()
    _check_params_name(cfg.params)

    out = Path(args.out) if args.out else Path("runs") / (
        "simulate-" + _dt.datetime.now().strftime("%Y%m%d-%H%M%S")
    )
    result = run(cfg, progress=not args.no_progress)
    paths = write_outputs(result, out)
    s = result.summary
    print(
        f"simulate: peak contact force {s['peak_contact_force_N'] / 1e3:.1f} kN, "
        f"target yaw change {s['target_yaw_change_deg']:+.1f} deg, final speeds "
        f"bullet {s['final_speed_bullet_mps']:.2f} m/s, target {s['final_speed_target_mps']:.2f} m/s "
        f"(seed {cfg.seed})"
    )
    print(f"simulate: wrote {paths['csv']}, {paths['png']}, {paths['json']}")
    return 0


def main(argv: Optional[List[str]] = None) -> int:
    from . import ParamError
    from .simulate import ConfigError

    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args))
    except (ConfigError, ParamError) as e:
        return _bad_input(str(e))
    except KeyboardInterrupt:
        print("picopit: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
