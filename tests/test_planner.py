"""Bindings of crates/planner: `Planner` (the decision package) and `PitController`."""

from __future__ import annotations

import math
import sys

import numpy as np
import pytest

import picopit
from picopit import _core

if sys.version_info >= (3, 11):
    import tomllib as _toml
else:  # pragma: no cover
    import tomli as _toml

pytestmark = pytest.mark.skipif(not hasattr(_core, "Planner"), reason="planner not bound")

# A 3-lane straight road along +X, centre line at Y = 0; the target cruises in the middle
# lane at 15 m/s, the bullet 6 m behind and 2.5 m to its left, 2 m/s faster.
TARGET = np.array([15.0, 0.0, 0.0, 0.0, 0.0, 0.0, 100.0, 0.0])  # [vx, vy, yaw, r, p, phi, X, Y]
BULLET = np.array([95.7, 2.2, 0.0, 16.0, 0.0, 0.0])  # [X, Y, yaw, vx, vy, r]; 4.3 m back, 1 m/s faster: the 0.8 s window fits the look-ahead
# A stopped car in the middle lane 20 m ahead of the target: [x, y, heading, vx, vy, l, w].
BLOCKER = [[120.0, 0.0, 0.0, 0.0, 0.0, 4.5, 1.8]]
# Determinism checks lift the wall-clock limits (QP time limit, MPC time budget): with them, a
# loaded machine could cut a solve short and legitimately change the answer.
NO_CLOCK_PLANNER = "[qp]\ntime_limit = 10.0\n"
NO_CLOCK_CONTROLLER = (
    "[planner.qp]\ntime_limit = 10.0\n[mpc]\ntime_budget = 10.0\n[mpc.qp]\ntime_limit = 10.0\n"
)


def planner(**kw) -> _core.Planner:
    p = _core.Planner(**kw)
    p.set_straight_road()
    return p


def same(a, b) -> bool:
    """Deep equality of two packages (arrays element-wise, NaN equal to NaN)."""
    if isinstance(a, dict):
        return isinstance(b, dict) and a.keys() == b.keys() and all(same(a[k], b[k]) for k in a)
    if isinstance(a, np.ndarray):
        return isinstance(b, np.ndarray) and a.shape == b.shape and np.array_equal(a, b, equal_nan=True)
    if isinstance(a, float) and math.isnan(a):
        return isinstance(b, float) and math.isnan(b)
    return a == b


def test_exports():
    for name in ("Planner", "PitController", "PlannerError"):
        assert getattr(picopit, name) is getattr(_core, name)
    assert issubclass(picopit.PlannerError, ValueError)


def test_straight_road_decides_a_pit_with_a_window():
    p = planner()
    d = p.plan(0.0, TARGET, BULLET)
    settings = _toml.loads(p.settings_toml())
    n = round(settings["horizon"] / settings["dt"])
    assert d["mode"] == "pit" and d["infeasible"] is None
    assert d["side"] == "left"  # the bullet is on the target's left
    assert d["feasible_candidates"] >= 1 and d["candidates"] >= d["feasible_candidates"]
    t0, t1 = d["window"]
    assert 0.0 <= t0 < t1 <= settings["horizon"] + 1e-9
    assert t1 - t0 <= settings["window"] + 1e-9
    assert d["predicted_heading_error"] <= d["terminal"]["heading_tol"]
    assert abs(abs(d["terminal"]["heading"]) - math.pi) < 1e-9  # reversed heading
    assert d["predicted_road_margin"] >= -settings["violation_tol"]
    for key, shape in (("times", (n + 1,)), ("forces", (n + 1, 2)), ("corridor", (n + 1, 2)),
                       ("targets", (n + 1, 8)), ("contact_point", (2,)), ("obstacles", (0, 7))):
        assert d[key].shape == shape, key
        assert d[key].dtype == np.float64
    assert np.allclose(d["times"], np.arange(n + 1) * settings["dt"])
    assert np.array_equal(d["targets"][0], TARGET)
    # The push spins the target towards the reversed heading.
    assert d["targets"][-1][2] > 1.0


