"""``picopit simulate``: one two-vehicle rear-quarter PIT contact on the plant.

A scripted bullet driver (pure Python, 20 Hz) chases an uncontrolled target on a straight
three-lane road, lines its front bumper up with the target's rear axle, makes the police
"quarter turn" of the steering wheel into the target's rear quarter, and steers back and
brakes once the target has rotated or the contact is over. The plant (Rust, 1 kHz) is the
truth. Results: a trajectory CSV, a figure and a JSON summary.

World frame: X along the road, Y to the left; the middle lane is centred on Y = 0.
"""

from __future__ import annotations

import csv
import dataclasses
import json
import math
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Dict, List, Mapping, Optional, Tuple

import numpy as np

from . import _core, load_params_dict

if sys.version_info >= (3, 11):
    import tomllib as _toml
else:  # pragma: no cover
    import tomli as _toml

#: Lanes of the straight road drawn and reported by ``simulate``.
LANE_COUNT = 3
LANE_WIDTH = 3.5
#: Controller period (s): the scripted driver runs at 20 Hz, like the MPC.
CONTROL_DT = 0.05


class ConfigError(ValueError):
    """A bad ``simulate`` setting; the message names the field."""


@dataclass
class SimulateConfig:
    """Settings of one ``picopit simulate`` run (SI units; CLI and TOML use the same names)."""

    params: str = "full_size"
    """Parameter set: a built-in name (full_size, half_scale) or a TOML file."""
    mu: float = 0.9
    """Road adhesion."""
    target_speed: float = 15.0
    """Initial target speed (m/s)."""
    speed_diff: float = 2.0
    """Initial bullet speed minus target speed (m/s); the bullet closes the gap with it."""
    lateral_offset: float = -3.5
    """Initial lateral offset of the bullet's c.g. from the target's (m); negative puts the
    bullet on the target's right (the target is pushed left and spins clockwise)."""
    gap: float = 6.0
    """Initial longitudinal gap from the bullet's front bumper to the target's rear bumper (m)."""
    duration: float = 8.0
    """Simulated time (s)."""
    seed: int = 0
    """Seed of the initial-condition jitter (recorded with every result)."""
    jitter: float = 0.0
    """Scale of random initial-condition noise: 1.0 means sigma = 0.2 m in position, 0.02 rad
    in heading and 0.3 m/s in speed for the target. 0 (default) is the nominal scenario."""
    target_brake: float = 0.6
    """The target driver's reaction: brake torque as a fraction of the target's maximum,
    applied ``target_reaction`` seconds after the first contact (0: never brakes)."""
    target_reaction: float = 0.5
    """Reaction time of the target driver after the first contact (s)."""
    pit_steer: float = 0.12
    """Road-wheel steer of the "quarter turn" into the target (rad)."""
    record_hz: float = 100.0
    """Rate of the trajectory samples (Hz, a multiple of 20); contact forces are averaged
    over each sample interval (impulse / time)."""

    def validate(self) -> "SimulateConfig":
        def bad(name: str, value: Any, reason: str) -> ConfigError:
            return ConfigError(f"{name} = {value!r}: {reason}")

        for f in dataclasses.fields(self):
            v = getattr(self, f.name)
            if f.type in ("float", float):
                if isinstance(v, bool) or not isinstance(v, (int, float)):
                    raise bad(f.name, v, "must be a number")
                if not math.isfinite(v):
                    raise bad(f.name, v, "must be finite")
        if not isinstance(self.params, str) or not self.params:
            raise bad("params", self.params, "must be a parameter set name or a TOML path")
        if isinstance(self.seed, bool) or not isinstance(self.seed, int) or self.seed < 0:
            raise bad("seed", self.seed, "must be a non-negative integer")
        if not 0.0 < self.mu <= 1.5:
            raise bad("mu", self.mu, "must lie in (0, 1.5]")
        if not 0.0 < self.target_speed <= 60.0:
            raise bad("target_speed", self.target_speed, "must lie in (0, 60] m/s")
        if not 0.0 <= self.speed_diff <= 20.0:
            raise bad("speed_diff", self.speed_diff, "must lie in [0, 20] m/s")
        if not 0.5 <= abs(self.lateral_offset) <= LANE_WIDTH * (LANE_COUNT - 1):
            raise bad(
                "lateral_offset", self.lateral_offset,
                f"its magnitude must lie in [0.5, {LANE_WIDTH * (LANE_COUNT - 1)}] m",
            )
        if not 0.0 <= self.gap <= 100.0:
            raise bad("gap", self.gap, "must lie in [0, 100] m")
        if not 0.0 < self.duration <= 120.0:
            raise bad("duration", self.duration, "must lie in (0, 120] s")
        if not 0.0 <= self.jitter <= 5.0:
            raise bad("jitter", self.jitter, "must lie in [0, 5]")
        if not 0.0 <= self.target_brake <= 1.0:
            raise bad("target_brake", self.target_brake, "must lie in [0, 1] (fraction of the maximum)")
        if not 0.0 <= self.target_reaction <= 10.0:
            raise bad("target_reaction", self.target_reaction, "must lie in [0, 10] s")
        if not 0.0 < self.pit_steer <= 0.5:
            raise bad("pit_steer", self.pit_steer, "must lie in (0, 0.5] rad")
        ratio = self.record_hz * CONTROL_DT
        if not (20.0 <= self.record_hz <= 1000.0 and abs(ratio - round(ratio)) < 1e-9):
            raise bad("record_hz", self.record_hz, "must be a multiple of 20 in [20, 1000] Hz")
        return self

    @classmethod
    def from_mapping(cls, values: Mapping[str, Any], source: str = "config") -> "SimulateConfig":
        """Build from a dict (e.g. a TOML table); unknown keys are refused by name."""
        names = {f.name: f for f in dataclasses.fields(cls)}
        kwargs: Dict[str, Any] = {}
        for key, value in values.items():
            if key not in names:
                raise ConfigError(
                    f"{source}: unknown field {key!r} (known: {', '.join(sorted(names))})"
                )
            if names[key].type in ("float", float) and isinstance(value, int) and not isinstance(value, bool):
                value = float(value)
            kwargs[key] = value
        return cls(**kwargs)


