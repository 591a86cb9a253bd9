"""The ``picopit`` command line. Subcommands grow with the project.

Bad input (a setting out of range, an unknown parameter set, a malformed file, an output path
that cannot be written) prints one line naming the field and exits with status 2, without a
traceback; output paths are checked before the work starts. Work that could not be completed
(episodes or trial runs that errored, a write that failed on the way) prints one line and
exits with status 1.
"""

from __future__ import annotations

import argparse
import dataclasses
import datetime as _dt
import importlib
import sys
from pathlib import Path
from typing import Any, Dict, List, NoReturn, Optional

from . import cli_surrogates
from .cli_surrogates import check_params_name
from .outputs import OutputError, check_dir, check_file

EXIT_BAD_INPUT = 2
#: The work could not be completed (errored episodes or runs, a failed write).
EXIT_FAILED = 1


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


def _scenarios_parser(sub) -> None:
    p = sub.add_parser(
        "scenarios",
        help="the PIT Scenario Dataset: sample from the priors, screen, select (jsonl + manifest)",
        description=(
            "Sample N scenarios conditionally on the priors table, screen them (geometry rules, "
            "then the target alone on the plant: trivial and impossible ones are dropped), select "
            "KEEP stratified by road category (22/18/60 %%), compare with the priors by per-attribute "
            "KL divergence. Writes OUT/scenarios.jsonl, OUT/scenarios.manifest.json and two figures."
        ),
    )
    p.add_argument("--priors", default="data/priors.csv", metavar="CSV", help="priors table (default data/priors.csv)")
    p.add_argument("--out", default="data", metavar="DIR", help="output folder (default data)")
    p.add_argument("--n", type=int, default=3600, metavar="N", help="scenarios to generate (default 3600)")
    p.add_argument("--keep", type=int, default=2048, metavar="K", help="scenarios to retain (default 2048)")
    p.add_argument("--seed", type=int, default=0, metavar="S", help="random seed (default 0)")
    p.add_argument("--workers", type=int, default=2, metavar="W", help="screening threads (default 2)")
    p.add_argument("--write-priors", action="store_true",
                   help="first (re)write the priors table from the documented design (design_priors)")
    p.add_argument("--no-figures", action="store_true", help="skip the figures")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=_cmd_scenarios)


def _bench_parser(sub) -> None:
    from .bench import SUBSET_SIZE

    p = sub.add_parser(
        "bench",
        help="the closed-loop benchmark: scenarios x controller configurations, tables and figures",
        description=(
            "Run the hierarchical PIT controller in closed loop on the plant over the PIT Scenario "
            f"Dataset: by default a fixed stratified subset of {SUBSET_SIZE} scenes (road category x "
            "adhesion band) x the four configurations (4dof, pinn, picopinn with the upper layer, "
            "picopinn_no_upper). Writes summary.md/.csv/.json, episodes.parquet, panels.png, the "
            "representative success and failure cases (PNG and MCAP) to the run folder."
        ),
    )
    p.add_argument("--scenarios", default="data/scenarios.jsonl", metavar="JSONL",
                   help="scenario dataset (default data/scenarios.jsonl)")
    p.add_argument("--models", default="models", metavar="DIR",
                   help="model folder: DIR/<params>/{pinn,picopinn}.safetensors (default models)")
    p.add_argument("--full", action="store_true", help="all scenes of the dataset, not the stratified subset")
    p.add_argument("--configs", default="4dof,pinn,picopinn,picopinn_no_upper", metavar="LIST",
                   help="comma-separated configurations (default all four: 4dof,pinn,picopinn,picopinn_no_upper)")
    p.add_argument("--limit", type=int, metavar="N", help="at most N scenes (evenly spaced over the scene set)")
    p.add_argument("--seed", type=int, default=0, metavar="S", help="seed of the episodes' noise and actuator errors (default 0)")
    p.add_argument("--uncertainty", metavar="JSON",
                   help="sensing noise / latency / actuator errors for every configuration, e.g. "
                        "'{\"position_std\": 0.05, \"latency\": 0.02}' (default none)")
    p.add_argument("--clock", default="wall", metavar="wall|simulated",
                   help="wall: real runtimes and time budgets (default); simulated: a tick clock, "
                        "every episode repeatable whatever the machine's load")
    p.add_argument("--target-gear", default="forward", metavar="forward|neutral",
                   help="the target's gear: forward (its powertrain engaged: engine braking, a stall that "
                        "holds the driven axle; default) or neutral (it rolls freely once let go: for "
                        "comparison)")
    p.add_argument("--controller-config", metavar="TOML",
                   help="controller settings for the full-size scenes over each configuration's (the "
                        "[planner], [phases], [mpc] tables of docs/planner.md; fields not given keep "
                        "theirs, e.g. the ablation's upper layer stays off)")
    p.add_argument("--controller-config-half-scale", metavar="TOML",
                   help="the same for the half-scale scenes (over the built-in "
                        "configs/controller_half_scale.toml)")
    p.add_argument("--out", metavar="DIR", help="run folder (default runs/bench-<timestamp>)")
    p.add_argument("--json", metavar="PATH", help="also write the summary JSON here")
    p.add_argument("--workers", type=int, default=0, metavar="W", help="worker processes (default 0: all cores)")
    p.add_argument("--ray-address", metavar="ADDR",
                   help="run the episodes on a Ray cluster: an address for ray.init (HOST:PORT, ray://HOST:PORT), "
                        "or 'local' to start one here; a head that does not answer within 10 s is an error")
    p.add_argument("--no-figures", action="store_true", help="skip the figures, the case re-runs and the MCAP")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=_cmd_bench)


