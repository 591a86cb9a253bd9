"""The plant checked against references no one here wrote.

* **Handling and braking** against CommonRoad's multi-body vehicle model (``vehiclemodels``,
  PyPI ``commonroad-vehicle-models``, model MB: 29 states, the BMW 320i of parameter set 2,
  the vehicle ``full_size`` is built from), integrated with scipy's LSODA. Both models drive
  the same manoeuvre through the same actuators: the plant's actual road-wheel steer and
  brake torque, recorded every step, are imposed on MB (its steer state is overwritten by
  the recorded angle; the brake torque becomes its acceleration input ``−T_b / (m R_w)``,
  which MB turns back into the same wheel torques with the same front share). Rolling
  resistance and drag are set to zero in the plant (MB has neither), the target coasts in
  neutral (MB has no engine), and the road's μ is MB's tyre peak (``p_dy1``), so the tyres
  are the same too.
* **Impacts** against impulse–momentum theory (Brach 1983): two cars with tyres off, one
  driven into the other; the plant's normal impulse and yaw-rate changes against the
  rigid-body prediction at the restitution and impulse ratio the contact produced, that
  restitution against the parameter file's, and the momentum balance.

Each check has a tolerance stated beside it and passes or fails; ``picopit validate-plant``
prints the table (docs/plant.md has the current one) and ``tests/test_plant_validation.py``
asserts every row.
"""

from __future__ import annotations

import math
import re
from dataclasses import asdict, dataclass
from typing import Callable, Dict, List, Optional, Sequence, Tuple

import numpy as np

try:  # Python 3.11+
    import tomllib as _toml
except ModuleNotFoundError:  # pragma: no cover - Python < 3.11
    import tomli as _toml  # type: ignore[no-redef]

from . import _core

#: Sampling period of the recorded traces (s).
SAMPLE = 0.01


@dataclass(frozen=True)
class Check:
    """One compared quantity."""

    manoeuvre: str
    quantity: str
    unit: str
    plant: float
    reference: float
    #: ``"rel"``: |plant − reference| ≤ tol · |reference|; ``"abs"``: |plant − reference| ≤ tol;
    #: ``"max"``: plant ≤ tol (reference unused); ``"band"``: reference ≤ plant ≤ tol.
    kind: str
    tol: float

    @property
    def passed(self) -> bool:
        d = self.plant - self.reference
        if not math.isfinite(self.plant):
            return False
        if self.kind == "rel":
            return abs(d) <= self.tol * abs(self.reference)
        if self.kind == "abs":
            return abs(d) <= self.tol
        if self.kind == "max":
            return self.plant <= self.tol
        if self.kind == "band":
            return self.reference <= self.plant <= self.tol
        raise ValueError(f"unknown check kind {self.kind!r}")

    def tolerance_text(self) -> str:
        if self.kind == "rel":
            return f"±{100 * self.tol:g} %"
        if self.kind == "abs":
            return f"±{self.tol:g} {self.unit}".rstrip()
        if self.kind == "max":
            return f"≤ {self.tol:g}"
        return f"[{self.reference:g}, {self.tol:g}]"

    def as_dict(self) -> Dict[str, object]:
        d = asdict(self)
        for key in ("plant", "reference", "tol"):
            d[key] = float(d[key])
        d["passed"] = bool(self.passed)
        return d


# ---------------------------------------------------------------------------------------------
# The plant side


def comparison_params(name: str = "full_size") -> str:
    """The TOML text of a built-in set with rolling resistance and drag off for both vehicles
    (MB has neither)."""
    text = _core.load_params(name)
    for key in ("rolling_resistance", "drag_area"):
        text, n = re.subn(rf"(?m)^{key} = .*$", f"{key} = 0.0", text)
        if n != 2:
            raise RuntimeError(f"{name}: expected {key} in both vehicles, found {n}")
    return text


