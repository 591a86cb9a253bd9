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

This module holds the run: the scene set, ``BenchConfig``, the episodes fanned out, the
representative cases picked and re-run with their trajectories, and ``write_outputs``. The
numbers and tables are ``picopit.bench_summary``, the figures ``picopit.bench_figures``
(the names the CLI and the tests use are importable from here too).
"""

from __future__ import annotations

import json
import math
import os
import platform
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Dict, Iterator, List, Mapping, Optional, Sequence, Tuple

import numpy as np

from . import _core, provenance
from .bench_checks import BenchError, check_ray
from .bench_figures import plot_case, plot_contacts, plot_panels
from .bench_summary import ERROR_CAUSE, episode_table, markdown, paired, summarise, write_csv, write_episodes
# picopit.bench's names from before the split into bench_summary and bench_figures.
from .bench_summary import BANDS, CAUSES, mcnemar_exact_p  # noqa: F401
from .cases_mcap import write_mcap

SUBSET_SIZE = 128
CATEGORIES = ("straight_urban", "straight_highway", "curved")


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
    # Controller settings over every configuration's, for the full-size and the half-scale
    # scenes (a TOML document as a dict: `load_controller_config`); None keeps the presets'.
    controller: Optional[Dict[str, Any]] = None
    controller_half_scale: Optional[Dict[str, Any]] = None

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
        # Validate each override once up front, alone: the core names the bad field.
        for key, option in (("uncertainty", "--uncertainty"), ("controller", "--controller-config"),
                            ("controller_half_scale", "--controller-config-half-scale")):
            if getattr(self, key) is not None:
                try:
                    _core.episode_config(self.episode_config(self.configs[0], {key: getattr(self, key)}))
                except _core.EpisodeError as e:
                    raise BenchError(f"{option}: {e}") from None
        return self

    def overrides(self) -> Dict[str, Any]:
        """The episode configuration's fields this run sets over every preset's."""
        return {k: v for k, v in (("uncertainty", self.uncertainty), ("controller", self.controller),
                                  ("controller_half_scale", self.controller_half_scale)) if v is not None}

    def episode_config(self, name: str, overrides: Optional[Mapping[str, Any]] = None) -> str:
        """The configuration text handed to the core: a preset name, or the preset with the
        clock, the target's gear and the overrides (default: all of this run's) as JSON."""
        over = self.overrides() if overrides is None else dict(overrides)
        if not over and self.clock == "wall" and self.target_gear == "forward":
            return name
        doc: Dict[str, Any] = {"preset": name, "clock": self.clock, "target_gear": self.target_gear, **over}
        return json.dumps(doc)

    def n_workers(self) -> int:
        return self.workers or (os.cpu_count() or 1)


def parse_configs(text: str) -> Tuple[str, ...]:
    return tuple(c.strip() for c in text.split(",") if c.strip())


def load_controller_config(path: Optional[str], option: str) -> Optional[Dict[str, Any]]:
    """A controller settings TOML file as a dict (`None` for no file); a file that cannot be
    read or parsed is a :class:`BenchError` naming the option and the file. Its fields are
    checked by the core with the episode configuration (``BenchConfig.validate``)."""
    if path is None:
        return None
    from . import _toml  # tomllib, or tomli before Python 3.11

    try:
        doc = _toml.loads(Path(path).read_text())
    except OSError as e:
        raise BenchError(f"{option} {path}: {e.strerror or e}") from None
    except ValueError as e:
        raise BenchError(f"{option} {path}: {e}") from None
    # TOML has nan and inf, JSON (the core's configuration) has not: name the field here.
    bad = _non_finite(doc)
    if bad is not None:
        raise BenchError(f"{option} {path}: `{bad}` must be a finite number")
    return doc


def _non_finite(doc: Mapping[str, Any], prefix: str = "") -> Optional[str]:
    """The dotted name of the first non-finite number in a parsed TOML table, if any."""
    for key, value in doc.items():
        name = f"{prefix}{key}"
        values = value if isinstance(value, list) else [value]
        for v in values:
            if isinstance(v, float) and not math.isfinite(v):
                return name
            if isinstance(v, dict):
                inner = _non_finite(v, f"{name}.")
                if inner is not None:
                    return inner
    return None


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


def curve_direction(scenario: Mapping[str, Any]) -> Optional[float]:
    """+1 for a road curving left, −1 right (the sign of ``road.radius``), None if straight."""
    radius = (scenario.get("road") or {}).get("radius")
    return math.copysign(1.0, radius) if radius else None


def run(cfg: BenchConfig, progress: bool = True) -> BenchResult:
    t0 = time.perf_counter()
    scenarios, scenes = load_scenes(cfg)
    meta = {i: {"id": scenarios[i]["id"], "category": scenarios[i]["category"],
                "road": road_type(scenarios[i]["category"]), "adhesion": scenarios[i]["adhesion"],
                "params": scenarios[i]["params"], "driver": (scenarios[i].get("driver") or {}).get("kind"),
                "curve": curve_direction(scenarios[i]),
                "mu": scenarios[i]["mu"],
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


# --- outputs ------------------------------------------------------------------------------


def write_outputs(res: BenchResult, cfg: BenchConfig, out: Path, extra: Mapping[str, Any]) -> Dict[str, Path]:
    out.mkdir(parents=True, exist_ok=True)
    paths: Dict[str, Path] = {}
    info = dict(extra)
    info.update(scenarios=str(cfg.scenarios), scene_set="full" if cfg.full else f"stratified subset of {cfg.subset}",
                scenes=len(res.scenes), limit=cfg.limit, configs=list(cfg.configs), seed=cfg.seed,
                workers=cfg.n_workers(), ray_address=cfg.ray_address, uncertainty=cfg.uncertainty,
                target_gear=cfg.target_gear, controller=cfg.controller,
                controller_half_scale=cfg.controller_half_scale,
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