def _replay_parser(sub) -> None:
    p = sub.add_parser(
        "replay",
        help="figure and summary of an MCAP recording of pit-controller/pit-vehicle",
        description=(
            "Read an MCAP recording (also one cut short by a killed process: up to its last "
            "complete message), draw the vehicles' paths, headings, the bullet commands and the "
            "controller phase and faults into a PNG, and print a one-paragraph summary."
        ),
    )
    p.add_argument("file", metavar="FILE.mcap", help="the recording")
    p.add_argument("--out", metavar="PATH", help="PNG to write, or a folder to write FILE's name .png into "
                                                 "(default FILE.png beside FILE)")
    p.set_defaults(func=_cmd_replay)


def _validate_parser(sub) -> None:
    p = sub.add_parser(
        "validate-plant",
        help="check the plant against CommonRoad's multi-body model and impulse-momentum theory",
        description=(
            "Run the plant validation suite (docs/plant.md): step steer, sine steer, steer ramp "
            "and straight braking against CommonRoad's multi-body model MB, and two-car impacts "
            "against impulse-momentum theory, each with its tolerance. Prints the table; exits 1 "
            "if a check fails. Needs scipy and commonroad-vehicle-models "
            "(pip install 'picopit[test]')."
        ),
    )
    p.add_argument("--json", metavar="PATH", help="also write the checks as JSON")
    p.set_defaults(func=_cmd_validate)


def _cmd_validate(args: argparse.Namespace) -> int:
    import json

    try:
        import scipy  # noqa: F401
        import vehiclemodels  # noqa: F401
    except ImportError as e:
        print(
            f"picopit validate-plant: {e.name} is not installed; it comes with the test extras "
            "(pip install 'picopit[test]')",
            file=sys.stderr,
        )
        return EXIT_BAD_INPUT
    from .validation import all_checks, format_table

    checks = all_checks("full_size")
    print(format_table(checks))
    failed = [c for c in checks if not c.passed]
    if args.json:
        Path(args.json).write_text(json.dumps([c.as_dict() for c in checks], indent=1))
    print(f"{len(checks) - len(failed)} of {len(checks)} checks pass")
    return 1 if failed else 0


def _cmd_replay(args: argparse.Namespace) -> int:
    from .replay import check_source, figure_path, replay

    check_source(args.file)
    png = check_file(figure_path(args.file, args.out), "--out" if args.out else "the figure (FILE.png)")
    _, png, summary = replay(args.file, png)
    print(summary)
    print(f"replay: wrote {png}")
    return 0


