"""``picopit eval-surrogates``: the 4-DOF model, the teacher PINN and PicoPINN on held-out
test episodes.

- One step: from every recorded x_k with the recorded u_k and contact, the error of the
  predicted x_{k+1} (heading ψ wrapped, yaw rate r, roll φ, position, velocities).
- Open loop: 2 s (40 steps) rollouts of each model on its own predictions with the recorded
  inputs and contacts (the body-frame contact force follows the predicted heading), from a
  start every ``stride`` steps of every test episode; RMSE over all rollout steps and the
  error at the end, and the speed error at the end. The same end errors over the rollouts
  that start sliding (body slip |atan2(v_y, |v_x|)| above ``SLIDE_SLIP``, faster than
  ``SLIDE_SPEED``): a spun target, whose free slide the planner predicts when it decides
  whether to let go (docs/RESULTS.md). For those, also the error of the stopping point the
  planner's S_post row takes from the state at 2 s (the slide carried on at
  ``stop_decel_fraction`` · μ g along the velocity, on a straight road): its RMSE and median, and its
  mean reach bias (predicted minus true distance of the stop from the rollout's start;
  positive: the model has the target slide further).

Every model is given the episode's road μ: the Rust ``FourDofTarget`` at construction, the
learned models (format version 3, μ is their last feature) through ``SurrogateModel.mu``. The
learned models run through the Rust ``SurrogateModel`` when the extension has it, otherwise
through the PyTorch implementation of the same file (``backend`` in the results says which).
Timings: microseconds per single-state ``step`` call from Python (including the binding's
overhead), and per ``step_jac`` where the backend has it.
"""

from __future__ import annotations

import functools
import json
import math
import time
from pathlib import Path
from typing import Any, Callable, Dict, List, Mapping, Optional, Tuple

import numpy as np
import torch

from . import _core
from .datagen import Dataset, windows
from .surrogate_nn import GatherMLP, load_model
from .train import torch_threads

MODELS = ("4dof", "pinn", "picopinn")
SLIDE_SLIP = 0.3
"""Body slip angle (rad) above which a rollout start counts as sliding."""
SLIDE_SPEED = 1.0
"""Speed (m/s) above which a rollout start counts as sliding."""


def _speed(x: np.ndarray) -> np.ndarray:
    return np.hypot(x[..., 0], x[..., 1])


def sliding(x: np.ndarray) -> np.ndarray:
    """Which states (rows of ``x``, target state order) slide: slip above ``SLIDE_SLIP``
    and speed above ``SLIDE_SPEED``."""
    slip = np.abs(np.arctan2(x[..., 1], np.abs(x[..., 0])))
    return (slip > SLIDE_SLIP) & (_speed(x) > SLIDE_SPEED)


PLANNER_GRAVITY = 9.81
"""g (m/s²) in the planner's stopping-distance model (``crates/planner``)."""


@functools.lru_cache(maxsize=1)
def planner_stop_decel_fraction() -> float:
    """The planner's default ``stop_decel_fraction``: its S_post slide decelerates at this
    fraction of μ g (read once from a default planner)."""
    from . import _toml  # tomllib, or tomli before Python 3.11

    return float(_toml.loads(_core.Planner().settings_toml())["stop_decel_fraction"])


def stop_points(x: np.ndarray, mu: np.ndarray, fraction: float) -> np.ndarray:
    """Where targets in states ``x`` (B, 8) come to rest sliding on at ``fraction`` · μ g
    along their velocity (the planner's stopping point on a straight road): (B, 2) world X, Y."""
    c, s = np.cos(x[:, 2]), np.sin(x[:, 2])
    v = np.stack([x[:, 0] * c - x[:, 1] * s, x[:, 0] * s + x[:, 1] * c], axis=1)
    decel = fraction * np.maximum(mu, 0.05) * PLANNER_GRAVITY  # the planner's floor on μ too
    return x[:, 6:8] + v * (np.hypot(v[:, 0], v[:, 1]) / (2.0 * decel))[:, None]


def wrap_angles(a: np.ndarray) -> np.ndarray:
    """Angles (any shape) wrapped to [−π, π]."""
    return np.arctan2(np.sin(a), np.cos(a))


