"""The learned-surrogate pipeline: physics prior, features, clustering, model files, datasets,
and a tiny datagen -> train -> compress -> eval run through the CLI."""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch")
pytest.importorskip("safetensors")
pytest.importorskip("scipy")

from safetensors import safe_open  # noqa: E402
from safetensors.numpy import load_file, save_file  # noqa: E402

from picopit import _core, load_params_dict  # noqa: E402
from picopit import datagen  # noqa: E402
from picopit.cli import main  # noqa: E402
from picopit.eval_surrogates import PLANNER_GRAVITY, planner_stop_decel_fraction, sliding, stop_points  # noqa: E402
from picopit.compress import CompressConfig, TensorClusters, choose_threshold, compressed_model  # noqa: E402
from picopit.physics import FourDof  # noqa: E402
from picopit.surrogate_nn import (FEATURES, OUTPUTS, ModelFileError, apply_increments,  # noqa: E402
                                  dense_mlp, features, increments, linear_base, load_model,
                                  physics_base, save_model)
from picopit.train import STATE_TO_OUT, Split, TrainError, one_step_loss, physics_targets  # noqa: E402


def _random_inputs(rng, n, contact=True):
    x = np.column_stack([
        rng.uniform(1, 30, n), rng.uniform(-3, 3, n), rng.uniform(-7, 7, n), rng.uniform(-2, 2, n),
        rng.uniform(-0.5, 0.5, n), rng.uniform(-0.1, 0.1, n), rng.uniform(-100, 100, n), rng.uniform(-10, 10, n),
    ])
    u = np.column_stack([rng.uniform(-0.3, 0.3, n), rng.uniform(0, 3000, n)])
    on = (rng.random(n) < 0.5) if contact else np.zeros(n, bool)
    fn = rng.uniform(0, 3e4, n) * on
    fc = np.column_stack([fn, rng.uniform(-0.4, 0.4, n) * fn])
    gamma = rng.uniform(-math.pi, math.pi, n)
    point = np.column_stack([rng.uniform(-2.5, 2.5, n), rng.uniform(-1, 1, n)])
    return x, u, fc, gamma, point


def _t(a):
    return torch.from_numpy(np.ascontiguousarray(a, dtype=np.float64))


#: A linear base with every kind of entry: kinematics, contact impulse (1500 kg, 2500 kg m²)
#: and a μ column.
BASE = physics_base(0.05, 1500.0, 2500.0)
BASE[0, 10] = -0.01


def _stats(rng):
    return {"in_mean": rng.normal(size=11), "in_std": rng.uniform(0.5, 2.0, 11) * np.array([10, 1, 1, 0.3, 0.05, 0.1, 1e3, 5e3, 5e3, 5e3, 0.3]),
            "out_mean": rng.normal(size=8) * 0.01, "out_std": rng.uniform(0.01, 0.5, 8)}


# --------------------------------------------------------------------------------------
# Physics prior
# --------------------------------------------------------------------------------------


@pytest.mark.parametrize("param_set", ["full_size", "half_scale"])
@pytest.mark.parametrize("mu", [0.2, 0.9])
def test_physics_residual_vanishes_on_fourdof_data(param_set, mu):
    """The torch Newton-Euler step reproduces Rust FourDofTarget, so the physics residual
    (network increment minus the integrated 4-DOF increment) is ~0 on 4-DOF data."""
    rng = np.random.default_rng(1)
    n = 300
    x, u, fc, gamma, point = _random_inputs(rng, n)
    rust = _core.FourDofTarget(param_set, mu=mu)
    xn = np.array([rust.step(x[i], u[i], fc[i], gamma[i], point[i]) for i in range(n)])
    m4 = FourDof.from_params(load_params_dict(param_set)["target"])
    assert m4.substeps == rust.substeps
    phys = m4.step(_t(x), _t(u), _t(fc), _t(gamma), _t(point), torch.full((n,), mu))
    o_data = increments(_t(x), _t(xn))
    o_phys = increments(_t(x), phys)
    scale = o_data.std(0)
    resid = ((o_data - o_phys) / scale).abs().max().item()
    assert resid < 1e-6, resid
    # ... and clearly not ~0 for a different road (the test can fail).
    other = m4.step(_t(x), _t(u), _t(fc), _t(gamma), _t(point), torch.full((n,), 1.5 - mu))
    assert ((o_data - increments(_t(x), other)) / scale).abs().max().item() > 1e-2