def _trials_parser(sub) -> None:
    p = sub.add_parser(
        "trials",
        help="the half-scale trials R1-R4 over IPC (pit-vehicle + pit-controller): tables, figure, MCAP",
        description=(
            "Run the trial cases with the release binaries pit-vehicle and pit-controller over "
            "iceoryx2 (lock step on a simulated clock; --realtime: wall clock): per case one nominal "
            "run (no noise, seed 0, MCAP recorded) for a table like the paper's real-vehicle table, "
            "then K repeats under sensing noise (seeds 1..K) for the success rate with a Wilson 95 %% "
            "interval. Writes trials.md/.csv/.json, trials.png and per-run summaries, logs and MCAP."
        ),
    )
    p.add_argument("--half-scale", action="store_true",
                   help="the half-scale trials: data/trials/half_scale.jsonl with configs/controller_half_scale.toml")
    p.add_argument("--scenarios", metavar="JSONL", help="trial scenarios (overrides --half-scale's)")
    p.add_argument("--controller-config", metavar="TOML", help="controller settings (overrides --half-scale's; without --half-scale: the built-in full-size settings)")
    p.add_argument("--cases", metavar="LIST", help="comma-separated case ids (default: all in the file)")
    p.add_argument("--repeats", type=int, default=5, metavar="K", help="noisy repeats per case, seeds 1..K (default 5)")
    p.add_argument("--noise", choices=("none", "paper"), default="paper", help="sensing noise of the repeats (default paper)")
    p.add_argument("--latency", type=float, default=0.05, metavar="S", help="sensing latency of the repeats (s, default 0.05)")
    p.add_argument("--realtime", action="store_true", help="pace both processes by the wall clock (default: lock step)")
    p.add_argument("--no-delay-compensation", action="store_true",
                   help="the controller takes the states as current instead of predicting them over their age")
    p.add_argument("--jobs", type=int, default=1, metavar="N", help="runs at a time (default 1)")
    p.add_argument("--timeout", type=float, metavar="S", help="wall-time limit of one run (s; default from T_max)")
    p.add_argument("--model", choices=("4dof", "pinn", "picopinn"), help="controller's target surrogate (default: its settings')")
    p.add_argument("--out", metavar="DIR", help="run folder (default runs/trials-<UTC stamp>)")
    p.add_argument("--json", metavar="PATH", help="also write trials.json here")
    p.add_argument("--bin-dir", metavar="DIR", help="folder of pit-vehicle and pit-controller "
                   "(default $PICOPIT_BIN_DIR, else <repo>/target/release)")
    p.add_argument("--no-figures", action="store_true", help="skip trials.png")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=_cmd_trials)


def _cmd_trials(args: argparse.Namespace) -> int:
    from . import trials

    try:
        summary, rows, paths = trials.run(args, args.command_line)
    except trials.TrialsError as e:
        return _bad_input(str(e))
    print(trials.nominal_table(summary), end="")
    if summary["overall"].get("repeats"):
        print()
        print(trials.repeats_table(summary), end="")
    errors = [r for r in rows if r["cause"] == trials.ERROR_CAUSE]
    for r in errors:
        print(f"trials: note: {r['case']} {r['kind']} seed {r['seed']}: {r['error']} (logs in {paths['md'].parent / r['dir']})")
    print("trials: wrote " + ", ".join(str(p) for p in paths.values()))
    if errors:
        print(f"trials: error: {len(errors)} of {len(rows)} runs did not complete (cause 'error'); "
              "see the notes above", file=sys.stderr)
        return 1
    return 0


def _unavailable_parser(sub, name: str, err: ModuleNotFoundError) -> None:
    """A command whose options need a package that is not installed: it takes any arguments
    and says what to install (``_missing_extra``)."""
    extra = EXTRAS.get((err.name or "").split(".")[0], "?")
    # No option prefix: every argument, `--out` and `--help` too, is taken as a word, so the
    # command parses and then says what is missing.
    p = sub.add_parser(name, help=f"(needs the '{extra}' extra: ./scripts/setup.sh --full)",
                       prefix_chars="\x00", add_help=False)
    p.add_argument("args", nargs="*", help=argparse.SUPPRESS)

    def run(args: argparse.Namespace) -> int:
        return _missing_extra(name, err)

    p.set_defaults(func=run)


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
    # The surrogate pipeline's options come from modules that import torch, which the main
    # job's set-up does not install.
    for add, name in ((cli_surrogates.datagen_parser, "datagen"), (cli_surrogates.train_parser, "train"),
                      (cli_surrogates.compress_parser, "compress")):
        try:
            importlib.import_module(f".{name}", __package__)
        except ModuleNotFoundError as e:
            _unavailable_parser(sub, name, e)
            continue
        add(sub)
    cli_surrogates.eval_parser(sub)
    _scenarios_parser(sub)
    _bench_parser(sub)
    from .cli_tools import add_parsers

    add_parsers(sub)
    _replay_parser(sub)
    _trials_parser(sub)
    _validate_parser(sub)
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


