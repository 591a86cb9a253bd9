"""The benchmark's numbers (``picopit bench``): the per-configuration summary, the paired
comparison, and the tables and files they are written to.

* ``summarise``: one row of metrics per configuration (success overall, by road and adhesion
  band, heading error, safety margin, violation and collision rates, pooled planning and control
  times, failure causes, the funnel, ``by_speed``: by the target's initial speed,
  ``by_driver``: by the target driver's kind, and ``by_curve_side``: the curved scenes by the
  side of the curve the first contact came from);
* ``paired`` and ``mcnemar_exact_p``: every pair of configurations on the scenes both ran;
* ``markdown`` and ``write_csv``: ``summary.md`` and ``summary.csv``;
* ``episode_table`` and ``write_episodes``: ``episodes.parquet`` (``episodes.csv`` without
  pyarrow), one row per episode.

The failure causes (``CAUSES``, ``ERROR_CAUSE``) and adhesion bands (``BANDS``) live here, the
leaf the runner (``picopit.bench``) and the figures (``picopit.bench_figures``) both import.
"""

from __future__ import annotations

import csv
import math
from pathlib import Path
from typing import Any, Dict, Iterable, List, Mapping, Optional, Sequence, Tuple

import numpy as np

from . import funnel
from .bench_checks import finite_or_none

BANDS = ("low", "mid", "high")
# The target's initial speed (m/s): label, lower bound (inclusive), upper bound (exclusive).
SPEED_BANDS: Tuple[Tuple[str, float, float], ...] = (
    ("< 10", 0.0, 10.0), ("10–15", 10.0, 15.0), ("15–20", 15.0, 20.0), ("≥ 20", 20.0, math.inf))
# The target driver's kinds (the scenarios' ``driver.kind``), in the order the tables list them.
DRIVERS = ("none", "lane_keep", "brake", "counter_steer")
# The side of a curve a push came from (``curve_side``), in the order the tables list them.
CURVE_SIDES = ("inside", "outside")
CAUSES = ("decision_infeasible", "no_termination", "boundary_violation", "secondary_collision",
          "unsafe_rebound")
ERROR_CAUSE = "error"


# --- aggregation --------------------------------------------------------------------------


def _pct(num: int, den: int) -> Optional[float]:
    return None if den == 0 else 100.0 * num / den


def _finite(v: Any) -> Optional[float]:
    if v is None:
        return None
    v = float(v)
    return v if math.isfinite(v) else None


def _pooled(arrays: Iterable[np.ndarray], q: float) -> Optional[float]:
    arrs = [np.asarray(a, dtype=float) for a in arrays if a is not None and len(a)]
    if not arrs:
        return None
    return _finite(np.percentile(np.concatenate(arrs), q))