def load_config_file(path: str) -> Dict[str, Any]:
    """Read a ``simulate`` TOML file: the fields at top level or under ``[simulate]``."""
    try:
        with open(path, "rb") as fh:
            data = _toml.load(fh)
    except OSError as e:
        raise ConfigError(f"config: cannot read {path}: {e.strerror or e}") from None
    except _toml.TOMLDecodeError as e:
        raise ConfigError(f"config: {path} is not valid TOML: {e}") from None
    if "simulate" in data:
        extra = sorted(k for k in data if k != "simulate")
        if extra:
            raise ConfigError(f"{path}: unknown field {extra[0]!r} beside [simulate]")
        data = data["simulate"]
        if not isinstance(data, dict):
            raise ConfigError(f"{path}: 'simulate' must be a table")
    return data


# --------------------------------------------------------------------------------------
# Vehicle geometry (from the parameter set) and the scripted bullet driver
# --------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Vehicle:
    """The few numbers of a vehicle the driver and the plots need."""

    mass: float
    lf: float
    lr: float
    length: float
    width: float
    cg_to_front: float
    wheel_radius: float
    drive_force_gain: float  # eta_d i_g / R_w (1/m)
    drive_torque_min: float
    drive_torque_max: float
    steer_max: float
    brake_torque_max: float

    @classmethod
    def from_params(cls, p: Mapping[str, Any]) -> "Vehicle":
        return cls(
            mass=p["mass"], lf=p["lf"], lr=p["lr"], length=p["length"], width=p["width"],
            cg_to_front=p["cg_to_front"], wheel_radius=p["wheel_radius"],
            drive_force_gain=p["drive_efficiency"] * p["gear_ratio"] / p["wheel_radius"],
            drive_torque_min=p["drive_torque_min"], drive_torque_max=p["drive_torque_max"],
            steer_max=p["steer_max"], brake_torque_max=p["brake_torque_max"],
        )

    @property
    def wheelbase(self) -> float:
        return self.lf + self.lr


def _rot(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s], [s, c]])