@dataclass
class Trace:
    """A manoeuvre as recorded every :data:`SAMPLE` s: time, body-frame speeds, yaw rate,
    lateral acceleration, actual steer and brake torque."""

    t: np.ndarray
    vx: np.ndarray
    vy: np.ndarray
    r: np.ndarray
    ay: np.ndarray
    x: np.ndarray
    steer: np.ndarray
    brake: np.ndarray


def _plant_trace(
    params_path: str,
    mu: float,
    speed: float,
    duration: float,
    steer_cmd: Callable[[float], float],
    brake_cmd: float,
    stop_below: float = -math.inf,
) -> Trace:
    plant = _core.Plant(params_path, mu=mu, target_gear="neutral")
    plant.reset([-200.0, 50.0, 0.0, 0.0, 0.0, 0.0], [0.0, 0.0, 0.0, speed, 0.0, 0.0])
    steps = int(round(SAMPLE / plant.dt))
    rows = []
    n = int(round(duration / SAMPLE))
    for k in range(n + 1):
        t = k * SAMPLE
        x = plant.target_state()
        body = plant.body("target")
        rows.append((t, x[0], x[1], x[3], body["acc_body"][1], x[6], body["steer"], body["brake"]))
        if k == n or x[0] < stop_below:
            break
        plant.set_commands(0.0, 0.0, steer_cmd(t), brake_cmd)
        for _ in range(steps):
            plant.step()
    a = np.array(rows)
    return Trace(*(a[:, i] for i in range(8)))


# ---------------------------------------------------------------------------------------------
# The reference side: CommonRoad MB


def _mb_trace(trace: Trace, mu_peak: float) -> Trace:
    """MB driven by the plant's recorded steer and brake (see the module docs)."""
    from scipy.integrate import solve_ivp
    from vehiclemodels.init_mb import init_mb
    from vehiclemodels.parameters_vehicle2 import parameters_vehicle2
    from vehiclemodels.vehicle_dynamics_mb import vehicle_dynamics_mb

    p = parameters_vehicle2()
    if abs(p.tire.p_dy1 - mu_peak) > 1e-9:
        raise RuntimeError("MB's tyre peak is not the comparison's μ")
    x0 = init_mb([0.0, 0.0, float(trace.steer[0]), float(trace.vx[0]), 0.0, 0.0, 0.0], p)
    m_rw = p.m * p.R_w

    def inputs(t: float) -> Tuple[float, float]:
        return (
            float(np.interp(t, trace.t, trace.steer)),
            float(np.interp(t, trace.t, trace.brake)),
        )

    def rhs(t: float, x: np.ndarray) -> List[float]:
        delta, brake = inputs(t)
        xs = list(x)
        xs[2] = delta
        f = vehicle_dynamics_mb(xs, [0.0, -brake / m_rw], p)
        f[2] = 0.0
        return f

    sol = solve_ivp(
        rhs,
        (0.0, float(trace.t[-1])),
        x0,
        method="LSODA",
        t_eval=trace.t,
        max_step=SAMPLE,
        rtol=1e-7,
        atol=1e-9,
    )
    if sol.status != 0:
        raise RuntimeError(f"MB integration failed: {sol.message}")
    y = sol.y
    # Lateral acceleration of the c.g. in the body frame: v̇y + r vx (MB's x[10] is the
    # sprung mass's lateral velocity, its c.g. velocity to within the unsprung share).
    vy_dot = np.array([rhs(t, y[:, i])[10] for i, t in enumerate(sol.t)])
    ay = vy_dot + y[5] * y[3]
    return Trace(sol.t, y[3], y[10], y[5], ay, y[0], trace.steer.copy(), trace.brake.copy())


# ---------------------------------------------------------------------------------------------
# Manoeuvres


def _steady(tr: Trace, t0: float, t1: float, a: np.ndarray) -> float:
    m = (tr.t >= t0) & (tr.t <= t1)
    return float(np.mean(a[m]))