def summarise(rows: Sequence[Mapping[str, Any]], meta: Mapping[int, Mapping[str, Any]],
              configs: Sequence[str]) -> Dict[str, Dict[str, Any]]:
    """Per-configuration metrics (rates in %, times in ms, angles in deg, margins in m)."""
    out: Dict[str, Dict[str, Any]] = {}
    for name in configs:
        rs = [r for r in rows if r["config"] == name]
        ok = [r for r in rs if r.get("error") is None]
        n = len(rs)
        s: Dict[str, Any] = {"episodes": n, "errors": n - len(ok)}
        succ = sum(bool(r["success"]) for r in rs)
        s["successes"] = succ
        s["success_rate"] = _pct(succ, n)
        # Successes by coming to rest reversed (the rest only settled, still rolling, at T_max).
        s["success_at_rest_rate"] = _pct(sum(bool(r["success"]) and bool(r.get("at_rest")) for r in rs), n)
        for key, groups in (("road", ("straight", "curved")), ("adhesion", BANDS)):
            for g in groups:
                sub = [r for r in rs if meta[r["index"]][key] == g]
                s[f"success_{g}"] = _pct(sum(bool(r["success"]) for r in sub), len(sub))
                s[f"n_{g}"] = len(sub)
        herr_s = [r["terminal_heading_error"] for r in ok if r["success"]]
        herr_all = [r["terminal_heading_error"] for r in ok if _finite(r["terminal_heading_error"]) is not None]
        s["heading_error_deg_success_mean"] = _finite(np.degrees(np.mean(herr_s))) if herr_s else None
        s["heading_error_deg_median"] = _finite(np.degrees(np.median(herr_all))) if herr_all else None
        margins = [r["min_margin"] for r in ok if _finite(r["min_margin"]) is not None]
        s["min_margin_m_median"] = _finite(np.median(margins)) if margins else None
        s["min_margin_m_mean"] = _finite(np.mean(margins)) if margins else None
        s["boundary_violation_rate"] = _pct(sum(bool(r["boundary_violation"]) for r in ok), n)
        s["secondary_collision_rate"] = _pct(sum(bool(r["secondary_collision"]) for r in ok), n)
        s["plan_ms_median"] = _pooled((r["plan_times_ms"] for r in ok), 50)
        s["plan_ms_p99"] = _pooled((r["plan_times_ms"] for r in ok), 99)
        s["ctrl_ms_median"] = _pooled((r["ctrl_times_ms"] for r in ok), 50)
        s["ctrl_ms_p99"] = _pooled((r["ctrl_times_ms"] for r in ok), 99)
        s["plan_ms_max"] = _finite(max((r["plan_ms_max"] for r in ok if r["plan_count"]), default=None))
        s["ctrl_ms_max"] = _finite(max((r["ctrl_ms_max"] for r in ok if r["ctrl_count"]), default=None))
        s["param_count"] = ok[0]["param_count"] if ok else None
        s["model"] = ok[0]["model"] if ok else None
        s["upper_layer"] = ok[0]["upper_layer"] if ok else None
        s["contacts_mean"] = _finite(np.mean([r["contacts"] for r in ok])) if ok else None
        for c in CAUSES + (ERROR_CAUSE,):
            s[f"fail_{c}"] = _pct(sum(r.get("cause") == c for r in rs), n)
        s["funnel"] = funnel.funnel(rs)
        s["by_speed"] = by_speed(rs, meta)
        s["by_driver"] = by_driver(rs, meta)
        s["by_curve_side"] = by_curve_side(rs, meta)
        out[name] = s
    return out


def _reversed(r: Mapping[str, Any]) -> bool:
    return _finite(r.get("reversed_at")) is not None


def by_speed(rs: Sequence[Mapping[str, Any]], meta: Mapping[int, Mapping[str, Any]]) -> List[Dict[str, Any]]:
    """One configuration's episodes by the target's initial speed (``SPEED_BANDS``): how many,
    the share saved and the share turned round, and the median speed (m/s) at the moment of
    reversal of the reversed targets that were lost and of the successes: a target turned
    round with speed left rolls on backwards, and that is where fast scenes are lost."""
    out = []
    for label, lo, hi in SPEED_BANDS:
        sub = [r for r in rs if (v := _finite(meta[r["index"]].get("target_speed"))) is not None and lo <= v < hi]
        lost = [_finite(r.get("reversed_speed")) for r in sub if _reversed(r) and not r["success"]]
        won = [_finite(r.get("reversed_speed")) for r in sub if _reversed(r) and r["success"]]
        lost = [v for v in lost if v is not None]
        won = [v for v in won if v is not None]
        out.append({
            "band": label, "episodes": len(sub),
            "success_rate": _pct(sum(bool(r["success"]) for r in sub), len(sub)),
            "reversed_rate": _pct(sum(_reversed(r) for r in sub), len(sub)),
            "reversed_speed_lost_median": _finite(np.median(lost)) if lost else None,
            "reversed_speed_success_median": _finite(np.median(won)) if won else None,
        })
    return out


def by_driver(rs: Sequence[Mapping[str, Any]], meta: Mapping[int, Mapping[str, Any]]) -> List[Dict[str, Any]]:
    """One configuration's episodes by the target driver's kind (``DRIVERS``; scenes whose meta
    names no driver are left out): how many, the shares touched, turned round and saved, and the
    share of the turned-round targets that were saved (the push's work kept or lost afterwards)."""
    out = []
    for kind in DRIVERS:
        sub = [r for r in rs if meta[r["index"]].get("driver") == kind]
        out.append({"driver": kind, "episodes": len(sub),
                    "contact_rate": _pct(sum((r.get("contacts") or 0) > 0 for r in sub), len(sub)),
                    **_reversal_shares(sub)})
    return out