def _cmd_simulate(args: argparse.Namespace) -> int:
    from .plots import plot_simulation
    from .simulate import SimulateConfig, load_config_file, run, write_outputs

    values: Dict[str, Any] = {}
    if args.config:
        values.update(load_config_file(args.config))
    for f in dataclasses.fields(SimulateConfig):
        v = getattr(args, f.name, None)
        if v is not None:
            values[f.name] = v
    cfg = SimulateConfig.from_mapping(values, source=args.config or "options").validate()
    check_params_name(cfg.params)

    out = Path(args.out) if args.out else Path("runs") / (
        "simulate-" + _dt.datetime.now().strftime("%Y%m%d-%H%M%S")
    )
    check_dir(out, "--out")
    result = run(cfg, progress=not args.no_progress)
    paths = write_outputs(result, out)
    paths["png"] = out / "simulate.png"
    plot_simulation(result, paths["png"])
    s = result.summary
    print(
        f"simulate: peak contact force {s['peak_contact_force_N'] / 1e3:.1f} kN, "
        f"target yaw change {s['target_yaw_change_deg']:+.1f} deg, final speeds "
        f"bullet {s['final_speed_bullet_mps']:.2f} m/s, target {s['final_speed_target_mps']:.2f} m/s "
        f"(seed {cfg.seed})"
    )
    print(f"simulate: wrote {paths['csv']}, {paths['png']}, {paths['json']}")
    return 0


def _command_line(argv: Optional[List[str]] = None) -> str:
    import shlex

    return "picopit " + " ".join(shlex.quote(a) for a in (sys.argv[1:] if argv is None else argv))


