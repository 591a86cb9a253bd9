"""The wall-clock IPC soak (tests/soak_ipc.py) in brief: pit-vehicle and pit-controller under
frequent random pauses and restarts neither freeze nor exit badly, and every recording they
leave (a killed process's too) reads to its last complete message. The full soak (10^5
cycles, docs/vehicle_io.md) is the same program with more cycles."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from soak_ipc import main as soak

RELEASE = Path(__file__).resolve().parents[1] / "target" / "release"


@pytest.mark.skipif(not (RELEASE / "pit-vehicle").exists() or not (RELEASE / "pit-controller").exists(),
                    reason="target/release/pit-vehicle or pit-controller not built (./scripts/setup.sh --full)")
def test_a_short_soak_with_pauses_and_restarts_keeps_both_processes_alive(tmp_path):
    out = tmp_path / "soak"
    soak(["--cycles", "300", "--seed", "3", "--event-every", "0.5", "1.0", "--out", str(out),
          "--bin-dir", str(RELEASE)])
    r = json.loads((out / "soak.json").read_text())
    assert r["cycles"] >= 300
    events = sum(r["pauses"].values()) + sum(n for side in r["restarts"].values() for n in side.values())
    assert events >= 3, r
    # Behaviour, not timing: no freeze, no bad exit, every MCAP readable (the safe stop's
    # lateness, a wall-clock figure, is the full soak's to report).
    assert r["freezes"] == [] and r["bad_exits"] == [] and r["unreadable_mcap"] == [], r
    assert r["mcap_files"] >= 2 and r["mcap_messages"] > 0
