"""The ``picopit trials`` report: statistics, tables, files and figure.

* statistics: the Wilson score interval (``wilson``), the repeats' success rate and heading
  error (``repeat_stats``), and ``summarise`` (per case the nominal run, the paper's real-vehicle
  row in ``PAPER`` and the repeats; an overall entry);
* tables (Markdown): ``nominal_table`` (laid out like the paper's), ``repeats_table``,
  ``runs_table``;
* outputs: ``trials.md``, ``trials.csv``, ``trials.json`` and ``trials.png``
  (``write_outputs``).
"""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path
from typing import Any, Dict, Mapping, Optional, Sequence, Tuple

from .trials_config import ERROR_CAUSE
from .trials_rows import _num

Z95 = 1.959963984540054


# The paper's real-vehicle trials on the half-scale platform: target speed and relative impact
# speed (km/h), impact angle (deg), terminal heading error (rad), outcome.
PAPER: Dict[str, Dict[str, Any]] = {
    "R1": {"target_kmh": 7.8, "impact_kmh": 3.1, "impact_angle_deg": 21.4, "heading_error_rad": 0.182,
           "outcome": "success"},
    "R2": {"target_kmh": 8.2, "impact_kmh": 4.2, "impact_angle_deg": 24.8, "heading_error_rad": 0.209,
           "outcome": "success"},
    "R3": {"target_kmh": 7.6, "impact_kmh": 2.6, "impact_angle_deg": 18.9, "heading_error_rad": 0.074,
           "outcome": "success"},
    "R4": {"target_kmh": 8.4, "impact_kmh": 0.8, "impact_angle_deg": 10.1, "heading_error_rad": 1.127,
           "outcome": "failed (weak excitation)"},
}


# --- statistics ---------------------------------------------------------------------------


def wilson(k: int, n: int, z: float = Z95) -> Tuple[Optional[float], Optional[float]]:
    """The Wilson score interval of a binomial proportion (k successes in n), as fractions."""
    if n <= 0:
        return None, None
    if not 0 <= k <= n:
        raise ValueError(f"wilson: k = {k} not in 0..{n}")
    p = k / n
    z2 = z * z
    centre = (p + z2 / (2 * n)) / (1 + z2 / n)
    half = z / (1 + z2 / n) * math.sqrt(p * (1 - p) / n + z2 / (4 * n * n))
    # The exact ends for k = 0 and k = n (the formula leaves rounding dust there).
    return (0.0 if k == 0 else max(0.0, centre - half)), (1.0 if k == n else min(1.0, centre + half))


def _mean(xs: Sequence[Optional[float]]) -> Optional[float]:
    v = [x for x in xs if x is not None]
    return sum(v) / len(v) if v else None


def _std(xs: Sequence[Optional[float]]) -> Optional[float]:
    v = [x for x in xs if x is not None]
    if len(v) < 2:
        return 0.0 if v else None
    m = sum(v) / len(v)
    return math.sqrt(sum((x - m) ** 2 for x in v) / (len(v) - 1))


