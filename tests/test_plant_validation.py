"""The plant against references no one here wrote (picopit.validation, docs/plant.md):
CommonRoad's multi-body model on handling and braking, impulse-momentum theory on impacts.
Every row of the suite must pass its stated tolerance."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

pytest.importorskip("scipy")
pytest.importorskip("vehiclemodels")

from picopit import validation  # noqa: E402


@pytest.fixture(scope="module")
def checks():
    return validation.all_checks("full_size")


def test_every_check_passes(checks):
    failed = [c for c in checks if not c.passed]
    assert not failed, "\n" + validation.format_table(failed)


def test_the_suite_covers_what_it_claims(checks):
    manoeuvres = {c.manoeuvre.split(",")[0] for c in checks}
    assert {
        "step steer 0.05 rad",
        "sine steer 0.02 rad",
        "steer ramp 0.01 rad/s",
        "straight braking 1500 N m",
        "straight braking 3000 N m",
        "rear offset impact",
        "quarter panel impact",
    } <= manoeuvres
    stated = [c for c in checks if c.quantity == "restitution e (stated)"]
    assert len(stated) == 2 and all(abs(c.reference - 0.3) < 1e-12 for c in stated)


def test_a_check_fails_outside_its_tolerance():
    c = validation.Check("m", "q", "", 1.11, 1.0, "rel", 0.10)
    assert not c.passed
    assert validation.Check("m", "q", "", 1.09, 1.0, "rel", 0.10).passed
    assert not validation.Check("m", "q", "", float("nan"), 1.0, "abs", 1.0).passed
    assert not validation.Check("m", "q", "", 0.5, 0.15, "band", 0.45).passed
    assert not validation.Check("m", "q", "", 2e-9, 0.0, "max", 1e-9).passed


def test_brach_impulse_of_a_central_frictionless_hit():
    # Two equal cars, central hit along x: P_n = (1 + e) m v / 2.
    import numpy as np

    bodies = (validation._Body(1000.0, 1500.0), validation._Body(1000.0, 1500.0))
    arms = (np.array([2.0, 0.0]), np.array([-2.0, 0.0]))
    p = validation.brach_impulse(bodies, arms, np.array([1.0, 0.0]), np.array([-3.0, 0.0]), 0.3, 0.0)
    assert p == pytest.approx([1.3 * 1000.0 * 3.0 / 2.0, 0.0])


def test_cli_prints_the_table_and_writes_json(tmp_path):
    out = tmp_path / "checks.json"
    run = subprocess.run(
        [sys.executable, "-m", "picopit", "validate-plant", "--json", str(out)],
        capture_output=True, text=True, timeout=600,
    )
    assert run.returncode == 0, run.stderr
    assert "| step steer 0.05 rad, 20 m/s | steady yaw rate |" in run.stdout
    rows = json.loads(out.read_text())
    assert rows and all(r["passed"] for r in rows)
