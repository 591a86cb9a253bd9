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
"""

from __future__ import annotations

import csv
import datetime as _dt
import json
import math
import os
import signal
import subprocess
import sys
import threading
import time
from concurrent.futures import FIRST_COMPLETED, Future, ThreadPoolExecutor, wait
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Dict, Iterable, List, Mapping, Optional, Sequence, Tuple

from .outputs import check_dir, check_file

VEHICLE_BIN = "pit-vehicle"
CONTROLLER_BIN = "pit-controller"
HALF_SCALE_SCENARIOS = Path("data/trials/half_scale.jsonl")
HALF_SCALE_CONTROLLER = Path("configs/controller_half_scale.toml")
BUILD_HINT = "run ./scripts/setup.sh --full or `cargo build --release -p picopit-vehicle-io --bins`"
KMH = 3.6
Z95 = 1.959963984540054
ERROR_CAUSE = "error"

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


class TrialsError(ValueError):
    """An option or input of ``picopit trials`` that cannot be used; the message names it."""


# --- locating things ----------------------------------------------------------------------


def _walk_up(start: Path) -> Iterable[Path]:
    start = start.resolve()
    yield start
    yield from start.parents


def repo_root(start: Optional[Path] = None) -> Optional[Path]:
    """The source tree (a folder with ``Cargo.toml`` and ``data/trials``), walking up from
    ``start`` (default: the current directory, then this package's location)."""
    starts = [start] if start is not None else [Path.cwd(), Path(__file__).parent]
    for s in starts:
        for d in _walk_up(s):
            if (d / "Cargo.toml").is_file() and (d / "data" / "trials").is_dir():
                return d
    return None


def find_bin_dir(bin_dir: Optional[str] = None, env: Optional[Mapping[str, str]] = None) -> Path:
    """The folder holding ``pit-vehicle`` and ``pit-controller``: ``bin_dir``, else
    ``$PICOPIT_BIN_DIR``, else ``<repo>/target/release`` found by walking up from the current
    directory and from this package. Raises ``TrialsError`` naming what is missing."""
    env = os.environ if env is None else env
    if bin_dir:
        candidates, source = [Path(bin_dir)], "--bin-dir"
    elif env.get("PICOPIT_BIN_DIR"):
        candidates, source = [Path(env["PICOPIT_BIN_DIR"])], "PICOPIT_BIN_DIR"
    else:
        candidates, source = [], "target/release"
        for s in (Path.cwd(), Path(__file__).parent):
            for d in _walk_up(s):
                if (d / "Cargo.toml").is_file() and d / "target" / "release" not in candidates:
                    candidates.append(d / "target" / "release")
        if not candidates:
            raise TrialsError(f"no source tree with target/release above {Path.cwd()} or the package; "
                              f"give --bin-dir or PICOPIT_BIN_DIR, or {BUILD_HINT}")
    for c in candidates:
        if all(os.access(c / b, os.X_OK) and (c / b).is_file() for b in (VEHICLE_BIN, CONTROLLER_BIN)):
            return c.resolve()
    c = candidates[0]
    missing = [b for b in (VEHICLE_BIN, CONTROLLER_BIN) if not (c / b).is_file()]
    what = " and ".join(missing) if missing else f"{VEHICLE_BIN}/{CONTROLLER_BIN} (not executable)"
    raise TrialsError(f"{what} not found in {c} ({source}): {BUILD_HINT}")


def load_cases(path: Path) -> Dict[str, Dict[str, Any]]:
    """The scenarios of a JSON-lines file by id (file order)."""
    if not path.is_file():
        raise TrialsError(f"--scenarios: {path} does not exist")
    cases: Dict[str, Dict[str, Any]] = {}
    for n, line in enumerate(path.read_text().splitlines(), 1):
        if not line.strip():
            continue
        try:
            sc = json.loads(line)
            cases[str(sc["id"])] = sc
        except (ValueError, KeyError, TypeError) as e:
            raise TrialsError(f"--scenarios: {path} line {n}: not a scenario ({e})") from None
    if not cases:
        raise TrialsError(f"--scenarios: {path} holds no scenario")
    return cases


def parse_cases(text: Optional[str], known: Sequence[str]) -> List[str]:
    """The case ids of ``--cases`` (all of ``known`` when the option is not given; an empty
    list is an error, not "all")."""
    if text is None:
        return list(known)
    ids = [c.strip() for c in text.split(",") if c.strip()]
    if not ids:
        raise TrialsError("--cases: no case given; known: " + ",".join(known))
    for c in ids:
        if c not in known:
            raise TrialsError(f"--cases: unknown case {c!r}; known: {','.join(known)}")
    if len(set(ids)) != len(ids):
        raise TrialsError(f"--cases: a case is repeated: {text}")
    return ids


# --- configuration ------------------------------------------------------------------------


@dataclass
class TrialsConfig:
    scenarios: Path
    controller_config: Path
    bin_dir: Path
    cases: List[str]
    repeats: int = 5
    noise: str = "paper"
    latency: float = 0.05
    realtime: bool = False
    jobs: int = 1
    timeout: Optional[float] = None  # wall seconds per run; None: from the scenario's T_max
    model: Optional[str] = None
    #: the controller predicts the states over their age (pit-controller's default)
    delay_compensation: bool = True
    cwd: Path = field(default_factory=Path.cwd)  # the controller finds models/ from here
    t_max: Dict[str, float] = field(default_factory=dict)

    def validate(self) -> "TrialsConfig":
        if self.repeats < 0:
            raise TrialsError(f"--repeats = {self.repeats}: must be >= 0")
        if self.jobs < 1:
            raise TrialsError(f"--jobs = {self.jobs}: must be >= 1")
        if not (self.latency >= 0 and math.isfinite(self.latency)):
            raise TrialsError(f"--latency = {self.latency}: must be a finite number >= 0 (s)")
        if self.noise not in ("none", "paper"):
            raise TrialsError(f"--noise = {self.noise!r}: none or paper")
        if self.timeout is not None and not self.timeout > 0:
            raise TrialsError(f"--timeout = {self.timeout}: must be > 0 (s)")
        if not self.controller_config.is_file():
            raise TrialsError(f"--controller-config: {self.controller_config} does not exist")
        return self

    def run_timeout(self, case: str) -> float:
        if self.timeout is not None:
            return self.timeout
        t_max = self.t_max.get(case, 10.0)
        # Lock step runs far faster than real time; the margin covers a loaded machine.
        return (t_max + 20.0) * 1.5 + 30.0 if self.realtime else 120.0 + 4.0 * t_max


@dataclass
class Trial:
    case: str
    kind: str  # "nominal" or "repeat"
    seed: int
    noise: str
    latency: float
    record: bool
    index: int = 0  # unique within the run (service prefix)

    @property
    def name(self) -> str:
        return "nominal" if self.kind == "nominal" else f"seed-{self.seed}"


def plan(cfg: TrialsConfig) -> List[Trial]:
    """The runs: per case the nominal run, then the noisy repeats (seeds 1..K)."""
    trials: List[Trial] = []
    for c in cfg.cases:
        trials.append(Trial(c, "nominal", 0, "none", 0.0, True))
        for s in range(1, cfg.repeats + 1):
            trials.append(Trial(c, "repeat", s, cfg.noise, cfg.latency, False))
    for i, t in enumerate(trials):
        t.index = i
    return trials


# --- running the processes ----------------------------------------------------------------

_LIVE: "set[subprocess.Popen]" = set()
_LIVE_LOCK = threading.Lock()


def _kill(p: Optional[subprocess.Popen]) -> None:
    """Stop one child we started (SIGINT first so it can finish its files, then SIGKILL)."""
    if p is None or p.poll() is not None:
        return
    for sig, grace in ((signal.SIGINT, 2.0), (signal.SIGKILL, 5.0)):
        try:
            p.send_signal(sig)
        except OSError:
            return
        try:
            p.wait(grace)
            return
        except subprocess.TimeoutExpired:
            continue


def kill_all() -> None:
    """Stop every child still running (on an error or Ctrl-C)."""
    with _LIVE_LOCK:
        procs = list(_LIVE)
    for p in procs:
        _kill(p)


def _spawn(cmd: List[str], log: Path, cwd: Path) -> subprocess.Popen:
    with open(log, "wb") as fh:
        # Its own session: Ctrl-C reaches only us, and we stop the children ourselves.
        p = subprocess.Popen(cmd, stdin=subprocess.DEVNULL, stdout=fh, stderr=subprocess.STDOUT,
                             cwd=str(cwd), start_new_session=True)
    with _LIVE_LOCK:
        _LIVE.add(p)
    return p


def _forget(*procs: Optional[subprocess.Popen]) -> None:
    with _LIVE_LOCK:
        for p in procs:
            _LIVE.discard(p)


def commands(cfg: TrialsConfig, t: Trial, run_dir: Path, prefix: str) -> Tuple[List[str], List[str]]:
    """The two command lines of one run."""
    veh = [str(cfg.bin_dir / VEHICLE_BIN), "--scenario", str(cfg.scenarios), "--id", t.case,
           "--clock", "wall" if cfg.realtime else "simulated", "--prefix", prefix, "--seed", str(t.seed),
           "--noise", t.noise, "--summary", str(run_dir / "vehicle.json")]
    if t.latency > 0:
        veh += ["--latency", repr(float(t.latency))]
    ctl = [str(cfg.bin_dir / CONTROLLER_BIN), "--scenario", str(cfg.scenarios), "--id", t.case,
           "--clock", "wall" if cfg.realtime else "vehicle", "--prefix", prefix,
           "--controller-config", str(cfg.controller_config), "--summary", str(run_dir / "controller.json")]
    if cfg.model:
        ctl += ["--model", cfg.model]
    if not cfg.delay_compensation:
        ctl += ["--no-delay-compensation"]
    if t.record:
        veh += ["--record", str(run_dir / "vehicle.mcap")]
        ctl += ["--record", str(run_dir / "controller.mcap")]
    return veh, ctl


def _read_json(path: Path) -> Optional[Dict[str, Any]]:
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError):
        return None


