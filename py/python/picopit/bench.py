"""The closed-loop benchmark (``picopit bench``): scenarios x controller configurations.

Every episode runs in Rust (``_core.run_episode``: the plant as the truth, the hierarchical
controller every 0.05 s, the success test); this module picks the scenes, fans the episodes
out over local processes or a Ray cluster, and writes the paper's tables and figures:

* ``summary.md``, ``summary.csv``, ``summary.json`` -- one row per configuration: success
  overall, by road (straight/curved) and adhesion band (low/mid/high), terminal heading
  error, minimum safety margin, boundary-violation and secondary-collision rates, planning
  and control times (median and p99, pooled over all steps), parameter count and the
  failure-cause breakdown, and the funnel (scenes → first contact → reversed → success, with
  the losses by stage, cause and who failed). JSON shape:
  ``{"configs": {"<name>": {"success_rate": ..., "funnel": {...}}}}``.
* ``episodes.parquet`` -- one row per episode (``episodes.csv`` when pyarrow is missing).
* ``panels.png`` -- A: success by road and adhesion, B: failure composition, C: runtimes,
  D: the funnel (scenes → first contact → reversed → success, ``picopit.funnel``).
* ``contacts.png`` -- D: success by where the first contact landed along the target, E: by
  the relative speed at that contact, F: the share of its start speed a spun target kept
  when it first came round to the reversed heading, successes against failures.
* ``case_success.png``, ``case_failure.png`` -- representative episodes (trajectories on the
  road, states, bullet inputs), and ``cases.mcap`` with both, which Foxglove opens: the scene,
  transforms and poses with Foxglove's schemas, the steps as plot-ready JSON
  (``picopit.cases_mcap``).

The default scene set is a fixed stratified subset of the dataset (``SUBSET_SIZE`` scenes,
strata = road category x adhesion band, proportional allocation, evenly spaced in file
order), so every default run benchmarks the same scenes.
"""

from __future__ import annotations

import csv
import json
import math
import os
import platform
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Dict, Iterable, Iterator, List, Mapping, Optional, Sequence, Tuple

import numpy as np

from . import _core, funnel, provenance
from .bench_checks import BenchError, check_ray, finite_or_none
from .cases_mcap import road_edges as _road_edges, station_span, write_mcap

SUBSET_SIZE = 128
CATEGORIES = ("straight_urban", "straight_highway", "curved")
BANDS = ("low", "mid", "high")
CAUSES = ("decision_infeasible", "no_termination", "boundary_violation", "secondary_collision",
          "unsafe_rebound")
ERROR_CAUSE = "error"


# --- scenes -------------------------------------------------------------------------------


def road_type(category: str) -> str:
    return "curved" if category == "curved" else "straight"


def stratified_subset(scenarios: Sequence[Mapping[str, Any]], n: int = SUBSET_SIZE) -> List[int]:
    """Indices (ascending) of a fixed stratified subset of ``n`` scenes: strata are road
    category x adhesion band; each stratum gets its proportional share (largest remainder,
    at least one scene when it has any), taken evenly spaced in file order."""
    if n >= len(scenarios):
        return list(range(len(scenarios)))
    strata: Dict[Tuple[str, str], List[int]] = {}
    for i, sc in enumerate(scenarios):
        strata.setdefault((sc["category"], sc["adhesion"]), []).append(i)
    keys = sorted(strata)
    total = len(scenarios)
    quota = {k: n * len(strata[k]) / total for k in keys}
    alloc = {k: max(1, int(math.floor(quota[k]))) for k in keys}
    # Largest remainders first (ties by stratum name) until the total is n.
    order = sorted(keys, key=lambda k: (-(quota[k] - math.floor(quota[k])), k))
    j = 0
    while sum(alloc.values()) < n:
        k = order[j % len(order)]
        if alloc[k] < len(strata[k]):
            alloc[k] += 1
        j += 1
    while sum(alloc.values()) > n:  # the at-least-one rule overshot: trim the largest
        k = max(keys, key=lambda k: (alloc[k], k))
        alloc[k] -= 1
    picked: List[int] = []
    for k in keys:
        members, m = strata[k], alloc[k]
        picked += [members[int((q + 0.5) * len(members) / m)] for q in range(m)]
    return sorted(picked)


def episode_seed(seed: int, index: int) -> int:
    """The seed of scene ``index`` (shared by all configurations: common random numbers)."""
    return int(np.random.SeedSequence([seed, index]).generate_state(1, dtype=np.uint64)[0])


