"""The control-oriented models through the binding: Jacobians against finite differences,
step/step_jac agreement, argument validation."""

from __future__ import annotations

import numpy as np
import pytest

import picopit
from conftest import has

RNG_SEED = 20240611


def central_jacobians(step, x, u, fc, gamma, point, u_scale=(0.1, 100.0)):
    """Central differences of step(x, u, fc) with respect to x, u and fc. Steps are 1e-6
    of each variable's size or of its typical magnitude (torques ~100 N m, forces ~1 kN),
    so round-off does not swamp the small force columns."""

    def jac(f, v, typical):
        v = np.asarray(v, dtype=float)
        cols = []
        for j in range(v.size):
            h = 1e-6 * max(typical[j], abs(v[j]))
            vp, vm = v.copy(), v.copy()
            vp[j] += h
            vm[j] -= h
            cols.append((f(vp) - f(vm)) / (2.0 * h))
        return np.stack(cols, axis=1)

    a = jac(lambda v: step(v, u, fc, gamma, point), x, np.ones(len(x)))
    b = jac(lambda v: step(x, v, fc, gamma, point), u, u_scale)
    f = jac(lambda v: step(x, u, v, gamma, point), fc, (1e3, 1e3))
    return a, b, f


def assert_jacobian_close(analytic, numeric, name):
    # Column-wise relative error: each column against its own magnitude.
    for j in range(numeric.shape[1]):
        scale = max(np.abs(numeric[:, j]).max(), np.abs(analytic[:, j]).max(), 1e-12)
        err = np.abs(analytic[:, j] - numeric[:, j]).max() / scale
        assert err <= 1e-5, f"{name}[:, {j}] relative error {err:.2e}"


def random_contact(rng, in_contact):
    if not in_contact:
        return np.zeros(2), 0.0, np.zeros(2)
    fn = rng.uniform(500.0, 8000.0)
    fc = np.array([fn, rng.uniform(-0.4, 0.4) * fn])
    point = np.array([rng.uniform(-2.2, -1.0), rng.choice([-1.0, 1.0]) * rng.uniform(0.6, 0.8)])
    return fc, rng.uniform(-np.pi, np.pi), point


@pytest.mark.skipif(not has("BulletModel"), reason="dynamics::bullet not bound yet")
@pytest.mark.parametrize("in_contact", [False, True])
def test_bullet_step_jac_matches_finite_differences(in_contact):
    rng = np.random.default_rng(RNG_SEED)
    model = picopit.BulletModel("full_size", mu=0.9, dt=0.05)
    for _ in range(10):
        x = np.array([rng.uniform(-50, 50), rng.uniform(-5, 5), rng.uniform(-np.pi, np.pi),
                      rng.uniform(5.0, 25.0), rng.uniform(-1.0, 1.0), rng.uniform(-0.5, 0.5)])
        u = np.array([rng.uniform(-0.3, 0.3), rng.uniform(-250.0, 450.0)])
        fc, gamma, point = random_contact(rng, in_contact)
        xn, a, b, f = model.step_jac(x, u, fc, gamma, point)
        assert xn.shape == (6,) and a.shape == (6, 6) and b.shape == (6, 2) and f.shape == (6, 2)
        assert np.array_equal(xn, model.step(x, u, fc, gamma, point))
        na, nb, nf = central_jacobians(model.step, x, u, fc, gamma, point)
        assert_jacobian_close(a, na, "A")
        assert_jacobian_close(b, nb, "B")
        assert_jacobian_close(f, nf, "F")


@pytest.mark.skipif(not has("FourDofTarget"), reason="dynamics::target4dof not bound yet")
@pytest.mark.parametrize("in_contact", [False, True])
def test_four_dof_step_jac_matches_finite_differences(in_contact):
    rng = np.random.default_rng(RNG_SEED + 1)
    model = picopit.FourDofTarget("full_size", mu=0.9, dt=0.05)
    assert model.param_count == 0 and model.name == "4dof"
    for _ in range(10):
        x = np.array([rng.uniform(5.0, 25.0), rng.uniform(-1.0, 1.0), rng.uniform(-np.pi, np.pi),
                      rng.uniform(-0.5, 0.5), rng.uniform(-0.2, 0.2), rng.uniform(-0.05, 0.05),
                      rng.uniform(-50, 50), rng.uniform(-5, 5)])
        u = np.array([rng.uniform(-0.2, 0.2), rng.uniform(0.0, 2000.0)])
        fc, gamma, point = random_contact(rng, in_contact)
        xn, a, b, f = model.step_jac(x, u, fc, gamma, point)
        assert xn.shape == (8,) and a.shape == (8, 8) and b.shape == (8, 2) and f.shape == (8, 2)
        assert np.array_equal(xn, model.step(x, u, fc, gamma, point))
        na, nb, nf = central_jacobians(model.step, x, u, fc, gamma, point)
        assert_jacobian_close(a, na, "A")
        assert_jacobian_close(b, nb, "B")
        assert_jacobian_close(f, nf, "F")


