"""``picopit datagen``: collision data for the learned target surrogates, from the plant.

Each episode places the bullet so that, driving straight, its front inner corner meets the
target's side at a sampled station over the rear quarter and side, at a sampled contact angle
and speed difference, after a sampled free-motion lead-in. Through the contact the bullet
holds a quarter turn into the target with drive torque, then steers away and brakes. The
target is a car in gear (its powertrain: engine braking, a stall that holds the driven axle
once the spin turns it backwards). Its driver holds the initial speed with the throttle
until the contact (as ``sim::TargetDriver``), then does one of: nothing (an uncontrolled,
slightly steered car), lane keeping, braking after a reaction time, counter-steering
against the yaw rate after a reaction time. Episodes run on until the target has settled or
the episode time is over, so the data hold the free motion before the hit, the contact, the
spin-out after it and the stalled target rolling backwards to rest.

Recorded at the MPC step (0.05 s), per sample k: the target state x_k, the target driver's
command u_k = [δ, T_b] held over [t_k, t_k + dt] (T_b < 0: the throttle), the contact
averaged over that interval (impulse / time; γ and the point of action weighted by the normal
impulse, zeros when there was no contact), the road μ, and x_{k+1}. Episodes are split into train / val / test with the
seed. Output: ``dataset.npz`` and ``manifest.json`` (sampling configuration, counts, seed,
command, SHA-256 content hash of the arrays).
"""

from __future__ import annotations

import dataclasses
import datetime as _dt
import hashlib
import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Dict, List, Mapping, Optional, Sequence, Tuple

import numpy as np

from . import _core, load_params_dict
from .physics import AIR_DENSITY, GRAVITY

THROTTLE_GAIN = 1.0  # 1/s, the speed loop of sim::TargetDriver (THROTTLE_GAIN)

DT = 0.05
DRIVER_MODES = ("none", "lane_keep", "brake", "counter_steer")
SPLITS = ("train", "val", "test")
#: Arrays of a dataset file, with their trailing shape.
ARRAYS: Dict[str, Tuple[int, ...]] = {
    "x": (8,), "u": (2,), "fc": (2,), "gamma": (), "point": (2,), "x_next": (8,),
    "mu": (), "episode": (), "step": (), "split": (),
}


class DatasetError(ValueError):
    """A bad datagen setting or dataset file; the message names the field."""


@dataclass
class DatagenConfig:
    """Sampling of the collision episodes (SI units; angles in degrees only here, at the edge)."""

    params: str = "full_size"
    episodes: int = 1200
    seed: int = 0
    target_speed: Tuple[float, float] = (5.0, 30.0)
    speed_diff: Tuple[float, float] = (0.0, 6.0)
    contact_angle_deg: Tuple[float, float] = (5.0, 35.0)
    station: Tuple[float, float] = (0.0, 0.5)
    """Where the bullet's corner meets the target's side, as a fraction of the target's
    length measured from its rear bumper (0: the rear corner, 0.5: mid-side)."""
    mu: Tuple[float, float] = (0.15, 1.0)
    lead_in: Tuple[float, float] = (0.3, 1.2)
    """Free motion before the planned contact (s)."""
    after: float = 3.5
    """Time simulated after the planned contact (s), unless the target settles first."""
    pit_steer: Tuple[float, float] = (0.0, 0.15)
    push_time: Tuple[float, float] = (0.1, 0.6)
    reaction_time: Tuple[float, float] = (0.2, 0.8)
    split_fractions: Tuple[float, float, float] = (0.7, 0.15, 0.15)

    @classmethod
    def for_params(cls, params: str, **kw) -> "DatagenConfig":
        """Defaults of a built-in set: half scale drives 1.5–4 m/s with speed differences
        0–3 m/s (the paper's half-scale trials closed at 0.2–1.2 m/s)."""
        base: Dict[str, Any] = {}
        if params == "half_scale":
            base.update(target_speed=(1.5, 4.0), speed_diff=(0.0, 3.0))
        base.update({k: v for k, v in kw.items() if v is not None})
        return cls(params=params, **base).validate()

    def validate(self) -> "DatagenConfig":
        def bad(name, v, why):
            return DatasetError(f"{name} = {v!r}: {why}")

        if isinstance(self.episodes, bool) or not isinstance(self.episodes, int) or self.episodes < 3:
            raise bad("episodes", self.episodes, "must be an integer >= 3 (one per split at least)")
        if isinstance(self.seed, bool) or not isinstance(self.seed, int) or self.seed < 0:
            raise bad("seed", self.seed, "must be a non-negative integer")
        for name in ("target_speed", "speed_diff", "contact_angle_deg", "station", "mu", "lead_in",
                     "pit_steer", "push_time", "reaction_time"):
            lo, hi = getattr(self, name)
            if not (math.isfinite(lo) and math.isfinite(hi) and 0 <= lo <= hi):
                raise bad(name, (lo, hi), "must be a finite range 0 <= lo <= hi")
        if not 0 < self.target_speed[0]:
            raise bad("target_speed", self.target_speed, "must be > 0")
        if not 0 < self.mu[0] <= self.mu[1] <= 1.5:
            raise bad("mu", self.mu, "must lie in (0, 1.5]")
        if not self.contact_angle_deg[1] < 80:
            raise bad("contact_angle_deg", self.contact_angle_deg, "must stay below 80 deg")
        if not 0 < self.after <= 30:
            raise bad("after", self.after, "must lie in (0, 30] s")
        f = self.split_fractions
        if len(f) != 3 or min(f) <= 0 or abs(sum(f) - 1) > 1e-9:
            raise bad("split_fractions", f, "three positive fractions summing to 1")
        return self