# --- configuration ------------------------------------------------------------------------


@dataclass
class BenchConfig:
    scenarios: Path = Path("data/scenarios.jsonl")
    models: Path = Path("models")
    full: bool = False
    subset: int = SUBSET_SIZE
    configs: Tuple[str, ...] = ("4dof", "pinn", "picopinn", "picopinn_no_upper")
    limit: Optional[int] = None
    seed: int = 0
    workers: int = 0  # 0: all cores
    ray_address: Optional[str] = None
    uncertainty: Optional[Dict[str, Any]] = None
    cases: bool = True
    figures: bool = True
    # "wall": real runtimes and real time budgets (the paper's table); "simulated": a tick
    # clock, so every episode is repeatable to the step whatever the machine's load.
    clock: str = "wall"
    # The target's gear: "forward" (its powertrain engaged) or "neutral" (for comparison).
    target_gear: str = "forward"

    def validate(self) -> "BenchConfig":
        known = list(_core.episode_presets())
        if not self.configs:
            raise BenchError("--configs: no configuration given; known: " + ", ".join(known))
        for c in self.configs:
            if c not in known:
                raise BenchError(f"--configs: unknown configuration {c!r}; known: {', '.join(known)}")
        if len(set(self.configs)) != len(self.configs):
            raise BenchError(f"--configs: a configuration is repeated: {','.join(self.configs)}")
        if self.limit is not None and self.limit < 1:
            raise BenchError(f"--limit = {self.limit}: must be a positive number of scenes")
        if self.subset < 1:
            raise BenchError(f"subset = {self.subset}: must be positive")
        if self.workers < 0:
            raise BenchError(f"--workers = {self.workers}: must be >= 0 (0: all cores)")
        if self.seed < 0:
            raise BenchError(f"--seed = {self.seed}: must be >= 0")
        if self.clock not in ("wall", "simulated"):
            raise BenchError(f"--clock = {self.clock!r}: must be wall or simulated")
        if self.target_gear not in ("forward", "neutral"):
            raise BenchError(f"--target-gear = {self.target_gear!r}: must be forward or neutral")
        if not self.scenarios.is_file():
            raise BenchError(f"--scenarios: {self.scenarios}: no such file")
        if not self.models.is_dir():
            raise BenchError(f"--models: {self.models}: no such folder")
        if self.uncertainty is not None:
            # Validate once up front: the core names the bad field.
            try:
                _core.episode_config(self.episode_config(self.configs[0]))
            except _core.EpisodeError as e:
                raise BenchError(f"--uncertainty: {e}") from None
        return self

    def episode_config(self, name: str) -> str:
        """The configuration text handed to the core: a preset name, or the preset with the
        uncertainty override and the clock as JSON."""
        if self.uncertainty is None and self.clock == "wall" and self.target_gear == "forward":
            return name
        doc: Dict[str, Any] = {"preset": name, "clock": self.clock, "target_gear": self.target_gear}
        if self.uncertainty is not None:
            doc["uncertainty"] = self.uncertainty
        return json.dumps(doc)

    def n_workers(self) -> int:
        return self.workers or (os.cpu_count() or 1)


def parse_configs(text: str) -> Tuple[str, ...]:
    return tuple(c.strip() for c in text.split(",") if c.strip())


def parse_uncertainty(text: str) -> Dict[str, Any]:
    try:
        v = json.loads(text)
    except json.JSONDecodeError as e:
        raise BenchError(f"--uncertainty: not valid JSON: {e}") from None
    if not isinstance(v, dict):
        raise BenchError("--uncertainty: expected a JSON object such as '{\"latency\": 0.02}'")
    return v


# --- running ------------------------------------------------------------------------------


@dataclass
class Task:
    index: int  # position in the scenario file
    scenario: str  # JSON line
    config: str  # config name in reports
    config_text: str  # what the core parses
    seed: int
    models: str


def run_task(task: Task, record: bool = False) -> Dict[str, Any]:
    """One episode; an episode that cannot be run becomes a row with cause ``error``."""
    try:
        r = _core.run_episode(task.scenario, task.config_text, task.seed, record=record,
                              models_dir=task.models)
        r["error"] = None
    except (_core.EpisodeError, _core.ScenarioError) as e:
        r = {"success": False, "cause": ERROR_CAUSE, "error": str(e), "config": task.config,
             "seed": task.seed, "plan_times_ms": np.zeros(0), "ctrl_times_ms": np.zeros(0)}
    r["config"] = task.config
    r["index"] = task.index
    return r