def test_forces_lie_in_the_friction_cone_and_the_window():
    p = planner()
    d = p.plan(0.0, TARGET, BULLET)
    s = _toml.loads(p.settings_toml())
    mass = picopit.load_params_dict("full_size")["target"]["mass"]
    f_max = s["force_max_g"] * mass * 9.81
    fn, ft = d["forces"][:, 0], d["forces"][:, 1]
    tol = 1e-6 * f_max
    assert np.all(fn >= -tol) and np.all(fn <= f_max + tol)
    assert np.all(np.abs(ft) <= s["friction"] * fn + tol)
    assert fn.max() > 0.05 * mass * 9.81  # a real push, not a zero plan
    t0, t1 = d["window"]
    outside = (d["times"] < t0 - 1e-9) | (d["times"] >= t1 - 1e-9)
    assert np.all(d["forces"][outside] == 0.0)
    assert np.all(d["corridor"][:, 0] <= d["corridor"][:, 1])
    assert np.all(d["corridor"][outside] == 0.0)


def test_planning_is_deterministic():
    a = planner(settings=NO_CLOCK_PLANNER).plan(0.0, TARGET, BULLET)
    p = planner(settings=NO_CLOCK_PLANNER)
    b = p.plan(0.0, TARGET, BULLET)
    c = p.plan(0.0, TARGET, BULLET)  # the same instance again: no hidden state
    assert same(a, b) and same(b, c)
    # The inputs are not aliased: mutating them after the call changes nothing.
    t = TARGET.copy()
    d = p.plan(0.0, t, BULLET)
    t[0] = 99.0
    assert same(d, a)


def test_an_obstacle_in_the_spin_zone_aborts_with_a_reason():
    p = planner(settings=NO_CLOCK_PLANNER)
    free = p.plan(0.0, TARGET, BULLET)
    p.set_obstacles(BLOCKER)
    d = p.plan(0.0, TARGET, BULLET)
    assert (d["mode"], d["window"]) != (free["mode"], free["window"])
    assert d["mode"] == "abort"
    assert d["infeasible"] == "obstacle_clearance"
    assert d["feasible_candidates"] == 0
    assert np.array_equal(d["obstacles"], np.array(BLOCKER))
    assert np.all(d["forces"] == 0.0)  # an abort carries the free prediction
    # Removing it restores the PIT.
    p.set_obstacles(np.zeros((0, 7)))
    assert same(p.plan(0.0, TARGET, BULLET), free)


def test_side_and_best_effort():
    p = planner()
    mirrored = BULLET * [1, -1, 1, 1, 1, 1]  # the bullet on the target's right
    d = p.plan(0.0, TARGET, mirrored)
    assert d["mode"] == "pit" and d["side"] == "right"
    assert d["terminal"]["heading"] == pytest.approx(-math.pi)  # spun clockwise
    assert d["targets"][-1][2] < -1.0
    # Committed to the far side, no contact is reachable within the look-ahead.
    far = p.plan(0.0, TARGET, BULLET, side="right")
    assert far["mode"] == "chase" and far["window"] is None and far["candidates"] == 0
    p.set_obstacles(BLOCKER)
    forced = p.plan(0.0, TARGET, BULLET, None, "left", True)
    # Under way a PIT is not dropped: the best infeasible candidate, with its reason.
    assert forced["mode"] == "pit" and forced["side"] == "left" and forced["window"] is not None
    assert forced["infeasible"] == "obstacle_clearance"
    assert forced["feasible_candidates"] == 0


def test_predict_is_the_free_rollout():
    p = planner()
    d = p.predict("stabilise", 1.5, TARGET, BULLET, target_input=[0.0, 0.0])
    assert d["mode"] == "stabilise" and d["window"] is None and d["infeasible"] is None
    assert d["candidates"] == 0
    assert np.all(d["forces"] == 0.0)
    assert d["times"][0] == 1.5
    # No force, no steer: the target keeps its heading and rolls on.
    assert np.allclose(d["targets"][:, 2], 0.0, atol=1e-9)
    assert np.all(np.diff(d["targets"][:, 6]) > 0)


