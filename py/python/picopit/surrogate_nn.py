"""Learned target surrogates in PyTorch (float64) and their model files.

The network and its file are exactly those of ``docs/model-format.md`` (format
``picopit-mlp`` version 3): 11 position- and heading-invariant features (the last is the road
adhesion μ, a property of the model instance), a tanh MLP on normalised features, 8
de-normalised increments added to a fixed linear base ``B z`` stored in the file (the
training writes the explicit-Euler kinematic increments ``dt·[0, 0, 0, 0, p, r, vx, vy]`` and
the rigid-body impulse of the step's contact force and moment, :func:`physics_base`), the
next state by the stated formulas.
Every layer's weights are a gather ŵ = sign ⊙ θ[idx] from one free-parameter vector θ; the
teacher PINN is the special case R = identity.
"""

from __future__ import annotations

import datetime as _dt
import json
import math
from pathlib import Path
from typing import Any, Dict, List, Mapping, Optional, Sequence, Tuple

import numpy as np
import torch

from . import provenance

FORMAT = "picopit-mlp"
VERSION = "3"
FEATURES = ("vx", "vy", "r", "p", "phi", "delta", "T_b", "f_bx", "f_by", "M_z", "mu")
OUTPUTS = ("dvx", "dvy", "dr", "dp", "dphi", "dpsi", "dx_b", "dy_b")
N_IN, N_OUT = len(FEATURES), len(OUTPUTS)
REQUIRED_KEYS = ("format", "version", "kind", "activation", "layers", "features", "outputs",
                 "dt", "param_set", "mu_range", "mu_default")
#: Which feature's explicit-Euler increment ``dt·z_j`` is the kinematic base of each output
#: (−1: none): Δφ ← p, Δψ ← r, Δx_b ← vx, Δy_b ← vy.
BASE_FEATURE = (-1, -1, -1, -1, 3, 2, 0, 1)
MU_DEFAULT = 0.9
KINDS = ("pinn", "picopinn")
#: The linear bases :func:`physics_base` builds: the kinematics alone, or with the contact's
#: rigid-body impulse.
BASES = ("kinematic", "impulse")


class ModelFileError(ValueError):
    """A model file that cannot be used; the message names the tensor or metadata key."""


# --------------------------------------------------------------------------------------
# Features and the discrete step (shared by training, evaluation and the parity test)
# --------------------------------------------------------------------------------------


def features(x: torch.Tensor, u: torch.Tensor, fc: torch.Tensor, gamma: torch.Tensor,
             point: torch.Tensor, mu) -> torch.Tensor:
    """z (B, 11) from state x (B, 8), input u (B, 2), contact fc (B, 2), γ (B,), point (B, 2)
    and road μ (B,) or a scalar."""
    a = gamma - x[:, 2]
    s, c = torch.sin(a), torch.cos(a)
    fbx = c * fc[:, 0] - s * fc[:, 1]
    fby = s * fc[:, 0] + c * fc[:, 1]
    mz = point[:, 0] * fby - point[:, 1] * fbx
    mu = torch.as_tensor(mu, dtype=x.dtype).expand(x.shape[0])
    return torch.stack([x[:, 0], x[:, 1], x[:, 3], x[:, 4], x[:, 5], u[:, 0], u[:, 1], fbx, fby, mz, mu], dim=1)


def physics_base(dt: float, mass: float, iz: float, kind: str = "impulse") -> np.ndarray:
    """The fixed linear base B (8 × 11) of the increments, ``o = B z + learned part``: the
    part of the increments the network does not have to learn.

    ``kinematic``: the explicit-Euler kinematic increments Δφ ← dt·p, Δψ ← dt·r,
    Δx_b ← dt·vx, Δy_b ← dt·vy. ``impulse`` adds what the step's contact force (f_bx, f_by,
    in the start body frame) and moment M_z do to a free rigid body of mass ``mass`` and yaw
    inertia ``iz`` over the step: Δv += dt·f_b/m, Δr += dt·M_z/I_z, Δψ += dt²/2·M_z/I_z,
    Δ(x_b, y_b) += dt²/2·f_b/m. Tyres, roll and the rotation of the body frame during the
    step are the network's to learn."""
    if kind not in BASES:
        raise ValueError(f"kind = {kind!r}: must be one of {', '.join(BASES)}")
    for name, v in (("dt", dt), ("mass", mass), ("iz", iz)):
        if not (math.isfinite(v) and v > 0):
            raise ValueError(f"{name} = {v!r}: must be finite and > 0")
    b = np.zeros((N_OUT, N_IN))
    for k, j in enumerate(BASE_FEATURE):
        if j >= 0:
            b[k, j] = dt
    if kind == "impulse":
        fbx, fby, mz = FEATURES.index("f_bx"), FEATURES.index("f_by"), FEATURES.index("M_z")
        b[0, fbx] = dt / mass
        b[1, fby] = dt / mass
        b[2, mz] = dt / iz
        b[5, mz] = 0.5 * dt * dt / iz
        b[6, fbx] = 0.5 * dt * dt / mass
        b[7, fby] = 0.5 * dt * dt / mass
    return b