def _cmd_scenarios(args: argparse.Namespace) -> int:
    from . import provenance
    from . import scenarios as sc

    priors_path = Path(args.priors)
    check_dir(args.out, "--out")
    if args.write_priors:
        check_file(priors_path, "--priors")
        n = sc.write_priors(priors_path)
        print(f"scenarios: wrote {n} priors to {priors_path}")
    priors = sc.load_priors(priors_path)
    cfg = sc.GenerateConfig(n=args.n, keep=args.keep, seed=args.seed, workers=args.workers).validate()
    res = sc.generate(priors, cfg, progress=not args.no_progress)
    extra = {"seed": cfg.seed, "command": args.command_line, "priors": str(priors_path),
             "priors_sha256": sc.sha256_file(priors_path),
             "git_commit": provenance.git_commit(ignore=("data",)),
             "created": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")}
    paths = sc.write_outputs(res, Path(args.out), extra, figures=not args.no_figures)
    c = res.counts
    shares = ", ".join(f"{k} {100 * v / max(1, c['retained']):.1f} %"
                       for k, v in res.composition["retained"]["category"].items())
    print(f"scenarios: {c['generated']} generated from {c['priors']} priors -> {c['rule_rejected']} rejected by "
          f"rules, {c['trivial']} trivial, {c['impossible']} impossible, {c['screened_keep']} kept -> "
          f"{c['retained']} retained ({shares}) in {res.seconds:.0f} s (seed {cfg.seed})")
    print("scenarios: KL(retained || priors) nats: " + ", ".join(f"{k} {v:.3f}" for k, v in res.kl["retained"].items()))
    print("scenarios: wrote " + ", ".join(str(p) for p in paths.values()))
    return 0


def _cmd_bench(args: argparse.Namespace) -> int:
    from . import bench

    cfg = bench.BenchConfig(
        scenarios=Path(args.scenarios), models=Path(args.models), full=args.full,
        configs=bench.parse_configs(args.configs), limit=args.limit, seed=args.seed, workers=args.workers,
        ray_address=args.ray_address,
        uncertainty=bench.parse_uncertainty(args.uncertainty) if args.uncertainty else None,
        cases=not args.no_figures, figures=not args.no_figures, clock=args.clock,
        target_gear=args.target_gear,
        controller=bench.load_controller_config(args.controller_config, "--controller-config"),
        controller_half_scale=bench.load_controller_config(args.controller_config_half_scale,
                                                           "--controller-config-half-scale"),
    ).validate()
    out = Path(args.out) if args.out else Path("runs") / ("bench-" + _dt.datetime.now().strftime("%Y%m%d-%H%M%S"))
    check_dir(out, "--out")
    if args.json:
        check_file(args.json, "--json")
    from .bench_checks import check_models, check_ray

    check_ray(cfg.ray_address)
    scenarios, idx = bench.load_scenes(cfg)
    check_models(cfg, [scenarios[i] for i in idx])
    started = _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")
    # The source tree's commit when the run starts (the extension is whatever was last built).
    extra = {"command": args.command_line, "created": started, "git_commit": bench.git_commit()}
    res = bench.run(cfg, progress=not args.no_progress)
    paths = bench.write_outputs(res, cfg, out, extra)
    if args.json:
        bench.write_json(paths["json"], Path(args.json))
    print(bench.markdown(res.summary, pairs=res.pairs), end="")
    for n in res.notes:
        print(f"bench: note: {n}")
    print(f"bench: {len(res.scenes)} scenes x {len(cfg.configs)} configurations in {res.seconds:.0f} s "
          f"on {cfg.n_workers()} workers (seed {cfg.seed})")
    print("bench: wrote " + ", ".join(str(p) for p in paths.values()) + (f", {args.json}" if args.json else ""))
    errors = [r for r in res.rows if r.get("error")]
    if errors:
        first = errors[0]
        print(f"bench: error: {len(errors)} of {len(res.rows)} episodes could not be run (cause 'error', "
              f"counted as failures in the tables); first: {res.meta[first['index']]['id']} / {first['config']}: "
              f"{first['error']}", file=sys.stderr)
        return 1
    return 0


# Optional packages and the extra that brings each (py/pyproject.toml); the main job's set-up
# (scripts/setup.sh) has none of them, scripts/setup.sh --full has all.
EXTRAS = {"torch": "train", "safetensors": "train", "scipy": "test", "vehiclemodels": "test",
          "casadi": "peers", "ray": "ray"}


def _missing_extra(command: str, e: ModuleNotFoundError) -> int:
    """One line naming the missing package and how to get it (exit status 2); other missing
    modules are bugs and re-raised."""
    name = (e.name or "").split(".")[0]
    if name not in EXTRAS:
        raise e
    extra = EXTRAS[name]
    print(f"picopit {command}: error: needs the Python package '{name}' (the '{extra}' extra): "
          f"run ./scripts/setup.sh --full, or pip install 'picopit[{extra}]'", file=sys.stderr)
    return EXIT_BAD_INPUT


def main(argv: Optional[List[str]] = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    args.command_line = _command_line(argv)
    try:
        return _main(args)
    except ModuleNotFoundError as e:
        return _missing_extra(args.command, e)


def _main(args: argparse.Namespace) -> int:
    from . import ParamError
    from .simulate import ConfigError

    bad_input: tuple = (ConfigError, ParamError, OutputError)
    if args.command in ("datagen", "train", "compress", "eval-surrogates"):
        from .datagen import DatasetError
        from .surrogate_nn import ModelFileError
        from .train import TrainError

        bad_input += (DatasetError, ModelFileError, TrainError)
    if args.command == "scenarios":
        from .scenarios import ScenarioGenError
        from ._core import ScenarioError

        bad_input += (ScenarioGenError, ScenarioError)
    if args.command == "bench":
        from .bench import BenchError
        from ._core import EpisodeError, ScenarioError

        bad_input += (BenchError, EpisodeError, ScenarioError)
    if args.command in ("compare", "headroom"):
        from .compare import CompareError
        from .headroom import HeadroomError

        bad_input += (CompareError, HeadroomError)
    if args.command in ("oracle", "trace", "push-models", "seed-scatter"):
        from .oracle import OracleError
        from .seed_scatter import SeedScatterError
        from .trace import TraceError
        from ._core import EpisodeError, ScenarioError

        bad_input += (OracleError, TraceError, SeedScatterError, EpisodeError, ScenarioError)
    if args.command == "replay":
        from .replay import ReplayError

        bad_input += (ReplayError,)
    try:
        return int(args.func(args))
    except bad_input as e:
        return _bad_input(str(e))
    except KeyboardInterrupt:
        print("picopit: interrupted", file=sys.stderr)
        return 130
    except (OSError, MemoryError) as e:
        # A write that failed after the checks (a full disk, a vanished folder): one line.
        what = f"{e.filename}: {e.strerror}" if isinstance(e, OSError) and e.filename and e.strerror else str(e)
        print(f"picopit: error: {what or type(e).__name__}", file=sys.stderr)
        return EXIT_FAILED


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
