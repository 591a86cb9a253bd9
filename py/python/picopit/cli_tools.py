"""The analysis subcommands of the ``picopit`` command line: ``oracle`` (the ideal-PIT bound
and its tiers), ``trace`` (one episode step by step), ``push-models`` (the models and the
plans against the pushes a run delivered), ``compare`` (two benchmark runs scene
by scene), ``headroom`` (a run against the bound) and ``seed-scatter`` (the surrogates' accuracy over training seeds). Same
conventions as ``cli``: bad input is one line and exit status 2 (``OracleError``,
``TraceError``, ``CompareError``, ``HeadroomError`` and the core's errors are bad input there), work that could
not be completed exit status 1."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from .outputs import check_dir, check_file

DEFAULT_SCENARIOS = "data/scenarios.jsonl"


def add_parsers(sub) -> None:
    _oracle_parser(sub)
    _trace_parser(sub)
    _push_models_parser(sub)
    _compare_parser(sub)
    _headroom_parser(sub)
    _seed_scatter_parser(sub)


def _oracle_parser(sub) -> None:
    p = sub.add_parser(
        "oracle",
        help="the ideal-PIT bound: could any single rear-quarter shove save each scene?",
        description=(
            "The ideal-PIT bound, a physics ceiling for the benchmark: for each scene, whether one "
            "instantaneous rear-quarter shove of the grid (sizes x candidate times from the "
            "bullet's earliest arrival x both sides) ends in success by the benchmark's test. "
            "Prints the share of feasible scenes overall and by category, adhesion, driver and "
            "parameter set. --tiers simulates the whole grid with the driver's true law and with "
            "its command held and reports how much of the bound a controller could reach when its "
            "push lands a step off, or when it sees only the driver's current command."
        ),
    )
    p.add_argument("--scenarios", default=DEFAULT_SCENARIOS, metavar="JSONL",
                   help=f"scenario file (default {DEFAULT_SCENARIOS}; the textbook set: data/textbook/scenarios.jsonl)")
    p.add_argument("--first", type=int, default=0, metavar="K", help="skip the first K scenes (default 0)")
    p.add_argument("--n", type=int, default=None, metavar="N", help="at most N scenes (default: all)")
    p.add_argument("--ids", metavar="LIST", help="comma-separated scene ids instead of --first/--n")
    p.add_argument("--subset", type=int, metavar="N",
                   help="the benchmark's stratified subset of N scenes (as picopit bench picks its "
                        "default 128) instead of --first/--n")
    p.add_argument("--params", metavar="NAME",
                   help="only the chosen scenes of this parameter set (full_size or half_scale)")
    p.add_argument("--tiers", action="store_true",
                   help="the tiers (the whole grid twice per scene; default grid 10 sizes 0.4-3.15 m/s "
                        "every 0.1 s)")
    p.add_argument("--settings", metavar="JSON",
                   help="oracle settings over the defaults, e.g. '{\"shoves\": [0.5, 1, 2, 3], "
                        "\"time_step\": 0.1}' (fields: shoves, time_step, contact_back, min_remaining, "
                        "exhaustive, sides, window, bullet_beside)")
    p.add_argument("--sides-of", metavar="RUN",
                   help="a picopit bench run (folder or episodes file): try each scene its controller "
                        "pushed only on the side it pushed from (the others on both sides)")
    p.add_argument("--config", metavar="NAME",
                   help="the configuration of --sides-of or --grid-run (default picopinn)")
    p.add_argument("--grid-plot", metavar="DIR",
                   help="instead of the bound: simulate every shove of the grid (default 10 sizes "
                        "0.4-3.15 m/s every 0.1 s, both sides) on each chosen scene (at most 20; 5-15 s "
                        "each) and draw its success map to DIR/<scene>_shoves.png, with one "
                        "line per scene: how many succeed and the widest band of sizes at one time")
    p.add_argument("--at-contact", metavar="RUN",
                   help="instead of the bound: for each chosen scene a picopit bench run's configuration "
                        "touched, every size of the grid shoved at the candidate time nearest its first "
                        "contact, from the side it came from; prints, by where the episode ended, how "
                        "often some size (and two or more adjacent sizes) would have saved the scene there")
    p.add_argument("--grid-run", metavar="RUN",
                   help="with --grid-plot: a picopit bench run (folder or episodes file) whose "
                        "configuration's first contact is marked on the map, with the sizes that "
                        "would have saved the scene there")
    p.add_argument("--workers", type=int, default=1, metavar="W", help="scenes at a time (threads; default 1)")
    p.add_argument("--scene-lines", action="store_true", help="also print one line per scene")
    p.add_argument("--json", metavar="PATH", help="write the settings, per-scene results and summary here")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=_cmd_oracle)


def _cmd_oracle(args: argparse.Namespace) -> int:
    from . import _core, oracle

    if args.workers < 1:
        raise oracle.OracleError(f"--workers {args.workers}: need at least 1")
    if args.json:
        check_file(args.json, "--json")
    settings = oracle.resolve_settings(args.settings, args.tiers)
    scenarios = _core.load_scenarios(str(args.scenarios))
    ids = [i.strip() for i in args.ids.split(",") if i.strip()] if args.ids else None
    if args.subset is not None and (ids or args.n is not None or args.first):
        raise oracle.OracleError("--subset: give it alone, not with --ids, --first or --n")
    scenes = oracle.select(scenarios, args.first, args.n, ids, args.subset)
    if args.params is not None:
        kept = [s for s in scenes if s.get("params") == args.params]
        if not kept:
            found = sorted({str(s.get("params")) for s in scenes})
            raise oracle.OracleError(f"--params {args.params}: none of the chosen scenes (they are {', '.join(found)})")
        scenes = kept
    if args.config is not None and not (args.sides_of or args.grid_run or args.at_contact):
        raise oracle.OracleError(f"--config {args.config}: only with --sides-of RUN, --grid-run RUN or "
                                 "--at-contact RUN")
    config = args.config or "picopinn"
    if args.grid_run and not args.grid_plot:
        raise oracle.OracleError("--grid-run: only with --grid-plot DIR")
    if args.grid_plot and args.at_contact:
        raise oracle.OracleError("--at-contact: not with --grid-plot")
    if args.grid_plot:
        return _grid_plots(args, scenes, config)
    if args.at_contact:
        return _at_contact(args, scenes, config)
    sides = oracle.sides_of(Path(args.sides_of), config) if args.sides_of else None
    res = oracle.run(scenes, settings, tiers=args.tiers, workers=args.workers, progress=not args.no_progress,
                     sides=sides)
    if args.scene_lines:
        for s in res.scenes:
            print(res.line(s))
    grid = f"shoves {settings['shoves']} m/s every {settings['time_step']} s"
    print(f"oracle{' tiers' if args.tiers else ''}: {len(scenes)} scenes of {args.scenarios}, {grid}")
    if sides is not None:
        held = sum(1 for s in scenes if s["id"] in sides)
        print(f"oracle: {held} of them tried only on the side {config} pushed from in {args.sides_of}")
    print(res.markdown(), end="")
    if args.json:
        print(f"oracle: wrote {oracle.write_json(res, Path(args.json))}")
    errors = [s for s in res.scenes if s["error"] is not None]
    if errors:
        print(f"picopit oracle: {len(errors)} scenes errored, the first: {errors[0]['id']}: {errors[0]['error']}",
              file=sys.stderr)
        return 1
    return 0


def _grid_plots(args: argparse.Namespace, scenes, config: str) -> int:
    from . import oracle, oracle_grid

    if args.tiers or args.sides_of or args.json:
        raise oracle.OracleError("--grid-plot: not with --tiers, --sides-of or --json")
    if len(scenes) > oracle_grid.MAX_SCENES:
        raise oracle.OracleError(f"--grid-plot: {len(scenes)} scenes chosen; at most {oracle_grid.MAX_SCENES} "
                                 "(name them with --ids)")
    settings = oracle.resolve_settings(args.settings, tiers=True)
    marks = oracle_grid.first_contacts(Path(args.grid_run), config) if args.grid_run else {}
    out = check_dir(args.grid_plot, "--grid-plot")
    for sc in scenes:
        m = oracle_grid.shove_map(sc, settings)
        mark = marks.get(sc["id"])
        path = oracle_grid.plot(m, out / f"{sc['id']}_shoves.png", mark)
        print(m.line(mark))
        print(f"oracle: wrote {path}")
    return 0


def _at_contact(args: argparse.Namespace, scenes, config: str) -> int:
    import json

    from . import oracle, oracle_grid

    if args.tiers or args.sides_of:
        raise oracle.OracleError("--at-contact: not with --tiers or --sides-of")
    settings = oracle.resolve_settings(args.settings, tiers=True)
    marks = oracle_grid.first_contacts(Path(args.at_contact), config, "--at-contact")
    res = oracle_grid.at_contact(scenes, marks, settings, workers=args.workers, progress=not args.no_progress)
    print(f"oracle at contact: {len(res.rows)} of {len(scenes)} scenes touched by {config} in {args.at_contact}, "
          f"shoves {settings['shoves']} m/s at the candidate time (every {settings['time_step']} s) nearest "
          "the first contact, from its side")
    print(res.markdown(), end="")
    if args.json:
        Path(args.json).write_text(json.dumps({"settings": res.settings, "summary": res.summary(),
                                               "scenes": res.rows}, indent=1) + "\n")
        print(f"oracle: wrote {args.json}")
    return 0


def _trace_parser(sub) -> None:
    p = sub.add_parser(
        "trace",
        help="one closed-loop episode step by step: both vehicles on the road, phase, command, contact",
        description=(
            "Run one episode of the benchmark with its trajectory recorded and print it step by "
            "step: time, phase, contact, the bullet's lead along the road (ds), each vehicle's "
            "lateral offset d and heading relative to the road (deg) and speed (T: target, B: "
            "bullet), the bullet's command and the contact force; then the episode's metrics. "
            "Every EVERY-th step is shown, and every step in contact or where the phase changes."
        ),
    )
    p.add_argument("scene", metavar="SCENE", help="scene id (e.g. sc-00000), or its 0-based position in the file")
    p.add_argument("--scenarios", default=DEFAULT_SCENARIOS, metavar="JSONL",
                   help=f"scenario file (default {DEFAULT_SCENARIOS}; the half-scale trials: "
                        "data/trials/half_scale.jsonl)")
    p.add_argument("--config", default="picopinn", metavar="NAME|JSON",
                   help="a preset (4dof, pinn, picopinn, picopinn_no_upper) or a JSON configuration "
                        "as picopit bench takes it (default picopinn)")
    p.add_argument("--controller-config", metavar="TOML",
                   help="controller settings over the configuration's (e.g. configs/controller_half_scale.toml)")
    p.add_argument("--clock", choices=("simulated", "wall"), default="simulated",
                   help="the controller's time budgets (default simulated: the trace repeats to the step)")
    p.add_argument("--seed", type=int, default=0, help="episode seed (noise, actuator errors; default 0)")
    p.add_argument("--models", default="models", metavar="DIR", help="model folder (default models)")
    p.add_argument("--every", type=int, default=2, metavar="N", help="show every N-th step (default 2)")
    p.add_argument("--plans", action="store_true",
                   help="also list the upper layer's plans (mode and, for an abort, why; side; planned push: window, "
                        "peak force, impulse; predicted heading error; how far the target then was from the "
                        "prediction, in metres and degrees, at the prediction's last recorded step)")
    p.add_argument("--push-models", action="store_true",
                   help="also step the target models (4-DOF, PINN, PicoPINN of --models) through the first push "
                        "as it happened (the recorded contact and driver commands, from the state before the "
                        "contact to 2 s past the push) beside the truth and the plan made before the contact: "
                        "whether a prediction's error is the model's or the planned push's")
    p.add_argument("--csv", metavar="PATH", help="write every step, with the road-frame columns, as CSV")
    p.add_argument("--plot", metavar="PNG", help="draw the episode (paths, yaw, speed, command, contact)")
    p.set_defaults(func=_cmd_trace)


def _cmd_trace(args: argparse.Namespace) -> int:
    from . import trace as tr

    if args.every < 1:
        raise tr.TraceError(f"--every {args.every}: need at least 1")
    for opt in ("csv", "plot"):
        if getattr(args, opt):
            check_file(getattr(args, opt), f"--{opt}")
    if args.controller_config and not Path(args.controller_config).is_file():
        raise tr.TraceError(f"--controller-config {args.controller_config}: no such file")
    scene = tr.find_scene(Path(args.scenarios), args.scene)
    t = tr.trace(scene, args.config, seed=args.seed, models=Path(args.models), clock=args.clock,
                 controller_toml=Path(args.controller_config) if args.controller_config else None)
    print(t.header())
    print(t.table(args.every))
    if args.plans:
        print("\n".join(t.plan_lines()))
    if args.push_models:
        print("\n".join(t.push_model_lines(Path(args.models))))
    print(t.metrics())
    if args.csv:
        print(f"trace: wrote {t.write_csv(Path(args.csv))}")
    if args.plot:
        from .bench_figures import plot_case

        plot_case({"trajectory": t.trajectory}, scene, Path(args.plot), f"{scene['id']}: {args.config}")
        print(f"trace: wrote {args.plot}")
    return 0


def _push_models_parser(sub) -> None:
    p = sub.add_parser(
        "push-models",
        help="the target models and the plans against the pushes a bench run delivered",
        description=(
            "Trace a seeded random sample of a picopit bench run's episodes that touched the target "
            "(simulated clock) and step the target models (4-DOF, PINN, PicoPINN) through each first "
            "push as it happened, as picopit trace --push-models does. For the pushes that turned the "
            "target more than 10 deg, print the turn each model (given the delivered push) and the plan "
            "made before the contact (given its own push) predict at the push's end, as a multiple of "
            "the truth's: median and 10 and 90 % quantiles."
        ),
    )
    p.add_argument("run", metavar="RUN", help="a picopit bench run folder (its episodes.parquet or .csv) or file")
    p.add_argument("--scenarios", default=DEFAULT_SCENARIOS, metavar="JSONL",
                   help=f"the run's scenario file (default {DEFAULT_SCENARIOS})")
    p.add_argument("--config", default="picopinn", metavar="NAME",
                   help="the run's configuration to trace (a preset; default picopinn)")
    p.add_argument("--params", default="full_size", choices=("full_size", "half_scale"),
                   help="the parameter set of the scenes drawn (default full_size)")
    p.add_argument("--n", type=int, default=300, help="episodes drawn (default 300)")
    p.add_argument("--seed", type=int, default=1, help="seed of the draw (default 1)")
    p.add_argument("--models", default="models", metavar="DIR", help="model folder (default models)")
    p.add_argument("--workers", type=int, default=2, help="episodes at a time (threads; default 2)")
    p.add_argument("--json", metavar="PATH", help="also write the summary and every push as JSON here")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=_cmd_push_models)


def _cmd_push_models(args: argparse.Namespace) -> int:
    import json

    from . import push_models as pmod

    if args.json:
        check_file(args.json, "--json")
    result = pmod.survey(Path(args.run), Path(args.scenarios), args.config, args.params, n=args.n, seed=args.seed,
                         models=Path(args.models), workers=args.workers, progress=not args.no_progress)
    print("\n".join(pmod.lines(result)))
    if args.json:
        Path(args.json).write_text(json.dumps(result, indent=1))
        print(f"push-models: wrote {args.json}")
    return 0


def _compare_parser(sub) -> None:
    p = sub.add_parser(
        "compare",
        help="two benchmark runs scene by scene: successes, scenes only one saved, exact McNemar p",
        description=(
            "Pair the episodes of two picopit bench runs by configuration and scene id (the "
            "scenes both ran) and print, for every configuration both ran and pooled over them, "
            "the successes of each run, the scenes only one of them saved and the two-sided exact "
            "McNemar p-value of that split; where both runs have the funnel's columns, the "
            "scenes whose outcome moved, counted by the stage each run ended them in (success, or "
            "lost before contact, in the push or after reversal). Run both with --clock "
            "simulated: a wall-clock run repeats only as far as the machine's load allows."
        ),
    )
    p.add_argument("run_a", metavar="A", help="a run folder (its episodes.parquet or .csv) or an episodes file")
    p.add_argument("run_b", metavar="B", help="the other run")
    _table_args(p, "every one both runs ran")
    p.set_defaults(func=_cmd_compare)


def _table_args(p, every: str) -> None:
    """``--configs`` (default: ``every``) and ``--json`` of a command that prints rows."""
    p.add_argument("--configs", metavar="LIST", help=f"comma-separated configurations (default: {every})")
    p.add_argument("--json", metavar="PATH", help="also write the rows as JSON here")


def _cmd_compare(args: argparse.Namespace) -> int:
    from . import compare as cmp

    if args.json:
        check_file(args.json, "--json")
    configs = _configs(args.configs, cmp.CompareError)
    fa, fb = cmp.episodes_file(Path(args.run_a)), cmp.episodes_file(Path(args.run_b))
    ra, rb = cmp.read_rows(fa), cmp.read_rows(fb)
    rows = cmp.compare(cmp.episodes_of(ra, fa), cmp.episodes_of(rb, fb), configs)
    print(cmp.markdown(rows, str(fa), str(fb)), end="")
    head: dict = {"a": str(fa), "b": str(fb)}
    sa, sb = cmp.stages_of(ra, fa), cmp.stages_of(rb, fb)
    if sa is not None and sb is not None:
        moved = cmp.moves(sa, sb, [r.config for r in rows if r.config != "pooled"])
        print(cmp.markdown_moves(moved), end="")
        head["moves"] = {c: [{"a": x, "b": y, "scenes": n} for x, y, n in m] for c, m in moved.items()}
    _write_rows(args.json, "compare", head, rows)
    return 0


def _configs(arg, error):
    """The configurations of a ``--configs LIST`` (None if not given); an empty list is
    ``error``."""
    configs = [c.strip() for c in arg.split(",") if c.strip()] if arg else None
    if arg is not None and not configs:
        raise error("--configs: empty list")
    return configs


def _write_rows(path, command: str, head: dict, rows) -> None:
    """Write ``head`` and the rows (their ``as_dict``) as JSON to ``path``, if given."""
    if path:
        import json

        Path(path).write_text(json.dumps({**head, "rows": [r.as_dict() for r in rows]}, indent=1) + "\n")
        print(f"{command}: wrote {path}")


def _headroom_parser(sub) -> None:
    p = sub.add_parser(
        "headroom",
        help="a benchmark run against the ideal-PIT bound: the share of what a shove could save",
        description=(
            "Put a picopit oracle --json bound beside a picopit bench run: for every "
            "configuration, how many of the scenes one shove could save it saves (overall and by "
            "parameter set, road category, adhesion and target driver), and how many it saves "
            "that no single shove does; for a picopit bench run, also where the scenes a shove "
            "could save are lost (the funnel over them: before contact, in the push, after the "
            "reversal, by cause and who failed). Only the scenes the bound and every chosen "
            "configuration ran are counted."
        ),
    )
    p.add_argument("bound", metavar="BOUND", help="the bound (picopit oracle --json PATH)")
    p.add_argument("run", metavar="RUN", help="a run folder (its episodes.parquet or .csv) or an episodes file")
    _table_args(p, "every one the run ran")
    p.add_argument("--params", metavar="SET", help="only the scenes of this parameter set (e.g. full_size)")
    p.set_defaults(func=_cmd_headroom)


def _cmd_headroom(args: argparse.Namespace) -> int:
    from . import compare as cmp
    from . import headroom as hr

    if args.json:
        check_file(args.json, "--json")
    configs = _configs(args.configs, hr.HeadroomError)
    bound = hr.read_bound(Path(args.bound))
    run = cmp.episodes_file(Path(args.run))
    episodes = cmp.read_rows(run)
    rows = hr.headroom(bound, cmp.episodes_of(episodes, run), configs, args.params)
    print(f"bound: {args.bound}\nrun: {run}\n")
    print(hr.markdown(rows), end="")
    head: dict = {"bound": str(args.bound), "run": str(run)}
    if episodes and all(c in episodes[0] for c in hr.FUNNEL_COLUMNS):
        from . import funnel
        lost = hr.lost(bound, episodes, configs, args.params, str(run))
        print("\nWhere the scenes a shove could save are lost (the funnel over those scenes only):\n")
        print(funnel.markdown(lost))
        head["lost"] = lost
    _write_rows(args.json, "headroom", head, rows)
    return 0


def _seed_scatter_parser(sub) -> None:
    p = sub.add_parser(
        "seed-scatter",
        help="how the surrogates' accuracies move with the training seed (teacher vs PicoPINN)",
        description=(
            "For each SEED, train a teacher and compress a PicoPINN from it exactly as "
            "models/regenerate.sh does (same data, the seed in place of 0), evaluate both on the "
            "test split and print the errors and the ratio PicoPINN / teacher side by side. Seed 0 "
            "is the shipped pair: its evaluation is read from models/<set>/eval.json. Each trained "
            "seed writes OUT/<set>/s<SEED>/ and a models folder OUT/models_s<SEED>/ for picopit "
            "bench --models (the other set linked to the shipped models). About 10 min per seed at "
            "full size on two cores; needs the train extra."
        ),
    )
    p.add_argument("seeds", nargs="+", type=int, metavar="SEED", help="training seeds (0: the shipped pair)")
    p.add_argument("--set", dest="param_set", choices=("full_size", "half_scale"), default="full_size",
                   help="parameter set (default full_size)")
    p.add_argument("--data", metavar="DIR", help="datagen folder (default runs/surrogates/<set>/data, "
                                                  "made by models/regenerate.sh)")
    p.add_argument("--out", default="runs/seed-scatter", metavar="DIR",
                   help="output folder (default runs/seed-scatter)")
    p.add_argument("--models", default="models", metavar="DIR", help="the shipped models (default models)")
    p.set_defaults(func=_cmd_seed_scatter)


def _cmd_seed_scatter(args: argparse.Namespace) -> int:
    from . import seed_scatter

    data = Path(args.data) if args.data else Path("runs/surrogates") / args.param_set / "data"
    evals = seed_scatter.run(args.seeds, args.param_set, data, Path(args.out), Path(args.models))
    print(seed_scatter.markdown(args.seeds, evals), end="")
    return 0