def _rms(v: np.ndarray) -> float:
    """Root mean square (NaN for no values)."""
    return float(np.sqrt(np.mean(v ** 2))) if v.size else float("nan")


def _errors(pred: np.ndarray, true: np.ndarray) -> Dict[str, float]:
    e = pred - true
    return {
        "heading_rmse_rad": _rms(wrap_angles(e[..., 2])),
        "yaw_rate_rmse_radps": _rms(e[..., 3]),
        "roll_rmse_rad": _rms(e[..., 5]),
        "position_rmse_m": _rms(np.hypot(e[..., 6], e[..., 7])),
        "vx_rmse_mps": _rms(e[..., 0]),
        "vy_rmse_mps": _rms(e[..., 1]),
    }


class _Batched:
    """A model evaluated on batches: ``step(x, u, fc, gamma, point, mu) -> x_next`` (all (B, …))."""

    def __init__(self, name: str, step: Callable, params: int, backend: str, single: Callable,
                 single_jac: Optional[Callable] = None):
        self.name, self.step, self.params, self.backend = name, step, params, backend
        self.single, self.single_jac = single, single_jac


def _fourdof(param_set: str) -> _Batched:
    cache: Dict[float, Any] = {}

    def model(mu: float):
        if mu not in cache:
            cache[mu] = _core.FourDofTarget(param_set, mu=float(mu))
        return cache[mu]

    def step(x, u, fc, gamma, point, mu):
        out = np.empty_like(x)
        for i in range(len(x)):
            out[i] = model(float(mu[i])).step(x[i], u[i], fc[i], float(gamma[i]), point[i])
        return out

    m0 = model(0.9)
    return _Batched("4dof", step, int(m0.param_count), "rust", m0.step, m0.step_jac)


def _learned(name: str, path: Path) -> _Batched:
    cls = getattr(_core, "SurrogateModel", None)
    if cls is not None:
        rm = cls(str(path))

        def step(x, u, fc, gamma, point, mu):
            out = np.empty_like(x)
            for i in range(len(x)):
                if rm.mu != mu[i]:
                    rm.mu = float(mu[i])  # one road per episode: set when it changes
                out[i] = rm.step(x[i], u[i], fc[i], float(gamma[i]), point[i])
            return out

        return _Batched(name, step, int(rm.param_count), "rust", rm.step, rm.step_jac)
    tm, meta = load_model(path)

    mu0 = float(meta["mu_default"])

    @torch.no_grad()
    def tstep(x, u, fc, gamma, point, mu):
        t = lambda a: torch.from_numpy(np.ascontiguousarray(a, dtype=np.float64))  # noqa: E731
        return tm.step(t(x), t(u), t(fc), t(gamma), t(point), t(mu)).numpy()

    def single(x, u, fc, gamma, point):
        return tstep(x[None], u[None], fc[None], np.array([gamma]), point[None], np.array([mu0]))[0]

    return _Batched(name, tstep, tm.param_count, "torch", single)


def _time_calls(fn: Optional[Callable], a: Mapping[str, np.ndarray], n: int = 2000) -> Optional[float]:
    if fn is None:
        return None
    k = min(n, len(a["x"]))
    args = [(a["x"][i], a["u"][i], a["fc"][i], float(a["gamma"][i]), a["point"][i]) for i in range(k)]
    fn(*args[0])
    t0 = time.perf_counter()
    for arg in args:
        fn(*arg)
    return (time.perf_counter() - t0) / k * 1e6