def step_steer(params_path: str, mu: float) -> List[Check]:
    """Step steer 0.05 rad at 20 m/s, coasting: steady yaw rate and lateral acceleration
    (mean over 1.5–2.5 s), yaw-rate overshoot."""
    tr = _plant_trace(params_path, mu, 20.0, 2.5, lambda t: 0.05, 0.0)
    ref = _mb_trace(tr, mu)
    out = []
    for tra, name in ((tr, "plant"), (ref, "mb")):
        r_ss = _steady(tra, 1.5, 2.5, tra.r)
        ay_ss = _steady(tra, 1.5, 2.5, tra.ay)
        over = float(np.max(tra.r)) / r_ss - 1.0
        if name == "plant":
            p = (r_ss, ay_ss, over)
        else:
            q = (r_ss, ay_ss, over)
    m = "step steer 0.05 rad, 20 m/s"
    out.append(Check(m, "steady yaw rate", "rad/s", p[0], q[0], "rel", 0.10))
    out.append(Check(m, "steady lateral acceleration", "m/s²", p[1], q[1], "rel", 0.10))
    out.append(Check(m, "yaw-rate overshoot", "", p[2], q[2], "abs", 0.05))
    return out


def sine_steer(params_path: str, mu: float) -> List[Check]:
    """Sine steer 0.02 rad at 0.5 Hz, 20 m/s: yaw-rate amplitude and phase lag behind the
    actual steer (fitted over the last two periods)."""
    f = 0.5
    amp = 0.02
    tr = _plant_trace(params_path, mu, 20.0, 6.0, lambda t: amp * math.sin(2 * math.pi * f * t), 0.0)
    ref = _mb_trace(tr, mu)

    def fit(tra: Trace) -> Tuple[float, float]:
        m = tra.t >= 2.0
        w = 2 * math.pi * f
        basis = np.column_stack([np.sin(w * tra.t[m]), np.cos(w * tra.t[m]), np.ones(m.sum())])
        (a_r, b_r, _), *_ = np.linalg.lstsq(basis, tra.r[m], rcond=None)
        (a_d, b_d, _), *_ = np.linalg.lstsq(basis, tra.steer[m], rcond=None)
        gain = math.hypot(a_r, b_r)
        phase = math.degrees(math.atan2(b_r, a_r) - math.atan2(b_d, a_d))
        return gain, (phase + 180.0) % 360.0 - 180.0

    (g_p, ph_p), (g_r, ph_r) = fit(tr), fit(ref)
    m = "sine steer 0.02 rad, 0.5 Hz, 20 m/s"
    return [
        Check(m, "yaw-rate amplitude", "rad/s", g_p, g_r, "rel", 0.15),
        Check(m, "yaw-rate phase to steer", "deg", ph_p, ph_r, "abs", 5.0),
    ]


def steer_ramp(params_path: str, mu: float) -> List[Check]:
    """Steer ramp 0.01 rad/s at 25 m/s towards the limit, coasting: lateral acceleration
    when the steer reaches 0.02, 0.03 and 0.045 rad (about 90 % of the limit), and when the
    body slip reaches 0.035 rad."""
    tr = _plant_trace(params_path, mu, 25.0, 4.6, lambda t: 0.01 * t, 0.0)
    ref = _mb_trace(tr, mu)
    m = "steer ramp 0.01 rad/s, 25 m/s"
    out = []
    for delta in (0.02, 0.03, 0.045):
        ap = float(np.interp(delta, tr.steer, tr.ay))
        ar = float(np.interp(delta, ref.steer, ref.ay))
        out.append(Check(m, f"lateral acceleration at δ = {delta:g} rad", "m/s²", ap, ar, "rel", 0.10))
    at_slip = []
    for tra in (tr, ref):
        slip = -np.arctan2(tra.vy, tra.vx)
        if slip.max() < 0.035:
            raise RuntimeError(f"{m}: the body slip never reached 0.035 rad")
        at_slip.append(float(np.interp(0.035, slip, tra.ay)))
    out.append(Check(m, "lateral acceleration at 0.035 rad body slip", "m/s²", *at_slip, "rel", 0.10))
    return out