@dataclass
class ScriptedBullet:
    """A police-style PIT driver for the bullet, called every ``CONTROL_DT``.

    Phases: ``approach`` (pure pursuit toward the point beside the target that puts the
    bullet's front bumper level with the target's rear axle, speed by T_r), ``pit`` (the
    quarter turn into the target's rear quarter, holding speed), ``exit`` (steer back to the
    road heading and brake), ``stopped``.
    """

    bullet: Vehicle
    target: Vehicle
    side: float  # -1: bullet on the target's right, +1: on its left
    pit_steer: float
    exit_brake: float = 0.8  # service brake in the exit phase, fraction of the maximum
    clearance: float = 0.35  # lateral gap between the bodies while lined up (m)
    overlap: float = 0.3  # bullet front bumper this far ahead of the target's rear axle (m)
    phase: str = "approach"
    t_phase: float = 0.0
    yaw_target_at_pit: float = 0.0
    contact_seen: bool = False
    no_contact_for: float = 0.0
    log: List[Tuple[float, str]] = field(default_factory=list)

    def aim_in_target(self) -> np.ndarray:
        """Where the bullet's c.g. should sit in the target's body frame when lined up."""
        x = -self.target.lr + self.overlap - self.bullet.cg_to_front
        y = self.side * (0.5 * self.target.width + 0.5 * self.bullet.width + self.clearance)
        return np.array([x, y])

    def _set_phase(self, t: float, phase: str) -> None:
        self.phase = phase
        self.t_phase = t
        self.log.append((t, phase))

    def _torque_for_speed(self, v_des: float, v: float, gain: float = 1.5) -> float:
        b = self.bullet
        a_des = gain * (v_des - v)
        t_r = b.mass * a_des / b.drive_force_gain
        return float(np.clip(t_r, b.drive_torque_min, b.drive_torque_max))

    def command(self, t: float, xb: np.ndarray, xt: np.ndarray, in_contact: bool) -> Tuple[float, float, float]:
        """Bullet steer (rad), drive torque T_r (N m) and service brake (N m) for the next
        control period."""
        b = self.bullet
        X, Y, psi, vx, _vy, _r = xb
        vt, _, psi_t = xt[0], xt[1], xt[2]
        pos_t = xt[6:8]
        pose_b = np.array([X, Y])
        # Bullet c.g. in the target's frame, and where it should be.
        p_rel = _rot(-psi_t) @ (pose_b - pos_t)
        aim = self.aim_in_target()
        err = aim - p_rel

        if in_contact:
            self.contact_seen = True
            self.no_contact_for = 0.0
        elif self.contact_seen:
            self.no_contact_for += CONTROL_DT

        if self.phase == "approach":
            # Pure pursuit from the rear axle toward a point ahead of the aim, along the target.
            lookahead = max(4.0, 0.5 * abs(vx))
            goal = pos_t + _rot(psi_t) @ (aim + np.array([lookahead, 0.0]))
            rear = pose_b - b.lr * np.array([math.cos(psi), math.sin(psi)])
            d = goal - rear
            alpha = math.atan2(d[1], d[0]) - psi
            alpha = math.atan2(math.sin(alpha), math.cos(alpha))
            steer = math.atan2(2.0 * b.wheelbase * math.sin(alpha), float(np.hypot(*d)))
            steer = float(np.clip(steer, -0.25, 0.25))
            v_des = vt + float(np.clip(0.8 * err[0], -3.0, 3.0))
            torque = self._torque_for_speed(v_des, vx)
            lined_up = abs(err[0]) < 0.3 and abs(err[1]) < 0.3
            if lined_up or in_contact or t - self.t_phase > 8.0:
                self._set_phase(t, "pit")
                self.yaw_target_at_pit = float(psi_t)
            return steer, torque, 0.0

        if self.phase == "pit":
            # The quarter turn into the target's rear quarter, pushing on at a little more
            # than the target's speed.
            steer = -self.side * self.pit_steer
            torque = self._torque_for_speed(vt + 1.0, vx)
            rotated = abs(psi_t - self.yaw_target_at_pit) > math.radians(45.0)
            released = self.contact_seen and self.no_contact_for >= 0.15
            if rotated or released or t - self.t_phase > 2.0:
                self._set_phase(t, "exit")
            return steer, torque, 0.0

        if self.phase == "exit":
            # Steer back to the road heading, away from the target, and brake.
            steer = float(np.clip(-1.5 * math.atan2(math.sin(psi), math.cos(psi)), -0.2, 0.2))
            if vx < 0.3:
                self._set_phase(t, "stopped")
            return steer, 0.0, self.exit_brake * b.brake_torque_max

        return 0.0, 0.0, self.exit_brake * b.brake_torque_max