def run_trial(cfg: TrialsConfig, t: Trial, out: Path, stop: Optional[threading.Event] = None) -> Dict[str, Any]:
    """Run one trial (vehicle first, then controller) and return its row."""
    run_dir = out / t.case / t.name
    run_dir.mkdir(parents=True, exist_ok=True)
    for f in ("vehicle.json", "controller.json"):
        (run_dir / f).unlink(missing_ok=True)
    prefix = f"picopit-trials-{os.getpid()}-{t.index}"
    veh_cmd, ctl_cmd = commands(cfg, t, run_dir, prefix)
    (run_dir / "commands.txt").write_text("\n".join(" ".join(c) for c in (veh_cmd, ctl_cmd)) + "\n")
    timeout = cfg.run_timeout(t.case)
    errors: List[str] = []
    veh = ctl = None
    t0 = time.monotonic()
    try:
        veh = _spawn(veh_cmd, run_dir / "vehicle.log", cfg.cwd)
        ctl = _spawn(ctl_cmd, run_dir / "controller.log", cfg.cwd)
        first_exit: Optional[float] = None
        while True:
            rv, rc = veh.poll(), ctl.poll()
            if rv is not None and rc is not None:
                break
            now = time.monotonic()
            if stop is not None and stop.is_set():
                errors.append("interrupted")
                break
            if now - t0 > timeout:
                errors.append(f"timeout after {timeout:.0f} s")
                break
            if (rv is None) != (rc is None):
                # One has exited: the other should follow within moments (the vehicle would
                # otherwise wait out its connect timeout for a controller that died).
                first_exit = first_exit if first_exit is not None else now
                if now - first_exit > 10.0:
                    errors.append(f"{'pit-controller' if rv is not None else 'pit-vehicle'} still running "
                                  f"10 s after the other exited")
                    break
            time.sleep(0.02)
    finally:
        _kill(ctl)
        _kill(veh)
        _forget(veh, ctl)
    wall = time.monotonic() - t0
    rcs = {"vehicle": veh.returncode if veh else None, "controller": ctl.returncode if ctl else None}
    for who, rc in rcs.items():
        if rc not in (0, None) and not errors:
            errors.append(f"pit-{who} exited with status {rc}: {_last_line(run_dir / f'{who}.log')}")
    vs = _read_json(run_dir / "vehicle.json")
    cs = _read_json(run_dir / "controller.json")
    if vs is None and not errors:
        errors.append("no vehicle summary")
    row = make_row(cfg, t, vs, cs, errors, wall, run_dir, out)
    return row