def straight_braking(params_path: str, mu: float, torque: float) -> List[Check]:
    """Straight braking from 20 m/s with total brake torque ``torque``: distance to 0.5 m/s and
    the mean deceleration in speed windows from 18 down to 0.5 m/s."""
    tr = _plant_trace(params_path, mu, 20.0, 12.0, lambda t: 0.0, torque, stop_below=0.3)
    ref = _mb_trace(tr, mu)
    m = f"straight braking {torque:g} N m, 20 m/s"

    def crossing(tra: Trace, v: float) -> Tuple[float, float]:
        i = int(np.argmax(tra.vx <= v))
        if tra.vx[i] > v:
            raise RuntimeError(f"{m}: never slowed to {v} m/s")
        w = (tra.vx[i - 1] - v) / (tra.vx[i - 1] - tra.vx[i])
        return tra.t[i - 1] + w * SAMPLE, tra.x[i - 1] + w * (tra.x[i] - tra.x[i - 1])

    out = [
        Check(m, "distance to 0.5 m/s", "m", crossing(tr, 0.5)[1], crossing(ref, 0.5)[1], "rel", 0.05)
    ]
    edges = [18.0, 10.0, 5.0, 2.0, 1.0, 0.5]
    for hi, lo in zip(edges, edges[1:]):
        decel = []
        for tra in (tr, ref):
            t_hi, t_lo = crossing(tra, hi)[0], crossing(tra, lo)[0]
            decel.append((hi - lo) / (t_lo - t_hi))
        out.append(Check(m, f"deceleration {hi:g}–{lo:g} m/s", "m/s²", decel[0], decel[1], "rel", 0.05))
    return out


def handling_checks(params: str = "full_size") -> List[Check]:
    """All CommonRoad MB comparisons for a built-in parameter set (``full_size``: MB's
    vehicle 2 is that car)."""
    import tempfile
    from vehiclemodels.parameters_vehicle2 import parameters_vehicle2

    if params != "full_size":
        raise ValueError("the MB comparison is for full_size (CommonRoad vehicle 2)")
    mu = float(parameters_vehicle2().tire.p_dy1)
    with tempfile.NamedTemporaryFile("w", suffix=".toml", delete=False) as f:
        f.write(comparison_params(params))
        path = f.name
    checks: List[Check] = []
    checks += step_steer(path, mu)
    checks += sine_steer(path, mu)
    checks += steer_ramp(path, mu)
    for torque in (1500.0, 3000.0):
        checks += straight_braking(path, mu, torque)
    return checks


# ---------------------------------------------------------------------------------------------
# Impacts: impulse-momentum theory


@dataclass(frozen=True)
class _Body:
    m: float
    iz: float


def _bodies(params: str) -> Tuple[_Body, _Body]:
    d = _toml.loads(_core.load_params(params))
    return _Body(d["bullet"]["mass"], d["bullet"]["iz"]), _Body(d["target"]["mass"], d["target"]["iz"])


def _perp(r: np.ndarray) -> np.ndarray:
    """ẑ × r."""
    return np.array([-r[1], r[0]])


def _cross(a: np.ndarray, b: np.ndarray) -> float:
    """The planar cross product a × b."""
    return float(a[0] * b[1] - a[1] * b[0])


def brach_impulse(
    bodies: Tuple[_Body, _Body],
    arms: Tuple[np.ndarray, np.ndarray],
    normal: np.ndarray,
    v_rel: np.ndarray,
    e: float,
    ratio: float,
) -> np.ndarray:
    """The impulse on body B (the target) of a planar rigid-body impact (Brach 1983): Newton
    restitution ``e`` on the normal velocity and an impulse ratio ``ratio`` = P_t / P_n
    (Brach's μ, here the one the contact produced), ``P = P_n (n + ratio t)`` with
    ``P_n = −(1 + e)(v_rel · n) / (nᵀ K (n + ratio t))``. ``arms``: c.g. → contact point of
    A and B; ``v_rel``: B's point velocity minus A's; ``t`` = n turned +90°."""
    k = (1.0 / bodies[0].m + 1.0 / bodies[1].m) * np.eye(2)
    for b, r in zip(bodies, arms):
        u = _perp(r)
        k += np.outer(u, u) / b.iz
    n = normal / np.linalg.norm(normal)
    d = n + ratio * _perp(n)
    pn = -(1.0 + e) * float(v_rel @ n) / float(n @ k @ d)
    return pn * d