def test_physics_targets_include_collocation_points():
    rng = np.random.default_rng(2)
    x, u, fc, gamma, point = _random_inputs(rng, 50)
    xn = x + 0.01
    a = {"x": x, "u": u, "fc": fc, "gamma": gamma, "point": point, "x_next": xn, "mu": np.full(50, 0.8),
         "episode": np.zeros(50, np.int32), "step": np.arange(50, dtype=np.int32)}
    s = Split.of(a, 4)
    m4 = FourDof.from_params(load_params_dict("full_size")["target"])
    p = physics_targets(s, m4, 0.5, seed=0)
    assert p.z.shape == (75, 11) and p.o.shape == (75, 8)
    assert torch.all(p.z[:, 10] == 0.8)  # μ is the last feature
    assert torch.isfinite(p.o).all()


# --------------------------------------------------------------------------------------
# Features, increments, the network
# --------------------------------------------------------------------------------------


def test_increments_round_trip_and_feature_invariance():
    rng = np.random.default_rng(3)
    x, u, fc, gamma, point = _random_inputs(rng, 200)
    xn = x + rng.normal(size=x.shape) * 0.3
    back = apply_increments(_t(x), increments(_t(x), _t(xn)))
    assert torch.allclose(back, _t(xn), atol=1e-10, rtol=0)
    # Moving and rotating the world (state and γ together) leaves the features unchanged.
    x2 = x.copy()
    x2[:, 2] += 1.234
    x2[:, 6:8] += 55.0
    mu = rng.uniform(0.15, 1.0, 200)
    z1 = features(_t(x), _t(u), _t(fc), _t(gamma), _t(point), _t(mu))
    z2 = features(_t(x2), _t(u), _t(fc), _t(gamma + 1.234), _t(point), _t(mu))
    assert torch.allclose(z1, z2, atol=1e-9)
    assert torch.equal(z1[:, 10], _t(mu))
    assert torch.equal(features(_t(x), _t(u), _t(fc), _t(gamma), _t(point), 0.4)[:, 10], torch.full((200,), 0.4, dtype=torch.float64))
    # The moment is the cross product of the point and the body-frame force.
    assert torch.allclose(z1[:, 9], z1[:, 7] * 0 + _t(point[:, 0]) * z1[:, 8] - _t(point[:, 1]) * z1[:, 7])


def test_physics_base_is_the_kinematics_and_the_contact_impulse():
    """The kinematic rows are dt·[p, r, vx, vy]; the impulse rows are what a free rigid body
    does under a constant force and moment over the step."""
    dt, m, iz = 0.05, 1500.0, 2500.0
    kin = physics_base(dt, m, iz, "kinematic")
    imp = physics_base(dt, m, iz, "impulse")
    f = {n: i for i, n in enumerate(FEATURES)}
    o = {n: i for i, n in enumerate(OUTPUTS)}
    assert kin[o["dphi"], f["p"]] == dt and kin[o["dpsi"], f["r"]] == dt
    assert kin[o["dx_b"], f["vx"]] == dt and kin[o["dy_b"], f["vy"]] == dt
    assert np.count_nonzero(kin) == 4 and np.all(imp[kin != 0] == kin[kin != 0])
    # A constant moment M from rest for dt: r = M dt / I_z, ψ = M dt² / (2 I_z); a constant
    # force: v = F dt / m, x = F dt² / (2 m).
    z = np.zeros(11)
    z[f["M_z"]], z[f["f_bx"]], z[f["f_by"]] = 4000.0, 3000.0, -2000.0
    out = imp @ z
    assert math.isclose(out[o["dr"]], 4000.0 * dt / iz) and math.isclose(out[o["dpsi"]], 4000.0 * dt * dt / (2 * iz))
    assert math.isclose(out[o["dvx"]], 3000.0 * dt / m) and math.isclose(out[o["dx_b"]], 3000.0 * dt * dt / (2 * m))
    assert math.isclose(out[o["dvy"]], -2000.0 * dt / m) and math.isclose(out[o["dy_b"]], -2000.0 * dt * dt / (2 * m))
    assert np.count_nonzero(imp) == 10
    for bad in (dict(kind="none"), dict(mass=0.0), dict(iz=float("nan"))):
        args = {"dt": dt, "mass": m, "iz": iz, "kind": "impulse", **bad}
        with pytest.raises(ValueError, match=next(iter(bad))):
            physics_base(**args)