# --------------------------------------------------------------------------------------
# Running the scenario
# --------------------------------------------------------------------------------------

#: CSV columns, in order.
COLUMNS = (
    "t",
    "bullet_X", "bullet_Y", "bullet_yaw", "bullet_vx", "bullet_vy", "bullet_r",
    "target_vx", "target_vy", "target_yaw", "target_r", "target_p", "target_phi",
    "target_X", "target_Y",
    "bullet_steer_cmd", "bullet_torque_cmd", "target_steer_cmd", "target_brake_cmd",
    "bullet_brake_cmd",
    "contact_Fn", "contact_Ft", "contact_gamma", "contact_X", "contact_Y", "contact_depth",
    "phase",
)


@dataclass
class SimulateResult:
    config: SimulateConfig
    data: Dict[str, np.ndarray]
    phases: List[Tuple[float, str]]
    summary: Dict[str, Any]
    bullet: Vehicle
    target: Vehicle


def initial_states(cfg: SimulateConfig, bullet: Vehicle, target: Vehicle) -> Tuple[np.ndarray, np.ndarray]:
    """Initial ``[X, Y, yaw, vx, vy, r]`` of bullet and target."""
    rng = np.random.default_rng(cfg.seed)
    j = cfg.jitter
    noise = rng.normal(size=3) * np.array([0.2, 0.02, 0.3]) * j
    target_init = np.array([0.0, noise[0], noise[1], cfg.target_speed + noise[2], 0.0, 0.0])
    target_rear = -(target.length - target.cg_to_front)
    x_b = target_rear - cfg.gap - bullet.cg_to_front
    bullet_init = np.array([x_b, cfg.lateral_offset, 0.0, cfg.target_speed + cfg.speed_diff, 0.0, 0.0])
    return bullet_init, target_init


def run(cfg: SimulateConfig, progress: bool = True) -> SimulateResult:
    """Run one scenario on the plant; pure computation, writes nothing."""
    cfg.validate()
    params = load_params_dict(cfg.params)
    bullet, target = Vehicle.from_params(params["bullet"]), Vehicle.from_params(params["target"])
    plant = _core.Plant(cfg.params, mu=cfg.mu)
    xb0, xt0 = initial_states(cfg, bullet, target)
    plant.reset(xb0, xt0)

    side = -1.0 if cfg.lateral_offset < 0 else 1.0
    driver = ScriptedBullet(bullet, target, side, cfg.pit_steer)
    driver.log.append((0.0, driver.phase))

    n_ctrl = int(round(cfg.duration / CONTROL_DT))
    sub = int(round(cfg.record_hz * CONTROL_DT))
    h = CONTROL_DT / sub
    rows: List[List[float]] = []
    phases: List[str] = []

    def record(cmd: Tuple[float, ...], contact: Optional[dict]) -> None:
        xb, xt = plant.bullet_state(), plant.target_state()
        if contact is None:
            c = [0.0, 0.0, math.nan, math.nan, math.nan, 0.0]
        else:
            c = [contact["fc"][0], contact["fc"][1], contact["gamma"],
                 contact["point_in_world"][0], contact["point_in_world"][1], contact["depth"]]
        rows.append([plant.time, *xb, *xt, *cmd, *c])
        phases.append(driver.phase)

    cmd = (0.0, 0.0, 0.0, 0.0, 0.0)
    record(cmd, None)
    in_contact = False
    first_contact: Optional[float] = None
    bar = _progress(n_ctrl, progress)
    try:
        for _ in range(n_ctrl):
            t = plant.time
            steer, torque, bullet_brake = driver.command(
                t, plant.bullet_state(), plant.target_state(), in_contact
            )
            # The target's driver has lost control: no steering; after the hit, a reflex brake.
            if in_contact and first_contact is None:
                first_contact = t
            brake = 0.0
            if first_contact is not None and t >= first_contact + cfg.target_reaction - 1e-9:
                brake = cfg.target_brake * target.brake_torque_max
            cmd = (steer, torque, 0.0, brake, bullet_brake)
            plant.set_commands(*cmd)
            in_contact = False
            for _ in range(sub):
                plant.advance(h)
                contact = plant.take_contact_average()
                in_contact = in_contact or contact is not None
                record(cmd, contact)
            if bar is not None:
                bar.update(1)
    finally:
        if bar is not None:
            bar.close()

    arr = np.array(rows, dtype=float)
    data = {name: arr[:, i] for i, name in enumerate(COLUMNS[:-1])}
    data["phase"] = np.array(phases)
    summary = summarize(cfg, data, driver.log)
    return SimulateResult(cfg, data, list(driver.log), summary, bullet, target)


