"""The half-scale trials over IPC (``picopit trials --half-scale``).

Every run starts the two release binaries, ``pit-vehicle`` (plant, sensing, judge) and
``pit-controller``, on a fresh iceoryx2 service prefix, by default in lock step on a
simulated clock (``--realtime``: both on the wall clock), and reads their JSON summaries.
Per case (R1-R4 of ``data/trials/half_scale.jsonl``):

* one nominal run (no sensing noise, seed 0, both processes recording MCAP) -> one row of a
  table laid out like the paper's real-vehicle table (target speed, relative impact speed,
  impact angle, terminal heading error, outcome), and an "Overall" row;
* K repeats under noise (``--noise paper --latency S``, seeds 1..K) -> the success rate with
  a Wilson 95 % interval and the heading error's mean and standard deviation.

Outputs (the run folder): ``trials.md`` (the tables, the command line, git commit, machine),
``trials.csv`` (one row per run), ``trials.json`` (``{"cases": {"R1": {..., "repeats": {...}}},
"overall": {...}, "runs": [...], "run": {...}}``), ``trials.png`` and, per case and run,
``<case>/<run>/`` with both summaries, both processes' logs and (nominal runs) their MCAP
recordings ``vehicle.mcap`` and ``controller.mcap`` for ``picopit replay``.

This module is the command: the options (``build_config``), the run and its outputs (``run``).
The parts live in ``picopit.trials_config`` (binaries, scenarios, ``TrialsConfig``, the plan),
``picopit.trials_run`` (the processes), ``picopit.trials_rows`` (one run's row) and
``picopit.trials_report`` (statistics, tables, files, figure); the names tests and the CLI use
are importable from here too.
"""

from __future__ import annotations

import datetime as _dt
import time
from pathlib import Path
from typing import Any, Dict, List, Optional, Tuple

from .outputs import check_dir, check_file
from .trials_config import (ERROR_CAUSE, HALF_SCALE_CONTROLLER, HALF_SCALE_SCENARIOS, TrialsConfig, TrialsError,
                            cfg_scenario, find_bin_dir, load_cases, parse_cases, repo_root)
from .trials_report import summarise, write_outputs
from .trials_run import run_all

# picopit.trials's names from before the split (the CLI and the tests use them from here).
from .trials_config import Trial  # noqa: F401
from .trials_report import nominal_table, repeats_table, runs_table, wilson  # noqa: F401
from .trials_run import commands  # noqa: F401


# --- the command --------------------------------------------------------------------------


def machine() -> str:
    from .bench import machine as _machine

    return _machine()


def git_commit() -> str:
    from .bench import git_commit as _git_commit

    return _git_commit()


def default_out() -> Path:
    return Path("runs") / ("trials-" + _dt.datetime.now(_dt.timezone.utc).strftime("%Y%m%d-%H%M%SZ"))


def build_config(args: Any) -> TrialsConfig:
    """A ``TrialsConfig`` from the ``picopit trials`` options (raises ``TrialsError``)."""
    root = repo_root()
    if not args.half_scale and not args.scenarios:
        raise TrialsError("no trial set given: use --half-scale (data/trials/half_scale.jsonl with "
                          "configs/controller_half_scale.toml) or --scenarios FILE")

    def resolve(opt: Optional[str], default: Path, name: str) -> Path:
        if opt:
            return Path(opt).resolve()
        if root is None:
            raise TrialsError(f"cannot find the source tree (for {default}) above {Path.cwd()}; give {name}")
        return root / default

    scenarios = resolve(args.scenarios, HALF_SCALE_SCENARIOS, "--scenarios")
    # Without --half-scale the controller keeps its built-in (full-size) settings.
    ctl_cfg = (resolve(args.controller_config, HALF_SCALE_CONTROLLER, "--controller-config")
               if args.half_scale or args.controller_config else None)
    known = load_cases(scenarios)
    cases = parse_cases(args.cases, list(known))
    bin_dir = find_bin_dir(args.bin_dir)
    cfg = TrialsConfig(scenarios=scenarios, controller_config=ctl_cfg, bin_dir=bin_dir, cases=cases,
                       repeats=args.repeats, noise=args.noise, latency=args.latency, realtime=args.realtime,
                       jobs=args.jobs, timeout=args.timeout, model=args.model,
                       delay_compensation=not getattr(args, "no_delay_compensation", False),
                       cwd=root if root is not None else Path.cwd(),
                       t_max={c: float(known[c].get("t_max", 10.0)) for c in cases})
    return cfg.validate()


def run(args: Any, command: str) -> Tuple[Dict[str, Any], List[Dict[str, Any]], Dict[str, Path]]:
    """``picopit trials``: run, summarise, write; returns the summary, the rows and the paths."""
    cfg = build_config(args)
    # Absolute: the processes run from the source tree, not from here.
    out = check_dir((Path(args.out) if args.out else default_out()).resolve(), "--out")
    if args.json:
        check_file(args.json, "--json")
    info: Dict[str, Any] = {
        "command": command, "created": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
        "git_commit": git_commit(), "machine": machine(), "scenarios": str(cfg.scenarios),
        "controller_config": str(cfg.controller_config or "built-in"), "bin_dir": str(cfg.bin_dir), "cases": cfg.cases,
        "repeats": cfg.repeats, "noise": cfg.noise, "latency": cfg.latency,
        "clock": "wall" if cfg.realtime else "simulated", "jobs": cfg.jobs, "model": cfg.model,
        "delay_compensation": cfg.delay_compensation,
    }
    t0 = time.perf_counter()
    rows = run_all(cfg, out, progress=not args.no_progress)
    info["seconds"] = round(time.perf_counter() - t0, 2)
    summary = summarise(rows, cfg.cases)
    notes = []
    n_err = sum(r["cause"] == ERROR_CAUSE for r in rows)
    if n_err:
        notes.append(f"{n_err} run(s) did not complete (cause 'error'); see the logs in their folders: "
                     + ", ".join(f"{r['dir']} ({r['error']})" for r in rows if r["cause"] == ERROR_CAUSE)[:1500])
    info["notes"] = notes
    eps = [cfg_scenario(cfg, c).get("eps_psi") for c in cfg.cases]
    eps_psi = eps[0] if eps and all(e == eps[0] for e in eps) else None
    paths = write_outputs(summary, rows, info, out, Path(args.json) if args.json else None,
                          figure=not args.no_figures, eps_psi=eps_psi)
    return summary, rows, paths
