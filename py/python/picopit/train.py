"""``picopit train``: the teacher PINN (and the loss machinery PicoPINN retraining shares).

The network (format version 2) predicts the increments as the explicit-Euler kinematic base
dt·[0, 0, 0, 0, p, r, vx, vy] plus a learned part whose statistics are the model's
out_mean / out_std; μ is its 11th feature. Loss, in normalised units:

- data, one step: ‖(o_net(z_k) − o_k) / s‖² with o_k the recorded increments x_k → x_{k+1}
  and s, per output, the geometric mean of the std of the whole increment and of its
  learned part (``loss_scale``; "increment" and "residual" are the alternatives);
- data, rollout: the model rolls its own predictions over ``horizon`` steps from a recorded
  x_k with the recorded inputs and contacts (the body-frame contact force follows the
  predicted heading); state errors divided by the std of the matching whole increment
  times the step number;
- physics: the residual of the 4-DOF Newton–Euler equations with the contact force and its
  moment (``physics.FourDof``), integrated over the step: the network's increment minus the
  increment the equations give from the same x_k, u_k, contact and road μ, on the training
  samples and on collocation points (perturbed states, inputs and contacts with no label).
  It vanishes on data the 4-DOF model produced itself.

``--no-physics`` sets the physics weight to 0 (the ablation).
"""

from __future__ import annotations

import dataclasses
import json
import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Dict, List, Mapping, Optional, Sequence, Tuple

import numpy as np
import torch

from . import load_params_dict
from .datagen import DT, Dataset, DatasetError, windows
from .physics import FourDof
from .surrogate_nn import (BASES, N_IN, N_OUT, GatherMLP, apply_increments, dense_mlp, features, increments,
                          linear_base, physics_base)

#: Which increment std scales each state's error in the rollout loss
#: (state order vx, vy, ψ, r, p, φ, X, Y → increment order dvx, dvy, dr, dp, dphi, dpsi, dx_b, dy_b).
STATE_TO_OUT = (0, 1, 5, 2, 3, 4, 6, 7)
LOSS_SCALES = ("geometric", "increment", "residual")


class TrainError(ValueError):
    """A bad training setting; the message names the field."""