def linear_base(z: torch.Tensor, base: torch.Tensor) -> torch.Tensor:
    """B z (B, 8) for features z (B, 11)."""
    return z @ base.T


def apply_increments(x: torch.Tensor, o: torch.Tensor) -> torch.Tensor:
    """x⁺ (B, 8) from x and the increments o = [Δvx, Δvy, Δr, Δp, Δφ, Δψ, Δx_b, Δy_b]."""
    psi = x[:, 2]
    c, s = torch.cos(psi), torch.sin(psi)
    return torch.stack([
        x[:, 0] + o[:, 0], x[:, 1] + o[:, 1], psi + o[:, 5], x[:, 3] + o[:, 2],
        x[:, 4] + o[:, 3], x[:, 5] + o[:, 4],
        x[:, 6] + c * o[:, 6] - s * o[:, 7], x[:, 7] + s * o[:, 6] + c * o[:, 7],
    ], dim=1)


def increments(x: torch.Tensor, x_next: torch.Tensor) -> torch.Tensor:
    """The increments o (B, 8) that take x to x_next (the inverse of :func:`apply_increments`)."""
    psi = x[:, 2]
    c, s = torch.cos(psi), torch.sin(psi)
    dX, dY = x_next[:, 6] - x[:, 6], x_next[:, 7] - x[:, 7]
    return torch.stack([
        x_next[:, 0] - x[:, 0], x_next[:, 1] - x[:, 1], x_next[:, 3] - x[:, 3],
        x_next[:, 4] - x[:, 4], x_next[:, 5] - x[:, 5], x_next[:, 2] - x[:, 2],
        c * dX + s * dY, -s * dX + c * dY,
    ], dim=1)


# --------------------------------------------------------------------------------------
# The network
# --------------------------------------------------------------------------------------