def _last_line(path: Path) -> str:
    try:
        lines = [ln for ln in path.read_text(errors="replace").splitlines() if ln.strip()]
    except OSError:
        return "(no log)"
    return lines[-1][:300] if lines else "(empty log)"


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


_SCEN: Dict[Tuple[str, str], Dict[str, Any]] = {}


def cfg_scenario(cfg: TrialsConfig, case: str) -> Dict[str, Any]:
    key = (str(cfg.scenarios), case)
    if key not in _SCEN:
        _SCEN.update({(str(cfg.scenarios), k): v for k, v in load_cases(cfg.scenarios).items()})
    return _SCEN.get(key, {})


class _Progress:
    """tqdm when installed, else one rewritten status line on stderr."""

    def __init__(self, total: int, enabled: bool):
        self.total, self.done, self.ok, self.bar = total, 0, 0, None
        self.enabled = enabled
        if enabled:
            try:
                from tqdm import tqdm

                self.bar = tqdm(total=total, unit="run", desc="trials", dynamic_ncols=True)
            except ImportError:
                self.bar = None

    def update(self, row: Mapping[str, Any]) -> None:
        self.done += 1
        self.ok += bool(row["success"])
        label = f"{row['case']} {row['kind'] if row['kind'] == 'nominal' else 'seed ' + str(row['seed'])}: {row['outcome']}"
        if self.bar is not None:
            self.bar.update(1)
            self.bar.set_postfix_str(f"{self.ok}/{self.done} ok, last {label}")
        elif self.enabled:
            print(f"\rtrials: {self.done}/{self.total} runs, {self.ok} successful; last {label}".ljust(78),
                  end="" if self.done < self.total else "\n", file=sys.stderr, flush=True)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()