# --------------------------------------------------------------------------------------
# One episode
# --------------------------------------------------------------------------------------


def _rot(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s], [s, c]])


def _wrap(a: float) -> float:
    return math.atan2(math.sin(a), math.cos(a))


@dataclass
class EpisodeSpec:
    target_speed: float
    speed_diff: float
    contact_angle: float
    station: float
    side: float
    mu: float
    lead_in: float
    after: float
    pit_steer: float
    push_time: float
    driver: str
    reaction_time: float
    driver_gain: float
    drift_steer: float
    heading: float


def sample_episode(cfg: DatagenConfig, rng: np.random.Generator) -> EpisodeSpec:
    u = lambda r: float(rng.uniform(*r))  # noqa: E731
    spec = EpisodeSpec(
        target_speed=u(cfg.target_speed), speed_diff=u(cfg.speed_diff),
        contact_angle=math.radians(u(cfg.contact_angle_deg)), station=u(cfg.station),
        side=float(rng.choice([-1.0, 1.0])), mu=u(cfg.mu), lead_in=u(cfg.lead_in), after=float(cfg.after),
        pit_steer=u(cfg.pit_steer), push_time=u(cfg.push_time),
        driver=str(rng.choice(DRIVER_MODES)), reaction_time=u(cfg.reaction_time),
        driver_gain=float(rng.uniform(0.6, 1.4)), drift_steer=float(rng.uniform(-0.02, 0.02)),
        heading=float(rng.uniform(-math.pi, math.pi)),
    )
    return spec


def initial_states(spec: EpisodeSpec, pb: Mapping[str, Any], pt: Mapping[str, Any]) -> Tuple[np.ndarray, np.ndarray]:
    """Bullet and target ``[X, Y, yaw, vx, vy, r]`` such that the bullet, driving straight,
    reaches the planned contact after ``lead_in`` seconds (target at the origin, heading
    ``spec.heading``)."""
    side = spec.side
    beta = -side * spec.contact_angle  # bullet heading relative to the target, toward it
    rear_x = -(pt["length"] - pt["cg_to_front"])
    corner_t = np.array([rear_x + spec.station * pt["length"], side * (0.5 * pt["width"] + 0.02)])
    corner_b = np.array([pb["cg_to_front"], -side * 0.5 * pb["width"]])
    cg_b = corner_t - _rot(beta) @ corner_b
    vb = spec.target_speed + spec.speed_diff
    v_rel = vb * np.array([math.cos(beta), math.sin(beta)]) - np.array([spec.target_speed, 0.0])
    start_b = cg_b - v_rel * spec.lead_in
    R = _rot(spec.heading)
    pos_b = R @ start_b
    xb = np.array([pos_b[0], pos_b[1], spec.heading + beta, vb, 0.0, 0.0])
    xt = np.array([0.0, 0.0, spec.heading, spec.target_speed, 0.0, 0.0])
    return xb, xt