class GatherMLP(torch.nn.Module):
    """tanh MLP whose weights and biases are gathered from one free vector θ:
    ŵ = sign ⊙ θ[idx] per tensor. ``layers`` are the widths, input first."""

    def __init__(self, layers: Sequence[int], theta: torch.Tensor,
                 idx: List[Tuple[torch.Tensor, torch.Tensor]],
                 sign: List[Tuple[torch.Tensor, torch.Tensor]],
                 in_mean, in_std, out_mean, out_std, dt: float, base):
        super().__init__()
        self.layers = [int(w) for w in layers]
        self.dt = float(dt)
        self.theta = torch.nn.Parameter(theta.detach().clone().to(torch.float64))
        for l, ((wi, bi), (ws, bs)) in enumerate(zip(idx, sign), start=1):
            self.register_buffer(f"w_idx{l}", wi.to(torch.long))
            self.register_buffer(f"b_idx{l}", bi.to(torch.long))
            self.register_buffer(f"w_sign{l}", ws.to(torch.float64))
            self.register_buffer(f"b_sign{l}", bs.to(torch.float64))
        for name, v in (("in_mean", in_mean), ("in_std", in_std), ("out_mean", out_mean), ("out_std", out_std),
                        ("base", base)):
            self.register_buffer(name, torch.as_tensor(np.asarray(v), dtype=torch.float64).clone())

    @property
    def n_layers(self) -> int:
        return len(self.layers) - 1

    def weights(self) -> List[Tuple[torch.Tensor, torch.Tensor]]:
        """The expanded (ŵ, b̂) of every layer."""
        out = []
        for l in range(1, self.n_layers + 1):
            w = getattr(self, f"w_sign{l}") * self.theta[getattr(self, f"w_idx{l}")]
            b = getattr(self, f"b_sign{l}") * self.theta[getattr(self, f"b_idx{l}")]
            out.append((w, b))
        return out

    def forward_normalised(self, zn: torch.Tensor) -> torch.Tensor:
        h = zn
        ws = self.weights()
        for l, (w, b) in enumerate(ws, start=1):
            h = torch.nn.functional.linear(h, w, b)
            if l < len(ws):
                h = torch.tanh(h)
        return h

    def residual(self, z: torch.Tensor) -> torch.Tensor:
        """The learned part of the increments, out_mean + out_std ⊙ y (B, 8)."""
        y = self.forward_normalised((z - self.in_mean) / self.in_std)
        return self.out_mean + self.out_std * y

    def forward(self, z: torch.Tensor) -> torch.Tensor:
        """Increments o (B, 8) from raw features z (B, 11): the linear base B z plus the
        learned residual."""
        return linear_base(z, self.base) + self.residual(z)

    def step(self, x, u, fc, gamma, point, mu) -> torch.Tensor:
        return apply_increments(x, self(features(x, u, fc, gamma, point, mu)))

    @property
    def param_count(self) -> int:
        return int(self.theta.numel())

    def tensors(self) -> Dict[str, np.ndarray]:
        """The safetensors payload of this model (docs/model-format.md)."""
        t: Dict[str, np.ndarray] = {"theta": self.theta.detach().cpu().numpy().astype(np.float64)}
        for l in range(1, self.n_layers + 1):
            for part in ("weight", "bias"):
                key = "w" if part == "weight" else "b"
                t[f"layer{l}.{part}.idx"] = getattr(self, f"{key}_idx{l}").cpu().numpy().astype(np.int32)
                t[f"layer{l}.{part}.sign"] = getattr(self, f"{key}_sign{l}").cpu().numpy().astype(np.int8)
        for name in ("in_mean", "in_std", "out_mean", "out_std", "base"):
            t[name] = np.ascontiguousarray(getattr(self, name).cpu().numpy().astype(np.float64))
        return t


def dense_mlp(layers: Sequence[int], stats: Mapping[str, np.ndarray], seed: int, dt: float,
              base: np.ndarray) -> GatherMLP:
    """A plain (R = identity) MLP with Xavier-initialised weights and zero biases, over the
    linear base ``base`` (8 × 11)."""
    g = torch.Generator().manual_seed(int(seed))
    thetas, idx, sign = [], [], []
    off = 0
    for n_in, n_out in zip(layers[:-1], layers[1:]):
        bound = math.sqrt(6.0 / (n_in + n_out))
        w = (torch.rand(n_out, n_in, generator=g, dtype=torch.float64) * 2 - 1) * bound
        b = torch.zeros(n_out, dtype=torch.float64)
        wi = torch.arange(off, off + w.numel()).reshape(n_out, n_in)
        off += w.numel()
        bi = torch.arange(off, off + n_out)
        off += n_out
        thetas += [w.reshape(-1), b]
        idx.append((wi, bi))
        sign.append((torch.ones(n_out, n_in), torch.ones(n_out)))
    return GatherMLP(layers, torch.cat(thetas), idx, sign, stats["in_mean"], stats["in_std"],
                     stats["out_mean"], stats["out_std"], dt, base)


def dense_from_weights(layers: Sequence[int], weights: List[Tuple[torch.Tensor, torch.Tensor]],
                       like: GatherMLP) -> GatherMLP:
    """An identity-R model holding the given expanded weights, with ``like``'s statistics."""
    m = dense_mlp(layers, {k: getattr(like, k).numpy() for k in ("in_mean", "in_std", "out_mean", "out_std")}, 0, like.dt,
                  like.base.numpy())
    with torch.no_grad():
        m.theta.copy_(torch.cat([torch.cat([w.reshape(-1), b]) for w, b in weights]))
    return m


# --------------------------------------------------------------------------------------
# Files
# --------------------------------------------------------------------------------------


def git_commit(cwd: Optional[Path] = None) -> str:
    """HEAD, with ``-dirty`` when a tracked file outside ``models/`` has changed: the shipped
    model files are what ``models/regenerate.sh`` writes, so the first set's new file must
    not mark the second set's provenance dirty."""
    return provenance.git_commit(cwd, ignore=("models",))


