"""The peer solvers' side of the comparison: picopit's control models ported to CasADi
symbolics, and the OCP of one control step built on picopit's linearisation of it.

The ports follow crates/dynamics (bullet.rs, target4dof.rs, tyre.rs, target.rs) line by
line: the Magic Formula control curves (E = 0) at the static axle loads, the tangent slip
``vy / sqrt(vx^2 + V_LOW^2)``, the contact force ``sign * R(gamma - psi) f_c`` with its yaw
moment ``p x f`` (gamma and the point of action held over the step), and classic RK4 in the
same number of equal sub-steps as ``BulletModel::new`` / ``FourDofTarget::new``.

The OCP (see README.md for the full statement) is written stage-wise so that
structure-exploiting solvers (fatrop, HPIPM) can see the optimal-control structure:
variables ``[X_0, U_0, X_1, U_1, ..., X_N]`` with the augmented state
``X_k = [x_T,k (8), x_B,k (6), u_{k-1} (2), F_n,k-1 (1), s_{k-1} (1)]`` and the control
``U_k = [delta_k, T_r,k, F_n,k, F_t,k, s_k]``; constraints per stage in the order
``[gap_k, path constraints of stage k]``.
"""

from __future__ import annotations

import math
import sys
from dataclasses import dataclass
from typing import Any, Dict, List, Optional, Sequence

import casadi as ca
import numpy as np

if sys.version_info >= (3, 11):
    import tomllib
else:  # Python 3.9 and 3.10: the tomli backport (a picopit dependency there)
    import tomli as tomllib

GRAVITY = 9.80665
V_LOW = 0.5  # tyre.rs
V_BRAKE = 0.5  # target4dof.rs
V_STALL_BLEND = 0.25  # target4dof.rs
AIR_DENSITY = 1.204  # plant/mod.rs
STABLE_DOWN_TO = 1.0  # bullet.rs
FAR = 1.0e4  # mpc.rs: a right-hand side that makes a row inactive

NT, NB = 8, 6
NX = NT + NB + 4  # augmented state
NU = 5
T_POSE = (6, 7, 2)  # X, Y, psi within x_T
B_POSE = (0, 1, 2)  # within x_B


# ---------------------------------------------------------------------------------------
# Models
# ---------------------------------------------------------------------------------------


@dataclass(frozen=True)
class AxleCurve:
    b: float
    c: float
    d: float

    @staticmethod
    def control(tyre: Dict[str, float], fz_axle: float, mu: float) -> "AxleCurve":
        """``AxleCurve::control``: the Magic Formula at the static axle load, E = 0."""
        d = mu * fz_axle
        k = tyre["pky1"] * fz_axle
        c = tyre["pcy1"]
        return AxleCurve(b=k / (c * d), c=c, d=d)

    def cornering_stiffness(self) -> float:
        return self.b * self.c * self.d

    def force(self, alpha):
        return -self.d * ca.sin(self.c * ca.atan(self.b * alpha))


def tan_slip(vx, vy):
    return vy / ca.sqrt(vx * vx + V_LOW * V_LOW)


def axles(p: Dict[str, Any], mu: float):
    lsum = p["lf"] + p["lr"]
    w = p["mass"] * GRAVITY
    fz_front, fz_rear = w * p["lr"] / lsum, w * p["lf"] / lsum
    return AxleCurve.control(p["tyre"], fz_front, mu), AxleCurve.control(p["tyre"], fz_rear, mu)


def stable_substeps(dt: float, cornering_sum: float, m_eff: float) -> int:
    n = math.ceil(dt * cornering_sum / (m_eff * STABLE_DOWN_TO * 2.5))
    return n if n >= 1 else 1