def _reversal_shares(sub: Sequence[Mapping[str, Any]]) -> Dict[str, Optional[float]]:
    """The shares (%) of ``sub`` turned round and saved, and of its turned-round targets saved."""
    rev = [r for r in sub if _reversed(r)]
    return {"reversed_rate": _pct(len(rev), len(sub)),
            "success_rate": _pct(sum(bool(r["success"]) for r in sub), len(sub)),
            "reversed_success_rate": _pct(sum(bool(r["success"]) for r in rev), len(rev))}


def curve_side(r: Mapping[str, Any], meta: Mapping[str, Any]) -> Optional[str]:
    """The side of its road's curve an episode's first contact came from: ``"inside"`` when the
    bullet touched the target on the side the curve turns to (the contact point's ``impact_y``,
    positive on the target's left, against the sign of the road's ``radius``, positive turning
    left), ``"outside"`` on the other; ``None`` on a straight road or without a contact."""
    turn, y = meta.get("curve"), _finite(r.get("impact_y"))
    if not turn or not (r.get("contacts") or 0) > 0 or y is None or y == 0.0:
        return None
    return "inside" if (y > 0) == (turn > 0) else "outside"


def by_curve_side(rs: Sequence[Mapping[str, Any]], meta: Mapping[int, Mapping[str, Any]]) -> List[Dict[str, Any]]:
    """One configuration's touched curved scenes by the side of the curve the first contact came
    from (``CURVE_SIDES``): how many, the shares turned round and saved, and the share of the
    turned-round targets saved. Pushed from the inside, the target's nose turns into the curve;
    from the outside it turns out, and the spin carries the target towards the outer edge."""
    out = []
    for side in CURVE_SIDES:
        sub = [r for r in rs if curve_side(r, meta[r["index"]]) == side]
        out.append({"curve_side": side, "episodes": len(sub), **_reversal_shares(sub)})
    return out


def mcnemar_exact_p(only_a: int, only_b: int) -> float:
    """Two-sided exact McNemar test: the probability, if both configurations succeed equally
    often, of a split of the discordant scenes at least as uneven (binomial, p = 1/2)."""
    n, k = only_a + only_b, min(only_a, only_b)
    if n == 0:
        return 1.0
    return min(1.0, 2 * sum(math.comb(n, j) for j in range(k + 1)) / 2 ** n)


def paired(rows: Sequence[Mapping[str, Any]], configs: Sequence[str]) -> Dict[str, Dict[str, Any]]:
    """Every pair of configurations on the scenes both ran (same scenes, same seeds): the
    scenes only the first saved, only the second, both, and the exact McNemar p-value of the
    difference. A difference in success rate with p above ~0.05 is within what the scenes'
    luck makes of two equal controllers."""
    won = {(r["config"], r["index"]): bool(r["success"]) for r in rows}
    ran = {c: {k for cc, k in won if cc == c} for c in configs}
    out: Dict[str, Dict[str, Any]] = {}
    for i, a in enumerate(configs):
        for b in configs[i + 1:]:
            scenes = ran[a] & ran[b]
            only_a = sum(won[(a, k)] and not won[(b, k)] for k in scenes)
            only_b = sum(won[(b, k)] and not won[(a, k)] for k in scenes)
            both = sum(won[(a, k)] and won[(b, k)] for k in scenes)
            out[f"{a} vs {b}"] = {"a": a, "b": b, "scenes": len(scenes), "only_a": only_a, "only_b": only_b,
                                  "both": both, "mcnemar_p": mcnemar_exact_p(only_a, only_b)}
    return out


def _fmt(v: Any, digits: int = 1) -> str:
    if v is None:
        return "–"
    if isinstance(v, bool):
        return "yes" if v else "no"
    if isinstance(v, str):
        return v
    if isinstance(v, int):
        return str(v)
    return f"{v:.{digits}f}"