def _impact(params: str, e: float, kind: str, approach: float) -> List[Check]:
    """One two-car impact with tyres off: ``kind`` "rear offset" (bullet square behind the
    target, 0.6 m to its right) or "quarter panel" (bullet at 25° into the right rear
    quarter)."""
    plant = _core.Plant(params, tyre_forces=False)
    d = _toml.loads(_core.load_params(params))
    lb, lt = d["bullet"], d["target"]
    target = [0.0, 0.0, 0.0, 15.0, 0.0, 0.0]
    if kind == "rear offset":
        rear = lt["length"] - lt["cg_to_front"]
        x = -(rear + lb["cg_to_front"]) - 0.002
        bullet = [x, -0.6, 0.0, 15.0 + approach, 0.0, 0.0]
    else:
        yaw = math.radians(25.0)
        # Aim the bullet's front-left corner at the target's right side 1.6 m behind its c.g.
        corner = np.array([lb["cg_to_front"], 0.5 * lb["width"]])
        c, s = math.cos(yaw), math.sin(yaw)
        corner_w = np.array([c * corner[0] - s * corner[1], s * corner[0] + c * corner[1]])
        hit = np.array([-1.6, -0.5 * lt["width"] - 0.002])
        pos = hit - corner_w
        # Both cars at the same forward speed; the bullet closes sideways at `approach`,
        # along the normal of the target's side.
        v_world = np.array([15.0, approach])
        vb = np.array([c * v_world[0] + s * v_world[1], -s * v_world[0] + c * v_world[1]])
        bullet = [pos[0], pos[1], yaw, vb[0], vb[1], 0.0]
    plant.reset(bullet, target)
    bodies = _bodies(params)

    def momenta() -> Tuple[np.ndarray, float, np.ndarray, np.ndarray]:
        xb, xt = plant.bullet_state(), plant.target_state()
        vb_w = _world_vel(xb[2], xb[3], xb[4])
        vt_w = _world_vel(xt[2], xt[0], xt[1])
        pb, pt = xb[:2], xt[6:8]
        lin = bodies[0].m * vb_w + bodies[1].m * vt_w
        ang = (
            bodies[0].iz * xb[5]
            + bodies[1].iz * xt[3]
            + bodies[0].m * _cross(pb, vb_w)
            + bodies[1].m * _cross(pt, vt_w)
        )
        return lin, ang, np.array([*vb_w, xb[5]]), np.array([*vt_w, xt[3]])

    lin0, ang0, sb0, st0 = momenta()
    yaws = (float(plant.bullet_state()[2]), float(plant.target_state()[2]))
    plant.take_contact_average()
    touched = False
    for _ in range(3000):
        plant.step()
        c = plant.contact()
        touched |= c is not None
        if touched and c is None:
            break
    avg = plant.take_contact_average()
    if avg is None:
        raise RuntimeError(f"{kind}: the cars never touched")
    lin1, ang1, sb1, st1 = momenta()
    # The rigid-body prediction acts at the impulse-weighted contact point and normal.
    arms = (
        _rotate(yaws[0], np.asarray(avg["point_in_bullet"])),
        _rotate(yaws[1], np.asarray(avg["point_in_target"])),
    )
    n = np.array([math.cos(avg["gamma"]), math.sin(avg["gamma"])])

    def point_vel(s: np.ndarray, arm: np.ndarray) -> np.ndarray:
        return s[:2] + s[2] * _perp(arm)

    v_rel0 = point_vel(st0, arms[1]) - point_vel(sb0, arms[0])
    v_rel1 = point_vel(st1, arms[1]) - point_vel(sb1, arms[0])
    e_meas = -float(v_rel1 @ n) / float(v_rel0 @ n)
    impulse = bodies[1].m * (st1[:2] - st0[:2])
    ratio = float(impulse @ _perp(n)) / float(impulse @ n)
    # The prediction at the restitution the contact produced (the file's value is checked
    # separately: the suspension takes a little energy a rigid body would not).
    pred = brach_impulse(bodies, arms, n, v_rel0, e_meas, ratio)
    dr_target = _cross(arms[1], pred) / bodies[1].iz
    dr_bullet = -_cross(arms[0], pred) / bodies[0].iz
    m = f"{kind} impact, {float(-(v_rel0 @ n)):.1f} m/s normal approach, tyres off"
    scale = bodies[1].m * approach
    return [
        Check(m, "restitution e (band)", "", e_meas, 0.15, "band", 0.45),
        Check(m, "restitution e (stated)", "", e_meas, e, "abs", 0.05),
        Check(m, "normal impulse", "N s", float(impulse @ n), float(pred @ n), "rel", 0.02),
        Check(m, "target speed change", "m/s", float(np.linalg.norm(st1[:2] - st0[:2])),
              float(np.linalg.norm(pred)) / bodies[1].m, "rel", 0.02),
        Check(m, "bullet speed change", "m/s", float(np.linalg.norm(sb1[:2] - sb0[:2])),
              float(np.linalg.norm(pred)) / bodies[0].m, "rel", 0.02),
        # A yaw change is a difference of moments about the c.g.: millimetres of pitch and
        # roll of the sprung body under the bumper-height force move it by a few per cent.
        Check(m, "target yaw-rate change", "rad/s", float(st1[2] - st0[2]), dr_target, "rel", 0.05),
        Check(m, "bullet yaw-rate change", "rad/s", float(sb1[2] - sb0[2]), dr_bullet, "rel", 0.05),
        Check(m, "linear momentum residual", "", float(np.linalg.norm(lin1 - lin0)) / scale, 0.0, "max", 1e-9),
        Check(m, "angular momentum residual", "", abs(ang1 - ang0) / (scale * 10.0), 0.0, "max", 1e-9),
    ]