def contact_force(fc, gamma, point, psi, sign: float):
    """``sign * R(gamma - psi) f_c`` in the body frame and its yaw moment ``p x f``."""
    sg, cg = ca.sin(gamma), ca.cos(gamma)
    sp, cp = ca.sin(psi), ca.cos(psi)
    s = sg * cp - cg * sp
    c = cg * cp + sg * sp
    fx = sign * (c * fc[0] - s * fc[1])
    fy = sign * (s * fc[0] + c * fc[1])
    return fx, fy, point[0] * fy - point[1] * fx


def front_lateral(curve: AxleCurve, lf, vx, vy, r, sd, cd):
    vyf = vy + lf * r
    vxw = cd * vx + sd * vyf
    vyw = -sd * vx + cd * vyf
    return curve.force(tan_slip(vxw, vyw))


def rear_lateral(curve: AxleCurve, lr, vx, vy, r):
    return curve.force(tan_slip(vx, vy - lr * r))


def rk4_substeps(f, x, dt: float, n: int):
    h = dt / n
    for _ in range(n):
        k1 = f(x)
        k2 = f(x + k1 * (0.5 * h))
        k3 = f(x + k2 * (0.5 * h))
        k4 = f(x + k3 * h)
        x = x + (k1 + (k2 + k3) * 2.0 + k4) * (h / 6.0)
    return x


class BulletPort:
    """``dynamics::bullet::BulletModel`` (single track, RK4 in ``substeps`` sub-steps)."""

    def __init__(self, p: Dict[str, Any], mu: float, dt: float):
        self.p = p
        self.front, self.rear = axles(p, mu)
        self.dt = dt
        self.drive_gain = p["drive_efficiency"] * p["gear_ratio"] / p["wheel_radius"]
        cs = self.front.cornering_stiffness() + self.rear.cornering_stiffness()
        self.substeps = stable_substeps(dt, cs, p["mass"])

    def rhs(self, x, u, fc, gamma, point):
        p = self.p
        psi, vx, vy, r = x[2], x[3], x[4], x[5]
        sd, cd = ca.sin(u[0]), ca.cos(u[0])
        sp, cp = ca.sin(psi), ca.cos(psi)
        fyf = front_lateral(self.front, p["lf"], vx, vy, r, sd, cd)
        fyr = rear_lateral(self.rear, p["lr"], vx, vy, r)
        fcx, fcy, mc = contact_force(fc, gamma, point, psi, -1.0)
        fxr = self.drive_gain * u[1]
        return ca.vertcat(
            vx * cp - vy * sp,
            vx * sp + vy * cp,
            r,
            (fxr - fyf * sd + fcx) / p["mass"] + r * vy,
            (fyf * cd + fyr + fcy) / p["mass"] - r * vx,
            (p["lf"] * fyf * cd - p["lr"] * fyr + mc) / p["iz"],
        )

    def step(self, x, u, fc, gamma, point):
        return rk4_substeps(lambda xs: self.rhs(xs, u, fc, gamma, point), x, self.dt, self.substeps)

    def function(self) -> ca.Function:
        x, u, fc, pt = ca.SX.sym("x", 6), ca.SX.sym("u", 2), ca.SX.sym("fc", 2), ca.SX.sym("pt", 2)
        g = ca.SX.sym("gamma")
        return ca.Function("bullet_step", [x, u, fc, g, pt], [self.step(x, u, fc, g, pt)])