MAIN_COLUMNS: Tuple[Tuple[str, str, int], ...] = (
    ("episodes", "episodes", 0),
    ("success_rate", "success %", 1),
    ("success_at_rest_rate", "at rest %", 1),
    ("success_straight", "straight %", 1),
    ("success_curved", "curved %", 1),
    ("success_low", "low μ %", 1),
    ("success_mid", "mid μ %", 1),
    ("success_high", "high μ %", 1),
    ("heading_error_deg_success_mean", "heading err. (succ.) °", 1),
    ("heading_error_deg_median", "heading err. (all, median) °", 1),
    ("min_margin_m_median", "min margin (median) m", 2),
    ("boundary_violation_rate", "boundary viol. %", 1),
    ("secondary_collision_rate", "2nd collision %", 1),
    ("plan_ms_median", "plan ms median", 2),
    ("plan_ms_p99", "plan ms p99", 2),
    ("ctrl_ms_median", "ctrl ms median", 2),
    ("ctrl_ms_p99", "ctrl ms p99", 2),
    ("param_count", "params", 0),
)
CAUSE_COLUMNS: Tuple[Tuple[str, str, int], ...] = tuple(
    (f"fail_{c}", c.replace("_", " ") + " %", 1) for c in CAUSES + (ERROR_CAUSE,)
)

SPEED_COLUMNS: Tuple[Tuple[str, str, int], ...] = (
    ("band", "target speed", 0),
    ("episodes", "episodes", 0),
    ("success_rate", "success %", 1),
    ("reversed_rate", "reversed %", 1),
    ("reversed_speed_lost_median", "speed at reversal, lost", 1),
    ("reversed_speed_success_median", "speed at reversal, success", 1),
)
# The columns of ``_reversal_shares``.
REVERSAL_SHARE_COLUMNS: Tuple[Tuple[str, str, int], ...] = (
    ("reversed_rate", "reversed %", 1),
    ("success_rate", "success %", 1),
    ("reversed_success_rate", "reversed → success %", 1),
)
DRIVER_COLUMNS: Tuple[Tuple[str, str, int], ...] = (
    ("driver", "driver", 0),
    ("episodes", "episodes", 0),
    ("contact_rate", "contact %", 1),
) + REVERSAL_SHARE_COLUMNS
CURVE_SIDE_COLUMNS: Tuple[Tuple[str, str, int], ...] = (
    ("curve_side", "first contact from", 0),
    ("episodes", "episodes", 0),
) + REVERSAL_SHARE_COLUMNS


def markdown(summary: Mapping[str, Mapping[str, Any]], header: str = "",
             pairs: Optional[Mapping[str, Mapping[str, Any]]] = None) -> str:
    lines = [header] if header else []

    def table(cols: Sequence[Tuple[str, str, int]], groups: Optional[str] = None) -> None:
        """One row per configuration, or with ``groups`` one per entry of its list of that name."""
        lines.append("| config | " + " | ".join(c[1] for c in cols) + " |")
        lines.append("|---|" + "---|" * len(cols))
        for name, s in summary.items():
            for row in (s.get(groups, ()) if groups else (s,)):
                lines.append(f"| {name} | " + " | ".join(_fmt(row.get(k), d) for k, _, d in cols) + " |")
        lines.append("")

    table(MAIN_COLUMNS)
    lines.append("Failure causes (first cause, % of the configuration's episodes):")
    lines.append("")
    table(CAUSE_COLUMNS)
    lines.append("Funnel (scenes → first contact → target reversed → success) and where the "
                 "episodes were lost, by first cause and who failed:")
    lines.append("")
    lines.append(funnel.markdown({name: s["funnel"] for name, s in summary.items() if "funnel" in s}))
    lines.append("")
    lines.append("By the target's initial speed (m/s): success and reversed shares, and the median speed "
                 "(m/s) at the moment of reversal of the reversed targets lost afterwards and of the "
                 "successes:")
    lines.append("")
    table(SPEED_COLUMNS, "by_speed")
    lines.append("By the target driver's kind: the shares touched, turned round and saved, and the share of "
                 "the turned-round targets saved:")
    lines.append("")
    table(DRIVER_COLUMNS, "by_driver")
    lines.append("Curved scenes with a contact, by the side of the curve the first contact came from "
                 "(inside: the bullet on the side the road turns to): the shares turned round and saved, "
                 "and the share of the turned-round targets saved:")
    lines.append("")
    table(CURVE_SIDE_COLUMNS, "by_curve_side")
    if pairs:
        lines.append("Paired comparison (the same scenes and seeds; exact McNemar test on the scenes "
                     "only one of the two saved):")
        lines.append("")
        lines.append("| A | B | scenes | A only | B only | both | p |")
        lines.append("|---|---|---|---|---|---|---|")
        for p in pairs.values():
            lines.append(f"| {p['a']} | {p['b']} | {p['scenes']} | {p['only_a']} | {p['only_b']} | {p['both']} "
                         f"| {p['mcnemar_p']:.3g} |")
        lines.append("")
    return "\n".join(lines)