def _run_local(tasks: Sequence[Task], workers: int) -> Iterator[Dict[str, Any]]:
    if workers <= 1 or len(tasks) <= 1:
        for t in tasks:
            yield run_task(t)
        return
    import multiprocessing as mp

    with mp.get_context("spawn").Pool(min(workers, len(tasks))) as pool:
        yield from pool.imap_unordered(run_task, tasks, chunksize=1)


def _run_ray(tasks: Sequence[Task], address: str, workers: int) -> Iterator[Dict[str, Any]]:
    try:
        import ray
    except ImportError:
        raise BenchError("--ray-address: ray is not installed (pip install 'picopit[ray]')") from None
    started = False
    if not ray.is_initialized():
        check_ray(address)
        if address == "local":
            ray.init(num_cpus=workers, include_dashboard=False, log_to_driver=False)
        else:
            ray.init(address=address, log_to_driver=False)
        started = True
    try:
        remote = ray.remote(num_cpus=1)(run_task)
        pending = [remote.remote(t) for t in tasks]
        while pending:
            done, pending = ray.wait(pending, num_returns=1)
            for ref in done:
                yield ray.get(ref)
    finally:
        if started:
            ray.shutdown()


def run_all(tasks: Sequence[Task], cfg: BenchConfig, progress: bool = True) -> List[Dict[str, Any]]:
    if cfg.ray_address:
        it = _run_ray(tasks, cfg.ray_address, cfg.n_workers())
    else:
        it = _run_local(tasks, cfg.n_workers())
    rows: List[Dict[str, Any]] = []
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=len(tasks), unit="ep", desc="bench", dynamic_ncols=True)
    n_ok = 0
    for r in it:
        rows.append(r)
        n_ok += bool(r.get("success"))
        if bar is not None:
            bar.update(1)
            bar.set_postfix(success=f"{100 * n_ok / len(rows):.0f}%")
    if bar is not None:
        bar.close()
    rows.sort(key=lambda r: (cfg.configs.index(r["config"]), r["index"]))
    return rows


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
        out[name] = s
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