@dataclass
class _Throttle:
    """The target driver's speed-holding throttle (``sim::TargetDriver``): the wheel torque
    ``T_ff + k m R_w (v0 − vx)``, clamped to the drive, with ``T_ff`` balancing engine
    braking, rolling resistance and drag at ``v0``."""

    v0: float
    hold: float
    gain: float
    max: float

    @classmethod
    def of(cls, pt: Mapping[str, Any], v0: float) -> "_Throttle":
        pw = pt.get("powertrain")
        engine = pt["gear_ratio"] * pw["engine_drag_torque"] if pw else 0.0
        resist = pt["rolling_resistance"] * pt["mass"] * GRAVITY + 0.5 * AIR_DENSITY * pt["drag_area"] * v0 * v0
        return cls(v0, engine + pt["wheel_radius"] * resist, THROTTLE_GAIN * pt["mass"] * pt["wheel_radius"],
                   pt["drive_efficiency"] * pt["gear_ratio"] * pt["drive_torque_max"])

    def wheel_torque(self, vx: float) -> float:
        return float(np.clip(self.hold + self.gain * (self.v0 - vx), 0.0, self.max))


@dataclass
class _Drive:
    mass: float
    gain: float  # eta i_g / R_w
    tmin: float
    tmax: float
    brake_max: float

    def torque(self, v_des: float, v: float) -> float:
        return float(np.clip(self.mass * 1.5 * (v_des - v) / self.gain, self.tmin, self.tmax))


def run_episode(spec: EpisodeSpec, params: str, pb: Mapping[str, Any], pt: Mapping[str, Any]
                ) -> Dict[str, np.ndarray]:
    """Simulate one episode; returns the per-step arrays (x, u, fc, gamma, point, x_next)."""
    plant = _core.Plant(params, mu=spec.mu)
    xb0, xt0 = initial_states(spec, pb, pt)
    plant.reset(xb0, xt0)
    plant.take_contact_average()
    drive = _Drive(pb["mass"], pb["drive_efficiency"] * pb["gear_ratio"] / pb["wheel_radius"],
                   pb["drive_torque_min"], pb["drive_torque_max"], pb["brake_torque_max"])
    vb_des = xb0[3]
    throttle = _Throttle.of(pt, float(xt0[3]))
    n_max = int(round((spec.lead_in + spec.after) / DT))
    y0 = np.array(xt0[:2])
    psi0 = xt0[2]
    first_contact: Optional[float] = None
    rows_x, rows_u, rows_c, rows_xn = [], [], [], []
    settled_for = 0.0
    for k in range(n_max):
        t = k * DT
        xt = plant.target_state()
        xb = plant.bullet_state()
        # Bullet: straight at speed, then the quarter turn with drive, then away and brake.
        if first_contact is None:
            b_cmd = (0.0, drive.torque(vb_des, xb[3]), 0.0)
        elif t < first_contact + spec.push_time:
            b_cmd = (-spec.side * spec.pit_steer, drive.torque(vb_des, xb[3]), 0.0)
        else:
            b_cmd = (spec.side * 0.1, 0.0, 0.8 * drive.brake_max)
        # Target driver.
        reacted = first_contact is not None and t >= first_contact + spec.reaction_time
        g = spec.driver_gain
        # Until the contact the driver holds its speed with the throttle (T_b < 0).
        steer, brake = 0.0, (-throttle.wheel_torque(xt[0]) if first_contact is None else 0.0)
        if spec.driver == "none":
            steer = spec.drift_steer
        elif spec.driver == "lane_keep":
            lat = (_rot(-psi0) @ (xt[6:8] - y0))[1]
            steer = float(np.clip(g * (-0.05 * lat - 0.6 * _wrap(xt[2] - psi0) - 0.1 * xt[3]), -0.15, 0.15))
        elif spec.driver == "brake":
            brake = (0.2 + 0.8 * (g - 0.6) / 0.8) * pt["brake_torque_max"] if reacted else 0.0
        elif spec.driver == "counter_steer":
            steer = float(np.clip(-0.25 * g * xt[3], -0.3, 0.3)) if reacted else 0.0
        plant.set_commands(b_cmd[0], b_cmd[1], steer, brake, b_cmd[2])
        plant.advance(DT)
        c = plant.take_contact_average()
        xn = plant.target_state()
        rows_x.append(xt)
        rows_u.append((steer, brake))
        if c is None:
            rows_c.append((0.0, 0.0, 0.0, 0.0, 0.0))
        else:
            if first_contact is None:
                first_contact = t
            rows_c.append((c["fc"][0], c["fc"][1], c["gamma"], c["point_in_target"][0], c["point_in_target"][1]))
        rows_xn.append(xn)
        # Stop once the target has come to rest after the contact window.
        if first_contact is not None and t > first_contact + 1.0 and c is None:
            if math.hypot(xn[0], xn[1]) < 0.3 and abs(xn[3]) < 0.05:
                settled_for += DT
                if settled_for >= 0.5:
                    break
    c = np.array(rows_c, dtype=np.float64)
    out = {
        "x": np.array(rows_x, dtype=np.float64), "u": np.array(rows_u, dtype=np.float64),
        "fc": c[:, 0:2].copy(), "gamma": c[:, 2].copy(), "point": c[:, 3:5].copy(),
        "x_next": np.array(rows_xn, dtype=np.float64),
    }
    return out