def _progress(total: int, enabled: bool):
    if not enabled:
        return None
    try:
        from tqdm import tqdm
    except ImportError:  # pragma: no cover - tqdm is a dependency
        return None
    # disable=None: no bar when stderr is not a terminal (CI logs, pipes).
    return tqdm(total=total, desc="simulate", unit="step", leave=False, dynamic_ncols=True, disable=None)


def summarize(cfg: SimulateConfig, d: Mapping[str, np.ndarray], phases: List[Tuple[float, str]]) -> Dict[str, Any]:
    fn = d["contact_Fn"]
    touching = fn > 0
    yaw_change = float(d["target_yaw"][-1] - d["target_yaw"][0])
    speed_b = float(np.hypot(d["bullet_vx"][-1], d["bullet_vy"][-1]))
    speed_t = float(np.hypot(d["target_vx"][-1], d["target_vy"][-1]))
    t = d["t"]
    edge = 0.5 * LANE_COUNT * LANE_WIDTH
    return {
        "peak_contact_force_N": float(fn.max()) if fn.size else 0.0,
        "contact_time_s": float(touching.sum() * (t[1] - t[0])) if t.size > 1 else 0.0,
        "first_contact_s": float(t[touching][0]) if touching.any() else None,
        "target_yaw_change_deg": math.degrees(yaw_change),
        "target_max_abs_yaw_change_deg": math.degrees(float(np.max(np.abs(d["target_yaw"] - d["target_yaw"][0])))),
        "final_speed_bullet_mps": speed_b,
        "final_speed_target_mps": speed_t,
        "target_max_abs_Y_m": float(np.max(np.abs(d["target_Y"]))),
        "bullet_max_abs_Y_m": float(np.max(np.abs(d["bullet_Y"]))),
        "road_half_width_m": edge,
        "phases": [{"t": round(tp, 3), "phase": ph} for tp, ph in phases],
        "seed": cfg.seed,
    }


# --------------------------------------------------------------------------------------
# Output
# --------------------------------------------------------------------------------------


def write_csv(path: Path, data: Mapping[str, np.ndarray]) -> None:
    n = len(data["t"])
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(COLUMNS)
        for i in range(n):
            w.writerow([
                repr(float(data[c][i])) if c != "phase" else data[c][i] for c in COLUMNS
            ])


def read_csv(path: Path) -> Dict[str, np.ndarray]:
    with open(path, newline="") as fh:
        r = csv.reader(fh)
        header = next(r)
        cols: Dict[str, list] = {h: [] for h in header}
        for row in r:
            for h, v in zip(header, row):
                cols[h].append(v)
    return {h: (np.array(v) if h == "phase" else np.array(v, dtype=float)) for h, v in cols.items()}


def write_outputs(result: SimulateResult, out: Path) -> Dict[str, Path]:
    """Write trajectory.csv and summary.json into ``out`` (the figure, simulate.png, is
    ``plots.plot_simulation``'s)."""
    out.mkdir(parents=True, exist_ok=True)
    paths = {"csv": out / "trajectory.csv", "json": out / "summary.json"}
    write_csv(paths["csv"], result.data)
    with open(paths["json"], "w") as fh:
        json.dump({"config": dataclasses.asdict(result.config), "summary": result.summary}, fh, indent=2)
        fh.write("\n")
    return paths