class FourDofPort:
    """``dynamics::target4dof::FourDofTarget`` (4-DOF, RK4 in ``substeps`` sub-steps)."""

    def __init__(self, p: Dict[str, Any], mu: float, dt: float):
        self.p = p
        h = p["h_sprung"] - p["h_roll_axis"]
        self.ms_h = p["sprung_mass"] * h
        self.ixx = p["ix_sprung"] + p["sprung_mass"] * h * h
        self.front, self.rear = axles(p, mu)
        self.roll_k = self.ms_h * GRAVITY - (p["roll_stiffness_front"] + p["roll_stiffness_rear"])
        self.roll_c = p["roll_damping_front"] + p["roll_damping_rear"]
        self.h_contact = p["bumper_height"] - p["h_roll_axis"]
        self.inv_det = 1.0 / (p["mass"] * self.ixx - self.ms_h * self.ms_h)
        self.dt = dt
        m_eff = p["mass"] - self.ms_h * self.ms_h / self.ixx
        cs = self.front.cornering_stiffness() + self.rear.cornering_stiffness()
        self.substeps = stable_substeps(dt, cs, m_eff)
        pw = p.get("powertrain")
        k = p["gear_ratio"] / p["wheel_radius"]
        self.driveline = None if pw is None else (
            k * pw["engine_drag_torque"], k * pw["stall_torque"], pw["stall_speed"] / k)
        self.rolling = p["rolling_resistance"] * p["mass"] * GRAVITY
        self.drag = 0.5 * AIR_DENSITY * p["drag_area"]

    def rhs(self, x, u, fc, gamma, point):
        p = self.p
        vx, vy, psi, r, pr, phi = x[0], x[1], x[2], x[3], x[4], x[5]
        sd, cd = ca.sin(u[0]), ca.cos(u[0])
        sp, cp = ca.sin(psi), ca.cos(psi)
        t = vx / ca.sqrt(vx * vx + V_BRAKE * V_BRAKE)
        brake = ca.fmax(u[1], 0.0) / p["wheel_radius"]
        drive = ca.fmax(-u[1], 0.0) / p["wheel_radius"]
        beta = p["brake_bias_front"]
        fxf, fxr = -beta * brake * t, -(1.0 - beta) * brake * t
        if self.driveline is None:
            fxr = fxr + drive
        else:
            drag, hold, v_stall = self.driveline
            w = 1.0 / (1.0 + ca.exp(-(vx - v_stall) / V_STALL_BLEND))
            fxr = fxr + w * (drive - drag * t) - (1.0 - w) * hold * t
        fres = -self.rolling * t - self.drag * vx * ca.fabs(vx)
        fyf = front_lateral(self.front, p["lf"], vx, vy, r, sd, cd)
        fyr = rear_lateral(self.rear, p["lr"], vx, vy, r)
        fcx, fcy, mc = contact_force(fc, gamma, point, psi, 1.0)
        ffx = fxf * cd - fyf * sd
        ffy = fxf * sd + fyf * cd
        sfx = ffx + fxr + fres + fcx
        sfy = ffy + fyr + fcy
        smz = p["lf"] * ffy - p["lr"] * fyr + mc
        mroll = self.roll_k * phi - self.roll_c * pr + fcy * self.h_contact
        ay = (self.ixx * sfy - self.ms_h * mroll) * self.inv_det
        pd = (p["mass"] * mroll - self.ms_h * sfy) * self.inv_det
        return ca.vertcat(
            sfx / p["mass"] + vy * r,
            ay - vx * r,
            r,
            smz / p["iz"],
            pd,
            pr,
            vx * cp - vy * sp,
            vx * sp + vy * cp,
        )

    def step(self, x, u, fc, gamma, point):
        return rk4_substeps(lambda xs: self.rhs(xs, u, fc, gamma, point), x, self.dt, self.substeps)

    def function(self) -> ca.Function:
        x, u, fc, pt = ca.SX.sym("x", 8), ca.SX.sym("u", 2), ca.SX.sym("fc", 2), ca.SX.sym("pt", 2)
        g = ca.SX.sym("gamma")
        return ca.Function("target_step", [x, u, fc, g, pt], [self.step(x, u, fc, g, pt)])


# ---------------------------------------------------------------------------------------
# The OCP of one control step
# ---------------------------------------------------------------------------------------