@pytest.mark.parametrize(
    "text, field",
    [
        ("horizon = 2.01", "horizon"),
        ("window = 3.0", "window"),
        ("start_offsets = [0.3, 0.1]", "start_offsets"),
        ("force_max_g = -1.0", "force_max_g"),
        ("[weights]\npenalty = 0.0", "weights.penalty"),
        ("horizn = 2.0", "horizn"),
    ],
)
def test_bad_planner_settings_name_the_field(text, field):
    with pytest.raises(picopit.PlannerError, match=field):
        _core.Planner(settings=text)


@pytest.mark.parametrize(
    "text, field",
    [
        ("[planner]\ndt = 0.1", "planner.dt"),
        ("[phases]\nrelease_gap = 0.01", "phases.release_gap"),
        ("[planner]\nscp_iterations = 0", "scp_iterations"),
        ("[mpc]\nhorizon = 1", "horizon"),
        ("upper_layer = false", "upper_layer"),  # contradicts upper_layer=True
        ("[planer]\nwindow = 0.5", "planer"),
    ],
)
def test_bad_controller_settings_name_the_field(text, field):
    with pytest.raises(picopit.PlannerError, match=field):
        _core.PitController(settings=text)


def test_settings_round_trip():
    p = _core.Planner(settings="window = 0.5")
    assert _toml.loads(p.settings_toml())["window"] == 0.5
    assert _core.Planner(settings=p.settings_toml()).settings_toml() == p.settings_toml()
    c = _core.PitController(settings="[phases]\nchase_timeout = 5.0", upper_layer=False)
    text = c.settings_toml()
    assert _toml.loads(text)["phases"]["chase_timeout"] == 5.0
    assert _toml.loads(text)["upper_layer"] is False
    assert _core.PitController(settings=text, upper_layer=False).settings_toml() == text


def test_bad_inputs_raise_planner_error():
    p = planner()
    bad = [
        lambda: p.plan(0.0, TARGET[:7], BULLET),
        lambda: p.plan(0.0, TARGET, BULLET.reshape(6, 1)),
        lambda: p.plan(0.0, TARGET, BULLET, target_input=[0.0, 0.0, 0.0]),
        lambda: p.plan(0.0, np.where(np.arange(8) == 3, np.nan, TARGET), BULLET),
        lambda: p.plan(math.inf, TARGET, BULLET),
        lambda: p.plan(0.0, TARGET, BULLET, side="up"),
        lambda: p.plan(0.0, "not an array", BULLET),
        lambda: p.predict("spin", 0.0, TARGET, BULLET),
        lambda: p.set_obstacles(np.zeros((2, 6))),
        lambda: p.set_obstacles(np.zeros(7)),
        lambda: p.set_obstacles([[1.0, 2.0, 0.0, 0.0, 0.0, -4.5, 1.8]]),
        lambda: p.set_obstacles([[1.0, 2.0, 0.0, math.inf, 0.0, 4.5, 1.8]]),
        lambda: p.set_obstacles(np.tile(BLOCKER, (33, 1))),
        lambda: p.set_straight_road(lanes=0),
        lambda: p.set_straight_road(length=-5.0),
        lambda: p.set_road("lanes = 3"),
        lambda: _core.Planner(target_model="5dof"),
        lambda: _core.Planner(mu=0.0),
        lambda: _core.PitController(target_model="no/such/file.safetensors"),
    ]
    for i, call in enumerate(bad):
        with pytest.raises(picopit.PlannerError):
            call()
    with pytest.raises(picopit.PlannerError, match=r"target: expected shape \(8,\)"):
        p.plan(0.0, TARGET[:7], BULLET)
    with pytest.raises(picopit.PlannerError, match=r"(?i)target\[3\] = nan"):
        p.plan(0.0, np.where(np.arange(8) == 3, np.nan, TARGET), BULLET)
    with pytest.raises(picopit.PlannerError, match=r"obstacles\[0\]"):
        p.set_obstacles([[1.0, 2.0, 0.0, 0.0, 0.0, -4.5, 1.8]])
    with pytest.raises(picopit.PlannerError, match="5dof"):
        _core.Planner(target_model="5dof")
    with pytest.raises(picopit.PlannerError, match="no road"):
        _core.Planner().plan(0.0, TARGET, BULLET)
    with pytest.raises(picopit.PlannerError, match="no road"):
        _core.PitController().step(0.0, TARGET, BULLET)
    # A failed setter leaves the previous road and obstacles in place.
    assert p.plan(0.0, TARGET, BULLET)["mode"] == "pit"