def test_network_adds_the_linear_base_to_its_residual():
    """o = B z + out_mean + out_std ⊙ y: a network whose last layer is zero predicts exactly
    the base increments plus out_mean, and μ is an input."""
    rng = np.random.default_rng(9)
    m = dense_mlp((11, 16, 8), _stats(rng), seed=3, dt=0.05, base=BASE)
    x, u, fc, gamma, point = _random_inputs(rng, 40)
    z = features(_t(x), _t(u), _t(fc), _t(gamma), _t(point), 0.5)
    base = linear_base(z, _t(BASE))
    assert torch.allclose(base, z @ _t(BASE).T, rtol=0, atol=0)
    with torch.no_grad():
        assert torch.allclose(m(z), base + m.residual(z), atol=1e-15)
        w2, b2 = m.weights()[1]
        m.theta[-(w2.numel() + b2.numel()):] = 0.0
        assert torch.allclose(m(z), base + m.out_mean, atol=1e-15)
        m2 = dense_mlp((11, 16, 8), _stats(np.random.default_rng(9)), seed=3, dt=0.05, base=BASE)
        z_wet = features(_t(x), _t(u), _t(fc), _t(gamma), _t(point), 0.2)
        assert not torch.allclose(m2(z), m2(z_wet))


def test_output_weights_weigh_each_output_and_its_state():
    """The weighted one-step loss is Σ_k w_k MSE_k / 8 over the outputs; the rollout's state
    weights are the same weights mapped from outputs to states (Δψ's weight on ψ)."""
    rng = np.random.default_rng(11)
    m = dense_mlp((11, 16, 8), _stats(rng), seed=3, dt=0.05, base=BASE)
    x, u, fc, gamma, point = _random_inputs(rng, 50)
    z = features(_t(x), _t(u), _t(fc), _t(gamma), _t(point), 0.5)
    o = _t(rng.normal(size=(50, 8)) * 0.01)
    w = torch.tensor([1.0, 2.0, 4.0, 1.0, 1.0, 4.0, 1.0, 1.0])
    with torch.no_grad():
        per = (((m(z) - o) / m.out_std) ** 2).mean(0)
        assert torch.isclose(one_step_loss(m, z, o), per.mean(), rtol=1e-13)
        assert torch.isclose(one_step_loss(m, z, o, weights=w), (w * per).sum() / 8, rtol=1e-13)
    # Δψ is output 5 and ψ is state 2; Δr output 2, r state 3.
    assert STATE_TO_OUT[2] == 5 and STATE_TO_OUT[3] == 2
    assert w[list(STATE_TO_OUT)].tolist() == [1.0, 2.0, 4.0, 4.0, 1.0, 1.0, 1.0, 1.0]


@pytest.mark.parametrize("edit, name", [
    ({"output_weights": (1.0,) * 7}, "output_weights"),
    ({"output_weights": (1.0, -1.0, 1, 1, 1, 1, 1, 1)}, "output_weights"),
    ({"output_weights": (0.0,) * 8}, "output_weights"),
    ({"output_weights": (float("nan"),) + (1.0,) * 7}, "output_weights"),
])
def test_compress_config_errors_name_the_field(edit, name):
    CompressConfig().validate()
    CompressConfig(output_weights=None).validate()
    with pytest.raises(TrainError, match=name):
        CompressConfig(**edit).validate()


# --------------------------------------------------------------------------------------
# Clustering
# --------------------------------------------------------------------------------------


