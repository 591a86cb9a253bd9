"""Launching the ``picopit trials`` runs: per trial the two release binaries, ``pit-vehicle``
first, then ``pit-controller``, on a fresh iceoryx2 service prefix, watched until both exit
(or a timeout, or one outliving the other by 10 s), their summaries read into a row
(``picopit.trials_rows``); ``run_all`` runs ``cfg.jobs`` trials at a time with a progress
line, and on Ctrl-C or an error stops every child it started (``kill_all``).
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from concurrent.futures import FIRST_COMPLETED, Future, ThreadPoolExecutor, wait
from pathlib import Path
from typing import Any, Dict, List, Mapping, Optional, Tuple

from .trials_config import CONTROLLER_BIN, VEHICLE_BIN, Trial, TrialsConfig, plan
from .trials_rows import make_row


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
           "--summary", str(run_dir / "controller.json")]
    if cfg.controller_config is not None:
        ctl += ["--controller-config", str(cfg.controller_config)]
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