# --------------------------------------------------------------------------------------
# The dataset
# --------------------------------------------------------------------------------------


def content_hash(arrays: Mapping[str, np.ndarray]) -> str:
    """SHA-256 over the arrays in ``ARRAYS`` order: name, dtype, shape and bytes."""
    h = hashlib.sha256()
    for name in ARRAYS:
        a = np.ascontiguousarray(arrays[name])
        h.update(name.encode())
        h.update(str(a.dtype).encode())
        h.update(str(a.shape).encode())
        h.update(a.tobytes())
    return h.hexdigest()


def generate(cfg: DatagenConfig, progress: bool = True) -> Tuple[Dict[str, np.ndarray], Dict[str, Any]]:
    """Run all episodes; returns the arrays and the manifest (without command/paths)."""
    cfg.validate()
    p = load_params_dict(cfg.params)
    pb, pt = p["bullet"], p["target"]
    ss = np.random.SeedSequence(cfg.seed)
    ep_seeds = ss.spawn(cfg.episodes)
    # Episode split, seeded: a permutation cut by the fractions.
    perm = np.random.default_rng(ss.spawn(1)[0]).permutation(cfg.episodes)
    n_tr = max(1, int(round(cfg.split_fractions[0] * cfg.episodes)))
    n_va = max(1, int(round(cfg.split_fractions[1] * cfg.episodes)))
    n_tr = min(n_tr, cfg.episodes - 2)
    ep_split = np.full(cfg.episodes, 2, dtype=np.int8)
    ep_split[perm[:n_tr]] = 0
    ep_split[perm[n_tr:n_tr + n_va]] = 1

    bar = None
    if progress:
        from tqdm import tqdm
        bar = tqdm(total=cfg.episodes, desc=f"datagen {cfg.params}", unit="ep", leave=False,
                   dynamic_ncols=True, disable=None)
    parts: Dict[str, List[np.ndarray]] = {k: [] for k in ARRAYS}
    modes = {m: 0 for m in DRIVER_MODES}
    contact_eps = 0
    try:
        for e in range(cfg.episodes):
            spec = sample_episode(cfg, np.random.default_rng(ep_seeds[e]))
            d = run_episode(spec, cfg.params, pb, pt)
            n = len(d["x"])
            for k in ("x", "u", "fc", "gamma", "point", "x_next"):
                parts.setdefault(k, []).append(d[k])
            parts["mu"].append(np.full(n, spec.mu))
            parts["episode"].append(np.full(n, e, dtype=np.int32))
            parts["step"].append(np.arange(n, dtype=np.int32))
            parts["split"].append(np.full(n, ep_split[e], dtype=np.int8))
            modes[spec.driver] += 1
            contact_eps += int(np.any(d["fc"][:, 0] > 0))
            if bar is not None:
                bar.update(1)
    finally:
        if bar is not None:
            bar.close()
    arrays = {k: np.concatenate(v) for k, v in parts.items()}
    contact = arrays["fc"][:, 0] > 0
    pw = pt.get("powertrain")
    v_stall = pw["stall_speed"] * pt["wheel_radius"] / pt["gear_ratio"] if pw else 0.0
    counts = {
        "episodes": cfg.episodes,
        "episodes_with_contact": contact_eps,
        "samples": int(len(arrays["x"])),
        "contact_samples": int(contact.sum()),
        "throttle_samples": int((arrays["u"][:, 1] < 0).sum()),
        "backward_samples": int((arrays["x"][:, 0] < -0.5).sum()),
        "below_stall_speed_samples": int((arrays["x"][:, 0] < v_stall).sum()),
        "driver_modes": modes,
    }
    for i, s in enumerate(SPLITS):
        counts[f"{s}_episodes"] = int((ep_split == i).sum())
        counts[f"{s}_samples"] = int((arrays["split"] == i).sum())
    manifest = {
        "format": "picopit-collision-data",
        "version": 1,
        "param_set": cfg.params,
        "dt": DT,
        "seed": cfg.seed,
        "sampling": dataclasses.asdict(cfg),
        "counts": counts,
        "arrays": {k: {"dtype": str(arrays[k].dtype), "shape": list(arrays[k].shape)} for k in ARRAYS},
        "data_hash": "sha256:" + content_hash(arrays),
    }
    return arrays, manifest