def test_clustering_ties_weights_to_sign_times_centre_and_meets_budget():
    rng = np.random.default_rng(4)
    student = dense_mlp((11, 24, 24, 8), _stats(rng), seed=5, dt=0.05, base=BASE)
    with torch.no_grad():  # a few near-zero weights to be pruned
        student.theta[:30] *= 1e-4
    ws = [w.detach().numpy() for w, _ in student.weights()]
    clusters = [TensorClusters.of(w) for w in ws]
    n_bias = 24 + 24 + 8
    budget = 300
    t, count = choose_threshold(clusters, n_bias, budget, prune=0.02)
    assert count <= budget
    # the bisection's threshold is tight: a little less exceeds the budget
    assert n_bias + sum(c.count(0.95 * t, 0.02) for c in clusters) > budget
    pico, info = compressed_model(student, clusters, t, prune=0.02)
    assert pico.param_count == count == info["free"]
    for (w_hat, b_hat), w, c, (_, b) in zip(pico.weights(), ws, clusters, student.weights()):
        labels, centres, sign = c.assign(t, 0.02)
        expect = np.where(sign == 0, 0.0, np.sign(w) * centres[labels] if len(centres) else 0.0)
        assert np.array_equal(w_hat.detach().numpy(), expect)  # exactly sign * centre
        assert np.array_equal(b_hat.detach().numpy(), b.detach().numpy())  # biases stay free
        for k in range(len(centres)):  # each centre is the mean |w| of its cluster
            m = (labels == k) & (sign != 0)
            assert math.isclose(centres[k], np.abs(w[m]).mean(), rel_tol=1e-12)
    assert sum(int((s == 0).sum()) for s in (c.assign(t, 0.02)[2] for c in clusters)) >= 30


# --------------------------------------------------------------------------------------
# Model files
# --------------------------------------------------------------------------------------


def _write_model(tmp_path, name="m.safetensors", compressed=False):
    rng = np.random.default_rng(6)
    m = dense_mlp((11, 16, 16, 8), _stats(rng), seed=7, dt=0.05, base=BASE)
    if compressed:
        c = [TensorClusters.of(w.detach().numpy()) for w, _ in m.weights()]
        t, _ = choose_threshold(c, 40, 150, prune=0.05)
        m, _ = compressed_model(m, c, t, prune=0.05)
    path = tmp_path / name
    save_model(m, path, kind="picopinn" if compressed else "pinn", param_set="full_size",
               mu_range=(0.15, 1.0), provenance={"data_hash": "sha256:test", "seed": "7", "command": "test"})
    return m, path


@pytest.mark.parametrize("compressed", [False, True])
def test_model_file_round_trip(tmp_path, compressed):
    m, path = _write_model(tmp_path, compressed=compressed)
    back, meta = load_model(path)
    assert back.param_count == m.param_count and back.layers == [11, 16, 16, 8]
    assert meta["format"] == "picopit-mlp" and meta["version"] == "3"
    assert meta["features"] == ",".join(FEATURES) and meta["outputs"] == ",".join(OUTPUTS)
    assert FEATURES[-1] == "mu" and len(FEATURES) == 11
    assert meta["layers"] == "11,16,16,8" and float(meta["dt"]) == 0.05 and meta["seed"] == "7"
    assert meta["mu_range"] == "0.15,1.0" and meta["mu_default"] == "0.9" and back.dt == 0.05
    assert meta["kind"] == ("picopinn" if compressed else "pinn")
    z = _t(np.random.default_rng(8).normal(size=(50, 11)) * back.in_std.numpy())
    with torch.no_grad():
        assert torch.equal(m(z), back(z))
    t = load_file(str(path))
    assert t["theta"].dtype == np.float64 and t["layer1.weight.idx"].dtype == np.int32
    assert t["layer1.weight.sign"].dtype == np.int8 and t["layer1.weight.idx"].shape == (16, 11)
    if not compressed:  # the teacher's R is the identity
        idx = np.concatenate([t[f"layer{l}.{p}.idx"].ravel() for l in (1, 2, 3) for p in ("weight", "bias")])
        assert np.array_equal(np.sort(idx), np.arange(m.param_count))
        assert all((t[f"layer{l}.weight.sign"] == 1).all() for l in (1, 2, 3))


def _corrupt(tmp_path, edit):
    _, path = _write_model(tmp_path)
    t = load_file(str(path))
    with safe_open(str(path), framework="numpy") as fh:
        meta = dict(fh.metadata())
    edit(t, meta)
    bad = tmp_path / "bad.safetensors"
    save_file(t, str(bad), metadata=meta)
    return bad


