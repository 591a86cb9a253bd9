"""Rust (``picopit._core.SurrogateModel``, crates/pico_nn) against the PyTorch float64
reference of the same model file (docs/model-format.md): outputs within 1e-9 relative on
1000 random inputs (random road μ within the model's range); step Jacobians against
torch.autograd and central finite differences.

Runs on a dense (teacher-like, R = identity) file, a clustered PicoPINN-like file with pruned
weights, and the shipped models when present. Skipped only while the binding does not exist.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch")
pytest.importorskip("safetensors")
pytest.importorskip("scipy")

from picopit import _core  # noqa: E402
from picopit.compress import TensorClusters, choose_threshold, compressed_model  # noqa: E402
from picopit.surrogate_nn import dense_mlp, load_model, physics_base, save_model  # noqa: E402

if not hasattr(_core, "SurrogateModel"):
    pytest.skip("picopit._core.SurrogateModel (crates/pico_nn binding) is not built yet",
                allow_module_level=True)

ROOT = Path(__file__).resolve().parents[1]
N = 1000
REL = 1e-9


#: Every kind of base entry: kinematics, contact impulse and a μ column.
BASE = physics_base(0.05, 1500.0, 2500.0)
BASE[0, 10] = -0.01


def _stats(rng):
    scale = np.array([10, 1, 0.5, 0.3, 0.05, 0.1, 1e3, 5e3, 5e3, 5e3, 0.3])
    return {"in_mean": rng.normal(size=11) * scale * 0.1, "in_std": rng.uniform(0.5, 2.0, 11) * scale,
            "out_mean": rng.normal(size=8) * 0.01, "out_std": rng.uniform(0.01, 0.5, 8)}


def _files(tmp_path_factory):
    d = tmp_path_factory.mktemp("parity")
    rng = np.random.default_rng(20)
    dense = dense_mlp((11, 64, 64, 64, 8), _stats(rng), seed=21, dt=0.05, base=BASE)
    with torch.no_grad():
        dense.theta.add_(0.05 * torch.randn(dense.param_count, generator=torch.Generator().manual_seed(22), dtype=torch.float64))
    save_model(dense, d / "dense.safetensors", kind="pinn", param_set="full_size",
               mu_range=(0.15, 1.0), provenance={"seed": "21"})
    student = dense_mlp((11, 32, 32, 8), _stats(rng), seed=23, dt=0.05, base=BASE)
    with torch.no_grad():
        student.theta[:40] *= 1e-4  # pruned weights
    clusters = [TensorClusters.of(w.detach().numpy()) for w, _ in student.weights()]
    t, _ = choose_threshold(clusters, 72, 812, prune=0.02)
    pico, _ = compressed_model(student, clusters, t, prune=0.02)
    save_model(pico, d / "pico.safetensors", kind="picopinn", param_set="full_size",
               mu_range=(0.15, 1.0), provenance={"seed": "23"})
    files = [d / "dense.safetensors", d / "pico.safetensors"]
    for s in ("full_size", "half_scale"):
        for k in ("pinn", "picopinn"):
            p = ROOT / "models" / s / f"{k}.safetensors"
            if p.is_file():
                files.append(p)
    return files


@pytest.fixture(scope="module")
def model_files(tmp_path_factory):
    return _files(tmp_path_factory)


def _inputs(rng, n, model):
    x = np.column_stack([
        rng.uniform(0.5, 30, n), rng.uniform(-3, 3, n), rng.uniform(-7, 7, n), rng.uniform(-2, 2, n),
        rng.uniform(-0.5, 0.5, n), rng.uniform(-0.1, 0.1, n), rng.uniform(-100, 100, n), rng.uniform(-10, 10, n),
    ])
    u = np.column_stack([rng.uniform(-0.3, 0.3, n), rng.uniform(0, 1.0, n) * 3 * model.in_std[6].item()])
    on = rng.random(n) < 0.5
    fn = rng.uniform(0, 3, n) * model.in_std[7].item() * on
    fc = np.column_stack([fn, rng.uniform(-0.4, 0.4, n) * fn])
    gamma = rng.uniform(-math.pi, math.pi, n)
    point = np.column_stack([rng.uniform(-2.5, 2.5, n), rng.uniform(-1, 1, n)])
    return x, u, fc, gamma, point


def _mus(rng, n, rm):
    lo, hi = rm.mu_range
    return rng.uniform(lo, hi, n)


def _rel(a, b, floor):
    return np.max(np.abs(a - b) / np.maximum(np.abs(b), floor))


def test_outputs_match_torch(model_files):
    rng = np.random.default_rng(30)
    for path in model_files:
        tm, meta = load_model(path)
        rm = _core.SurrogateModel(str(path))
        assert rm.param_count == tm.param_count
        assert list(rm.layers) == tm.layers
        assert math.isclose(rm.dt, float(meta["dt"]))
        assert rm.mu == float(meta["mu_default"])
        z = tm.in_mean.numpy() + rng.normal(size=(N, 11)) * 2 * tm.in_std.numpy()
        with torch.no_grad():
            ref = tm(torch.from_numpy(z)).numpy()
        got = np.array([rm.forward(z[i]) for i in range(N)])
        floor = 1e-6 * tm.out_std.numpy()
        assert _rel(got, ref, floor) <= REL, path
        assert rm.mu == float(meta["mu_default"]), "forward leaves the model's mu"
        x, u, fc, gamma, point = _inputs(rng, N, tm)
        mu = _mus(rng, N, rm)
        with torch.no_grad():
            ref = tm.step(*(torch.from_numpy(np.ascontiguousarray(a)) for a in (x, u, fc, gamma, point, mu))).numpy()
        got = []
        for i in range(N):
            rm.mu = mu[i]
            got.append(rm.step(x[i], u[i], fc[i], gamma[i], point[i]))
        assert _rel(np.array(got), ref, 1e-6) <= REL, path


def _torch_jac(tm, x, u, fc, gamma, point, mu):
    def f(xx, uu, ff):
        return tm.step(xx[None], uu[None], ff[None], torch.tensor([gamma], dtype=torch.float64),
                       torch.from_numpy(point)[None], torch.tensor([mu], dtype=torch.float64))[0]

    return torch.autograd.functional.jacobian(
        f, (torch.from_numpy(x), torch.from_numpy(u), torch.from_numpy(fc)))


def test_jacobians_match_autograd_and_finite_differences(model_files):
    rng = np.random.default_rng(31)
    for path in model_files:
        tm, _ = load_model(path)
        rm = _core.SurrogateModel(str(path))
        x, u, fc, gamma, point = _inputs(rng, 40, tm)
        mu = _mus(rng, 40, rm)
        # positions near the origin: central differences of X+ = X + ... lose digits at large X
        x[:, 6:8] = rng.uniform(-5, 5, (40, 2))
        # difference steps scaled like the inputs (N and N m arguments are large)
        typical = [np.ones(8), np.array([1.0, tm.in_std[6].item()]), np.full(2, tm.in_std[7].item())]
        for i in range(40):
            rm.mu = mu[i]
            xn, A, B, F = (np.asarray(v) for v in rm.step_jac(x[i], u[i], fc[i], gamma[i], point[i]))
            assert A.shape == (8, 8) and B.shape == (8, 2) and F.shape == (8, 2)
            assert np.array_equal(xn, np.asarray(rm.step(x[i], u[i], fc[i], gamma[i], point[i])))
            JA, JB, JF = (j.numpy() for j in _torch_jac(tm, x[i], u[i], fc[i], gamma[i], point[i], mu[i]))
            for got, ref in ((A, JA), (B, JB), (F, JF)):
                scale = np.maximum(np.abs(ref).max(axis=0, keepdims=True), 1e-12)
                assert np.max(np.abs(got - ref) / scale) <= 1e-8, path
            # central differences of the Rust step itself
            for which, arg, J in ((0, x[i], A), (1, u[i], B), (2, fc[i], F)):
                for k in range(len(arg)):
                    h = 1e-6 * max(typical[which][k], abs(arg[k]))
                    args_p = [x[i].copy(), u[i].copy(), fc[i].copy()]
                    args_m = [x[i].copy(), u[i].copy(), fc[i].copy()]
                    args_p[which][k] += h
                    args_m[which][k] -= h
                    fp = np.asarray(rm.step(*args_p, gamma[i], point[i]))
                    fm = np.asarray(rm.step(*args_m, gamma[i], point[i]))
                    fd = (fp - fm) / (2 * h)
                    scale = max(np.abs(fd).max(), 1e-9)
                    assert np.max(np.abs(J[:, k] - fd)) / scale <= 1e-5, (path, which, k)