def write(arrays: Mapping[str, np.ndarray], manifest: Dict[str, Any], out: Path) -> Dict[str, Path]:
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    paths = {"npz": out / "dataset.npz", "manifest": out / "manifest.json"}
    np.savez_compressed(paths["npz"], **{k: arrays[k] for k in ARRAYS})
    with open(paths["manifest"], "w") as fh:
        json.dump(manifest, fh, indent=2)
        fh.write("\n")
    return paths


@dataclass
class Dataset:
    arrays: Dict[str, np.ndarray]
    manifest: Dict[str, Any]
    path: Path

    @property
    def param_set(self) -> str:
        return str(self.manifest["param_set"])

    @property
    def data_hash(self) -> str:
        return str(self.manifest["data_hash"])

    def subset(self, split: str) -> Dict[str, np.ndarray]:
        i = SPLITS.index(split)
        m = self.arrays["split"] == i
        return {k: v[m] for k, v in self.arrays.items()}


def load(path: Path) -> Dataset:
    """Read and check a dataset folder (or its dataset.npz): every array present with the
    right shape and finite, the manifest's hash equal to the arrays' hash."""
    path = Path(path)
    folder = path.parent if path.suffix == ".npz" else path
    npz, man = folder / "dataset.npz", folder / "manifest.json"
    if not npz.is_file():
        raise DatasetError(f"{npz}: dataset file missing")
    if not man.is_file():
        raise DatasetError(f"{man}: manifest missing")
    try:
        with open(man) as fh:
            manifest = json.load(fh)
    except (OSError, json.JSONDecodeError) as e:
        raise DatasetError(f"{man}: not readable JSON: {e}") from None
    for key in ("param_set", "dt", "seed", "data_hash"):
        if key not in manifest:
            raise DatasetError(f"{man}: manifest key {key!r} missing")
    try:
        with np.load(npz, allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files}
    except (OSError, ValueError) as e:
        raise DatasetError(f"{npz}: not a readable npz file: {e}") from None
    n = None
    for name, tail in ARRAYS.items():
        if name not in arrays:
            raise DatasetError(f"{npz}: array {name!r} missing")
        a = arrays[name]
        if a.ndim != 1 + len(tail) or tuple(a.shape[1:]) != tail:
            raise DatasetError(f"{npz}: array {name!r} has shape {list(a.shape)}, expected [n{''.join(', ' + str(t) for t in tail)}]")
        if n is None:
            n = a.shape[0]
        elif a.shape[0] != n:
            raise DatasetError(f"{npz}: array {name!r} has {a.shape[0]} rows, expected {n}")
        if a.dtype.kind == "f" and not np.all(np.isfinite(a)):
            raise DatasetError(f"{npz}: array {name!r} holds NaN or inf")
    if not np.all(arrays["fc"][:, 0] >= 0):
        raise DatasetError(f"{npz}: array 'fc': normal force F_n must be >= 0")
    if not np.all(np.isin(arrays["split"], (0, 1, 2))):
        raise DatasetError(f"{npz}: array 'split': values must be 0, 1 or 2")
    h = "sha256:" + content_hash(arrays)
    if h != manifest["data_hash"]:
        raise DatasetError(f"{man}: data_hash {manifest['data_hash']} does not match the arrays ({h})")
    return Dataset(arrays, manifest, folder)


def windows(arrays: Mapping[str, np.ndarray], horizon: int) -> np.ndarray:
    """Start indices i such that samples i … i+horizon−1 are consecutive steps of one episode."""
    ep, st = arrays["episode"], arrays["step"]
    n = len(ep)
    if n < horizon:
        return np.zeros(0, dtype=np.int64)
    ok = np.ones(n - horizon + 1, dtype=bool)
    for j in range(1, horizon):
        ok &= (ep[j:n - horizon + 1 + j] == ep[:n - horizon + 1]) & (st[j:n - horizon + 1 + j] == st[:n - horizon + 1] + j)
    return np.nonzero(ok)[0]
