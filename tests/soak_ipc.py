#!/usr/bin/env python3
"""Soak of pit-vehicle and pit-controller on the wall clock, with random pauses and restarts.

Runs the release binaries on a fresh service prefix (the vehicle in soak mode: the scenario
restarts whenever a run ends) until the vehicle processes together have run ``--cycles``
control periods. Every few seconds (seeded) it pauses one side with SIGSTOP/SIGCONT, or
restarts one side (SIGTERM, or SIGKILL for a crash). It checks:

* no freeze: a process that is not paused must grow its MCAP recording (every period brings
  states or heartbeats) within ``--freeze-after`` seconds; a frozen process fails the soak;
* every safe stop latched within one control period of the command timeout's deadline
  (``safe_stop_late_max_ms`` of every vehicle summary <= 50 ms);
* every MCAP file is readable to its last complete message (also a killed process's), with
  ``picopit.replay.read_recording``;
* every process that was not killed exits with status 0.

Usage (after ./scripts/setup.sh --full, which builds the binaries; about 85 min for the
default 10^5 cycles)::

    .venv/bin/python tests/soak_ipc.py --cycles 100000 --out runs/soak

``tests/test_soak.py`` runs it briefly (a few hundred cycles with frequent events).

It prints a summary and writes ``<out>/soak.json``; exit status 1 when a check failed.
Recordings are deleted once read (``--keep-mcap`` keeps them).
"""

from __future__ import annotations

import argparse
import json
import os
import random
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any, Dict, List, Optional

ROOT = Path(__file__).resolve().parents[1]
PERIOD_MS = 50.0


class Side:
    """One of the two processes, restarted as often as the soak asks."""

    def __init__(self, name: str, cmd: List[str], out: Path):
        self.name, self.base_cmd, self.out = name, cmd, out
        self.proc: Optional[subprocess.Popen] = None
        self.generation = 0
        self.paused_until = 0.0
        self.last_size = 0
        self.last_growth = time.monotonic()
        self.started = 0.0
        self.scanner = McapScanner("/state" if name == "vehicle" else "/heartbeat/controller")

    def files(self, gen: int) -> Dict[str, Path]:
        stem = self.out / f"{self.name}-{gen:04d}"
        return {"mcap": stem.with_suffix(".mcap"), "json": stem.with_suffix(".json"),
                "log": stem.with_suffix(".log")}

    def start(self) -> None:
        self.generation += 1
        f = self.files(self.generation)
        cmd = self.base_cmd + ["--record", str(f["mcap"]), "--summary", str(f["json"])]
        with open(f["log"], "wb") as log:
            self.proc = subprocess.Popen(cmd, cwd=ROOT, stdin=subprocess.DEVNULL, stdout=log,
                                         stderr=subprocess.STDOUT, start_new_session=True)
        self.last_size = 0
        self.last_growth = time.monotonic()
        self.started = time.monotonic()
        self.scanner.reset()

    def alive(self) -> bool:
        return self.proc is not None and self.proc.poll() is None

    def signal(self, sig: int) -> None:
        if self.alive():
            os.kill(self.proc.pid, sig)

    def check_progress(self, now: float) -> Optional[float]:
        """Seconds since the process last published on its own topic (None while paused or
        not running). The recorder has a thread of its own, so a growing file alone would
        not show that the main loop runs: the vehicle's states and the controller's
        heartbeats come from the loop."""
        if not self.alive() or now < self.paused_until:
            self.last_growth = now
            return None
        n = self.scanner.count(self.files(self.generation)["mcap"])
        if n != self.last_size:
            self.last_size, self.last_growth = n, now
        return now - self.last_growth


class McapScanner:
    """Counts the messages on one topic of a growing MCAP file, reading only what is new."""

    def __init__(self, topic: str):
        self.topic = topic
        self.reset()

    def reset(self) -> None:
        self.offset, self.channels, self.n = 8, set(), 0

    def count(self, path: Path) -> int:
        try:
            with open(path, "rb") as fh:
                fh.seek(self.offset)
                data = fh.read()
        except OSError:
            return self.n
        off = 0
        while off + 9 <= len(data):
            op = data[off]
            length = int.from_bytes(data[off + 1:off + 9], "little")
            end = off + 9 + length
            if end > len(data):
                break
            body = data[off + 9:end]
            if op == 0x04:  # Channel: id u16, schema id u16, topic (u32 length + bytes)
                tlen = int.from_bytes(body[4:8], "little")
                if body[8:8 + tlen].decode(errors="replace") == self.topic:
                    self.channels.add(int.from_bytes(body[0:2], "little"))
            elif op == 0x05 and int.from_bytes(body[0:2], "little") in self.channels:
                self.n += 1
            off = end
        self.offset += off
        return self.n