def save_model(model: GatherMLP, path: Path, *, kind: str, param_set: str,
               mu_range: Tuple[float, float], provenance: Mapping[str, Any],
               mu_default: Optional[float] = None) -> None:
    """Write ``model`` as a ``picopit-mlp`` v3 safetensors file with provenance metadata;
    ``mu_range`` is the road adhesion span of the training data, ``mu_default`` the μ a
    reader uses until told the road's (default :data:`MU_DEFAULT` clamped into the range)."""
    from safetensors.numpy import save_file

    if kind not in KINDS:
        raise ModelFileError(f"kind = {kind!r}: must be one of {', '.join(KINDS)}")
    if mu_default is None:
        mu_default = min(max(MU_DEFAULT, float(mu_range[0])), float(mu_range[1]))
    dt = model.dt
    if not (dt > 0 and math.isfinite(dt)):
        raise ModelFileError(f"dt = {dt!r}: must be > 0")
    meta = {
        "format": FORMAT, "version": VERSION, "kind": kind, "activation": "tanh",
        "layers": ",".join(str(w) for w in model.layers),
        "features": ",".join(FEATURES), "outputs": ",".join(OUTPUTS),
        "dt": repr(float(dt)), "param_set": str(param_set),
        "mu_range": f"{float(mu_range[0])!r},{float(mu_range[1])!r}", "mu_default": repr(float(mu_default)),
        "created": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
    }
    for k, v in provenance.items():
        meta[k] = v if isinstance(v, str) else json.dumps(v, sort_keys=True)
    tensors = model.tensors()
    _validate(tensors, meta, str(path))  # never write a file we would refuse
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    save_file(tensors, str(path), metadata=meta)


def _validate(t: Mapping[str, np.ndarray], meta: Mapping[str, str], where: str) -> List[int]:
    def bad(name: str, why: str) -> ModelFileError:
        return ModelFileError(f"{where}: {name}: {why}")

    # Format and version first: a file of another version may differ in anything else.
    for k in ("format", "version"):
        if k not in meta:
            raise bad(k, "required metadata key missing")
    if meta["format"] != FORMAT:
        raise bad("format", f"{meta['format']!r} is not {FORMAT!r}")
    if meta["version"] != VERSION:
        raise bad("version", f"unknown version {meta['version']!r} (this reader knows {VERSION}; "
                             "regenerate older files with models/regenerate.sh)")
    for k in REQUIRED_KEYS:
        if k not in meta:
            raise bad(k, "required metadata key missing")
    if meta["kind"] not in KINDS:
        raise bad("kind", f"{meta['kind']!r} is not one of {', '.join(KINDS)}")
    if meta["activation"] != "tanh":
        raise bad("activation", f"{meta['activation']!r}: only tanh in version 3")
    if meta["features"] != ",".join(FEATURES):
        raise bad("features", f"must be {','.join(FEATURES)}")
    if meta["outputs"] != ",".join(OUTPUTS):
        raise bad("outputs", f"must be {','.join(OUTPUTS)}")
    try:
        dt = float(meta["dt"])
    except ValueError:
        raise bad("dt", f"{meta['dt']!r} is not a number") from None
    if not (dt > 0 and math.isfinite(dt)):
        raise bad("dt", f"{meta['dt']!r}: must be > 0")
    mu_lo, mu_hi = parse_mu_range(meta["mu_range"], bad)
    try:
        mu_def = float(meta["mu_default"])
    except ValueError:
        raise bad("mu_default", f"{meta['mu_default']!r} is not a number") from None
    if not (mu_lo <= mu_def <= mu_hi):
        raise bad("mu_default", f"{meta['mu_default']!r}: must lie in mu_range [{mu_lo}, {mu_hi}]")
    try:
        layers = [int(w) for w in meta["layers"].split(",")]
    except ValueError:
        raise bad("layers", f"{meta['layers']!r} is not a comma-separated list of widths") from None
    if len(layers) < 2 or layers[0] != N_IN or layers[-1] != N_OUT or min(layers) < 1:
        raise bad("layers", f"{meta['layers']!r}: must start with {N_IN}, end with {N_OUT}, widths >= 1")

    def tensor(name: str, dtype, shape) -> np.ndarray:
        if name not in t:
            raise bad(name, "tensor missing")
        a = t[name]
        if a.dtype != dtype:
            raise bad(name, f"dtype {a.dtype}, expected {np.dtype(dtype)}")
        if tuple(a.shape) != tuple(shape):
            raise bad(name, f"shape {list(a.shape)}, expected {list(shape)}")
        return a

    if "theta" not in t:
        raise bad("theta", "tensor missing")
    theta = t["theta"]
    if theta.dtype != np.float64 or theta.ndim != 1 or theta.size == 0:
        raise bad("theta", f"must be a non-empty 1-D float64 tensor (got {theta.dtype} {list(theta.shape)})")
    if not np.all(np.isfinite(theta)):
        raise bad("theta", "holds NaN or inf")
    n = theta.size
    for l, (n_in, n_out) in enumerate(zip(layers[:-1], layers[1:]), start=1):
        for part, shape in (("weight", (n_out, n_in)), ("bias", (n_out,))):
            i = tensor(f"layer{l}.{part}.idx", np.int32, shape)
            s = tensor(f"layer{l}.{part}.sign", np.int8, shape)
            if i.size and (i.min() < 0 or i.max() >= n):
                raise bad(f"layer{l}.{part}.idx", f"index out of bounds for theta of length {n}")
            if not np.all(np.isin(s, (-1, 0, 1))):
                raise bad(f"layer{l}.{part}.sign", "values must be -1, 0 or +1")
    for name, k in (("in_mean", N_IN), ("in_std", N_IN), ("out_mean", N_OUT), ("out_std", N_OUT)):
        a = tensor(name, np.float64, (k,))
        if not np.all(np.isfinite(a)):
            raise bad(name, "holds NaN or inf")
        if name.endswith("std") and not np.all(a > 0):
            raise bad(name, "std must be > 0")
    if not np.all(np.isfinite(tensor("base", np.float64, (N_OUT, N_IN)))):
        raise bad("base", "holds NaN or inf")
    extra = sorted(set(t) - {"theta", "in_mean", "in_std", "out_mean", "out_std", "base"}
                   - {f"layer{l}.{p}.{q}" for l in range(1, len(layers)) for p in ("weight", "bias") for q in ("idx", "sign")})
    if extra:
        raise bad(extra[0], "unexpected tensor")
    return layers


