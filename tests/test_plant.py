"""The plant through the binding: validation, determinism, GIL release, contact reports."""

from __future__ import annotations

import math
import threading
import time

import numpy as np
import pytest

import picopit
from conftest import has

pytestmark = pytest.mark.skipif(not has("Plant"), reason="dynamics::plant not bound yet")

# A rear-quarter push: the bullet beside and slightly behind the target, steering into it.
BULLET0 = [-4.4, -1.95, 0.0, 15.5, 0.0, 0.0]
TARGET0 = [0.0, 0.0, 0.0, 15.0, 0.0, 0.0]


def pit_run(plant: "picopit.Plant", seconds: float = 3.0):
    plant.reset(BULLET0, TARGET0)
    out = []
    for k in range(int(round(seconds / 0.05))):
        steer = 0.12 if k * 0.05 > 0.2 else 0.0
        plant.set_commands(steer, 150.0, 0.0, 0.0)
        plant.advance(0.05)
        c = plant.take_contact_average()
        fc = c["fc"] if c is not None else np.zeros(2)
        out.append(np.concatenate([[plant.time], plant.bullet_state(), plant.target_state(), fc]))
    return np.array(out)


def test_states_have_the_documented_layout():
    p = picopit.Plant("full_size")
    p.reset([1.0, 2.0, 0.3, 10.0, 0.5, 0.1], [5.0, -1.0, -0.2, 12.0, 0.0, 0.0])
    xb, xt = p.bullet_state(), p.target_state()
    assert xb.shape == (6,) and xt.shape == (8,)
    np.testing.assert_allclose(xb, [1.0, 2.0, 0.3, 10.0, 0.5, 0.1], atol=1e-12)
    # Target: [vx, vy, yaw, r, p, phi, X, Y]
    np.testing.assert_allclose(xt, [12.0, 0.0, -0.2, 0.0, 0.0, 0.0, 5.0, -1.0], atol=1e-12)
    assert p.time == 0.0 and p.dt == pytest.approx(1e-3) and p.mu == pytest.approx(0.9)
    p.advance(0.25)
    assert p.time == pytest.approx(0.25)


def test_footprints_are_the_vehicle_rectangles():
    p = picopit.Plant("half_scale")
    p.reset([0.0, -2.0, 0.4, 5.0, 0.0, 0.0], [3.0, 0.0, -0.1, 5.0, 0.0, 0.0])
    fp = p.footprints()
    assert fp.shape == (2, 4, 2)
    d = picopit.load_params_dict("half_scale")
    for k, (who, pose) in enumerate((("bullet", [0.0, -2.0, 0.4]), ("target", [3.0, 0.0, -0.1]))):
        v = d[who]
        expect = picopit.footprint(pose, v["length"], v["width"], v["cg_to_front"])
        np.testing.assert_allclose(fp[k], expect, atol=1e-9)


def test_bad_arguments_raise_value_error_naming_them():
    p = picopit.Plant()
    with pytest.raises(ValueError, match=r"bullet: expected shape \(6,\)"):
        p.reset([0.0] * 5, TARGET0)
    with pytest.raises(ValueError, match=r"target\[3\] = NaN"):
        p.reset(BULLET0, [0.0, 0.0, 0.0, float("nan"), 0.0, 0.0])
    with pytest.raises(ValueError, match="bullet_torque"):
        p.set_commands(0.0, float("inf"))
    # (A negative target_brake is the throttle; a non-finite one is refused.)
    with pytest.raises(ValueError, match="target_brake"):
        p.set_commands(0.0, 0.0, 0.0, float("nan"))
    with pytest.raises(ValueError, match="target_gear"):
        picopit.Plant(target_gear="reverse")
    with pytest.raises(ValueError, match="which"):
        p.body("both")
    with pytest.raises(ValueError, match="duration"):
        p.advance(-1.0)
    with pytest.raises(ValueError, match="duration"):
        p.advance(float("nan"))


def test_bad_settings_raise_param_error():
    with pytest.raises(picopit.ParamError, match="plant.mu"):
        picopit.Plant(mu=-0.5)
    with pytest.raises(picopit.ParamError, match="plant.dt"):
        picopit.Plant(dt=0.01)
    with pytest.raises(picopit.ParamError):
        picopit.Plant("no_such_set")


def test_plant_runs_are_bit_for_bit_deterministic():
    a = pit_run(picopit.Plant("full_size"))
    b = pit_run(picopit.Plant("full_size"))
    assert np.isfinite(a).all()
    assert a[:, -2].max() > 0, "the scripted push should touch the target"
    assert np.array_equal(a, b)
    # reset() really restarts: the same plant again gives the same numbers.
    p = picopit.Plant("full_size")
    pit_run(p)
    assert np.array_equal(pit_run(p), a)