def test_provenance_commit_is_dirty_for_code_changes_not_for_model_files(tmp_path):
    import shutil
    import subprocess

    from picopit.provenance import git_commit as tree_commit
    from picopit.surrogate_nn import git_commit

    if shutil.which("git") is None:
        pytest.skip("git not installed")

    def git(*args):
        subprocess.run(["git", "-c", "user.name=t", "-c", "user.email=t@t", *args], cwd=tmp_path,
                       check=True, capture_output=True)

    (tmp_path / "models").mkdir()
    (tmp_path / "code.py").write_text("a = 1\n")
    (tmp_path / "models" / "m.safetensors").write_bytes(b"old")
    git("init", "-q")
    git("add", ".")
    git("commit", "-qm", "init")
    head = git_commit(tmp_path)
    assert len(head) == 40 and not head.endswith("-dirty")
    # regenerate.sh writes the first set's model before the second set records its commit
    (tmp_path / "models" / "m.safetensors").write_bytes(b"new")
    assert git_commit(tmp_path) == head
    # ... while the benchmark's provenance counts the models it ran with
    assert tree_commit(tmp_path) == head + "-dirty"
    (tmp_path / "code.py").write_text("a = 2\n")
    assert git_commit(tmp_path) == head + "-dirty"
    # from a subfolder (the package's own folder) the whole tree still counts
    (tmp_path / "models" / "sub").mkdir()
    assert git_commit(tmp_path / "models" / "sub") == head + "-dirty"


@pytest.mark.parametrize("edit, name", [
    (lambda t, m: t.pop("in_std"), "in_std"),
    (lambda t, m: t.__setitem__("theta", np.where(np.arange(t["theta"].size) == 3, np.nan, t["theta"])), "theta"),
    (lambda t, m: t.__setitem__("out_std", -t["out_std"]), "out_std"),
    (lambda t, m: t.__setitem__("layer2.weight.idx", t["layer2.weight.idx"] + 10_000), "layer2.weight.idx"),
    (lambda t, m: t.__setitem__("layer1.bias.sign", t["layer1.bias.sign"] * 3), "layer1.bias.sign"),
    (lambda t, m: t.__setitem__("layer3.weight.idx", t["layer3.weight.idx"].astype(np.int64)), "layer3.weight.idx"),
    (lambda t, m: t.__setitem__("layer1.weight.sign", t["layer1.weight.sign"][:, :5].copy()), "layer1.weight.sign"),
    (lambda t, m: m.pop("dt"), "dt"),
    (lambda t, m: m.__setitem__("version", "1"), "version"),
    (lambda t, m: m.__setitem__("version", "2"), "version"),
    (lambda t, m: t.pop("base"), "base"),
    (lambda t, m: t.__setitem__("base", t["base"][:, :10].copy()), "base"),
    (lambda t, m: t.__setitem__("base", np.where(t["base"] != 0, np.inf, 0.0)), "base"),
    (lambda t, m: m.__setitem__("features", "vx,vy"), "features"),
    (lambda t, m: m.__setitem__("layers", "11,16,8"), "layer"),
    (lambda t, m: m.pop("mu_range"), "mu_range"),
    (lambda t, m: m.__setitem__("mu_range", "0.15"), "mu_range"),
    (lambda t, m: m.__setitem__("mu_range", "1.0,0.15"), "mu_range"),
    (lambda t, m: m.__setitem__("mu_default", "0.05"), "mu_default"),
])
def test_malformed_model_file_names_the_field(tmp_path, edit, name):
    bad = _corrupt(tmp_path, edit)
    with pytest.raises(ModelFileError, match=name.replace(".", r"\.")):
        load_model(bad)