def parse_mu_range(text: str, bad=None) -> Tuple[float, float]:
    """``lo,hi`` with 0 < lo <= hi, both finite."""
    bad = bad or (lambda name, why: ModelFileError(f"{name}: {why}"))
    try:
        lo, hi = (float(v) for v in str(text).split(","))
    except ValueError:
        raise bad("mu_range", f"{text!r} is not two comma-separated numbers lo,hi") from None
    if not (math.isfinite(lo) and math.isfinite(hi) and 0 < lo <= hi):
        raise bad("mu_range", f"{text!r}: must be finite with 0 < lo <= hi")
    return lo, hi


def load_model(path: Path) -> Tuple[GatherMLP, Dict[str, str]]:
    """Read and validate a model file; returns the torch model and its metadata."""
    from safetensors import SafetensorError
    from safetensors.numpy import load_file
    from safetensors import safe_open

    path = Path(path)
    if not path.is_file():
        raise ModelFileError(f"{path}: no such model file")
    try:
        t = load_file(str(path))
        with safe_open(str(path), framework="numpy") as fh:
            meta = dict(fh.metadata() or {})
    except (SafetensorError, OSError, ValueError) as e:
        raise ModelFileError(f"{path}: not a readable safetensors file: {e}") from None
    layers = _validate(t, meta, str(path))
    idx, sign = [], []
    for l in range(1, len(layers)):
        idx.append((torch.from_numpy(t[f"layer{l}.weight.idx"].astype(np.int64)),
                    torch.from_numpy(t[f"layer{l}.bias.idx"].astype(np.int64))))
        sign.append((torch.from_numpy(t[f"layer{l}.weight.sign"].astype(np.float64)),
                     torch.from_numpy(t[f"layer{l}.bias.sign"].astype(np.float64))))
    model = GatherMLP(layers, torch.from_numpy(t["theta"]), idx, sign, t["in_mean"], t["in_std"],
                      t["out_mean"], t["out_std"], float(meta["dt"]), t["base"])
    return model, meta