def test_a_road_from_toml():
    p = _core.Planner(settings=NO_CLOCK_PLANNER)
    p.set_road(
        'lanes = 3\nlane_width = 3.5\nshoulder = 1.0\norigin = [0.0, 0.0, 0.0]\n'
        'segments = [{ kind = "straight", length = 2000.0 }]\n'
    )
    expected = planner(settings=NO_CLOCK_PLANNER).plan(0.0, TARGET, BULLET)
    assert same(p.plan(0.0, TARGET, BULLET), expected)


def closed_loop(ctl: _core.PitController, steps: int):
    """Drive the plant's bullet with `ctl` for `steps` control steps of the MPC's dt."""
    dt = _toml.loads(ctl.settings_toml())["mpc"]["dt"]
    plant = _core.Plant("full_size", 0.9)
    # Plant states are [X, Y, yaw, vx, vy, r] for both vehicles at reset.
    plant.reset([94.0, 2.5, 0.0, 17.0, 0.0, 0.0], [100.0, 0.0, 0.0, 15.0, 0.0, 0.0])
    outs = []
    for k in range(steps):
        out = ctl.step(k * dt, plant.target_state(), plant.bullet_state())
        outs.append(out)
        plant.set_bullet_command_blended(float(out["command"][0]), float(out["command"][1]))
        plant.advance(dt)
    return outs, plant


def test_closed_loop_with_the_plant_reaches_the_pit():
    ctl = _core.PitController()
    ctl.set_straight_road()
    outs, plant = closed_loop(ctl, 100)
    assert all(np.all(np.isfinite(o["command"])) and o["command"].shape == (2,) for o in outs)
    phases = [o["phase"] for o in outs]
    order = ["chasing", "pit", "stabilising", "done"]
    assert phases[0] == "chasing"
    reached = any(ph in ("pit", "stabilising", "done") for ph in phases)
    assert reached or ctl.abort_reason is not None, (phases, ctl.abort_reason)
    if ctl.abort_reason is None:
        # Phases only move forward.
        idx = [order.index(ph) for ph in phases]
        assert idx == sorted(idx)
    assert outs[0]["replanned"] and outs[0]["mode"] in ("pit", "chase", "abort")
    for o in outs:
        assert o["plan_time"] >= 0.0 and o["ctrl_time"] >= 0.0
        if not o["replanned"]:
            assert o["plan_time"] == 0.0
        if o["phase"] in ("chasing", "pit"):
            assert o["mpc_status"] is not None
    assert ctl.phase == phases[-1]
    pkg = ctl.package()
    assert pkg is not None and pkg["mode"] in ("chase", "pit", "stabilise", "abort")
    assert pkg["targets"].shape[1] == 8
    assert np.all(np.isfinite(plant.target_state()))


def test_reset_starts_a_new_maneuver():
    ctl = _core.PitController(settings=NO_CLOCK_CONTROLLER)
    ctl.set_straight_road()
    a, _ = closed_loop(ctl, 5)
    ctl.reset()
    b, _ = closed_loop(ctl, 5)
    assert [o["phase"] for o in a] == [o["phase"] for o in b]
    assert b[0]["replanned"]
    for x, y in zip(a, b):
        assert np.allclose(x["command"], y["command"])


def test_without_the_upper_layer_there_is_no_package():
    ctl = _core.PitController(upper_layer=False)
    assert not ctl.upper_layer
    ctl.set_straight_road()
    assert ctl.package() is None
    outs, _ = closed_loop(ctl, 10)
    assert ctl.package() is None
    for o in outs:
        assert o["mode"] is None and not o["replanned"] and o["plan_time"] == 0.0
        assert np.all(np.isfinite(o["command"]))
    # With the upper layer: no package until the first plan, one after it.
    on = _core.PitController()
    on.set_straight_road()
    assert on.package() is None
    closed_loop(on, 1)
    assert on.package() is not None
    on.reset()
    assert on.package() is None