@dataclass
class OcpConfig:
    """What the OCP reads from picopit: parameters, road adhesion and the MPC settings."""

    params: Dict[str, Any]
    mu: float
    settings: Dict[str, Any]

    @staticmethod
    def from_mpc(params_toml: str, mu: float, settings_toml: str) -> "OcpConfig":
        return OcpConfig(tomllib.loads(params_toml), mu, tomllib.loads(settings_toml))


# Per-stage parameter block (stage j = 0..N-1, rows at x_{j+1}):
#  0 gamma, 1:3 point_target, 3:5 point_bullet, 5 gap, 6:9 grad_b, 9:12 grad_t,
#  12 band_rhs (band - gap, or +inf when the band row is off),
#  13:16 road_b g, 16 rhs, 17:20 road_t g, 20 rhs, 21:24 obs_b g, 24 rhs, 25:28 obs_t g, 28 rhs,
#  29:32 bullet pose at the linearisation (x_{j+1}), 32:35 target pose at the linearisation,
#  35:43 reference stage [rel_x, rel_y, rel_heading, rel_speed, track, fn_lo, fn_hi, env_lat]
NP_STAGE = 43
# Global block: x0 (NX: x_T, x_B, last_command, 0, 0), target_input (2), target_heading,
# target_weight.
NP_GLOBAL = NX + 4


