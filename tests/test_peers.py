"""The peer comparison (benchmarks/peers): the CasADi ports of the control models agree with
the Rust models, and the peer OCP solved with IPOPT gives a plan that picopit's own
yardstick scores sanely and that keeps the hard constraints. Skips without casadi (the
``peers`` extra)."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

ca = pytest.importorskip("casadi")

from picopit import _core, _toml  # noqa: E402  (_toml: tomllib, or tomli before 3.11)

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "benchmarks" / "peers"))

import peer_ocp  # noqa: E402
import run_peers  # noqa: E402

MU = 0.9


@pytest.fixture(scope="module")
def params():
    return _toml.loads(_core.load_params("full_size"))


def _random_contact(rng):
    fc = np.array([rng.uniform(0.0, 30000.0), rng.uniform(-9000.0, 9000.0)])
    return fc, rng.uniform(-np.pi, np.pi), rng.uniform(-2.5, 2.5, 2)


def test_bullet_port_matches_the_rust_model(params):
    rust = _core.BulletModel("full_size", MU, 0.05)
    port = peer_ocp.BulletPort(params["bullet"], MU, 0.05)
    assert port.substeps == rust.substeps
    f = port.function()
    rng = np.random.default_rng(1)
    for i in range(50):
        x = np.array([rng.uniform(-50, 150), rng.uniform(-5, 5), rng.uniform(-4, 4),
                      rng.uniform(0.5, 30), rng.uniform(-3, 3), rng.uniform(-1.5, 1.5)])
        u = np.array([rng.uniform(-0.5, 0.5), rng.uniform(-300, 500)])
        fc, gamma, point = _random_contact(rng)
        if i % 5 == 0:
            fc[:] = 0.0
        want = rust.step(x, u, fc, gamma, point)
        got = np.asarray(f(x, u, fc, gamma, point)).ravel()
        np.testing.assert_allclose(got, want, rtol=1e-9, atol=1e-9)


def test_four_dof_port_matches_the_rust_model(params):
    rust = _core.FourDofTarget("full_size", MU, 0.05)
    port = peer_ocp.FourDofPort(params["target"], MU, 0.05)
    assert port.substeps == rust.substeps
    f = port.function()
    rng = np.random.default_rng(2)
    for i in range(50):
        x = np.array([rng.uniform(0.5, 30), rng.uniform(-3, 3), rng.uniform(-4, 4),
                      rng.uniform(-1.5, 1.5), rng.uniform(-0.5, 0.5), rng.uniform(-0.1, 0.1),
                      rng.uniform(-50, 150), rng.uniform(-5, 5)])
        u = np.array([rng.uniform(-0.3, 0.3), rng.uniform(0, 3000)])
        fc, gamma, point = _random_contact(rng)
        if i % 5 == 0:
            fc[:] = 0.0
        want = rust.step(x, u, fc, gamma, point)
        got = np.asarray(f(x, u, fc, gamma, point)).ravel()
        np.testing.assert_allclose(got, want, rtol=1e-9, atol=1e-9)


def _touching(params):
    """Bullet c.g. with its front-right corner 4 cm into the target's left rear quarter."""
    b, t = params["bullet"], params["target"]
    x = -t["lr"] - 0.3 - b["cg_to_front"]
    y = 0.5 * t["width"] + 0.5 * b["width"] - 0.04
    target = np.array([15.0, 0.0, 0.0, 0.0, 0.0, 0.0, 100.0, 0.0])
    bullet = np.array([100.0 + x, y, 0.0, 16.0, 0.0, 0.0])
    return target, bullet


def test_reference_scalars_match_the_default_reference(params):
    """run_peers infers target_heading and target_weight (the binding returns the stages
    only); setting them explicitly must give the same merit as the default reference."""
    target, bullet = _touching(params)
    a = run_peers.make_mpc()
    a.default_reference(target, bullet)
    a.solve(target, bullet)
    plan = a.plan()
    ref, psi, wt = run_peers.reference_scalars(a, target, bullet)
    assert wt == 1.0
    b = run_peers.make_mpc()
    b.set_reference(ref, psi, wt)
    assert b.evaluate(target, bullet, plan["u"], plan["f"]) == a.evaluate(
        target, bullet, plan["u"], plan["f"])


def test_ipopt_on_the_peer_ocp_is_sane_and_keeps_the_hard_constraints(params):
    target, bullet = _touching(params)
    last = np.zeros(2)
    m = run_peers.make_mpc()
    m.default_reference(target, bullet)
    out = m.solve(target, bullet, last_command=last)
    assert out["coupled"] is True
    plan = m.plan()
    merit_rti, _ = m.evaluate(target, bullet, plan["u"], plan["f"], last_command=last)
    lin = m.linearisation()
    ref, psi, wt = run_peers.reference_scalars(m, target, bullet)
    cfg = peer_ocp.OcpConfig.from_mpc(_core.load_params("full_size"), MU, m.settings)
    ocp = peer_ocp.PeerOcp(cfg, "ipopt")
    d = ocp.data(lin, ref, target, bullet, last, np.zeros(2), psi, wt)
    u, f, stats, _ = ocp.solve(d)
    assert stats["success"], stats["return_status"]
    merit, viol = m.evaluate(target, bullet, u, f, last_command=last)
    assert np.isfinite(merit)
    # Same OCP up to the frozen contact geometry and picopit's trust region: the converged
    # NLP must score within a sane factor of picopit's one QP.
    assert merit < 2.0 * merit_rti + 1.0, (merit, merit_rti)
    assert merit > 0.2 * merit_rti, (merit, merit_rti)
    hard_u, hard_f = run_peers.hard_violation(ocp, u, f, last, np.asarray(lin["fn_max"]))
    assert hard_u < 1e-6 and hard_f < 1e-6 * 1e4, (hard_u, hard_f)
    assert np.any(f[:, 0] > 100.0)  # it plans a push, like picopit