def test_contact_report_fields_and_conventions():
    p = picopit.Plant("full_size")
    p.reset(BULLET0, TARGET0)
    seen = None
    for k in range(60):
        p.set_commands(0.12 if k > 4 else 0.0, 150.0)
        p.advance(0.05)
        c = p.contact()
        if c is not None:
            seen = c
            break
    assert seen is not None, "no contact within 3 s"
    assert set(seen) == {"fc", "gamma", "point_in_world", "point_in_target", "point_in_bullet", "depth"}
    assert seen["fc"].shape == (2,) and seen["fc"][0] >= 0.0  # F_n >= 0
    assert seen["depth"] >= 0.0
    # The bullet is on the target's right and pushes left: the normal points roughly +Y.
    assert math.cos(seen["gamma"] - math.pi / 2) > 0.5
    # Contact on the target's right-rear quarter: behind its c.g., on its right side.
    assert seen["point_in_target"][0] < 0.0 and seen["point_in_target"][1] < 0.0


def test_momentum_is_conserved_without_tyres():
    p = picopit.Plant("full_size", tyre_forces=False)
    d = picopit.load_params_dict("full_size")
    mb, mt = d["bullet"]["mass"], d["target"]["mass"]
    p.reset([-4.6, 0.3, 0.0, 8.0, 0.0, 0.0], [0.0, 0.0, 0.0, 2.0, 0.0, 0.0])

    def momentum():
        xb, xt = p.bullet_state(), p.target_state()
        vb = xb[3] * np.array([math.cos(xb[2]), math.sin(xb[2])]) + xb[4] * np.array(
            [-math.sin(xb[2]), math.cos(xb[2])])
        vt = xt[0] * np.array([math.cos(xt[2]), math.sin(xt[2])]) + xt[1] * np.array(
            [-math.sin(xt[2]), math.cos(xt[2])])
        return mb * vb + mt * vt

    m0 = momentum()
    touched = False
    for _ in range(40):
        p.advance(0.05)
        touched = touched or p.take_contact_average() is not None
    assert touched
    assert np.linalg.norm(momentum() - m0) <= 1e-6 * np.linalg.norm(m0)


def test_advance_releases_the_gil():
    p = picopit.Plant("full_size")
    p.reset(BULLET0, TARGET0)
    t0 = time.perf_counter()
    p.advance(20.0)
    per_second = (time.perf_counter() - t0) / 20.0
    # Long enough to see (aim for ~0.6 s of wall time), bounded for slow machines.
    sim_seconds = float(np.clip(0.6 / max(per_second, 1e-6), 20.0, 5000.0))
    p.reset(BULLET0, TARGET0)

    window = {}
    ticks = []

    def worker():
        window["start"] = time.perf_counter()
        p.advance(sim_seconds)
        window["end"] = time.perf_counter()

    th = threading.Thread(target=worker)
    th.start()
    while th.is_alive():
        ticks.append(time.perf_counter())
    th.join()
    start, end = window["start"], window["end"]
    assert end - start > 0.1, "advance finished too fast to judge"
    mid_lo, mid_hi = start + 0.25 * (end - start), start + 0.75 * (end - start)
    in_middle = sum(1 for t in ticks if mid_lo <= t <= mid_hi)
    # With the GIL held the main thread could not run at all in the middle of the call.
    assert in_middle > 100, f"main thread ran {in_middle} times during advance()"


def test_blended_bullet_command_brakes_on_all_wheels_and_refuses_non_finite() -> None:
    """A negative T_r through the blended command decelerates the bullet with the force the
    drivetrain mapping gives it (service brakes), a positive one drives like set_commands."""
    speeds = {}
    for torque in (-300.0, 0.0):
        p = picopit.Plant("full_size", mu=0.9)
        p.reset([0, 0, 0, 15.0, 0, 0], [100, 0, 0, 15.0, 0, 0])
        p.set_bullet_command_blended(0.0, torque)
        p.advance(1.0)
        speeds[torque] = p.bullet_state()[3]
    # Rolling resistance and drag alone slow the bullet by well under 1 m/s in a second;
    # 300 N m at the rear axle through the brakes is about 3 kN on 1.1 t: ~2.5 m/s more.
    assert speeds[0.0] - speeds[-300.0] > 1.5, speeds
    with pytest.raises(ValueError, match="torque"):
        p.set_bullet_command_blended(0.0, float("nan"))