def _median(xs: Sequence[Optional[float]]) -> Optional[float]:
    v = sorted(x for x in xs if x is not None)
    if not v:
        return None
    n = len(v)
    return v[n // 2] if n % 2 else 0.5 * (v[n // 2 - 1] + v[n // 2])


def repeat_stats(rows: Sequence[Mapping[str, Any]]) -> Dict[str, Any]:
    n = len(rows)
    k = sum(bool(r["success"]) for r in rows)
    lo, hi = wilson(k, n)
    he = [r["heading_error_rad"] for r in rows]
    causes: Dict[str, int] = {}
    for r in rows:
        if not r["success"]:
            causes[str(r["cause"])] = causes.get(str(r["cause"]), 0) + 1
    return {
        "runs": n, "successes": k, "success_rate": (k / n) if n else None,
        "wilson95": [lo, hi],
        "heading_error_mean": _mean(he), "heading_error_std": _std(he),
        "impact_kmh_mean": _mean([r["impact_kmh"] for r in rows]),
        "impact_angle_deg_mean": _mean([r["impact_angle_deg"] for r in rows]),
        "causes": causes,
        "seeds": [r["seed"] for r in rows],
        "heading_errors": he,
        "fallbacks": sum(int(r["fallbacks"] or 0) for r in rows),
        "safe_stops": sum(r["safe_stop"] is not None for r in rows),
        "errors": sum(r["cause"] == ERROR_CAUSE for r in rows),
        "round_trip_ms_median": _median([r["round_trip_ms_median"] for r in rows]),
        "cycle_ms_median": _median([r["cycle_ms_median"] for r in rows]),
        "cycle_ms_p99_max": max((r["cycle_ms_p99"] for r in rows if r["cycle_ms_p99"] is not None), default=None),
    }


_NOMINAL_KEYS = ("target_kmh", "impact_kmh", "impact_angle_deg", "heading_error_rad", "success", "cause",
                 "outcome", "decided_at", "contacts", "seed", "vehicle_ending", "controller_ending",
                 "round_trip_ms_median", "round_trip_ms_p99", "cycle_ms_median", "cycle_ms_p99", "fallbacks",
                 "deadline_misses", "safe_stop", "error", "vehicle_mcap", "controller_mcap", "dir")


def summarise(rows: Sequence[Mapping[str, Any]], cases: Sequence[str]) -> Dict[str, Any]:
    """``{"cases": {id: {nominal fields, "paper": ..., "repeats": ...}}, "overall": ...}``."""
    out: Dict[str, Any] = {"cases": {}, "overall": {}}
    noms, reps = [], []
    for c in cases:
        nom = [r for r in rows if r["case"] == c and r["kind"] == "nominal"]
        rep = [r for r in rows if r["case"] == c and r["kind"] == "repeat"]
        entry: Dict[str, Any] = {k: nom[0][k] for k in _NOMINAL_KEYS} if nom else {}
        entry["paper"] = PAPER.get(c)
        entry["repeats"] = repeat_stats(rep) if rep else None
        out["cases"][c] = entry
        noms += nom
        reps += rep
    out["overall"]["nominal"] = {
        "cases": len(noms), "successes": sum(bool(r["success"]) for r in noms),
        "target_kmh": _mean([r["target_kmh"] for r in noms]),
        "impact_kmh": _mean([r["impact_kmh"] for r in noms]),
        "impact_angle_deg": _mean([r["impact_angle_deg"] for r in noms]),
        "heading_error_rad": _mean([r["heading_error_rad"] for r in noms]),
    }
    papers = [PAPER[c] for c in cases if c in PAPER]
    if papers:
        out["overall"]["paper"] = {
            "cases": len(papers), "successes": sum(p["outcome"] == "success" for p in papers),
            **{k: _mean([p[k] for p in papers]) for k in ("target_kmh", "impact_kmh", "impact_angle_deg",
                                                           "heading_error_rad")},
        }
    out["overall"]["repeats"] = repeat_stats(reps) if reps else None
    return out


# --- tables -------------------------------------------------------------------------------


def _f(v: Any, digits: int = 1) -> str:
    if v is None:
        return "—"
    if isinstance(v, float) and not math.isfinite(v):
        return "—"
    return f"{v:.{digits}f}"


def _cause_text(cause: Optional[str]) -> str:
    return (cause or "undecided").replace("_", " ")


def nominal_table(summary: Mapping[str, Any], paper: bool = True) -> str:
    """The paper-style table of the nominal runs (Markdown), with an Overall row."""
    head = ("| case | target speed (km/h) | relative impact speed (km/h) | impact angle (°) | "
            "heading error (rad) | outcome |")
    if paper:
        head += " paper |"
    lines = [head, "|" + "---|" * (head.count("|") - 1)]
    for c, e in summary["cases"].items():
        if not e or "success" not in e:
            continue
        outcome = "success" if e["success"] else f"failed ({_cause_text(e['cause'])})"
        line = (f"| {c} | {_f(e['target_kmh'])} | {_f(e['impact_kmh'])} | {_f(e['impact_angle_deg'])} | "
                f"{_f(e['heading_error_rad'], 3)} | {outcome} |")
        if paper:
            p = e.get("paper")
            line += (f" {p['target_kmh']:.1f} / {p['impact_kmh']:.1f}, {p['impact_angle_deg']:.1f}°, "
                     f"{p['heading_error_rad']:.3f} rad, {p['outcome']} |" if p else " — |")
        lines.append(line)
    o = summary["overall"]["nominal"]
    line = (f"| Overall | {_f(o['target_kmh'])} | {_f(o['impact_kmh'])} | {_f(o['impact_angle_deg'])} | "
            f"{_f(o['heading_error_rad'], 3)} | {o['successes']}/{o['cases']} successful |")
    if paper:
        p = summary["overall"].get("paper")
        line += (f" {p['target_kmh']:.1f} / {p['impact_kmh']:.1f}, {p['impact_angle_deg']:.1f}°, "
                 f"{p['heading_error_rad']:.3f} rad, {p['successes']}/{p['cases']} successful |" if p else " — |")
    lines.append(line)
    return "\n".join(lines) + "\n"


def _rate(st: Mapping[str, Any]) -> str:
    lo, hi = st["wilson95"]
    if st["runs"] == 0 or lo is None:
        return "—"
    return f"{st['successes']}/{st['runs']} ({100 * st['success_rate']:.0f} %, 95 % CI {100 * lo:.0f}–{100 * hi:.0f} %)"


def _causes(st: Mapping[str, Any]) -> str:
    return ", ".join(f"{_cause_text(k)} {v}" for k, v in sorted(st["causes"].items())) or "—"


def repeats_table(summary: Mapping[str, Any]) -> str:
    """Success rate (Wilson 95 % interval) and heading error of the noisy repeats."""
    head = ("| case | runs | success (Wilson 95 % CI) | heading error (rad, mean ± std) | "
            "impact speed (km/h, mean) | impact angle (°, mean) | failures | fallbacks | safe stops |")
    lines = [head, "|" + "---|" * (head.count("|") - 1)]
    entries = [(c, e["repeats"]) for c, e in summary["cases"].items() if e.get("repeats")]
    if summary["overall"].get("repeats"):
        entries.append(("Overall", summary["overall"]["repeats"]))
    for c, st in entries:
        he = "—" if st["heading_error_mean"] is None else \
            f"{st['heading_error_mean']:.3f} ± {st['heading_error_std']:.3f}"
        lines.append(f"| {c} | {st['runs']} | {_rate(st)} | {he} | {_f(st['impact_kmh_mean'])} | "
                     f"{_f(st['impact_angle_deg_mean'])} | {_causes(st)} | {st['fallbacks']} | {st['safe_stops']} |")
    return "\n".join(lines) + "\n"


def safe_stop_text(ss: Any) -> str:
    """The vehicle summary's ``safe_stop`` in a few words: ``none`` or ``<reason> at <t> s``."""
    if ss is None:
        return "none"
    if isinstance(ss, Mapping):
        at = _num(ss.get("at"))
        return f"{_cause_text(str(ss.get('reason', '?')))}" + (f" at {at:.2f} s" if at is not None else "")
    return str(ss)


def runs_table(rows: Sequence[Mapping[str, Any]]) -> str:
    """Per run: outcome, IPC round trip and controller step times, fallbacks, safe stops."""
    head = ("| case | run | outcome | heading error (rad) | round trip median / p99 (ms) | "
            "IPC transit median / p99 (µs) | controller step median / p99 (ms) | fallbacks | "
            "deadline misses | safe stop | wall (s) |")
    lines = [head, "|" + "---|" * (head.count("|") - 1)]
    for r in rows:
        run = "nominal" if r["kind"] == "nominal" else f"seed {r['seed']}"
        outcome = "success" if r["success"] else _cause_text(r["cause"])
        if r.get("error"):
            outcome += f" ({r['error']})"
        lines.append(
            f"| {r['case']} | {run} | {outcome} | {_f(r['heading_error_rad'], 3)} | "
            f"{_f(r['round_trip_ms_median'], 2)} / {_f(r['round_trip_ms_p99'], 2)} | "
            f"{_f(r['ipc_us_median'], 0)} / {_f(r['ipc_us_p99'], 0)} | "
            f"{_f(r['cycle_ms_median'], 2)} / {_f(r['cycle_ms_p99'], 2)} | "
            f"{r['fallbacks'] if r['fallbacks'] is not None else '—'} | "
            f"{r['deadline_misses'] if r['deadline_misses'] is not None else '—'} | "
            f"{safe_stop_text(r['safe_stop'])} | {r['wall_s']:.1f} |")
    return "\n".join(lines) + "\n"


# --- outputs ------------------------------------------------------------------------------

CSV_FIELDS = ("case", "kind", "seed", "noise", "latency", "clock", "success", "cause", "target_kmh", "impact_kmh",
              "impact_angle_deg", "heading_error_rad", "decided_at", "contacts", "min_margin", "vehicle_ending",
              "controller_ending", "time", "periods", "commands_stale", "lockstep_misses", "safe_stop",
              "ipc_us_median", "ipc_us_p99", "round_trip_ms_median", "round_trip_ms_p99", "cycle_ms_median",
              "cycle_ms_p99", "cycle_ms_max", "plan_ms_median", "plan_ms_p99", "cycles", "solves", "fallbacks",
              "deadline_misses", "solver_failures", "controller_peak_rss_kib", "wall_s", "error", "dir",
              "vehicle_mcap", "controller_mcap")


def write_csv(rows: Sequence[Mapping[str, Any]], path: Path) -> None:
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(CSV_FIELDS)
        for r in rows:
            w.writerow(["" if r.get(k) is None else (json.dumps(r[k]) if isinstance(r[k], (dict, list)) else r[k])
                        for k in CSV_FIELDS])


def plot(summary: Mapping[str, Any], path: Path, eps_psi: Optional[float] = None) -> None:
    """A: success rate of the noisy repeats per case (Wilson 95 % bars), the nominal outcome
    and the paper's; B: terminal heading error of the repeats, the nominal run and the paper."""
    from .bench_figures import _pyplot

    plt = _pyplot()
    cases = list(summary["cases"])
    fig, (a, b) = plt.subplots(1, 2, figsize=(12, 4.6))
    xs = list(range(len(cases)))
    labels = cases + (["Overall"] if summary["overall"].get("repeats") else [])
    stats = [summary["cases"][c].get("repeats") for c in cases] + \
            ([summary["overall"]["repeats"]] if summary["overall"].get("repeats") else [])
    for i, st in enumerate(stats):
        if not st or not st["runs"]:
            continue
        lo, hi = st["wilson95"]
        rate = 100 * st["success_rate"]
        a.bar(i, rate, color="#3182bd" if i < len(cases) else "#636363", alpha=0.8,
              label="repeats under noise" if i == 0 else None)
        a.errorbar(i, rate, yerr=[[rate - 100 * lo], [100 * hi - rate]], color="k", capsize=5,
                   label="Wilson 95 %" if i == 0 else None)
        a.text(i, 100 * hi + 2, f"{st['successes']}/{st['runs']}", ha="center", va="bottom", fontsize=8)
    for i, c in enumerate(cases):
        e = summary["cases"][c]
        if "success" in e:
            a.plot(i - 0.2, 100 if e["success"] else 0, "D", color="#31a354", ms=7,
                   label="nominal (no noise)" if i == 0 else None)
        p = e.get("paper")
        if p:
            a.plot(i + 0.2, 100 if p["outcome"] == "success" else 0, "*", color="#de2d26", ms=12,
                   label="paper (real vehicle)" if i == 0 else None)
    a.set_xticks(range(len(labels)), labels)
    a.set_ylim(-5, 135)
    a.set_yticks(range(0, 101, 20))
    a.set_ylabel("success (%)")
    a.set_title("A: success rate per case")
    a.legend(fontsize=8, loc="upper center", ncol=2)
    for i, c in enumerate(cases):
        e = summary["cases"][c]
        st = e.get("repeats")
        if st:
            ys = [h for h in st["heading_errors"] if h is not None]
            jit = [i + 0.25 * ((j + 0.5) / max(1, len(ys)) - 0.5) for j in range(len(ys))]
            b.scatter(jit, ys, s=18, color="#3182bd", alpha=0.8, label="repeats" if i == 0 else None)
            if st["heading_error_mean"] is not None:
                b.errorbar(i + 0.22, st["heading_error_mean"], yerr=st["heading_error_std"], fmt="o", color="k",
                           capsize=4, ms=4, label="mean ± std" if i == 0 else None)
        if e.get("heading_error_rad") is not None:
            b.plot(i - 0.3, e["heading_error_rad"], "D", color="#31a354", ms=7,
                   label="nominal" if i == 0 else None)
        p = e.get("paper")
        if p:
            b.plot(i + 0.35, p["heading_error_rad"], "*", color="#de2d26", ms=12, label="paper" if i == 0 else None)
    if eps_psi is not None:
        b.axhline(eps_psi, color="#636363", ls="--", lw=1, label=f"ε_ψ = {eps_psi:.3f} rad")
    b.set_xticks(xs, cases)
    b.set_ylim(bottom=0)
    b.set_ylabel("terminal heading error (rad)")
    b.set_title("B: heading error")
    b.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def markdown(summary: Mapping[str, Any], rows: Sequence[Mapping[str, Any]], info: Mapping[str, Any]) -> str:
    md = [
        "# picopit trials\n",
        f"`{info.get('command', 'picopit trials')}` — {info.get('created', '')}; git {info.get('git_commit', '?')}; "
        f"{info.get('machine', '')}.\n",
        f"Scenarios `{info.get('scenarios')}`, controller settings `{info.get('controller_config')}`"
        f"{', model ' + info['model'] if info.get('model') else ''}, binaries `{info.get('bin_dir')}`; "
        f"{info.get('clock')} clock, {info.get('jobs')} job(s), {info.get('seconds', 0):.0f} s.\n",
        "## Nominal runs (no sensing noise, seed 0)\n",
        nominal_table(summary),
    ]
    if summary["overall"].get("repeats"):
        md += [f"\n## Repeats under noise ({info.get('noise')} noise, latency {info.get('latency')} s, "
               f"seeds 1..{info.get('repeats')})\n", repeats_table(summary)]
    md += ["\n## Runs: IPC and controller timing, faults\n", runs_table(rows)]
    notes = info.get("notes") or []
    if notes:
        md += ["\nNotes:\n"] + [f"- {n}" for n in notes]
    return "\n".join(md) + "\n"


def write_outputs(summary: Dict[str, Any], rows: Sequence[Mapping[str, Any]], info: Mapping[str, Any],
                  out: Path, json_path: Optional[Path] = None, figure: bool = True,
                  eps_psi: Optional[float] = None) -> Dict[str, Path]:
    out.mkdir(parents=True, exist_ok=True)
    paths = {"md": out / "trials.md", "csv": out / "trials.csv", "json": out / "trials.json"}
    paths["md"].write_text(markdown(summary, rows, info))
    write_csv(rows, paths["csv"])
    doc = dict(summary, runs=list(rows), run=dict(info))
    text = json.dumps(doc, indent=2) + "\n"
    paths["json"].write_text(text)
    if json_path is not None:
        json_path.parent.mkdir(parents=True, exist_ok=True)
        json_path.write_text(text)
        paths["json_copy"] = json_path
    if figure:
        paths["png"] = out / "trials.png"
        plot(summary, paths["png"], eps_psi)
    return paths
