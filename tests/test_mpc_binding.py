"""The coupled MPC through picopit._core.CoupledMpc: numpy in and out, errors naming the
field, the same behaviour for the 4-DOF model and the shipped surrogates."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from picopit import _core

ROOT = Path(__file__).resolve().parent.parent
MODELS = ROOT / "models" / "full_size"


def states(rel_x: float, rel_y: float, v_t: float = 15.0, v_b: float = 17.0):
    target = np.array([v_t, 0.0, 0.0, 0.0, 0.0, 0.0, 100.0, 0.0])
    bullet = np.array([100.0 + rel_x, rel_y, 0.0, v_b, 0.0, 0.0])
    return target, bullet


def mpc(target_model: str = "4dof") -> _core.CoupledMpc:
    m = _core.CoupledMpc("full_size", 0.9, target_model)
    m.set_straight_road()
    return m


def touching():
    """Bullet c.g. with its front-right corner 4 cm into the target's left rear quarter."""
    p = _core.load_params("full_size")
    from picopit import _toml  # tomllib, or tomli before Python 3.11

    d = _toml.loads(p)
    b, t = d["bullet"], d["target"]
    x = -t["lr"] - 0.3 - b["cg_to_front"]
    y = 0.5 * t["width"] + 0.5 * b["width"] - 0.04
    return x, y


def test_apart_no_force_and_the_bullet_only_qp():
    m = mpc()
    (n1, m1), (n2, m2) = m.qp_sizes
    assert n2 < n1 and m2 < m1
    target, bullet = states(-12.0, 3.5)
    m.default_reference(target, bullet)
    out = m.solve(target, bullet)
    assert out["status"] == "RtiStep"
    assert out["coupled"] is False
    assert np.all(np.isfinite(out["command"]))
    plan = m.plan()
    assert plan["u"].shape == (20, 2) and plan["target"].shape == (21, 8)
    assert plan["bullet"].shape == (21, 6) and plan["gap"].shape == (21,)
    assert np.all(plan["f"] == 0.0)


@pytest.mark.parametrize("model", ["4dof", "pinn", "picopinn"])
def test_in_contact_every_surrogate_plans_forces_in_the_cone(model):
    path = "4dof" if model == "4dof" else str(MODELS / f"{model}.safetensors")
    m = mpc(path)
    assert m.target_model == model
    target, bullet = states(*touching(), v_b=16.0)
    m.default_reference(target, bullet)
    out = m.solve(target, bullet)
    assert out["coupled"] is True
    assert out["status"] in ("RtiStep", "TimeBudget"), out
    f = m.plan()["f"]
    assert np.all(f[:, 0] >= 0.0)
    assert np.all(np.abs(f[:, 1]) <= 0.3 * f[:, 0] + 1e-6)
    assert f[:, 0].max() > 100.0


def test_bad_settings_and_inputs_name_the_field():
    with pytest.raises(_core.MpcError, match="weights.penalty"):
        _core.CoupledMpc(settings="[weights]\npenalty = -1.0")
    with pytest.raises(_core.MpcError, match="side"):
        _core.CoupledMpc(side="middle")
    m = mpc()
    target, bullet = states(-10.0, 3.0)
    with pytest.raises(ValueError, match=r"bullet\[2\]"):
        m.solve(target, [1.0, 2.0, float("nan"), 4.0, 5.0, 6.0])
    with pytest.raises(ValueError, match="stages"):
        m.set_reference(np.zeros((3, 8)), 0.0, 1.0)
    with pytest.raises(ValueError, match=r"obstacles\[0\]"):
        m.set_obstacles([[0.0, 0.0, 0.0, 0.0, 0.0, -1.0, 1.0]])


def test_same_input_same_command():
    target, bullet = states(-8.0, 3.0)
    outs = []
    for _ in range(2):
        m = mpc()
        m.default_reference(target, bullet)
        outs.append(m.solve(target, bullet, last_command=[0.0, 0.0])["command"])
    np.testing.assert_array_equal(outs[0], outs[1])


def test_evaluate_scores_the_solvers_own_plan_with_its_merit():
    m = mpc()
    target, bullet = states(*touching(), v_b=16.0)
    m.default_reference(target, bullet)
    out = m.solve(target, bullet)
    plan = m.plan()
    merit, viol = m.evaluate(target, bullet, plan["u"], plan["f"])
    assert merit == pytest.approx(out["merit"], rel=1e-9)
    assert viol == pytest.approx(out["max_violation"], rel=1e-9, abs=1e-12)
    # A worse plan (hold the steering hard left) scores worse.
    u_bad = plan["u"].copy()
    u_bad[:, 0] = 0.3
    assert m.evaluate(target, bullet, u_bad, plan["f"])[0] > merit
    heading, weight = m.reference_target
    assert heading == pytest.approx(np.pi) and weight == 1.0  # left side, engaged
    lin = m.linearisation()
    assert lin["gap"].shape == (20,) and lin["road_bullet"].shape == (20, 4)
    assert any(lin["band"])