def evaluate_model(m: _Batched, a: Mapping[str, np.ndarray], horizon: int, stride: int) -> Dict[str, Any]:
    t0 = time.perf_counter()
    pred = m.step(a["x"], a["u"], a["fc"], a["gamma"], a["point"], a["mu"])
    one = _errors(pred, a["x_next"])
    contact = a["fc"][:, 0] > 0
    one_contact = _errors(pred[contact], a["x_next"][contact])
    one_free = _errors(pred[~contact], a["x_next"][~contact])
    starts = windows(a, horizon)
    starts = starts[a["step"][starts] % stride == 0]
    x = a["x"][starts].copy()
    errs = np.empty((horizon, len(starts), 8))
    for j in range(horizon):
        k = starts + j
        x = m.step(x, a["u"][k], a["fc"][k], a["gamma"][k], a["point"][k], a["mu"][k])
        errs[j] = x - a["x_next"][k]
    seconds = time.perf_counter() - t0
    roll = _errors(errs, np.zeros_like(errs))
    end = _errors(errs[-1], np.zeros_like(errs[-1]))
    per_step_heading = np.sqrt(np.mean(wrap_angles(errs[..., 2]) ** 2, axis=1))
    res: Dict[str, Any] = {"params": m.params, "backend": m.backend}
    res.update(one)
    res["contact_heading_rmse_rad"] = one_contact["heading_rmse_rad"]
    res["free_heading_rmse_rad"] = one_free["heading_rmse_rad"]
    res.update({f"rollout_{k}": v for k, v in roll.items()})
    res["rollout_final_heading_rmse_rad"] = end["heading_rmse_rad"]
    res["rollout_final_position_rmse_m"] = end["position_rmse_m"]
    true_end = a["x_next"][starts + horizon - 1]
    dv = _speed(x) - _speed(true_end)
    res["rollout_final_speed_rmse_mps"] = _rms(dv)
    slide = sliding(a["x"][starts])
    end_slide = _errors(errs[-1][slide], np.zeros_like(errs[-1][slide]))
    res["sliding_windows"] = int(slide.sum())
    res["sliding_final_heading_rmse_rad"] = end_slide["heading_rmse_rad"]
    res["sliding_final_position_rmse_m"] = end_slide["position_rmse_m"]
    res["sliding_final_speed_rmse_mps"] = _rms(dv[slide])
    f = planner_stop_decel_fraction()
    mu0 = a["mu"][starts][slide]
    pred_stop, true_stop = stop_points(x[slide], mu0, f), stop_points(true_end[slide], mu0, f)
    origin = a["x"][starts][slide][:, 6:8]
    stop_err = np.hypot(*(pred_stop - true_stop).T)
    res["sliding_stop_point_rmse_m"] = _rms(stop_err)
    res["sliding_stop_point_median_m"] = float(np.median(stop_err)) if stop_err.size else float("nan")
    reach = np.hypot(*(pred_stop - origin).T) - np.hypot(*(true_stop - origin).T)
    res["sliding_stop_reach_bias_m"] = float(reach.mean()) if reach.size else float("nan")
    res["rollout_heading_rmse_by_step"] = per_step_heading.tolist()
    res["rollout_windows"] = int(len(starts))
    res["eval_seconds"] = seconds
    res["step_us"] = _time_calls(m.single, a, 2000 if m.backend == "rust" else 200)
    res["step_jac_us"] = _time_calls(m.single_jac, a)
    return res


def run(ds: Dataset, pinn: Path, picopinn: Path, horizon: int = 40, stride: int = 10,
        progress: bool = True) -> Dict[str, Any]:
    torch_threads()
    a = ds.subset("test")
    if len(a["x"]) == 0:
        from .datagen import DatasetError
        raise DatasetError(f"{ds.path}: the test split is empty")
    models = [_fourdof(ds.param_set), _learned("pinn", Path(pinn)), _learned("picopinn", Path(picopinn))]
    out: Dict[str, Any] = {"models": {}, "param_set": ds.param_set, "data_hash": ds.data_hash,
                           "test_samples": int(len(a["x"])),
                           "test_episodes": int(len(np.unique(a["episode"]))),
                           "contact_samples": int((a["fc"][:, 0] > 0).sum()),
                           "horizon_steps": horizon, "horizon_s": horizon * float(ds.manifest["dt"]),
                           "stride": stride}
    bar = None
    if progress:
        from tqdm import tqdm
        bar = tqdm(total=len(models), desc="eval-surrogates", unit="model", leave=False, disable=None)
    try:
        for m in models:
            out["models"][m.name] = evaluate_model(m, a, horizon, stride)
            if bar is not None:
                bar.update(1)
    finally:
        if bar is not None:
            bar.close()
    return out


