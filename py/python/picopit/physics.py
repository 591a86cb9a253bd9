"""The 4-DOF Newton–Euler target model in PyTorch (vectorised, float64): the physics prior
of the PINN and PicoPINN losses.

It is an independent implementation of the equations of ``crates/dynamics/src/target4dof.rs``
(``docs/models.md``), from the same parameter TOML:

```
m (v̇x − vy r)              = ΣF_x
m (v̇y + vx r) + m_s h ṗ    = ΣF_y
I_z ṙ                      = ΣM_z                       (M_z includes the contact moment p × f_b)
I_xx ṗ + m_s h (v̇y + vx r) = (m_s g h − K_φ) φ − C_φ p + F_cy h_c
φ̇ = p, ψ̇ = r, Ẋ = vx cosψ − vy sinψ, Ẏ = vx sinψ + vy cosψ
```

with the Magic Formula axle curves at the static axle loads (E = 0), the smooth brake
sign, the driver's signed longitudinal torque (``T_b ≥ 0`` brakes, ``T_b < 0`` the throttle
at the driven axle), the powertrain in gear (closed-throttle engine braking, blended into the
stalled engine's hold below the stall speed) and rolling resistance and drag. The discrete
map integrates them over one step with classic RK4 in the same stable
number of sub-steps as the Rust model, so on data produced by ``FourDofTarget`` the physics
residual (network increment minus the integrated Newton–Euler increment) vanishes to
rounding (``tests/test_surrogates.py`` checks it).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Mapping

import torch

GRAVITY = 9.80665
V_LOW = 0.5  # slip-angle regularisation speed (m/s), as crates/dynamics tyre::V_LOW
V_BRAKE = 0.5  # brake-sign regularisation speed (m/s)
V_STALL_BLEND = 0.25  # running/stalled switch width (m/s), as target4dof::V_STALL_BLEND
AIR_DENSITY = 1.204  # kg/m³, as plant::AIR_DENSITY
STABLE_DOWN_TO = 1.0


@dataclass(frozen=True)
class FourDof:
    """Constants of the 4-DOF model of one vehicle (the ``[target]`` table of a parameter set)."""

    mass: float
    iz: float
    lf: float
    lr: float
    ms_h: float
    ixx: float
    roll_k: float
    roll_c: float
    h_contact: float
    inv_rw: float
    bias: float
    fz_front: float
    fz_rear: float
    pcy1: float
    rolling: float  # f_r m g (N)
    drag: float  # ½ ρ C_d A (kg/m)
    drive_drag: float  # i_g T_drag / R_w (N); 0 without a powertrain
    drive_hold: float  # i_g T_stall / R_w (N)
    v_stall: float  # ω_stall R_w / i_g (m/s); None-like -inf without a powertrain
    k_front: float  # axle cornering stiffness (N/rad), mu-independent
    k_rear: float
    dt: float
    substeps: int

    @classmethod
    def from_params(cls, p: Mapping[str, Any], dt: float = 0.05) -> "FourDof":
        h = p["h_sprung"] - p["h_roll_axis"]
        ms_h = p["sprung_mass"] * h
        ixx = p["ix_sprung"] + p["sprung_mass"] * h * h
        L = p["lf"] + p["lr"]
        w = p["mass"] * GRAVITY
        fzf, fzr = w * p["lr"] / L, w * p["lf"] / L
        tyre = p["tyre"]
        # CommonRoad's tyre: cornering stiffness p_Ky1 F_z, peak μ F_z (tyre::AxleCurve).
        kf = tyre["pky1"] * fzf
        kr = tyre["pky1"] * fzr
        m_eff = p["mass"] - ms_h * ms_h / ixx
        pt = p.get("powertrain")
        i_g, r_w = p["gear_ratio"], p["wheel_radius"]
        n = math.ceil(dt * (kf + kr) / (m_eff * STABLE_DOWN_TO * 2.5))
        return cls(
            mass=p["mass"], iz=p["iz"], lf=p["lf"], lr=p["lr"], ms_h=ms_h, ixx=ixx,
            roll_k=ms_h * GRAVITY - (p["roll_stiffness_front"] + p["roll_stiffness_rear"]),
            roll_c=p["roll_damping_front"] + p["roll_damping_rear"],
            h_contact=p["bumper_height"] - p["h_roll_axis"],
            inv_rw=1.0 / p["wheel_radius"], bias=p["brake_bias_front"],
            fz_front=fzf, fz_rear=fzr, pcy1=tyre["pcy1"],
            rolling=p["rolling_resistance"] * p["mass"] * GRAVITY,
            drag=0.5 * AIR_DENSITY * p["drag_area"],
            drive_drag=i_g * pt["engine_drag_torque"] / r_w if pt else 0.0,
            drive_hold=i_g * pt["stall_torque"] / r_w if pt else 0.0,
            v_stall=pt["stall_speed"] * r_w / i_g if pt else -math.inf,
            k_front=kf, k_rear=kr, dt=dt, substeps=max(1, n),
        )

    # ------------------------------------------------------------------ axle curves
    def _curve(self, fz_axle: float, mu: torch.Tensor, k: float):
        """(B, C, D) of the control axle curve for per-sample road adhesion ``mu``."""
        d = mu * fz_axle
        c = self.pcy1
        return k / (c * d), c, d

    def rates(self, x, sd, cd, tb, fcx, fcy, mc, curves):
        """ẋ (B, 8) for body-frame contact force ``(fcx, fcy)`` and moment ``mc``."""
        vx, vy, psi, r, p, phi = x[:, 0], x[:, 1], x[:, 2], x[:, 3], x[:, 4], x[:, 5]
        (bf, cf, df), (br, cr, dr) = curves
        sp, cp = torch.sin(psi), torch.cos(psi)
        t = vx / torch.sqrt(vx * vx + V_BRAKE * V_BRAKE)
        brake = torch.clamp(tb, min=0.0) * self.inv_rw
        drive = torch.clamp(-tb, min=0.0) * self.inv_rw
        fxf = -self.bias * brake * t
        fxr = -(1.0 - self.bias) * brake * t
        if math.isinf(self.v_stall):
            fxr = fxr + drive
        else:
            w = torch.sigmoid((vx - self.v_stall) / V_STALL_BLEND)
            fxr = fxr + w * (drive - self.drive_drag * t) - (1.0 - w) * self.drive_hold * t
        fres = -self.rolling * t - self.drag * vx * torch.abs(vx)
        vyf = vy + self.lf * r
        vxw, vyw = cd * vx + sd * vyf, -sd * vx + cd * vyf
        af = vyw / torch.sqrt(vxw * vxw + V_LOW * V_LOW)
        fyf = -df * torch.sin(cf * torch.atan(bf * af))
        ar = (vy - self.lr * r) / torch.sqrt(vx * vx + V_LOW * V_LOW)
        fyr = -dr * torch.sin(cr * torch.atan(br * ar))
        ffx = fxf * cd - fyf * sd
        ffy = fxf * sd + fyf * cd
        sfx = ffx + fxr + fres + fcx
        sfy = ffy + fyr + fcy
        smz = self.lf * ffy - self.lr * fyr + mc
        mroll = self.roll_k * phi - self.roll_c * p + fcy * self.h_contact
        det = self.mass * self.ixx - self.ms_h * self.ms_h
        ay = (self.ixx * sfy - self.ms_h * mroll) / det
        pd = (self.mass * mroll - self.ms_h * sfy) / det
        return torch.stack([
            sfx / self.mass + vy * r,
            ay - vx * r,
            r,
            smz / self.iz,
            pd,
            p,
            vx * cp - vy * sp,
            vx * sp + vy * cp,
        ], dim=1)

    def step(self, x, u, fc, gamma, point, mu, substeps: int | None = None):
        """One discrete step of ``dt`` (RK4 in ``substeps`` sub-steps, default the stable
        count). All arguments are batched tensors: x (B, 8), u (B, 2), fc (B, 2),
        gamma (B,), point (B, 2), mu (B,). The contact force is rotated into the body frame
        at every stage with the stage's heading (γ and the point held), as in Rust."""
        n = self.substeps if substeps is None else int(substeps)
        h = self.dt / n
        delta, tb = u[:, 0], u[:, 1]
        sd, cd = torch.sin(delta), torch.cos(delta)
        sg, cg = torch.sin(gamma), torch.cos(gamma)
        curves = (self._curve(self.fz_front, mu, self.k_front), self._curve(self.fz_rear, mu, self.k_rear))

        def f(xs):
            sp, cp = torch.sin(xs[:, 2]), torch.cos(xs[:, 2])
            s, c = sg * cp - cg * sp, cg * cp + sg * sp  # sin, cos of (γ − ψ)
            fcx = c * fc[:, 0] - s * fc[:, 1]
            fcy = s * fc[:, 0] + c * fc[:, 1]
            mc = point[:, 0] * fcy - point[:, 1] * fcx
            return self.rates(xs, sd, cd, tb, fcx, fcy, mc, curves)

        xk = x
        for _ in range(n):
            k1 = f(xk)
            k2 = f(xk + 0.5 * h * k1)
            k3 = f(xk + 0.5 * h * k2)
            k4 = f(xk + h * k3)
            xk = xk + (h / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
        return xk