@pytest.mark.skipif(not has("BulletModel"), reason="dynamics::bullet not bound yet")
def test_bullet_contact_defaults_are_no_contact_and_force_pushes_away():
    model = picopit.BulletModel("full_size", dt=0.05)
    x = np.array([0.0, 0.0, 0.0, 15.0, 0.0, 0.0])
    u = np.array([0.0, 0.0])
    free = model.step(x, u)
    assert np.array_equal(free, model.step(x, u, (0.0, 0.0), 0.0, (0.0, 0.0)))
    # A normal force on the target pointing +Y (gamma = pi/2) pushes the bullet toward -Y.
    pushed = model.step(x, u, (5000.0, 0.0), np.pi / 2, (2.0, 0.7))
    assert pushed[4] < free[4]


@pytest.mark.skipif(not has("FourDofTarget"), reason="dynamics::target4dof not bound yet")
def test_rear_quarter_push_yaws_the_target():
    model = picopit.FourDofTarget("full_size", dt=0.05)
    x = np.array([15.0, 0, 0, 0, 0, 0, 0, 0])
    # Push at the right-rear quarter toward +Y: the yaw rate becomes negative (clockwise).
    nxt = model.step(x, (0.0, 0.0), (5000.0, 0.0), np.pi / 2, (-1.6, -0.8))
    assert nxt[3] < 0.0 and nxt[1] > 0.0


@pytest.mark.skipif(not (has("BulletModel") and has("FourDofTarget")), reason="models not bound yet")
def test_model_arguments_are_validated():
    bullet = picopit.BulletModel()
    target = picopit.FourDofTarget()
    with pytest.raises(ValueError, match=r"x: expected shape \(6,\)"):
        bullet.step(np.zeros(8), np.zeros(2))
    with pytest.raises(ValueError, match=r"u\[1\] = NaN"):
        bullet.step_jac(np.zeros(6), [0.0, np.nan])
    with pytest.raises(ValueError, match=r"fc: expected shape \(2,\)"):
        target.step(np.zeros(8), np.zeros(2), fc=[1.0, 2.0, 3.0])
    with pytest.raises(ValueError, match=r"point\[0\] = inf"):
        target.step_jac(np.zeros(8), np.zeros(2), point=[np.inf, 0.0])
    with pytest.raises(ValueError, match="gamma"):
        target.step(np.zeros(8), np.zeros(2), gamma=np.nan)
    with pytest.raises(ValueError, match="mu"):
        picopit.BulletModel(mu=0.0)
    with pytest.raises(ValueError, match="dt"):
        picopit.FourDofTarget(dt=-0.05)
    with pytest.raises(ValueError, match="vehicle"):
        picopit.FourDofTarget(vehicle="truck")
    with pytest.raises(picopit.ParamError):
        picopit.BulletModel(params="no_such_set")
    # The half-scale target through the bullet model class is allowed (same equations).
    assert picopit.BulletModel("half_scale", vehicle="target").dt == pytest.approx(0.05)


@pytest.mark.skipif(not has("FourDofTarget"), reason="models not bound")
def test_default_substeps_keep_slow_predictions_stable():
    """Built with the defaults, both models pick enough RK4 sub-steps to stay stable down to
    1 m/s; a single 0.05 s step is not (the 4-DOF target diverges below ~9 m/s)."""
    target = picopit.FourDofTarget("full_size", dt=0.05)
    bullet = picopit.BulletModel("full_size", dt=0.05)
    assert target.substeps > 1 and bullet.substeps > 1
    single = picopit.FourDofTarget("full_size", dt=0.05, substeps=1)

    def roll_out(model, x, steps=60):
        for _ in range(steps):
            x = model.step(x, [0.0, 0.0])
        return x

    # 2 m/s with a small sideslip and yaw rate: the stable model settles, the single step
    # blows the lateral velocity up.
    x0 = np.array([2.0, 0.2, 0.0, 0.1, 0.0, 0.0, 0.0, 0.0])
    settled = roll_out(target, x0)
    assert np.all(np.isfinite(settled)) and abs(settled[1]) < 0.2 and abs(settled[3]) < 0.1
    diverged = roll_out(single, x0)
    assert not (abs(diverged[1]) < 0.2 and abs(diverged[3]) < 0.1)
    xb = roll_out(bullet, np.array([0.0, 0.0, 0.0, 1.5, 0.2, 0.1]))
    assert abs(xb[4]) < 0.2 and abs(xb[5]) < 0.1