def markdown(res: Mapping[str, Any]) -> str:
    rows = [
        ("parameters", "params", "{:d}"),
        ("one-step heading ψ RMSE (mrad)", "heading_rmse_rad", "m"),
        ("  in contact (mrad)", "contact_heading_rmse_rad", "m"),
        ("  free motion (mrad)", "free_heading_rmse_rad", "m"),
        ("one-step yaw rate RMSE (mrad/s)", "yaw_rate_rmse_radps", "m"),
        ("one-step roll φ RMSE (mrad)", "roll_rmse_rad", "m"),
        ("one-step position RMSE (mm)", "position_rmse_m", "m"),
        ("2 s rollout heading RMSE (rad)", "rollout_heading_rmse_rad", "{:.4f}"),
        ("2 s rollout yaw rate RMSE (rad/s)", "rollout_yaw_rate_rmse_radps", "{:.4f}"),
        ("2 s rollout roll RMSE (mrad)", "rollout_roll_rmse_rad", "m"),
        ("2 s rollout position RMSE (m)", "rollout_position_rmse_m", "{:.3f}"),
        ("heading error at 2 s, RMSE (rad)", "rollout_final_heading_rmse_rad", "{:.4f}"),
        ("position error at 2 s, RMSE (m)", "rollout_final_position_rmse_m", "{:.3f}"),
        ("speed error at 2 s, RMSE (m/s)", "rollout_final_speed_rmse_mps", "{:.3f}"),
        ("rollouts starting in a slide (slip > 0.3 rad)", "sliding_windows", "{:d}"),
        ("  heading error at 2 s, RMSE (rad)", "sliding_final_heading_rmse_rad", "{:.4f}"),
        ("  position error at 2 s, RMSE (m)", "sliding_final_position_rmse_m", "{:.3f}"),
        ("  speed error at 2 s, RMSE (m/s)", "sliding_final_speed_rmse_mps", "{:.3f}"),
        ("  planner's stopping point, error RMSE (m)", "sliding_stop_point_rmse_m", "{:.2f}"),
        ("  … median error (m)", "sliding_stop_point_median_m", "{:.2f}"),
        ("  … mean reach bias, predicted − true (m)", "sliding_stop_reach_bias_m", "{:+.2f}"),
        ("step from Python (µs/call)", "step_us", "{:.1f}"),
        ("step+Jacobian from Python (µs/call)", "step_jac_us", "{:.1f}"),
        ("backend", "backend", "{}"),
    ]
    names = [n for n in MODELS if n in res["models"]]
    lines = ["| metric | " + " | ".join(names) + " |", "|---|" + "---|" * len(names)]
    for label, key, fmt in rows:
        cells = []
        for n in names:
            v = res["models"][n].get(key)
            if v is None:
                cells.append("–")
            elif fmt == "m":
                cells.append(f"{1e3 * v:.2f}")
            else:
                cells.append(fmt.format(v))
        lines.append(f"| {label} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def plot(res: Mapping[str, Any], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, 2, figsize=(9, 3.4), dpi=80)
    dt = res["horizon_s"] / res["horizon_steps"]
    for n, m in res["models"].items():
        h = np.array(m["rollout_heading_rmse_by_step"])
        ax[0].plot(dt * np.arange(1, len(h) + 1), h, label=f"{n} ({m['params']} p.)")
    ax[0].set_xlabel("open-loop time (s)"); ax[0].set_ylabel("heading RMSE (rad)")
    ax[0].set_title(f"{res['param_set']}: open-loop rollouts", fontsize=9); ax[0].legend(fontsize=8)
    keys = [("heading_rmse_rad", "ψ"), ("contact_heading_rmse_rad", "ψ contact"),
            ("free_heading_rmse_rad", "ψ free"), ("roll_rmse_rad", "φ")]
    w = 0.25
    for i, (n, m) in enumerate(res["models"].items()):
        ax[1].bar(np.arange(len(keys)) + (i - 1) * w, [1e3 * m[k] for k, _ in keys], w, label=n)
    ax[1].set_xticks(np.arange(len(keys)), [l for _, l in keys])
    ax[1].set_ylabel("one-step RMSE (mrad)"); ax[1].set_yscale("log"); ax[1].legend(fontsize=8)
    ax[1].set_title("one step (0.05 s)", fontsize=9)
    fig.tight_layout()
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    plt.close(fig)