@dataclass
class TrainConfig:
    layers: Tuple[int, ...] = (11, 64, 64, 64, 8)
    epochs: int = 120
    batch: int = 1024
    lr: float = 3e-3
    lr_final: float = 1e-4
    w_data: float = 1.0
    w_rollout: float = 0.3
    w_physics: float = 0.05
    horizon: int = 4
    rollout_batch: int = 256
    collocation: float = 0.5
    """Collocation points per training sample for the physics term."""
    seed: int = 0
    checkpoint_every: int = 10
    loss_scale: str = "geometric"
    """Error scale of the one-step loss per output (``output_scale``)."""
    base: str = "impulse"
    """The fixed linear base of the increments (``surrogate_nn.physics_base``): ``impulse``
    (kinematics and the contact's rigid-body impulse) or ``kinematic`` (the ablation)."""

    def validate(self) -> "TrainConfig":
        def bad(name, why):
            return TrainError(f"{name} = {getattr(self, name)!r}: {why}")

        if len(self.layers) < 3 or self.layers[0] != N_IN or self.layers[-1] != N_OUT or min(self.layers) < 1:
            raise bad("layers", f"widths from {N_IN} inputs to {N_OUT} outputs with at least one hidden layer")
        for name in ("epochs", "batch", "horizon", "rollout_batch", "checkpoint_every"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise bad(name, "must be a positive integer")
        for name in ("lr", "lr_final"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise bad(name, "must be > 0")
        for name in ("w_data", "w_rollout", "w_physics", "collocation"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise bad(name, "must be >= 0")
        if isinstance(self.seed, bool) or not isinstance(self.seed, int) or self.seed < 0:
            raise bad("seed", "must be a non-negative integer")
        if self.loss_scale not in LOSS_SCALES:
            raise bad("loss_scale", f"must be one of {', '.join(LOSS_SCALES)}")
        if self.base not in BASES:
            raise bad("base", f"must be one of {', '.join(BASES)}")
        return self


def torch_threads() -> int:
    """Set and return the torch CPU thread count: ``PICOPIT_THREADS`` (1 or 2), default 2.

    On the shared 2-core machine one thread is the faster choice whenever another process
    is busy: the tensors are small, and two OpenMP threads that wait on each other lose
    far more to a preempted partner than they gain (docs/surrogates.md, measured)."""
    import os

    v = os.environ.get("PICOPIT_THREADS", "2")
    if v.strip() not in ("1", "2"):
        raise TrainError(f"PICOPIT_THREADS = {v!r}: must be 1 or 2")
    torch.set_num_threads(int(v))
    return int(v)


def parse_layers(text: str) -> Tuple[int, ...]:
    try:
        return tuple(int(w) for w in str(text).split(","))
    except ValueError:
        raise TrainError(f"layers = {text!r}: a comma-separated list of widths, e.g. 11,64,64,64,8") from None


# --------------------------------------------------------------------------------------
# Tensors of a split
# --------------------------------------------------------------------------------------


@dataclass
class Split:
    x: torch.Tensor
    u: torch.Tensor
    fc: torch.Tensor
    gamma: torch.Tensor
    point: torch.Tensor
    x_next: torch.Tensor
    mu: torch.Tensor
    z: torch.Tensor
    o: torch.Tensor
    win: torch.Tensor  # rollout window starts

    @classmethod
    def of(cls, a: Mapping[str, np.ndarray], horizon: int) -> "Split":
        t = {k: torch.from_numpy(np.ascontiguousarray(a[k], dtype=np.float64))
             for k in ("x", "u", "fc", "gamma", "point", "x_next", "mu")}
        z = features(t["x"], t["u"], t["fc"], t["gamma"], t["point"], t["mu"])
        o = increments(t["x"], t["x_next"])
        return cls(z=z, o=o, win=torch.from_numpy(windows(a, horizon)), **t)

    def __len__(self) -> int:
        return int(self.x.shape[0])


def stats_of(s: Split, base: np.ndarray) -> Dict[str, np.ndarray]:
    """Feature normalisation, and the normalisation of the learned residual (the increments
    minus their linear base ``base``), from the training split (std floored, never 0)."""
    def mean_std(a: torch.Tensor):
        m = a.mean(0).numpy()
        sd = a.std(0).numpy()
        sd = np.where(sd > 1e-12, sd, 1.0)
        return m, sd

    im, isd = mean_std(s.z)
    om, osd = mean_std(s.o - linear_base(s.z, torch.from_numpy(base)))
    return {"in_mean": im, "in_std": isd, "out_mean": om, "out_std": osd}


@dataclass
class PhysicsTargets:
    """4-DOF increments on the training samples and on collocation points (precomputed:
    they depend on the inputs only, the residual on the network through its outputs)."""

    z: torch.Tensor
    o: torch.Tensor


def physics_targets(s: Split, model4: FourDof, collocation: float, seed: int) -> PhysicsTargets:
    g = torch.Generator().manual_seed(int(seed) + 7919)
    n = len(s)
    xs, us, fcs, gs, ps, mus = [s.x], [s.u], [s.fc], [s.gamma], [s.point], [s.mu]
    m = int(round(collocation * n))
    if m > 0:
        pick = torch.randint(0, n, (m,), generator=g)
        sx = s.x.std(0)
        x = s.x[pick] + 0.2 * sx * torch.randn(m, 8, generator=g, dtype=torch.float64)
        x[:, 0] = x[:, 0].abs()
        u = s.u[pick].clone()
        u[:, 0] += 0.05 * torch.randn(m, generator=g, dtype=torch.float64)
        u[:, 1] = (u[:, 1] * torch.rand(m, generator=g, dtype=torch.float64) * 1.5).clamp(min=0)
        scale = torch.rand(m, 1, generator=g, dtype=torch.float64) * 1.5
        fc = s.fc[pick] * scale
        gamma = s.gamma[pick] + 0.2 * torch.randn(m, generator=g, dtype=torch.float64)
        xs.append(x); us.append(u); fcs.append(fc); gs.append(gamma); ps.append(s.point[pick]); mus.append(s.mu[pick])
    x, u, fc, gamma, point, mu = (torch.cat(v) for v in (xs, us, fcs, gs, ps, mus))
    with torch.no_grad():
        xn = model4.step(x, u, fc, gamma, point, mu)
    return PhysicsTargets(z=features(x, u, fc, gamma, point, mu), o=increments(x, xn))


# --------------------------------------------------------------------------------------
# Losses
# --------------------------------------------------------------------------------------


def one_step_loss(model: GatherMLP, z: torch.Tensor, o: torch.Tensor,
                  scale: Optional[torch.Tensor] = None,
                  weights: Optional[torch.Tensor] = None) -> torch.Tensor:
    """Mean squared increment error, each output divided by ``scale`` (default: the model's
    output std) and, if given, weighted per output by ``weights`` (mean 1)."""
    e = ((model(z) - o) / (model.out_std if scale is None else scale)) ** 2
    return (e if weights is None else e * weights).mean()


def increment_scale(s: Split) -> torch.Tensor:
    """Per state (vx, vy, ψ, r, p, φ, X, Y), the std of its one-step increment over the split
    (whole increments, kinematic base included): the error scale of the rollout loss."""
    sd = s.o.std(0)
    return torch.where(sd > 1e-12, sd, torch.ones_like(sd))[list(STATE_TO_OUT)]


def rollout_loss(model: GatherMLP, s: Split, starts: torch.Tensor, horizon: int,
                 scale: torch.Tensor, weights: Optional[torch.Tensor] = None) -> torch.Tensor:
    """Mean squared state error over a ``horizon``-step rollout, per state divided by
    ``scale`` times the step number; ``weights`` (per output, as ``one_step_loss``) are
    applied to the matching states."""
    x = s.x[starts]
    total = 0.0
    ws = None if weights is None else weights[list(STATE_TO_OUT)]
    for j in range(horizon):
        k = starts + j
        x = model.step(x, s.u[k], s.fc[k], s.gamma[k], s.point[k], s.mu[k])
        err = ((x - s.x_next[k]) / (scale * (j + 1))) ** 2
        total = total + (err if ws is None else err * ws).mean()
    return total / horizon


def weight_norm(model: GatherMLP) -> torch.Tensor:
    """Σ‖W‖₂ (unsquared Frobenius norms of the expanded weight matrices, biases excluded)."""
    return sum(torch.linalg.norm(w) for w, _ in model.weights())


@torch.no_grad()
def evaluate(model: GatherMLP, s: Split, horizon: int = 4, max_windows: int = 2000) -> Dict[str, float]:
    """Validation numbers: normalised one-step MSE, one-step heading RMSE, rollout heading RMSE."""
    pred = model(s.z)
    mse = float((((pred - s.o) / model.out_std) ** 2).mean())
    hd = float(torch.sqrt(((pred[:, 5] - s.o[:, 5]) ** 2).mean()))
    w = s.win[:: max(1, len(s.win) // max_windows)]
    x = s.x[w]
    errs = []
    for j in range(horizon):
        k = w + j
        x = model.step(x, s.u[k], s.fc[k], s.gamma[k], s.point[k], s.mu[k])
        errs.append(x[:, 2] - s.x_next[k, 2])
    rh = float(torch.sqrt((torch.stack(errs) ** 2).mean())) if len(w) else float("nan")
    return {"mse": mse, "heading_rmse_rad": hd, "rollout_heading_rmse_rad": rh}


# --------------------------------------------------------------------------------------
# The loop
# --------------------------------------------------------------------------------------


def fit(
    model: GatherMLP,
    loss_fn: Callable[[torch.Tensor, torch.Tensor], Tuple[torch.Tensor, Dict[str, float]]],
    n_samples: int,
    n_windows: int,
    val: Callable[[], Dict[str, float]],
    *,
    epochs: int,
    batch: int,
    rollout_batch: int,
    lr: float,
    lr_final: float,
    seed: int,
    desc: str,
    progress: bool,
    checkpoint: Optional[Callable[[int, bool], None]] = None,
    checkpoint_every: int = 10,
    select: str = "mse",
) -> Dict[str, List[float]]:
    """Adam with a cosine learning-rate decay; keeps the parameters of the best validation
    ``select`` value. ``loss_fn(sample_idx, window_idx)`` returns (loss, parts)."""
    torch.manual_seed(seed)
    rng = np.random.default_rng(seed)
    opt = torch.optim.Adam(model.parameters(), lr=lr)
    steps_per_epoch = max(1, math.ceil(n_samples / batch))
    total = epochs * steps_per_epoch
    sched = torch.optim.lr_scheduler.LambdaLR(
        opt, lambda i: (lr_final + 0.5 * (lr - lr_final) * (1 + math.cos(math.pi * min(i, total) / total))) / lr)
    hist: Dict[str, List[float]] = {}
    best, best_state = math.inf, None
    bar = None
    if progress:
        from tqdm import tqdm
        bar = tqdm(total=epochs, desc=desc, unit="epoch", leave=False, dynamic_ncols=True, disable=None)
    try:
        for ep in range(epochs):
            perm = torch.from_numpy(rng.permutation(n_samples))
            sums: Dict[str, float] = {}
            for b in range(steps_per_epoch):
                idx = perm[b * batch:(b + 1) * batch]
                widx = torch.from_numpy(rng.integers(0, n_windows, rollout_batch)) if n_windows else None
                loss, parts = loss_fn(idx, widx)
                opt.zero_grad(set_to_none=True)
                loss.backward()
                opt.step()
                sched.step()
                for k, v in parts.items():
                    sums[k] = sums.get(k, 0.0) + v
            for k, v in sums.items():
                hist.setdefault(f"train_{k}", []).append(v / steps_per_epoch)
            v = val()
            for k, x in v.items():
                hist.setdefault(f"val_{k}", []).append(x)
            is_best = v[select] < best
            if is_best:
                best = v[select]
                best_state = model.theta.detach().clone()
            if checkpoint is not None and ((ep + 1) % checkpoint_every == 0 or ep + 1 == epochs or is_best):
                checkpoint(ep + 1, is_best)
            if bar is not None:
                bar.set_postfix(loss=f"{sums.get('total', 0) / steps_per_epoch:.3g}", val=f"{v[select]:.3g}")
                bar.update(1)
    finally:
        if bar is not None:
            bar.close()
    if best_state is not None:
        with torch.no_grad():
            model.theta.copy_(best_state)
    hist["best_epoch"] = [float(int(np.argmin(hist[f"val_{select}"])) + 1)]
    return hist


def output_scale(model: GatherMLP, tr: Split, how: str) -> torch.Tensor:
    """Per output, the error scale of the one-step (data and physics) loss: ``increment``
    the std of the whole increment, ``residual`` the std of the learned part (the model's
    out_std), ``geometric`` their geometric mean (the default: measured best, see
    docs/surrogates.md)."""
    sd = tr.o.std(0)
    sd = torch.where(sd > 1e-12, sd, torch.ones_like(sd))
    if how == "increment":
        return sd
    if how == "residual":
        return model.out_std
    if how == "geometric":
        return torch.sqrt(sd * model.out_std)
    raise TrainError(f"loss_scale = {how!r}: must be one of {', '.join(LOSS_SCALES)}")


def supervised_loss(model: GatherMLP, tr: Split, phys: Optional[PhysicsTargets], w_data: float,
                    w_rollout: float, w_physics: float, horizon: int, batch: int,
                    loss_scale: str = "geometric", weights: Optional[torch.Tensor] = None):
    """The data + rollout + physics loss used by ``train`` and PicoPINN retraining
    (``weights``: per output, see ``one_step_loss``)."""
    n_phys = 0 if phys is None else int(phys.z.shape[0])
    scale = increment_scale(tr)
    oscale = output_scale(model, tr, loss_scale)
    g = torch.Generator().manual_seed(12345)

    def loss_fn(idx, widx):
        parts: Dict[str, float] = {}
        total = torch.zeros((), dtype=torch.float64)
        if w_data > 0:
            l = one_step_loss(model, tr.z[idx], tr.o[idx], oscale, weights)
            total = total + w_data * l
            parts["data"] = float(l.detach())
        if w_rollout > 0 and widx is not None and len(tr.win):
            l = rollout_loss(model, tr, tr.win[widx], horizon, scale, weights)
            total = total + w_rollout * l
            parts["rollout"] = float(l.detach())
        if w_physics > 0 and n_phys:
            pi = torch.randint(0, n_phys, (batch,), generator=g)
            l = one_step_loss(model, phys.z[pi], phys.o[pi], oscale, weights)
            total = total + w_physics * l
            parts["physics"] = float(l.detach())
        parts["total"] = float(total.detach())
        return total, parts

    return loss_fn


def plot_curves(hist: Mapping[str, Sequence[float]], path: Path, title: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, 2, figsize=(9, 3.4), dpi=80)
    for k, v in hist.items():
        if k.startswith("train_"):
            ax[0].semilogy(np.arange(1, len(v) + 1), v, label=k[6:])
    ax[0].set_xlabel("epoch"); ax[0].set_ylabel("training loss (normalised)"); ax[0].legend(fontsize=8)
    for k in ("val_heading_rmse_rad", "val_rollout_heading_rmse_rad"):
        if k in hist:
            ax[1].semilogy(np.arange(1, len(hist[k]) + 1), hist[k], label=k[4:])
    ax[1].set_xlabel("epoch"); ax[1].set_ylabel("validation (rad)"); ax[1].legend(fontsize=8)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    plt.close(fig)


def prepare(ds: Dataset, horizon: int):
    tr = Split.of(ds.subset("train"), horizon)
    va = Split.of(ds.subset("val"), horizon)
    if len(tr) == 0 or len(va) == 0:
        raise DatasetError(f"{ds.path}: the train and val splits must not be empty")
    return tr, va


def train_teacher(ds: Dataset, cfg: TrainConfig, out: Path, progress: bool = True) -> Tuple[GatherMLP, Dict[str, Any]]:
    """Train the teacher PINN on ``ds``; writes checkpoints and the curve figure into ``out``."""
    cfg.validate()
    torch_threads()
    torch.manual_seed(cfg.seed)
    t0 = time.time()
    tr, va = prepare(ds, cfg.horizon)
    dt = float(ds.manifest["dt"])
    model4 = FourDof.from_params(load_params_dict(ds.param_set)["target"], dt=dt)
    base = physics_base(dt, model4.mass, model4.iz, cfg.base)
    stats = stats_of(tr, base)
    model = dense_mlp(cfg.layers, stats, cfg.seed, dt, base)
    phys = physics_targets(tr, model4, cfg.collocation, cfg.seed) if cfg.w_physics > 0 else None
    out = Path(out)
    ckdir = out / "checkpoints"
    ckdir.mkdir(parents=True, exist_ok=True)

    def checkpoint(epoch: int, best: bool) -> None:
        state = {"epoch": epoch, "theta": model.theta.detach().clone(), "config": dataclasses.asdict(cfg)}
        torch.save(state, ckdir / "last.pt")
        if best:
            torch.save(state, ckdir / "best.pt")

    hist = fit(
        model,
        supervised_loss(model, tr, phys, cfg.w_data, cfg.w_rollout, cfg.w_physics, cfg.horizon, cfg.batch,
                        cfg.loss_scale),
        len(tr), len(tr.win), lambda: evaluate(model, va, cfg.horizon),
        epochs=cfg.epochs, batch=cfg.batch, rollout_batch=cfg.rollout_batch, lr=cfg.lr,
        lr_final=cfg.lr_final, seed=cfg.seed, desc="train", progress=progress,
        checkpoint=checkpoint, checkpoint_every=cfg.checkpoint_every,
    )
    plot_curves(hist, out / "train_curves.png", f"teacher PINN {ds.param_set} ({model.param_count} params)")
    with open(out / "train_history.json", "w") as fh:
        json.dump(hist, fh)
    info = {"val": evaluate(model, va, cfg.horizon), "seconds": time.time() - t0,
            "params": model.param_count, "config": dataclasses.asdict(cfg)}
    return model, info