def read_mcap(path: Path) -> Dict[str, Any]:
    from picopit.replay import ReplayError, read_recording

    try:
        rec = read_recording(path)
    except ReplayError as e:
        return {"ok": False, "error": str(e)}
    return {"ok": rec.undecodable == 0, "messages": rec.n_messages, "truncated": rec.truncated,
            "states": len(rec.messages.get("/state", [])), "undecodable": rec.undecodable}


def main(argv: Optional[List[str]] = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cycles", type=int, default=100_000, help="vehicle periods in total (default 10^5)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", default="runs/soak", help="folder for logs, summaries, soak.json")
    ap.add_argument("--bin-dir", default=str(ROOT / "target" / "release"))
    ap.add_argument("--scenario", default="R1", help="case of data/trials/half_scale.jsonl (default R1)")
    ap.add_argument("--event-every", type=float, nargs=2, default=(2.0, 8.0), metavar=("MIN", "MAX"),
                    help="seconds between faults, uniform (default 2 8)")
    ap.add_argument("--freeze-after", type=float, default=5.0, help="no recording growth this long: frozen (s)")
    ap.add_argument("--keep-mcap", action="store_true")
    args = ap.parse_args(argv)

    rng = random.Random(args.seed)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    prefix = f"picopit-soak-{os.getpid()}"
    b = Path(args.bin_dir)
    common = ["--scenario", "data/trials/half_scale.jsonl", "--id", args.scenario, "--clock", "wall",
              "--prefix", prefix]
    vehicle = Side("vehicle", [str(b / "pit-vehicle")] + common + [
        "--soak-periods", str(10 ** 9), "--max-time", "1e7", "--connect-timeout", "60"], out)
    controller = Side("controller", [str(b / "pit-controller")] + common + [
        "--controller-config", "configs/controller_half_scale.toml", "--connect-timeout", "60"], out)
    sides = {"vehicle": vehicle, "controller": controller}

    report: Dict[str, Any] = {
        "command": " ".join(sys.argv if argv is None else ["soak_ipc.py", *argv]), "seed": args.seed, "cycles_goal": args.cycles,
        "pauses": {"vehicle": 0, "controller": 0}, "pause_s": {"vehicle": 0.0, "controller": 0.0},
        "restarts": {"vehicle": {"SIGTERM": 0, "SIGKILL": 0}, "controller": {"SIGTERM": 0, "SIGKILL": 0}},
        "freezes": [], "bad_exits": [], "late_safe_stops": [], "unreadable_mcap": [],
        "processes": [],
    }
    cycles_done = 0  # periods of the vehicle processes that ended

    def finish(side: Side, how: str) -> None:
        """Reap the side's current process and check what it left."""
        nonlocal cycles_done
        p = side.proc
        try:
            rc = p.wait(timeout=30)
        except subprocess.TimeoutExpired:
            report["freezes"].append({"side": side.name, "gen": side.generation, "at": "exit"})
            os.kill(p.pid, signal.SIGKILL)
            rc = p.wait()
        f = side.files(side.generation)
        entry: Dict[str, Any] = {"side": side.name, "gen": side.generation, "end": how, "rc": rc}
        summary = None
        try:
            summary = json.loads(f["json"].read_text())
        except (OSError, ValueError):
            pass
        if how != "SIGKILL" and rc != 0:
            report["bad_exits"].append(entry)
        m = read_mcap(f["mcap"])
        entry["mcap"] = m
        if not m.get("ok"):
            report["unreadable_mcap"].append(entry)
        if side.name == "vehicle":
            periods = summary["periods"] if summary else m.get("states", 0)
            cycles_done += periods
            entry["periods"] = periods
            if summary:
                for k in ("safe_stops", "resumes", "safe_stop_late_max_ms", "controller_restarts", "restarts",
                          "lockstep_misses", "commands_applied", "commands_stale"):
                    entry[k] = summary.get(k)
                if summary.get("safe_stop_late_max_ms", 0.0) > PERIOD_MS:
                    report["late_safe_stops"].append(entry)
        elif summary:
            for k in ("ending", "cycles", "fallbacks", "stale_states", "deadline_misses", "vehicle_restarts"):
                entry[k] = summary.get(k)
        report["processes"].append(entry)
        if not args.keep_mcap:
            f["mcap"].unlink(missing_ok=True)
        print(f"soak: {side.name} #{side.generation} ended ({how}, status {rc}): "
              + ", ".join(f"{k} {entry[k]}" for k in ("periods", "safe_stops", "resumes", "safe_stop_late_max_ms",
                                                        "ending", "cycles", "fallbacks") if k in entry)
              + f"; MCAP {m}", flush=True)

    def restart(side: Side, sig: int) -> None:
        side.signal(sig)
        name = "SIGKILL" if sig == signal.SIGKILL else "SIGTERM"
        report["restarts"][side.name][name] += 1
        finish(side, name)
        time.sleep(rng.uniform(0.0, 1.5))
        side.start()

    t0 = time.monotonic()
    controller.start()
    vehicle.start()
    next_event = time.monotonic() + rng.uniform(*args.event_every)
    last_print = 0.0
    try:
        while True:
            now = time.monotonic()
            # Periods of the running vehicle so far: its states on record.
            live = vehicle.scanner.n if vehicle.alive() else 0
            if cycles_done + live >= args.cycles:
                break
            for side in sides.values():
                if not side.alive():
                    rc = side.proc.returncode
                    report["bad_exits"].append({"side": side.name, "gen": side.generation, "rc": rc,
                                                "end": "by itself"})
                    finish(side, "by itself")
                    side.start()
                stuck = side.check_progress(now)
                if stuck is not None and stuck > args.freeze_after:
                    report["freezes"].append({"side": side.name, "gen": side.generation,
                                              "stuck_s": round(stuck, 1), "at_s": round(now - t0, 1)})
                    print(f"soak: FREEZE: {side.name} #{side.generation} silent for {stuck:.1f} s", flush=True)
                    restart(side, signal.SIGKILL)
            if now >= next_event:
                side = sides[rng.choice(("vehicle", "controller"))]
                r = rng.random()
                if r < 0.85:
                    d = rng.uniform(0.05, 0.5) if rng.random() < 0.9 else rng.uniform(0.5, 3.0)
                    side.signal(signal.SIGSTOP)
                    side.paused_until = time.monotonic() + d + 0.5
                    time.sleep(d)
                    side.signal(signal.SIGCONT)
                    report["pauses"][side.name] += 1
                    report["pause_s"][side.name] += d
                else:
                    restart(side, signal.SIGKILL if rng.random() < 0.5 else signal.SIGTERM)
                next_event = time.monotonic() + rng.uniform(*args.event_every)
            if now - last_print > 60.0:
                last_print = now
                print(f"soak: {now - t0:.0f} s, ~{cycles_done + live} / {args.cycles} cycles; pauses "
                      f"{report['pauses']}, restarts {report['restarts']}, freezes {len(report['freezes'])}",
                      flush=True)
            time.sleep(0.05)
    finally:
        for side in (vehicle, controller):
            if side.alive():
                side.signal(signal.SIGCONT)
                side.signal(signal.SIGTERM)
                finish(side, "SIGTERM (end)")
    vs = [p for p in report["processes"] if p["side"] == "vehicle"]
    report.update(
        wall_s=round(time.monotonic() - t0, 1), cycles=cycles_done,
        safe_stops=sum(p.get("safe_stops") or 0 for p in vs), resumes=sum(p.get("resumes") or 0 for p in vs),
        safe_stop_late_max_ms=max((p.get("safe_stop_late_max_ms") or 0.0 for p in vs), default=0.0),
        mcap_files=len(report["processes"]),
        mcap_messages=sum(p["mcap"].get("messages", 0) for p in report["processes"]),
        mcap_truncated=sum(bool(p["mcap"].get("truncated")) for p in report["processes"]),
    )
    ok = not (report["freezes"] or report["bad_exits"] or report["late_safe_stops"] or report["unreadable_mcap"])
    report["ok"] = ok
    (out / "soak.json").write_text(json.dumps(report, indent=2) + "\n")
    print(f"soak: {'OK' if ok else 'FAILED'}: {report['cycles']} cycles in {report['wall_s']:.0f} s; pauses "
          f"{report['pauses']} ({report['pause_s']['vehicle']:.0f} s / {report['pause_s']['controller']:.0f} s); "
          f"restarts {report['restarts']}; {report['safe_stops']} safe stops ({report['resumes']} resumed), "
          f"latest {report['safe_stop_late_max_ms']:.1f} ms after its deadline; {len(report['freezes'])} freezes; "
          f"{len(report['bad_exits'])} bad exits; {report['mcap_files']} MCAP files read "
          f"({report['mcap_messages']} messages, {report['mcap_truncated']} truncated by a kill), "
          f"{len(report['unreadable_mcap'])} unreadable; wrote {out / 'soak.json'}")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