def write_csv(summary: Mapping[str, Mapping[str, Any]], path: Path) -> None:
    """The scalar metrics, one row per configuration (the funnel's stage counts flattened to
    ``funnel_<stage>``; its losses, the speed bands, the drivers and the curve sides are in
    summary.json and summary.md)."""
    flat = {name: {**{k: v for k, v in s.items() if k not in ("funnel", "by_speed", "by_driver", "by_curve_side")},
                   **{f"funnel_{st}": s["funnel"][st] for st in funnel.STAGES if "funnel" in s}}
            for name, s in summary.items()}
    summary = flat
    keys = sorted({k for s in summary.values() for k in s})
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["config"] + keys)
        for name, s in summary.items():
            w.writerow([name] + ["" if s.get(k) is None else s.get(k) for k in keys])


EPISODE_FIELDS = ("config", "index", "scenario", "category", "road", "adhesion", "params", "driver",
                  "curve_side", "mu",
                  "target_speed",
                  "seed", "model", "param_count", "upper_layer", "success", "at_rest", "cause", "decided_at",
                  "terminal_heading_error", "min_margin", "boundary_violation", "secondary_collision",
                  "contacts", "contact_at", "impact_speed", "impact_angle", "impact_x", "impact_y", "reversed_at",
                  "reversed_speed", "failed_vehicle", "sim_time", "control_steps", "plan_count",
                  "plan_ms_median", "plan_ms_p99", "plan_ms_max", "ctrl_count", "ctrl_ms_median",
                  "ctrl_ms_p99", "ctrl_ms_max",
                  "final_phase", "abort", "mpc_failures", "mpc_time_budget", "held_back_until", "wall_time", "error")


def episode_table(rows: Sequence[Mapping[str, Any]], meta: Mapping[int, Mapping[str, Any]]) -> List[Dict[str, Any]]:
    out = []
    for r in rows:
        m = meta[r["index"]]
        d = {k: r.get(k) for k in EPISODE_FIELDS}
        d.update(scenario=m["id"], category=m["category"], road=m["road"], adhesion=m["adhesion"],
                 params=m["params"], driver=m.get("driver"), curve_side=curve_side(r, m), mu=m["mu"],
                 target_speed=m.get("target_speed"))
        out.append(finite_or_none(d))
    return out


def write_episodes(table: Sequence[Mapping[str, Any]], out: Path) -> Tuple[Path, Optional[str]]:
    """Parquet when pyarrow is importable, else CSV; returns (path, note)."""
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq
    except ImportError:
        path = out / "episodes.csv"
        with open(path, "w", newline="") as fh:
            w = csv.DictWriter(fh, fieldnames=list(EPISODE_FIELDS))
            w.writeheader()
            w.writerows(table)
        return path, "pyarrow is not installed: per-episode results written as CSV, not Parquet"
    cols = {k: [row.get(k) for row in table] for k in EPISODE_FIELDS}
    schema = pa.schema([
        (k, pa.string()) if k in ("config", "scenario", "category", "road", "adhesion", "params", "driver",
                                  "curve_side", "model", "cause", "failed_vehicle", "final_phase", "abort", "error")
        else (k, pa.bool_()) if k in ("upper_layer", "success", "at_rest", "boundary_violation", "secondary_collision")
        else (k, pa.uint64()) if k == "seed"
        else (k, pa.int64()) if k in ("index", "param_count", "contacts", "control_steps", "plan_count",
                                      "ctrl_count", "mpc_failures", "mpc_time_budget")
        else (k, pa.float64())
        for k in EPISODE_FIELDS
    ])
    path = out / "episodes.parquet"
    pq.write_table(pa.table(cols, schema=schema), path)
    return path, None