def _rotate(yaw: float, v: np.ndarray) -> np.ndarray:
    c, s = math.cos(yaw), math.sin(yaw)
    return np.array([c * v[0] - s * v[1], s * v[0] + c * v[1]])


def _world_vel(yaw: float, vx: float, vy: float) -> np.ndarray:
    return _rotate(yaw, np.array([vx, vy]))


def impact_checks(params: str = "full_size") -> List[Check]:
    """Two-car impacts with tyres off at 2 m/s (rear offset) and 4.4 m/s (quarter panel)
    normal approach, against impulse–momentum theory at the restitution and impulse ratio
    the contact produced; the restitution against the file's."""
    e = float(_toml.loads(_core.load_params(params))["contact"]["restitution"])
    return _impact(params, e, "rear offset", 2.0) + _impact(params, e, "quarter panel", 4.4)


def all_checks(params: str = "full_size") -> List[Check]:
    """Every check of the suite."""
    return impact_checks(params) + handling_checks(params)


def format_table(checks: Sequence[Check]) -> str:
    """A Markdown table of the checks."""
    lines = [
        "| manoeuvre | quantity | plant | reference | tolerance | pass |",
        "|---|---|---|---|---|---|",
    ]
    for c in checks:
        ref = "—" if c.kind in ("max", "band") else f"{c.reference:.4g}"
        unit = f" {c.unit}" if c.unit else ""
        lines.append(
            f"| {c.manoeuvre} | {c.quantity} | {c.plant:.4g}{unit} | {ref} | "
            f"{c.tolerance_text()} | {'yes' if c.passed else 'NO'} |"
        )
    return "\n".join(lines)
