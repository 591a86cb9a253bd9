"""One ``picopit trials`` run's row: what the vehicle's and the controller's JSON summaries
say (outcome, the paper's table columns in km/h and degrees, IPC and controller timing,
faults), with the run's errors, wall time and files (``make_row``).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Dict, Mapping, Optional, Sequence

from .trials_config import ERROR_CAUSE, Trial, TrialsConfig, cfg_scenario

KMH = 3.6


def _num(v: Any) -> Optional[float]:
    if v is None or isinstance(v, bool):
        return None
    try:
        f = float(v)
    except (TypeError, ValueError):
        return None
    return f if math.isfinite(f) else None


def _scaled(v: Any, k: float) -> Optional[float]:
    f = _num(v)
    return None if f is None else f * k


def make_row(cfg: TrialsConfig, t: Trial, vs: Optional[Mapping[str, Any]], cs: Optional[Mapping[str, Any]],
             errors: Sequence[str], wall: float, run_dir: Path, out: Path) -> Dict[str, Any]:
    vs = vs or {}
    cs = cs or {}
    m = vs.get("metrics") or {}
    sc = cfg_scenario(cfg, t.case)
    success = bool(vs.get("success", m.get("success", False))) and not errors
    cause = None if success else (ERROR_CAUSE if errors else (vs.get("cause") or m.get("cause")
                                                             or (vs.get("ending") and f"undecided ({vs['ending']})")
                                                             or "undecided"))
    ipc, rt = vs.get("ipc_us") or {}, vs.get("round_trip_ms") or {}
    cyc, pl = cs.get("cycle_ms") or {}, cs.get("plan_ms") or {}
    rel = lambda p: str(p.relative_to(out)) if p.exists() else None  # noqa: E731
    return {
        "case": t.case, "kind": t.kind, "seed": t.seed, "noise": t.noise, "latency": t.latency,
        "clock": "wall" if cfg.realtime else "simulated",
        "success": success, "cause": cause, "outcome": "success" if success else cause,
        "target_kmh": _scaled(sc.get("target", {}).get("vx"), KMH),
        "impact_kmh": _scaled(m.get("impact_speed"), KMH),
        "impact_angle_deg": _scaled(m.get("impact_angle"), 180.0 / math.pi),
        "heading_error_rad": _num(m.get("terminal_heading_error")),
        "decided_at": _num(m.get("decided_at")), "contacts": m.get("contacts"),
        "min_margin": _num(m.get("min_margin")),
        "vehicle_ending": vs.get("ending"), "controller_ending": cs.get("ending"),
        "time": _num(vs.get("time")), "periods": vs.get("periods"),
        "commands_stale": vs.get("commands_stale"), "lockstep_misses": vs.get("lockstep_misses"),
        "safe_stop": vs.get("safe_stop"),
        "ipc_us_median": _num(ipc.get("median")), "ipc_us_p99": _num(ipc.get("p99")),
        "round_trip_ms_median": _num(rt.get("median")), "round_trip_ms_p99": _num(rt.get("p99")),
        "cycle_ms_median": _num(cyc.get("median")), "cycle_ms_p99": _num(cyc.get("p99")),
        "cycle_ms_max": _num(cyc.get("max")),
        "plan_ms_median": _num(pl.get("median")), "plan_ms_p99": _num(pl.get("p99")),
        "cycles": cs.get("cycles"), "solves": cs.get("solves"), "fallbacks": cs.get("fallbacks"),
        "deadline_misses": cs.get("deadline_misses"), "solver_failures": cs.get("solver_failures"),
        "controller_peak_rss_kib": cs.get("peak_rss_kib"),
        "wall_s": round(wall, 3), "error": "; ".join(errors) or None,
        "dir": str(run_dir.relative_to(out)),
        "vehicle_mcap": rel(run_dir / "vehicle.mcap"), "controller_mcap": rel(run_dir / "controller.mcap"),
    }