class PeerOcp:
    """The peer NLP of one control step, built once; per-step data are parameters and
    bounds. ``solve`` returns the plan's ``u`` (N, 2) and ``f`` (N, 2)."""

    def __init__(self, cfg: OcpConfig, solver: str, options: Optional[Dict[str, Any]] = None):
        s = cfg.settings
        self.n = n = int(s["horizon"])
        self.dt = dt = float(s["dt"])
        b = cfg.params["bullet"]
        self.bullet = BulletPort(b, cfg.mu, dt)
        self.target = FourDofPort(cfg.params["target"], cfg.mu, dt)
        w, c = s["weights"], s["contact"]
        self.steer_max, self.steer_rate = b["steer_max"], b["steer_rate_max"]
        self.torque_min, self.torque_max = b["drive_torque_min"], b["drive_torque_max"]
        ts = max(abs(b["drive_torque_max"]), abs(b["drive_torque_min"]))
        fs = 0.25 * c["force_max"]
        # Decision variables carry picopit's QP scaling (a change of variables only): the
        # torque over its largest magnitude, the forces over force_max / 4.
        self.ts, self.fs = ts, fs
        self.mu_c, self.kc, self.band = c["friction"], c["stiffness"], c["band"]
        self.solver_name = solver

        fb, ft = self.bullet.function(), self.target.function()
        X = [ca.MX.sym(f"X{k}", NX) for k in range(n + 1)]
        U = [ca.MX.sym(f"U{k}", NU) for k in range(n)]
        P = ca.MX.sym("P", NP_GLOBAL + NP_STAGE * n)
        x0 = P[:NX]
        ut = P[NX : NX + 2]
        psi_ref, wt = P[NX + 2], P[NX + 3]
        stage_p = [P[NP_GLOBAL + NP_STAGE * j : NP_GLOBAL + NP_STAGE * (j + 1)] for j in range(n)]

        def soft_rows(xk, j):
            """Rows of step j at x_{j+1} = xk (its x_T, x_B, carried F_n,j and s_j):
            g(x) <= 0 after moving the right-hand side over."""
            q = stage_p[j]
            xt, xb = xk[:NT], xk[NT : NT + NB]
            fn, sl = xk[NT + NB + 2] * fs, xk[NT + NB + 3]
            db = ca.vertcat(*[xb[i] for i in B_POSE]) - q[29:32]
            dt_ = ca.vertcat(*[xt[i] for i in T_POSE]) - q[32:35]
            lin_gap = q[5] + ca.dot(q[6:9], db) + ca.dot(q[9:12], dt_)
            sn, cs = ca.sin(xt[2]), ca.cos(xt[2])
            rel_y = -sn * (xb[0] - xt[6]) + cs * (xb[1] - xt[7])
            dev = rel_y - q[35 + 1]
            env = q[35 + 7]
            rows = [
                (-lin_gap - fn / self.kc - sl, 0.0),  # penetration
                (fn / self.kc + lin_gap - sl, None),  # band (rhs: band, or inf)
                (ca.dot(q[13:16], db) - sl, 16),
                (ca.dot(q[17:20], dt_) - sl, 20),
                (ca.dot(q[21:24], db) - sl, 24),
                (ca.dot(q[25:28], dt_) - sl, 28),
                (dev - sl, -1),
                (-dev - sl, -1),
            ]
            out = []
            for expr, rhs in rows:
                if rhs is None:
                    out.append(expr - self.band)  # ub set per step (0 or inf)
                elif rhs == -1:
                    out.append(expr - env)
                elif isinstance(rhs, int):
                    out.append(expr - q[rhs])
                else:
                    out.append(expr)
            return out

        def tracking(xk, j):
            q = stage_p[j]
            xt, xb = xk[:NT], xk[NT : NT + NB]
            sn, cs = ca.sin(xt[2]), ca.cos(xt[2])
            dx, dy = xb[0] - xt[6], xb[1] - xt[7]
            e = [
                cs * dx + sn * dy - q[35],
                -sn * dx + cs * dy - q[36],
                xb[2] - xt[2] - q[37],
                xb[3] - xt[0] - q[38],
            ]
            we = [w["rel_long"], w["rel_lat"], w["rel_heading"], w["rel_speed"]]
            return q[39] * sum(wi * ei * ei for wi, ei in zip(we, e))

        J = 0
        g: List[ca.MX] = []
        self.g_kind: List[str] = []  # eq / rate / cone / soft:<row index>:<stage>
        self.ng_stage: List[int] = []
        for k in range(n + 1):
            ng0 = len(self.g_kind)
            xk = X[k]
            if k < n:
                uk = U[k]
                q = stage_p[k]
                fc = uk[2:4] * fs
                xt_next = ft(xk[:NT], ut, fc, q[0], q[1:3])
                xb_next = fb(xk[NT : NT + NB], ca.vertcat(uk[0], uk[1] * ts), fc, q[0], q[3:5])
                nxt = ca.vertcat(xt_next, xb_next, uk[0:2], uk[2], uk[4])
                g.append(X[k + 1] - nxt)
                self.g_kind += ["gap"] * NX
                ng0 = len(self.g_kind)  # gap rows are not path constraints
            if k == 0:
                g.append(xk - x0)
                self.g_kind += ["eq"] * NX
            if k < n:
                uk = U[k]
                g.append(uk[0] - xk[NT + NB])
                self.g_kind.append("rate")
                g.append(uk[3] - self.mu_c * uk[2])
                g.append(-uk[3] - self.mu_c * uk[2])
                self.g_kind += ["cone", "cone"]
                # Cost of stage k's inputs and force.
                q = stage_p[k]
                up = xk[NT + NB : NT + NB + 2]
                J += w["steer"] * uk[0] ** 2 + w["torque"] * uk[1] ** 2
                J += w["steer_rate"] * (uk[0] - up[0]) ** 2
                J += w["torque_rate"] * (uk[1] - up[1]) ** 2
                fn_k = uk[2] * fs
                dist = (fn_k - ca.fmin(ca.fmax(fn_k, q[40]), q[41])) / fs
                J += w["corridor"] * dist * dist
                J += w["penalty"] * uk[4]
            if k >= 1:
                rows = soft_rows(xk, k - 1)
                g += rows
                self.g_kind += [f"soft:{i}:{k - 1}" for i in range(len(rows))]
                J += tracking(xk, k - 1)
            if k == n:
                xt = xk[:NT]
                eh = xt[2] - psi_ref
                J += w["target"] * wt * (
                    w["target_heading"] * eh * eh + w["target_speed"] * (xt[0] ** 2 + xt[1] ** 2)
                )
            self.ng_stage.append(len(self.g_kind) - ng0)

        z = []
        for k in range(n + 1):
            z.append(X[k])
            if k < n:
                z.append(U[k])
        self.z = ca.vertcat(*z)
        self.g = ca.vertcat(*g)
        self.nz, self.ng = self.z.shape[0], self.g.shape[0]
        nlp = {"x": self.z, "f": J, "g": self.g, "p": P}
        self.equality = [kind in ("gap", "eq") for kind in self.g_kind]
        self.solver = self._make(nlp, solver, options or {})

    # -- solver construction -----------------------------------------------------------

    def _make(self, nlp, solver: str, options: Dict[str, Any]) -> ca.Function:
        n = self.n
        if solver == "ipopt":
            opts = {
                "expand": True,
                "print_time": False,
                "ipopt": {
                    "tol": 1e-4,
                    "acceptable_tol": 1e-3,
                    "print_level": 0,
                    "sb": "yes",
                    "max_iter": 500,
                },
            }
        elif solver == "fatrop":
            opts = {
                "expand": True,
                "print_time": False,
                "structure_detection": "auto",
                "equality": self.equality,
                "fatrop": {"tol": 1e-4, "print_level": 0, "max_iter": 500},
            }
        elif solver == "sqp_hpipm":
            opts = {
                "expand": True,
                "print_time": False,
                "qpsol": "hpipm",
                "hessian_approximation": "exact",
                "convexify_strategy": "regularize",
                "convexify_margin": 1e-6,
                "max_iter": 50,
                "tol_pr": 1e-4,
                "tol_du": 1e-4,
                "print_header": False,
                "print_iteration": False,
                "print_status": False,
                "qpsol_options": {
                    "N": n,
                    "nx": [NX] * (n + 1),
                    "nu": [NU] * n + [0],
                    "ng": self.ng_stage,
                    "error_on_fail": False,
                    "hpipm": {"mode": "balance", "iter_max": 100, "res_g_max": 1e-6,
                              "res_b_max": 1e-8, "res_d_max": 1e-8, "res_m_max": 1e-8},
                },
            }
            solver = "sqpmethod"
        else:
            raise ValueError(f"unknown peer solver {solver!r}")
        _merge(opts, options)
        return ca.nlpsol(f"peer_{self.solver_name}", solver, nlp, opts)

    # -- per-step data -----------------------------------------------------------------

    def data(self, lin: Dict[str, Any], reference: np.ndarray, target: np.ndarray,
             bullet: np.ndarray, last_command: np.ndarray, target_input: np.ndarray,
             target_heading: float, target_weight: float) -> Dict[str, np.ndarray]:
        """Parameters, bounds and the initial guess (the linearisation point) of one step."""
        n = self.n
        x0 = np.concatenate([target, bullet, [last_command[0], last_command[1] / self.ts, 0.0, 0.0]])
        p = np.zeros(NP_GLOBAL + NP_STAGE * n)
        p[:NX] = x0
        p[NX : NX + 2] = target_input
        p[NX + 2], p[NX + 3] = target_heading, target_weight
        coupled = bool(np.any(lin["band"]))
        tl, bl = np.asarray(lin["target_lin"]), np.asarray(lin["bullet_lin"])
        for j in range(n):
            q = p[NP_GLOBAL + NP_STAGE * j : NP_GLOBAL + NP_STAGE * (j + 1)]
            q[0] = lin["gamma"][j]
            q[1:3] = lin["point_target"][j]
            q[3:5] = lin["point_bullet"][j]
            q[5] = lin["gap"][j]
            q[6:9] = lin["gap_grad_bullet"][j]
            q[9:12] = lin["gap_grad_target"][j] if coupled else 0.0
            q[12] = 0.0  # unused (the band row's bound is in ubg)
            for off, name in ((13, "road_bullet"), (17, "road_target"), (21, "obstacle_bullet"),
                              (25, "obstacle_target")):
                q[off : off + 4] = lin[name][j]
            q[29:32] = bl[j + 1, list(B_POSE)]
            q[32:35] = tl[j + 1, list(T_POSE)]
            q[35:43] = reference[j]
        lbz, ubz, z0 = [], [], []
        ul, fl = np.asarray(lin["u_lin"]), np.asarray(lin["f_lin"])
        ts, fs = self.ts, self.fs
        inf = np.inf
        for k in range(n + 1):
            lbz += [-inf] * NX
            ubz += [inf] * NX
            up = last_command if k == 0 else ul[k - 1]
            fnp = 0.0 if k == 0 else fl[k - 1, 0]
            z0 += list(tl[k]) + list(bl[k]) + [up[0], up[1] / ts, fnp / fs, 0.0]
            if k < n:
                fmax = float(lin["fn_max"][k])
                lbz += [-self.steer_max, self.torque_min / ts, 0.0, -self.mu_c * fmax / fs, 0.0]
                ubz += [self.steer_max, self.torque_max / ts, fmax / fs, self.mu_c * fmax / fs, inf]
                z0 += [ul[k, 0], ul[k, 1] / ts, fl[k, 0] / fs, fl[k, 1] / fs, 0.0]
        lbg, ubg = [], []
        dmax = self.steer_rate * self.dt
        for kind in self.g_kind:
            if kind in ("gap", "eq"):
                lbg.append(0.0)
                ubg.append(0.0)
            elif kind == "rate":
                lbg.append(-dmax)
                ubg.append(dmax)
            elif kind == "cone":
                lbg.append(-inf)
                ubg.append(0.0)
            else:
                _, row, j = kind.split(":")
                row, j = int(row), int(j)
                lbg.append(-inf)
                off = {2: 16, 3: 20, 4: 24, 5: 28}.get(row)
                if row == 1:
                    ubg.append(0.0 if lin["band"][j] else inf)
                elif off is not None and not coupled and row in (3, 5):
                    # The bullet-only QP has no target rows (its target is fixed).
                    ubg.append(inf)
                else:
                    ubg.append(0.0)
        return {
            "p": p,
            "lbx": np.array(lbz),
            "ubx": np.array(ubz),
            "x0": np.array(z0),
            "lbg": np.array(lbg),
            "ubg": np.array(ubg),
        }

    def solve(self, d: Dict[str, np.ndarray]):
        """Solve; returns (u (N, 2), f (N, 2), stats dict, the raw solution vector)."""
        try:
            sol = self.solver(x0=d["x0"], p=d["p"], lbx=d["lbx"], ubx=d["ubx"], lbg=d["lbg"],
                              ubg=d["ubg"])
            z = np.asarray(sol["x"]).ravel()
        except RuntimeError as e:  # a solver that throws: keep the initial guess, flag it
            z = d["x0"]
            return self.unpack(z) + ({"success": False, "return_status": f"error: {e}"[:80]},
                                     z)
        try:
            st = self.solver.stats()
        except RuntimeError:  # sqpmethod after a failed QP has no status string
            st = {"success": False, "return_status": "qp_failed"}
        return self.unpack(z) + (st, z)

    def unpack(self, z: np.ndarray):
        n = self.n
        u = np.zeros((n, 2))
        f = np.zeros((n, 2))
        for k in range(n):
            o = k * (NX + NU) + NX
            u[k] = [z[o], z[o + 1] * self.ts]
            f[k] = z[o + 2 : o + 4] * self.fs
        return u, f


def _merge(base: Dict[str, Any], extra: Dict[str, Any]) -> None:
    for k, v in extra.items():
        if isinstance(v, dict) and isinstance(base.get(k), dict) and k != "qpsol_options":
            _merge(base[k], v)
        else:
            base[k] = v