def test_truncated_model_file(tmp_path):
    _, path = _write_model(tmp_path)
    data = path.read_bytes()
    (tmp_path / "cut.safetensors").write_bytes(data[: len(data) // 2])
    with pytest.raises(ModelFileError, match="cut.safetensors"):
        load_model(tmp_path / "cut.safetensors")


# --------------------------------------------------------------------------------------
# Datasets
# --------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def tiny_data(tmp_path_factory):
    out = tmp_path_factory.mktemp("data")
    cfg = datagen.DatagenConfig.for_params("half_scale", episodes=12, seed=11)
    arrays, manifest = datagen.generate(cfg, progress=False)
    datagen.write(arrays, manifest, out)
    return out, arrays, manifest


def test_datagen_records_contacts_free_motion_and_splits(tiny_data):
    out, a, man = tiny_data
    ds = datagen.load(out)
    assert ds.data_hash == man["data_hash"]
    contact = a["fc"][:, 0] > 0
    assert contact.any() and (~contact).sum() > contact.sum()  # free motion before/after the hit
    # the first touch of every episode is on the target's rear quarter or side (later ones may
    # land anywhere once the target spins)
    firsts = [np.nonzero(contact & (a["episode"] == e))[0] for e in np.unique(a["episode"])]
    firsts = [f[0] for f in firsts if len(f)]
    assert len(firsts) >= 10 and np.all(a["point"][firsts, 0] < 0.2 * 1.9)
    # consecutive samples chain: x_next of step k is x of step k+1 in the same episode
    w = datagen.windows(a, 2)
    assert len(w) > 0 and np.array_equal(a["x_next"][w], a["x"][w + 1])
    # splits by episode, all three present, no episode in two splits
    per_ep = {int(e): set(a["split"][a["episode"] == e].tolist()) for e in np.unique(a["episode"])}
    assert all(len(s) == 1 for s in per_ep.values())
    assert {next(iter(s)) for s in per_ep.values()} == {0, 1, 2}
    for key in ("sampling", "counts", "seed", "data_hash"):
        assert key in man
    # determinism with the seed
    a2, m2 = datagen.generate(datagen.DatagenConfig.for_params("half_scale", episodes=12, seed=11), progress=False)
    assert m2["data_hash"] == man["data_hash"]


@pytest.mark.parametrize("edit, name", [
    (lambda a: a.pop("gamma"), "gamma"),
    (lambda a: a.__setitem__("x", np.where(np.arange(a["x"].size).reshape(a["x"].shape) == 5, np.inf, a["x"])), "'x'"),
    (lambda a: a.__setitem__("u", a["u"][:, :1].copy()), "'u'"),
    (lambda a: a["mu"].__setitem__(0, 0.5), "data_hash"),
])
def test_malformed_dataset_names_the_field(tiny_data, tmp_path, edit, name):
    out, a, man = tiny_data
    arrays = {k: v.copy() for k, v in a.items()}
    edit(arrays)
    np.savez(tmp_path / "dataset.npz", **arrays)
    (tmp_path / "manifest.json").write_text(json.dumps(man))
    with pytest.raises(datagen.DatasetError, match=name):
        datagen.load(tmp_path)


def test_datagen_config_errors_name_the_field():
    with pytest.raises(datagen.DatasetError, match="episodes"):
        datagen.DatagenConfig.for_params("full_size", episodes=1)
    with pytest.raises(datagen.DatasetError, match="mu"):
        datagen.DatagenConfig(mu=(0.0, 2.0)).validate()
    with pytest.raises(datagen.DatasetError, match="push_time"):
        datagen.DatagenConfig(push_time=(1.0, 0.5)).validate()


# --------------------------------------------------------------------------------------
# The pipeline through the CLI
# --------------------------------------------------------------------------------------


def test_pipeline_smoke(tiny_data, tmp_path, capsys):
    data, _, man = tiny_data
    assert main(["train", "--data", str(data), "--out", str(tmp_path / "train"), "--epochs", "2",
                 "--seed", "3", "--no-progress"]) == 0
    pinn = tmp_path / "train" / "pinn.safetensors"
    assert (tmp_path / "train" / "train_curves.png").is_file()
    assert (tmp_path / "train" / "checkpoints" / "best.pt").is_file()
    assert main(["compress", "--teacher", str(pinn), "--data", str(data), "--out", str(tmp_path / "cmp"),
                 "--distil-epochs", "2", "--retrain-epochs", "2", "--no-progress"]) == 0
    pico = tmp_path / "cmp" / "picopinn.safetensors"
    for f in ("cluster_threshold.png", "retrain_curves.png"):
        assert (tmp_path / "cmp" / f).is_file()
    assert main(["eval-surrogates", "--data", str(data), "--pinn", str(pinn), "--picopinn", str(pico),
                 "--horizon", "10", "--stride", "20", "--json", str(tmp_path / "e.json"),
                 "--out", str(tmp_path / "ev"), "--no-progress"]) == 0
    res = json.loads((tmp_path / "e.json").read_text())
    assert set(res["models"]) == {"4dof", "pinn", "picopinn"}
    for m in res["models"].values():
        for k in ("params", "heading_rmse_rad", "roll_rmse_rad", "rollout_heading_rmse_rad"):
            assert k in m and m[k] is not None
    for m in res["models"].values():
        assert 0 <= m["sliding_windows"] <= m["rollout_windows"]
        assert m["rollout_final_speed_rmse_mps"] >= 0
        if m["sliding_windows"]:
            assert m["sliding_stop_point_rmse_m"] >= m["sliding_stop_point_median_m"] >= 0
            assert math.isfinite(m["sliding_stop_reach_bias_m"])
    assert res["models"]["4dof"]["params"] == 0
    assert res["models"]["pinn"]["params"] == 11 * 64 + 64 + 2 * (64 * 64 + 64) + 64 * 8 + 8
    assert 56 < res["models"]["picopinn"]["params"] <= 812
    assert (tmp_path / "ev" / "eval.png").is_file()
    _, meta = load_model(pico)
    assert meta["data_hash"] == man["data_hash"] and meta["seed"] == "0" and meta["kind"] == "picopinn"
    assert "picopit compress" in meta["command"] and meta["git_commit"]
    assert "| parameters |" in capsys.readouterr().out


def test_sliding_starts_are_spun_targets_moving():
    # [vx, vy, ψ, r, p, φ, X, Y]: straight on, slipping 0.46 rad, sideways, backwards at
    # 30° slip, slipping but almost at rest.
    x = np.array([[20.0, 1.0, 0, 0, 0, 0, 0, 0],
                  [10.0, 5.0, 0, 0, 0, 0, 0, 0],
                  [0.0, -3.0, 0, 0, 0, 0, 0, 0],
                  [-4.0, 2.4, 0, 0, 0, 0, 0, 0],
                  [0.3, 0.5, 0, 0, 0, 0, 0, 0]])
    assert sliding(x).tolist() == [False, True, True, True, False]


def test_stop_points_slide_on_along_the_velocity_at_the_planners_deceleration():
    f = planner_stop_decel_fraction()
    assert 0.0 < f <= 3.0
    # state order vx, vy, psi, r, p, phi, X, Y
    x = np.array([
        [10.0, 0.0, 0.0, 0.0, 0.0, 0.0, 5.0, 1.0],        # straight ahead along +X
        [0.0, 6.0, 0.5 * np.pi, 0.0, 0.0, 0.0, 0.0, 0.0],  # sliding sideways, heading +Y: moves −X
        [0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 2.0, 3.0],          # at rest: stays
    ])
    mu = np.array([0.8, 0.3, 0.5])
    p = stop_points(x, mu, f)
    d0 = 10.0 ** 2 / (2 * f * 0.8 * PLANNER_GRAVITY)
    d1 = 6.0 ** 2 / (2 * f * 0.3 * PLANNER_GRAVITY)
    np.testing.assert_allclose(p, [[5.0 + d0, 1.0], [-d1, 0.0], [2.0, 3.0]], atol=1e-12)
    # a lower μ slides further, in proportion
    np.testing.assert_allclose(stop_points(x[:1], np.array([0.4]), f)[0, 0] - 5.0, 2 * d0)


def test_cli_bad_input_exits_2_naming_the_problem(tmp_path, capsys):
    assert main(["train", "--data", str(tmp_path / "nope"), "--out", str(tmp_path / "o")]) == 2
    assert "dataset.npz" in capsys.readouterr().err
    assert main(["train", "--data", str(tmp_path), "--out", str(tmp_path / "o"), "--layers", "11,x,8"]) == 2
    assert "layers" in capsys.readouterr().err
    assert main(["train", "--data", str(tmp_path), "--out", str(tmp_path / "o"), "--epochs", "0"]) == 2
    assert "epochs" in capsys.readouterr().err
    assert main(["train", "--data", str(tmp_path), "--out", str(tmp_path / "o"), "--base", "affine"]) == 2
    err = capsys.readouterr().err
    assert "base" in err and "impulse" in err
    assert main(["datagen", "--params", "nope", "--out", str(tmp_path / "d")]) == 2
    assert "params" in capsys.readouterr().err
    for bad in ("1,2,x,1,1,4,1,1", "1,2,4"):
        assert main(["compress", "--teacher", str(tmp_path / "t.safetensors"), "--data", str(tmp_path),
                     "--out", str(tmp_path / "c"), "--output-weights", bad]) == 2
        assert "output_weights" in capsys.readouterr().err