def markdown(summary: Mapping[str, Mapping[str, Any]], header: str = "",
             pairs: Optional[Mapping[str, Mapping[str, Any]]] = None) -> str:
    lines = [header] if header else []

    def table(cols: Sequence[Tuple[str, str, int]]) -> None:
        lines.append("| config | " + " | ".join(c[1] for c in cols) + " |")
        lines.append("|---|" + "---|" * len(cols))
        for name, s in summary.items():
            lines.append(f"| {name} | " + " | ".join(_fmt(s.get(k), d) for k, _, d in cols) + " |")
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
    ``funnel_<stage>``; its losses are in summary.json and summary.md)."""
    flat = {name: {**{k: v for k, v in s.items() if k != "funnel"},
                   **{f"funnel_{st}": s["funnel"][st] for st in funnel.STAGES if "funnel" in s}}
            for name, s in summary.items()}
    summary = flat
    keys = sorted({k for s in summary.values() for k in s})
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["config"] + keys)
        for name, s in summary.items():
            w.writerow([name] + ["" if s.get(k) is None else s.get(k) for k in keys])


EPISODE_FIELDS = ("config", "index", "scenario", "category", "road", "adhesion", "params", "mu", "target_speed",
                  "seed", "model", "param_count", "upper_layer", "success", "at_rest", "cause", "decided_at",
                  "terminal_heading_error", "min_margin", "boundary_violation", "secondary_collision",
                  "contacts", "contact_at", "impact_speed", "impact_angle", "impact_x", "impact_y", "reversed_at",
                  "reversed_speed", "failed_vehicle", "sim_time", "control_steps", "plan_count",
                  "plan_ms_median", "plan_ms_p99", "plan_ms_max", "ctrl_count", "ctrl_ms_median",
                  "ctrl_ms_p99", "ctrl_ms_max",
                  "final_phase", "abort", "mpc_failures", "mpc_time_budget", "wall_time", "error")


def episode_table(rows: Sequence[Mapping[str, Any]], meta: Mapping[int, Mapping[str, Any]]) -> List[Dict[str, Any]]:
    out = []
    for r in rows:
        m = meta[r["index"]]
        d = {k: r.get(k) for k in EPISODE_FIELDS}
        d.update(scenario=m["id"], category=m["category"], road=m["road"], adhesion=m["adhesion"],
                 params=m["params"], mu=m["mu"], target_speed=m.get("target_speed"))
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
        (k, pa.string()) if k in ("config", "scenario", "category", "road", "adhesion", "params",
                                  "model", "cause", "failed_vehicle", "final_phase", "abort", "error")
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


# --- representative cases -----------------------------------------------------------------


def pick_cases(rows: Sequence[Mapping[str, Any]], config: str) -> Dict[str, Optional[Mapping[str, Any]]]:
    """A representative success (the median decision time among successes) and failure (of
    the most frequent cause, preferring episodes with a contact; median decision time)."""
    rs = [r for r in rows if r["config"] == config and r.get("error") is None]

    def median_of(cands: List[Mapping[str, Any]]) -> Optional[Mapping[str, Any]]:
        if not cands:
            return None
        cands = sorted(cands, key=lambda r: (r["decided_at"] or 0.0, r["index"]))
        return cands[(len(cands) - 1) // 2]

    succ = median_of([r for r in rs if r["success"]])
    fails = [r for r in rs if not r["success"]]
    fail = None
    if fails:
        counts: Dict[str, int] = {}
        for r in fails:
            counts[r["cause"]] = counts.get(r["cause"], 0) + 1
        top = max(sorted(counts), key=lambda c: counts[c])
        of_top = [r for r in fails if r["cause"] == top]
        fail = median_of([r for r in of_top if r["contacts"] > 0] or of_top)
    return {"success": succ, "failure": fail}


# --- figures ------------------------------------------------------------------------------


def _pyplot():
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    return plt


CAUSE_COLORS = {"decision_infeasible": "#8c6bb1", "no_termination": "#bdbdbd",
                "boundary_violation": "#e6550d", "secondary_collision": "#de2d26",
                "unsafe_rebound": "#3182bd", "error": "#000000"}


def plot_panels(summary: Mapping[str, Mapping[str, Any]], path: Path) -> None:
    plt = _pyplot()
    names = list(summary)
    fig, axes = plt.subplots(1, 4, figsize=(21, 4.8))
    # A: success by road and adhesion.
    ax = axes[0]
    groups = [("success_rate", "all"), ("success_straight", "straight"), ("success_curved", "curved"),
              ("success_low", "low μ"), ("success_mid", "mid μ"), ("success_high", "high μ")]
    w = 0.8 / max(1, len(names))
    x = np.arange(len(groups))
    for i, n in enumerate(names):
        vals = [summary[n].get(k) or 0.0 for k, _ in groups]
        ax.bar(x + (i - (len(names) - 1) / 2) * w, vals, w, label=n)
    ax.set_xticks(x, [g for _, g in groups])
    ax.set_ylabel("success (%)")
    ax.set_ylim(0, 100)
    ax.set_title("A  success by road and adhesion")
    ax.legend(fontsize=8)
    # B: failure composition.
    ax = axes[1]
    bottom = np.zeros(len(names))
    for c in CAUSES + (ERROR_CAUSE,):
        vals = np.array([summary[n].get(f"fail_{c}") or 0.0 for n in names])
        if c == ERROR_CAUSE and not vals.any():
            continue
        ax.bar(names, vals, bottom=bottom, color=CAUSE_COLORS[c], label=c.replace("_", " "))
        bottom += vals
    ax.set_ylabel("episodes (%)")
    ax.set_ylim(0, 100)
    ax.set_title("B  failure composition (first cause)")
    # Below the axes: inside, the legend hid the stacks it describes.
    ax.legend(fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.2), ncol=3, frameon=False)
    ax.tick_params(axis="x", labelrotation=15)
    # C: runtimes.
    ax = axes[2]
    x = np.arange(len(names))
    for j, (k, lab, hatch) in enumerate((("plan", "plan", ""), ("ctrl", "ctrl", "//"))):
        med = [summary[n].get(f"{k}_ms_median") or 0.0 for n in names]
        p99 = [summary[n].get(f"{k}_ms_p99") or 0.0 for n in names]
        pos = x + (j - 0.5) * 0.38
        ax.bar(pos, med, 0.36, label=f"{lab} median", color=f"C{j}")
        ax.scatter(pos, p99, marker="_", s=300, color="k", zorder=3, label="p99" if j == 0 else None)
    ax.axhline(50.0, color="#888", ls=":", lw=1)
    ax.text(x[-1] + 0.5 if len(x) else 0.5, 50.0, "control period 50 ms", ha="right", va="bottom",
            fontsize=7, color="#666")
    ax.set_xticks(x, names, rotation=15)
    ax.set_ylabel("ms per step")
    ax.set_yscale("log")
    from matplotlib.ticker import FormatStrFormatter

    ax.yaxis.set_major_formatter(FormatStrFormatter("%g"))
    ax.yaxis.set_minor_formatter(FormatStrFormatter(""))
    ax.set_title("C  planning and control times")
    shown = [v for n in names for k in ("plan", "ctrl") for v in
             (summary[n].get(f"{k}_ms_median"), summary[n].get(f"{k}_ms_p99")) if v]
    if shown:  # every bar from the same floor, and room for the legend above the 50 ms line
        ax.set_ylim(0.5 * min(shown), 4.0 * max(max(shown), 50.0))
    ax.legend(fontsize=8, loc="upper right", ncol=3)
    # D: the funnel.
    funnel.plot(axes[3], {n: summary[n]["funnel"] for n in names if "funnel" in summary[n]})
    fig.tight_layout()
    fig.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(fig)


def plot_case(case: Mapping[str, Any], sc: Mapping[str, Any], path: Path, title: str) -> None:
    from matplotlib.patches import Polygon

    from . import load_params_dict

    plt = _pyplot()
    cols = list(_core.trajectory_columns())
    tr = np.asarray(case["trajectory"])
    c = {k: tr[:, i] for i, k in enumerate(cols)}
    p = load_params_dict(sc["params"])
    fig = plt.figure(figsize=(15, 8.5))
    gs = fig.add_gridspec(3, 3, height_ratios=[1.6, 1, 1])
    ax = fig.add_subplot(gs[0, :])
    # Road: edges, lane lines; stations spanned by the episode.
    edges = _road_edges(sc, *station_span(sc, c))
    for k, e in enumerate(edges):
        if k < 2:
            ax.plot(e[:, 0], e[:, 1], color="k", lw=1.5)
        elif k >= len(edges) - 2:
            ax.plot(e[:, 0], e[:, 1], color="#555", lw=0.8)
        else:
            ax.plot(e[:, 0], e[:, 1], color="#999", lw=0.8, ls=(0, (6, 6)))
    for ob in sc.get("obstacles", []):
        b = ob["body"]
        t_end = float(c["time"][-1])
        for tt, a in ((0.0, 0.5), (t_end, 1.0)):
            corners = _core.footprint([b["x"] + b["vx"] * tt, b["y"] + b["vy"] * tt, b["heading"]],
                                      b["length"], b["width"], 0.5 * b["length"])
            ax.add_patch(Polygon(corners, closed=True, facecolor="#555", alpha=0.3 * a, edgecolor="#333"))
    picks = np.unique(np.linspace(0, len(tr) - 1, 12).round().astype(int))
    for who, color, xk, yk, pk in (("bullet", "#1f5fbf", "bullet_x", "bullet_y", "bullet_psi"),
                                   ("target", "#d1402a", "target_x", "target_y", "target_psi")):
        geo = p[who]
        ax.plot(c[xk], c[yk], color=color, lw=1.2, label=who)
        for j, i in enumerate(picks):
            corners = _core.footprint([c[xk][i], c[yk][i], c[pk][i]], geo["length"], geo["width"],
                                      geo["cg_to_front"])
            a = 0.25 + 0.75 * j / max(1, len(picks) - 1)
            ax.add_patch(Polygon(corners, closed=True, facecolor=color, alpha=0.15 * a + 0.03,
                                 edgecolor=color, lw=0.8))
    contact = c["contact_fn"] > 0
    if contact.any():
        ax.scatter(c["target_x"][contact], c["target_y"][contact], s=6, color="#7a3fb0", zorder=5,
                   label="in contact")
    # Frame the vehicles' paths (obstacles far away would shrink them to nothing).
    xs = np.concatenate([c["target_x"], c["bullet_x"]])
    ys = np.concatenate([c["target_y"], c["bullet_y"]])
    pad = 8.0 * max(p["bullet"]["length"], p["target"]["length"]) / 4.5
    ax.set_xlim(xs.min() - pad, xs.max() + pad)
    ax.set_ylim(ys.min() - pad, ys.max() + pad)
    ax.set_aspect("equal", adjustable="box")
    ax.set_xlabel("X (m)")
    ax.set_ylabel("Y (m)")
    ax.legend(loc="upper left", fontsize=8)
    ax.set_title(title)
    t = c["time"]
    panels = [
        ("yaw ψ (deg)", [(np.degrees(c["target_psi"]), "target", "#d1402a"),
                                  (np.degrees(c["bullet_psi"]), "bullet", "#1f5fbf")]),
        ("speed (m/s)", [(np.hypot(c["target_vx"], c["target_vy"]), "target", "#d1402a"),
                         (np.hypot(c["bullet_vx"], c["bullet_vy"]), "bullet", "#1f5fbf")]),
        ("yaw rate (rad/s)", [(c["target_r"], "target", "#d1402a"), (c["bullet_r"], "bullet", "#1f5fbf")]),
        ("bullet steer δ_f (rad)", [(c["cmd_steer"], "command", "#1f5fbf")]),
        ("bullet torque T_r (N m)", [(c["cmd_torque"], "command", "#1f5fbf")]),
        ("contact force (kN)", [(c["contact_fn"] / 1e3, "F_n", "#7a3fb0"), (c["contact_ft"] / 1e3, "F_t", "#b07a3f")]),
    ]
    for k, (lab, series) in enumerate(panels):
        a = fig.add_subplot(gs[1 + k // 3, k % 3])
        for y, name, color in series:
            a.plot(t, y, color=color, lw=1.2, label=name)
        phase = c["phase"]
        for ph, shade in ((1.0, "#f2e6ff"), (2.0, "#e6f2e6")):
            on = phase == ph
            if on.any():
                a.fill_between(t, 0, 1, where=on, color=shade, transform=a.get_xaxis_transform(), zorder=0)
        a.set_ylabel(lab, fontsize=8)
        a.set_xlabel("t (s)", fontsize=8)
        a.grid(alpha=0.3)
        if len(series) > 1:
            a.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


# --- the whole run ------------------------------------------------------------------------


@dataclass
class BenchResult:
    summary: Dict[str, Dict[str, Any]]
    rows: List[Dict[str, Any]]
    meta: Dict[int, Dict[str, Any]]
    scenes: List[int]
    seconds: float
    notes: List[str] = field(default_factory=list)
    cases: Dict[str, Optional[Dict[str, Any]]] = field(default_factory=dict)
    pairs: Dict[str, Dict[str, Any]] = field(default_factory=dict)
    """``paired(rows, configs)``."""


def load_scenes(cfg: BenchConfig) -> Tuple[List[Dict[str, Any]], List[int]]:
    scenarios = _core.load_scenarios(str(cfg.scenarios))
    scenes = list(range(len(scenarios))) if cfg.full else stratified_subset(scenarios, cfg.subset)
    if cfg.limit is not None:
        # Keep the stratification when limiting: take evenly spaced scenes of the set.
        if cfg.limit < len(scenes):
            scenes = [scenes[int((q + 0.5) * len(scenes) / cfg.limit)] for q in range(cfg.limit)]
    return scenarios, scenes


def run(cfg: BenchConfig, progress: bool = True) -> BenchResult:
    t0 = time.perf_counter()
    scenarios, scenes = load_scenes(cfg)
    meta = {i: {"id": scenarios[i]["id"], "category": scenarios[i]["category"],
                "road": road_type(scenarios[i]["category"]), "adhesion": scenarios[i]["adhesion"],
                "params": scenarios[i]["params"], "mu": scenarios[i]["mu"],
                "target_speed": math.hypot(scenarios[i]["target"]["vx"], scenarios[i]["target"]["vy"])}
            for i in scenes}
    models = str(cfg.models.resolve())
    tasks = [Task(i, json.dumps(scenarios[i]), c, cfg.episode_config(c), episode_seed(cfg.seed, i), models)
             for c in cfg.configs for i in scenes]
    rows = run_all(tasks, cfg, progress=progress)
    res = BenchResult(summary=summarise(rows, meta, cfg.configs), rows=rows, meta=meta, scenes=scenes,
                      seconds=0.0, pairs=paired(rows, cfg.configs))
    errors = [r for r in rows if r.get("error")]
    if errors:
        res.notes.append(f"{len(errors)} episodes could not be run (cause 'error'); first: "
                         f"{meta[errors[0]['index']]['id']} / {errors[0]['config']}: {errors[0]['error']}")
    if cfg.cases:
        focus = "picopinn" if "picopinn" in cfg.configs else cfg.configs[0]
        for kind, row in pick_cases(rows, focus).items():
            if row is None:
                res.notes.append(f"no {kind} episode for {focus}: no {kind} case figure")
                res.cases[kind] = None
                continue
            i = row["index"]
            task = Task(i, json.dumps(scenarios[i]), focus, cfg.episode_config(focus), row["seed"], models)
            rec = run_task(task, record=True)
            if rec.get("cause") != row.get("cause") or rec.get("success") != row.get("success"):
                res.notes.append(f"the recorded re-run of the {kind} case ({meta[i]['id']}) ended "
                                 f"{rec.get('cause') or 'success'}, the benchmark run "
                                 f"{row.get('cause') or 'success'} (wall-clock time budgets)")
            res.cases[kind] = rec
    res.seconds = time.perf_counter() - t0
    return res


def git_commit() -> str:
    """HEAD of the source tree (``-dirty`` with uncommitted changes, the models included),
    or ``unknown``."""
    return provenance.git_commit()


def machine() -> str:
    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return f"{platform.system()} {platform.machine()}, {os.cpu_count()} cores, {cpu}, Python {platform.python_version()}"


# Bins of the contact figure (full-size scenes; the target's rear bumper is 2.39 m and its rear
# axle 1.42 m behind its c.g.).
IMPACT_X_EDGES = (-2.45, -2.2, -1.8, -1.4, -1.0, 0.0, 2.2)
IMPACT_V_EDGES = (0.0, 2.0, 3.0, 4.0, 5.0, 8.0)


def _binned_success(rows: Sequence[Mapping[str, Any]], key: str, edges: Sequence[float]):
    """Success % and counts per bin of ``key`` (episodes with that value only)."""
    n = np.zeros(len(edges) - 1)
    ok = np.zeros(len(edges) - 1)
    for r in rows:
        v = _finite(r.get(key))
        if v is None:
            continue
        j = int(np.searchsorted(edges, v, side="right")) - 1
        if 0 <= j < len(n):
            n[j] += 1
            ok[j] += bool(r.get("success"))
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(n > 0, 100.0 * ok / np.maximum(n, 1), np.nan), n


def plot_contacts(table: Sequence[Mapping[str, Any]], names: Sequence[str], path: Path) -> None:
    """D: success by the first contact's point along the target; E: by the relative speed
    at it (full-size episodes with a contact, per configuration); F: the share of its start
    speed a spun target kept at its first reversal, successes against failures."""
    plt = _pyplot()
    fig, axes = plt.subplots(1, 3, figsize=(16, 4.6))
    full = [r for r in table if r.get("params") == "full_size"]
    focus = "picopinn" if "picopinn" in names else (names[0] if names else "")
    for ax, key, edges, label, title in (
            (axes[0], "impact_x", IMPACT_X_EDGES, "first contact along the target, body x (m)",
             "D  success by where the first contact landed"),
            (axes[1], "impact_speed", IMPACT_V_EDGES, "relative speed at the first contact (m/s)",
             "E  success by the speed of the first contact")):
        centres = 0.5 * (np.array(edges[:-1]) + np.array(edges[1:]))
        for i, name in enumerate(names):
            rate, n = _binned_success([r for r in full if r.get("config") == name], key, edges)
            ax.plot(centres, rate, "o-", color=f"C{i}", label=name)
            if name == focus:
                for c, k in zip(centres, n):
                    if k:
                        ax.annotate(f"{int(k)}", (c, 2), ha="center", fontsize=7, color="#666")
        ax.text(0.01, 0.99, f"grey: {focus} episodes per bin", transform=ax.transAxes, ha="left",
                va="top", fontsize=7, color="#666")
        for e in edges:
            ax.axvline(e, color="#ddd", lw=0.8, zorder=0)
        ax.set_xlabel(label)
        ax.set_ylabel("success (%)")
        ax.set_ylim(0, 100)
        ax.set_title(title)
        ax.legend(fontsize=8)
    axes[0].axvspan(-2.2, -1.4, color="#e5f5e0", zorder=0)
    axes[0].text(-1.8, 90, "rear quarter", ha="center", va="top", fontsize=8, color="#31a354")
    ax = axes[2]
    kept = {True: [], False: []}
    for r in table:
        vr, v0 = _finite(r.get("reversed_speed")), _finite(r.get("target_speed"))
        if r.get("config") == focus and vr is not None and v0 and int(r.get("contacts") or 0) > 0:
            kept[bool(r.get("success"))].append(vr / v0)
    bins = np.linspace(0.0, 1.0, 21)
    for ok, color, lab in ((True, "#31a354", "success"), (False, "#e6550d", "failure")):
        if kept[ok]:
            ax.hist(kept[ok], bins=bins, alpha=0.6, color=color,
                    label=f"{lab} (n={len(kept[ok])}, median {np.median(kept[ok]):.2f})")
    ax.set_xlabel("speed at the first reversal / start speed")
    ax.set_ylabel("spun targets")
    ax.set_title(f"F  speed a spun target kept ({focus})")
    if kept[True] or kept[False]:
        ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def write_outputs(res: BenchResult, cfg: BenchConfig, out: Path, extra: Mapping[str, Any]) -> Dict[str, Path]:
    out.mkdir(parents=True, exist_ok=True)
    paths: Dict[str, Path] = {}
    info = dict(extra)
    info.update(scenarios=str(cfg.scenarios), scene_set="full" if cfg.full else f"stratified subset of {cfg.subset}",
                scenes=len(res.scenes), limit=cfg.limit, configs=list(cfg.configs), seed=cfg.seed,
                workers=cfg.n_workers(), ray_address=cfg.ray_address, uncertainty=cfg.uncertainty,
                target_gear=cfg.target_gear,
                seconds=round(res.seconds, 2), machine=machine(), notes=res.notes,
                scene_ids=[res.meta[i]["id"] for i in res.scenes])
    header = (f"# picopit bench\n\n`{info.get('command', 'picopit bench')}` — {info.get('created', '')}, "
              f"{len(res.scenes)} scenes ({info['scene_set']}) × {len(cfg.configs)} configurations, "
              f"seed {cfg.seed}, {res.seconds:.0f} s on {cfg.n_workers()} workers ({info['machine']}).\n")
    md = markdown(res.summary, header, res.pairs)
    if res.notes:
        md += "\nNotes:\n\n" + "\n".join(f"- {n}" for n in res.notes) + "\n"
    paths["md"] = out / "summary.md"
    paths["md"].write_text(md)
    paths["csv"] = out / "summary.csv"
    write_csv(res.summary, paths["csv"])
    doc = {"configs": res.summary, "paired": res.pairs, "run": info}
    paths["json"] = out / "summary.json"
    paths["json"].write_text(json.dumps(doc, indent=2) + "\n")
    table = episode_table(res.rows, res.meta)
    paths["episodes"], note = write_episodes(table, out)
    if note:
        res.notes.append(note)
    if cfg.figures:
        paths["panels"] = out / "panels.png"
        plot_panels(res.summary, paths["panels"])
        paths["contacts"] = out / "contacts.png"
        plot_contacts(table, list(cfg.configs), paths["contacts"])
        cases = {k: v for k, v in res.cases.items() if v is not None and v.get("trajectory") is not None}
        scenes = {}
        for kind, case in cases.items():
            sc = _core.validate_scenario_line(json.dumps(_scenario_by_id(cfg, case["scenario"])))
            scenes[kind] = sc
            title = (f"{kind}: {case['scenario']} ({sc['category']}, μ {sc['mu']:.2f}, {case['config']}) — "
                     f"{case['cause'] or 'success'} at {case['decided_at']:.2f} s, "
                     f"heading error {math.degrees(case['terminal_heading_error']):.0f}°")
            paths[f"case_{kind}"] = out / f"case_{kind}.png"
            plot_case(case, sc, paths[f"case_{kind}"], title)
        if cases:
            mcap_path = out / "cases.mcap"
            note = write_mcap(cases, scenes, mcap_path)
            if note:
                res.notes.append(note)
                (out / "cases.mcap.txt").write_text(note + "\n")
            else:
                paths["mcap"] = mcap_path
    if res.notes:
        # Notes found while writing go into the Markdown and JSON too.
        md = markdown(res.summary, header, res.pairs) + "\nNotes:\n\n" + "\n".join(f"- {n}" for n in res.notes) + "\n"
        paths["md"].write_text(md)
        info["notes"] = res.notes
        paths["json"].write_text(json.dumps(doc, indent=2) + "\n")
    return paths


_SCENE_CACHE: Dict[str, Dict[str, Dict[str, Any]]] = {}


def _scenario_by_id(cfg: BenchConfig, sid: str) -> Dict[str, Any]:
    key = str(cfg.scenarios)
    if key not in _SCENE_CACHE:
        _SCENE_CACHE[key] = {s["id"]: s for s in _core.load_scenarios(key)}
    return _SCENE_CACHE[key][sid]


def write_json(summary_path: Path, target: Path) -> None:
    target.parent.mkdir(parents=True, exist_ok=True)
    target.write_text(summary_path.read_text())

