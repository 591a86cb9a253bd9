"""The surrogate binding (picopit._core.SurrogateModel, crates/pico_nn): files written with
the safetensors numpy API load, the network matches a numpy reference of
docs/model-format.md, step_jac matches finite differences, and bad files raise
picopit.ModelError naming the key or tensor. (Rust vs PyTorch parity: tests/test_parity.py.)"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import picopit

safetensors_numpy = pytest.importorskip("safetensors.numpy")

FEATURES = "vx,vy,r,p,phi,delta,T_b,f_bx,f_by,M_z,mu"
OUTPUTS = "dvx,dvy,dr,dp,dphi,dpsi,dx_b,dy_b"
WIDTHS = [11, 16, 16, 8]
DT = 0.05
SEED = 20261122

IN_MEAN = np.array([15.0, 0.0, 0.0, 0.0, 0.0, 0.0, 500.0, 0.0, 0.0, 0.0, 0.55])
IN_STD = np.array([6.0, 1.0, 0.4, 0.2, 0.03, 0.1, 800.0, 4000.0, 4000.0, 6000.0, 0.25])
OUT_MEAN = np.array([-0.1, 0.0, 0.0, 0.0, 0.0, 0.0, 0.75, 0.0])
OUT_STD = np.array([0.3, 0.2, 0.1, 0.05, 0.01, 0.02, 0.3, 0.05])
# The linear base o += B z: dt·[p, r, vx, vy] kinematics, the contact's rigid-body impulse
# (1500 kg, 2500 kg m²) and a μ column.
BASE = np.zeros((8, 11))
BASE[4, 3] = BASE[5, 2] = BASE[6, 0] = BASE[7, 1] = DT
BASE[0, 7] = BASE[1, 8] = DT / 1500.0
BASE[2, 9] = DT / 2500.0
BASE[5, 9] = DT * DT / 5000.0
BASE[6, 7] = BASE[7, 8] = DT * DT / 3000.0
BASE[0, 10] = -0.01


def dense_weights(rng):
    return [
        (rng.uniform(-1, 1, (o, i)) * 1.5 / np.sqrt(i), rng.uniform(-0.2, 0.2, o))
        for i, o in zip(WIDTHS[:-1], WIDTHS[1:])
    ]


def model_tensors(weights, n_shared=None, rng=None):
    """Tensors of the file: teacher layout (R = identity) or, with n_shared, a clustered one."""
    tensors = {}
    if n_shared is None:
        theta = []
        for l, (w, b) in enumerate(weights, start=1):
            for part, v in (("weight", w), ("bias", b)):
                start = sum(len(t) for t in theta)
                tensors[f"layer{l}.{part}.idx"] = (start + np.arange(v.size, dtype=np.int32)).reshape(v.shape)
                tensors[f"layer{l}.{part}.sign"] = np.ones(v.shape, dtype=np.int8)
                theta.append(v.ravel())
        theta = np.concatenate(theta)
    else:
        theta = rng.uniform(0.05, 0.6, n_shared)
        for l, (w, b) in enumerate(weights, start=1):
            for part, v in (("weight", w), ("bias", b)):
                tensors[f"layer{l}.{part}.idx"] = rng.integers(0, n_shared, v.shape, dtype=np.int32)
                tensors[f"layer{l}.{part}.sign"] = rng.integers(-1, 2, v.shape, dtype=np.int8)
    tensors["theta"] = theta.astype(np.float64)
    tensors.update(in_mean=IN_MEAN, in_std=IN_STD, out_mean=OUT_MEAN, out_std=OUT_STD, base=BASE)
    return tensors


def expanded(tensors):
    """The dense weights a file encodes, w = sign * theta[idx]."""
    theta = tensors["theta"]
    return [
        tuple(
            tensors[f"layer{l}.{p}.sign"] * theta[tensors[f"layer{l}.{p}.idx"]]
            for p in ("weight", "bias")
        )
        for l in range(1, len(WIDTHS))
    ]


def metadata(**over):
    meta = {
        "format": "picopit-mlp",
        "version": "3",
        "kind": "picopinn",
        "activation": "tanh",
        "layers": ",".join(map(str, WIDTHS)),
        "features": FEATURES,
        "outputs": OUTPUTS,
        "dt": "0.05",
        "param_set": "full_size",
        "mu_range": "0.15,1.0",
        "mu_default": "0.9",
        "seed": str(SEED),
    }
    meta.update(over)
    return {k: v for k, v in meta.items() if v is not None}


def write(path: Path, tensors, meta) -> Path:
    safetensors_numpy.save_file({k: np.ascontiguousarray(v) for k, v in tensors.items()}, str(path), metadata=meta)
    return path


def reference_forward(weights, z):
    """The network on the 11 features plus the linear base B z."""
    z = np.asarray(z)
    h = (z - IN_MEAN) / IN_STD
    for l, (w, b) in enumerate(weights):
        h = w @ h + b
        if l + 1 < len(weights):
            h = np.tanh(h)
    return OUT_MEAN + OUT_STD * h + BASE @ z


def features(x, u, fc, gamma, point, mu):
    a = gamma - x[2]
    fb = np.array([np.cos(a) * fc[0] - np.sin(a) * fc[1], np.sin(a) * fc[0] + np.cos(a) * fc[1]])
    mz = point[0] * fb[1] - point[1] * fb[0]
    return np.array([x[0], x[1], x[3], x[4], x[5], u[0], u[1], fb[0], fb[1], mz, mu])


def random_case(rng):
    psi = rng.uniform(-3, 3)
    x = np.array([rng.uniform(3, 30), rng.uniform(-1, 1), psi, rng.uniform(-0.8, 0.8),
                  rng.uniform(-0.3, 0.3), rng.uniform(-0.05, 0.05), rng.uniform(-5, 5), rng.uniform(-5, 5)])
    u = np.array([rng.uniform(-0.2, 0.2), rng.uniform(0, 1500)])
    fn = rng.uniform(0, 1.5e4)
    fc = np.array([fn, rng.uniform(-0.5, 0.5) * fn])
    return x, u, fc, psi + rng.uniform(-2, 2), np.array([rng.uniform(-2.5, 2.5), rng.uniform(-0.9, 0.9)])


@pytest.fixture
def clustered_file(tmp_path):
    rng = np.random.default_rng(SEED)
    tensors = model_tensors(dense_weights(rng), n_shared=30, rng=rng)
    return write(tmp_path / "pico.safetensors", tensors, metadata()), tensors


def test_load_and_properties(clustered_file):
    path, tensors = clustered_file
    m = picopit.SurrogateModel(str(path))
    assert m.name == "picopinn"
    assert m.dt == 0.05
    assert m.param_count == 30 == tensors["theta"].size
    assert m.layers == WIDTHS
    assert m.metadata["seed"] == str(SEED)
    assert m.metadata["format"] == "picopit-mlp"
    assert m.mu == 0.9 and m.mu_range == (0.15, 1.0)
    # A pathlib.Path works too, and μ is a constructor argument.
    assert picopit.SurrogateModel(path, mu=0.4).mu == 0.4
    assert picopit.SurrogateModel(path).param_count == 30


def test_mu_is_validated_and_changes_the_prediction(clustered_file):
    path, _ = clustered_file
    m = picopit.SurrogateModel(str(path))
    x, u, fc, gamma, point = random_case(np.random.default_rng(SEED + 9))
    dry = m.step(x, u, fc, gamma, point)
    for bad in (0.1, 1.01, -1.0, float("nan"), float("inf")):
        with pytest.raises(picopit.ModelError, match="mu"):
            m.mu = bad
        with pytest.raises(picopit.ModelError, match="mu_range"):
            picopit.SurrogateModel(str(path), mu=bad)
        assert m.mu == 0.9
    m.mu = 0.2
    wet = m.step(x, u, fc, gamma, point)
    assert not np.array_equal(wet, dry)
    np.testing.assert_array_equal(picopit.SurrogateModel(str(path), mu=0.2).step(x, u, fc, gamma, point), wet)


def test_forward_and_step_match_the_numpy_reference(clustered_file):
    path, tensors = clustered_file
    m = picopit.SurrogateModel(str(path))
    weights = expanded(tensors)
    rng = np.random.default_rng(SEED + 1)
    for _ in range(50):
        x, u, fc, gamma, point = random_case(rng)
        m.mu = rng.uniform(0.15, 1.0)
        z = features(x, u, fc, gamma, point, m.mu)
        o = reference_forward(weights, z)
        np.testing.assert_allclose(m.forward(z), o, rtol=1e-12, atol=1e-14)
        c, s = np.cos(x[2]), np.sin(x[2])
        expect = x + np.array([o[0], o[1], o[5], o[2], o[3], o[4],
                               c * o[6] - s * o[7], s * o[6] + c * o[7]])
        np.testing.assert_allclose(m.step(x, u, fc, gamma, point), expect, rtol=1e-12, atol=1e-12)


def test_teacher_layout_of_the_same_weights_is_the_same_model(clustered_file, tmp_path):
    path, tensors = clustered_file
    teacher = write(tmp_path / "teacher.safetensors", model_tensors(expanded(tensors)), metadata(kind="pinn"))
    a, b = picopit.SurrogateModel(str(path)), picopit.SurrogateModel(str(teacher))
    assert b.name == "pinn" and b.param_count > a.param_count
    rng = np.random.default_rng(SEED + 2)
    for _ in range(20):
        x, u, fc, gamma, point = random_case(rng)
        for ra, rb in zip(a.step_jac(x, u, fc, gamma, point), b.step_jac(x, u, fc, gamma, point)):
            np.testing.assert_array_equal(ra, rb)


def test_step_jac_matches_finite_differences(clustered_file):
    path, _ = clustered_file
    m = picopit.SurrogateModel(str(path))
    rng = np.random.default_rng(SEED + 3)

    def fd(f, v, typical):
        cols = []
        for j in range(v.size):
            h = 1e-5 * max(typical[j], abs(v[j]))
            vp, vm, vp2, vm2 = v.copy(), v.copy(), v.copy(), v.copy()
            vp[j] += h
            vm[j] -= h
            vp2[j] += 2 * h
            vm2[j] -= 2 * h
            cols.append((8 * (f(vp) - f(vm)) - (f(vp2) - f(vm2))) / (12 * h))
        return np.stack(cols, axis=1)

    for _ in range(10):
        x, u, fc, gamma, point = random_case(rng)
        xn, a, b, f = m.step_jac(x, u, fc, gamma, point)
        np.testing.assert_array_equal(xn, m.step(x, u, fc, gamma, point))
        na = fd(lambda v: m.step(v, u, fc, gamma, point), x, np.ones(8))
        nb = fd(lambda v: m.step(x, v, fc, gamma, point), u, (0.1, 100.0))
        nf = fd(lambda v: m.step(x, u, v, gamma, point), fc, (1e3, 1e3))
        for exact, num, name in ((a, na, "A"), (b, nb, "B"), (f, nf, "F")):
            scale = np.maximum(np.abs(num).max(axis=0), 1e-9)
            err = np.abs(exact - num).max(axis=0) / scale
            assert err.max() < 1e-6, f"{name}: column errors {err}"
    # No contact by default.
    x, u, *_ = random_case(rng)
    np.testing.assert_array_equal(m.step(x, u), m.step(x, u, np.zeros(2), 0.0, np.zeros(2)))


def test_model_error_is_exported_and_a_value_error():
    assert picopit.ModelError is picopit._core.ModelError
    assert issubclass(picopit.ModelError, ValueError)
    assert "ModelError" in picopit.__all__ and "SurrogateModel" in picopit.__all__


@pytest.mark.parametrize(
    "change, needle",
    [
        (lambda t, m: m.pop("dt"), "dt"),
        (lambda t, m: m.pop("features"), "features"),
        (lambda t, m: m.update(version="1"), "version"),
        (lambda t, m: m.update(version="2"), "version"),
        (lambda t, m: t.pop("base"), "base"),
        (lambda t, m: t.update(base=BASE[:, :10].copy()), "base"),
        (lambda t, m: t.update(base=np.where(BASE != 0, np.nan, 0.0)), "base"),
        (lambda t, m: m.update(layers="11,16,8"), "layer"),
        (lambda t, m: m.update(layers="10,16,16,8"), "layers"),
        (lambda t, m: m.pop("mu_range"), "mu_range"),
        (lambda t, m: m.update(mu_range="1.0,0.15"), "mu_range"),
        (lambda t, m: m.update(mu_default="1.5"), "mu_default"),
        (lambda t, m: m.update(features="vx,vy,r,p,phi,delta,T_b,f_bx,f_by,M_z"), "features"),
        (lambda t, m: m.update(outputs="dvx,dvy"), "outputs"),
        (lambda t, m: t["theta"].__setitem__(3, np.nan), "theta"),
        (lambda t, m: t["in_std"].__setitem__(2, 0.0), "in_std"),
        (lambda t, m: t["out_mean"].__setitem__(0, np.inf), "out_mean"),
        (lambda t, m: t["layer2.weight.idx"].__setitem__((0, 0), 10_000), "layer2.weight.idx"),
        (lambda t, m: t["layer1.bias.sign"].__setitem__(1, 3), "layer1.bias.sign"),
        (lambda t, m: t.update({"layer3.bias.idx": t["layer3.bias.idx"].astype(np.int64)}), "layer3.bias.idx"),
        (lambda t, m: t.update({"in_mean": t["in_mean"][:10]}), "in_mean"),
        (lambda t, m: t.pop("out_std"), "out_std"),
    ],
)
def test_bad_files_raise_model_error_naming_the_field(tmp_path, change, needle):
    rng = np.random.default_rng(SEED)
    tensors = {k: np.array(v) for k, v in model_tensors(dense_weights(rng)).items()}
    meta = metadata()
    change(tensors, meta)
    path = write(tmp_path / "bad.safetensors", tensors, meta)
    with pytest.raises(picopit.ModelError, match=needle):
        picopit.SurrogateModel(str(path))


def test_unreadable_and_truncated_files(tmp_path, clustered_file):
    with pytest.raises(picopit.ModelError, match="missing.safetensors"):
        picopit.SurrogateModel(str(tmp_path / "missing.safetensors"))
    path, _ = clustered_file
    data = path.read_bytes()
    for n in (0, 7, 100, len(data) - 1):
        cut = tmp_path / f"cut{n}.safetensors"
        cut.write_bytes(data[:n])
        with pytest.raises(picopit.ModelError):
            picopit.SurrogateModel(str(cut))


def test_arguments_are_validated(clustered_file):
    m = picopit.SurrogateModel(str(clustered_file[0]))
    with pytest.raises(ValueError, match="x"):
        m.step(np.zeros(7), np.zeros(2))
    with pytest.raises(ValueError, match="fc"):
        m.step_jac(np.zeros(8), np.zeros(2), fc=[np.nan, 0.0])
    with pytest.raises(ValueError, match="features"):
        m.forward(np.zeros(8))
    with pytest.raises(ValueError, match="features"):
        m.forward(np.zeros(10))