def run_all(cfg: TrialsConfig, out: Path, progress: bool = True) -> List[Dict[str, Any]]:
    """Run every trial (``cfg.jobs`` at a time); on Ctrl-C or an error stop all children."""
    trials = plan(cfg)
    bar = _Progress(len(trials), progress)
    stop = threading.Event()
    rows: List[Dict[str, Any]] = []
    pool = ThreadPoolExecutor(max_workers=cfg.jobs)
    pending: "set[Future]" = set()
    try:
        pending = {pool.submit(run_trial, cfg, t, out, stop) for t in trials}
        while pending:
            done, pending = wait(pending, timeout=0.2, return_when=FIRST_COMPLETED)
            for f in done:
                row = f.result()
                rows.append(row)
                bar.update(row)
    except BaseException:
        stop.set()
        for f in pending:
            f.cancel()
        kill_all()
        pool.shutdown(wait=True, cancel_futures=True)
        kill_all()
        raise
    finally:
        bar.close()
    pool.shutdown(wait=True)
    order = {(t.case, t.kind, t.seed): i for i, t in enumerate(trials)}
    rows.sort(key=lambda r: order[(r["case"], r["kind"], r["seed"])])
    return rows


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
    from .bench import _pyplot

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
    ctl_cfg = resolve(args.controller_config, HALF_SCALE_CONTROLLER, "--controller-config")
    if not args.half_scale and not args.controller_config:
        raise TrialsError("--scenarios without --half-scale: give --controller-config too")
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
    out = check_dir(Path(args.out) if args.out else default_out(), "--out")
    if args.json:
        check_file(args.json, "--json")
    info: Dict[str, Any] = {
        "command": command, "created": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
        "git_commit": git_commit(), "machine": machine(), "scenarios": str(cfg.scenarios),
        "controller_config": str(cfg.controller_config), "bin_dir": str(cfg.bin_dir), "cases": cfg.cases,
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
