//! The 4-DOF analytic target model: longitudinal, lateral, yaw and roll, with planar
//! kinematics, the driver's steer and brake, Magic Formula axle curves and the contact
//! force. It is the first [`TargetModel`] and the physics prior of the PINN.
//!
//! State `x_T = [vx, vy, ψ, r, p, φ, X, Y]`, input `u_T = [δ, T_b]` (front steer, and the
//! driver's longitudinal torque at the wheels: `T_b ≥ 0` the total service-brake torque,
//! `T_b < 0` the throttle's drive torque `−T_b` at the driven rear axle), contact
//! `f_c = [F_n, F_t]` (the target receives `+f_c`), and the powertrain in gear
//! ([`crate::params::PowertrainParams`], absent for a vehicle without one):
//!
//! ```text
//! B = max(T_b, 0)/R_w,  D = max(−T_b, 0)/R_w,  s(v) = v/sqrt(v² + v_b²)   (v_b = 0.5 m/s)
//! w(v) = 1/(1 + exp(−(v − v_stall)/v_w))   (running engine; v_stall = ω_stall R_w/i_g, v_w = 0.25 m/s)
//! F_x,f = −β B s(vx)
//! F_x,r = −(1−β) B s(vx) + w(vx) (D − i_g T_drag/R_w · s(vx)) − (1 − w(vx)) i_g T_stall/R_w · s(vx)
//! F_res = −f_r m g s(vx) − ½ ρ C_d A vx |vx|   (rolling resistance and drag)
//! ΣF_x = F_x,f cosδ − F_y,f sinδ + F_x,r + F_res + F_cx
//! ΣF_y = F_x,f sinδ + F_y,f cosδ + F_y,r + F_cy
//! ΣM_z = l_f (F_x,f sinδ + F_y,f cosδ) − l_r F_y,r + M_c
//! m (v̇x − vy r)                  = ΣF_x
//! m (v̇y + vx r) + m_s h ṗ        = ΣF_y
//! I_z ṙ                          = ΣM_z
//! I_xx ṗ + m_s h (v̇y + vx r)     = (m_s g h − K_φ) φ − C_φ p + F_cy h_c
//! φ̇ = p,  ψ̇ = r,  Ẋ = vx cosψ − vy sinψ,  Ẏ = vx sinψ + vy cosψ
//! ```
//!
//! with `h` the roll arm (sprung c.g. above the roll axis), `I_xx = I_x,s + m_s h²`,
//! `K_φ`, `C_φ` the total roll stiffness and damping, `h_c = h_bumper − h_roll axis` and
//! `(F_cx, F_cy, M_c) = c.body_force(ψ, +1)`. The lateral tyre forces are those of the
//! bullet model (see [`crate::bullet`]).
//!
//! Roll sign: with these equations φ > 0 leans the body toward +y (left); in a steady left
//! turn (a_y > 0) the body leans out of the turn, `φ = −m_s h a_y / (K_φ − m_s g h)`.

use crate::bullet::{
    front_lateral, front_lateral_d, rear_lateral, rear_lateral_d, stable_substeps, Axles, Held,
};
use crate::integrate::{rk4_jac_substeps, rk4_substeps, split_columns};
use crate::params::VehicleParams;
use crate::target::{idx, ContactInput, TargetInput, TargetJacobians, TargetModel, TargetState};
use crate::GRAVITY;
use nalgebra::SMatrix;

/// Speed (m/s) of the brake-force regularisation `vx / sqrt(vx² + V_BRAKE²)`.
pub const V_BRAKE: f64 = 0.5;

/// Width (m/s) of the smooth switch between a running and a stalled engine around the
/// stall speed (the plant switches at once and stays stalled).
pub const V_STALL_BLEND: f64 = 0.25;

/// The powertrain as rear-axle forces (see the module docs).
#[derive(Debug, Clone, Copy)]
struct Driveline {
    /// `i_g T_drag / R_w` (N).
    drag: f64,
    /// `i_g T_stall / R_w` (N).
    hold: f64,
    /// Road speed at the engine's stall speed, `ω_stall R_w / i_g` (m/s).
    v_stall: f64,
}

impl Driveline {
    /// `(w, dw/dvx)`: the share of a running engine at speed `vx`.
    #[inline]
    fn running(&self, vx: f64) -> (f64, f64) {
        let w = 1.0 / (1.0 + (-(vx - self.v_stall) / V_STALL_BLEND).exp());
        (w, w * (1.0 - w) / V_STALL_BLEND)
    }
}

/// Number of target states.
const NX: usize = 8;
/// Columns of the stacked continuous Jacobian `[∂f/∂x | ∂f/∂u | ∂f/∂f_c]`.
const NJ: usize = NX + 4;

/// The 4-DOF analytic target model (see the module docs for the equations).
#[derive(Debug, Clone)]
pub struct FourDofTarget {
    mass: f64,
    inv_mass: f64,
    inv_iz: f64,
    lf: f64,
    lr: f64,
    /// m_s h.
    ms_h: f64,
    /// I_xx = I_x,s + m_s h².
    ixx: f64,
    /// m_s g h − K_φ (< 0 for a statically stable roll mode).
    roll_k: f64,
    /// C_φ.
    roll_c: f64,
    /// h_c: height of the contact line above the roll axis.
    h_contact: f64,
    /// 1 / (m I_xx − (m_s h)²), the inverse determinant of the lateral/roll mass matrix.
    inv_det: f64,
    /// 1/R_w.
    inv_rw: f64,
    /// Front brake share β.
    bias: f64,
    /// The powertrain in gear, or `None` (the throttle then drives the axle directly).
    driveline: Option<Driveline>,
    /// Rolling resistance `f_r m g` (N) and the drag factor `½ ρ C_d A` (kg/m).
    rolling: f64,
    drag: f64,
    axles: Axles,
    dt: f64,
    substeps: usize,
}

impl FourDofTarget {
    /// The model of vehicle `p` on a road of adhesion `mu`, stepping over `dt` seconds, in
    /// [`stable_substeps`] RK4 sub-steps (stable down to
    /// [`STABLE_DOWN_TO`](crate::bullet::STABLE_DOWN_TO); the free roll lowers the effective
    /// lateral mass to `m − (m_s h)²/I_xx`, which makes this model the stiffer of the two).
    #[must_use]
    pub fn new(p: &VehicleParams, mu: f64, dt: f64) -> Self {
        let h = p.roll_arm();
        let ms_h = p.sprung_mass * h;
        let ixx = p.ix_sprung + p.sprung_mass * h * h;
        let axles = Axles::new(p, mu);
        let m_eff = p.mass - ms_h * ms_h / ixx;
        let substeps = stable_substeps(dt, axles.cornering_sum(), m_eff);
        Self {
            mass: p.mass,
            inv_mass: 1.0 / p.mass,
            inv_iz: 1.0 / p.iz,
            lf: p.lf,
            lr: p.lr,
            ms_h,
            ixx,
            roll_k: ms_h * GRAVITY - (p.roll_stiffness_front + p.roll_stiffness_rear),
            roll_c: p.roll_damping_front + p.roll_damping_rear,
            h_contact: p.bumper_height - p.h_roll_axis,
            inv_det: 1.0 / (p.mass * ixx - ms_h * ms_h),
            inv_rw: 1.0 / p.wheel_radius,
            bias: p.brake_bias_front,
            driveline: p.powertrain.as_ref().map(|pt| Driveline {
                drag: p.gear_ratio * pt.engine_drag_torque / p.wheel_radius,
                hold: p.gear_ratio * pt.stall_torque / p.wheel_radius,
                v_stall: pt.stall_speed * p.wheel_radius / p.gear_ratio,
            }),
            rolling: p.rolling_resistance * p.mass * GRAVITY,
            drag: 0.5 * crate::plant::AIR_DENSITY * p.drag_area,
            axles,
            dt,
            substeps,
        }
    }

    /// Split every step into `n` equal RK4 sub-steps (0 is treated as 1), replacing the
    /// default [`stable_substeps`]; the Jacobians stay exact. See [`crate::bullet::BulletModel::with_substeps`].
    #[must_use]
    pub fn with_substeps(mut self, n: usize) -> Self {
        self.substeps = n.max(1);
        self
    }

    /// Number of RK4 sub-steps per step.
    #[must_use]
    pub fn substeps(&self) -> usize {
        self.substeps
    }

    /// Change the road adhesion: rebuilds both axle curves.
    pub fn set_mu(&mut self, mu: f64) {
        self.axles.set_mu(mu);
    }

    /// Steady-state roll gradient `dφ/da_y = −m_s h / (K_φ − m_s g h)` (rad per m/s²);
    /// negative: the body leans out of the turn.
    #[must_use]
    pub fn roll_gradient(&self) -> f64 {
        self.ms_h / self.roll_k
    }

    /// Brake force factor `s(vx) = vx / sqrt(vx² + V_BRAKE²)` (a smooth sign: the brake
    /// opposes the motion) and its derivative `V_BRAKE² / (vx² + V_BRAKE²)^{3/2}`.
    #[inline]
    fn brake_factor(vx: f64) -> (f64, f64) {
        let q = vx * vx + V_BRAKE * V_BRAKE;
        let inv = 1.0 / q.sqrt();
        (vx * inv, V_BRAKE * V_BRAKE * inv / q)
    }

    /// The longitudinal wheel forces `(F_x,f, F_x,r)` at speed `vx` for the driver's torque
    /// `T_b` (module docs), with their partial derivatives by `vx` and by `T_b`:
    /// `[F_x,f, F_x,r, ∂F_x,f/∂vx, ∂F_x,r/∂vx, ∂F_x,f/∂T_b, ∂F_x,r/∂T_b]` (at `T_b = 0` the
    /// brake side's derivative).
    #[inline]
    fn longitudinal(&self, vx: f64, tb: f64) -> [f64; 6] {
        let (s, ds) = Self::brake_factor(vx);
        let beta = self.bias;
        let brake = tb.max(0.0) * self.inv_rw;
        let drive = (-tb).max(0.0) * self.inv_rw;
        let mut out = [
            -beta * brake * s,
            -(1.0 - beta) * brake * s,
            -beta * brake * ds,
            -(1.0 - beta) * brake * ds,
            0.0,
            0.0,
        ];
        if tb >= 0.0 {
            out[4] = -beta * self.inv_rw * s;
            out[5] = -(1.0 - beta) * self.inv_rw * s;
        }
        match &self.driveline {
            None => {
                out[1] += drive;
                if tb < 0.0 {
                    out[5] = -self.inv_rw;
                }
            }
            Some(d) => {
                let (w, dw) = d.running(vx);
                out[1] += w * (drive - d.drag * s) - (1.0 - w) * d.hold * s;
                out[3] += dw * (drive - d.drag * s) - w * d.drag * ds + dw * d.hold * s
                    - (1.0 - w) * d.hold * ds;
                if tb < 0.0 {
                    out[5] = -w * self.inv_rw;
                }
            }
        }
        out
    }

    /// Rolling resistance and aerodynamic drag along x and their derivative by `vx`.
    #[inline]
    fn resistance(&self, vx: f64) -> (f64, f64) {
        let (s, ds) = Self::brake_factor(vx);
        (
            -self.rolling * s - self.drag * vx * vx.abs(),
            -self.rolling * ds - 2.0 * self.drag * vx.abs(),
        )
    }

    /// The continuous-time dynamics `ẋ = f(x, u, f_c)`.
    #[must_use]
    pub fn derivative(&self, x: &TargetState, u: &TargetInput, c: &ContactInput) -> TargetState {
        self.eval(x, &Held::new(u[0], c, 1.0), u[1])
    }

    /// `f(x)` with the steer and contact held in `held` and the driver's torque `tb`.
    #[inline]
    fn eval(&self, x: &TargetState, held: &Held, tb: f64) -> TargetState {
        let (vx, vy, psi, r) = (x[idx::VX], x[idx::VY], x[idx::PSI], x[idx::R]);
        let (sd, cd) = (held.sd, held.cd);
        let (sp, cp) = psi.sin_cos();
        let [fxf, fxr, ..] = self.longitudinal(vx, tb);
        let fyf = front_lateral(&self.axles.front, self.lf, vx, vy, r, sd, cd);
        let fyr = rear_lateral(&self.axles.rear, self.lr, vx, vy, r);
        let (fc, mc) = held.contact.force(sp, cp);
        let ffx = fxf * cd - fyf * sd;
        let ffy = fxf * sd + fyf * cd;
        let sfx = ffx + fxr + self.resistance(vx).0 + fc.x;
        let sfy = ffy + fyr + fc.y;
        let smz = self.lf * ffy - self.lr * fyr + mc;
        self.rates(x, sp, cp, [sfx, sfy, smz, fc.y])
    }

    /// `ẋ` from the force sums `[ΣF_x, ΣF_y, ΣM_z, F_cy]`: the 2 × 2 lateral/roll solve and
    /// the kinematics. Shared by `eval` and `eval_jac`, so `step` and `step_jac` agree bit
    /// for bit.
    #[inline]
    fn rates(&self, x: &TargetState, sp: f64, cp: f64, sums: [f64; 4]) -> TargetState {
        let (vx, vy, r, p, phi) = (x[idx::VX], x[idx::VY], x[idx::R], x[idx::P], x[idx::PHI]);
        let [sfx, sfy, smz, fcy] = sums;
        let mroll = self.roll_k * phi - self.roll_c * p + fcy * self.h_contact;
        let ay = (self.ixx * sfy - self.ms_h * mroll) * self.inv_det;
        let pd = (self.mass * mroll - self.ms_h * sfy) * self.inv_det;
        TargetState::from([
            sfx * self.inv_mass + vy * r,
            ay - vx * r,
            r,
            smz * self.inv_iz,
            pd,
            p,
            vx * cp - vy * sp,
            vx * sp + vy * cp,
        ])
    }

    /// `f(x)` and its stacked Jacobian `[∂f/∂x | ∂f/∂u | ∂f/∂f_c]` (8 × 12) in `j`.
    ///
    /// Writes every structurally nonzero entry, unconditionally; the others are never
    /// touched, so `j` must come zero-initialised (as `rk4_jac` provides it) and can then be
    /// reused for every stage without clearing.
    #[inline]
    fn eval_jac(
        &self,
        x: &TargetState,
        held: &Held,
        tb: f64,
        j: &mut SMatrix<f64, NX, NJ>,
    ) -> TargetState {
        use idx::{P, PHI, PSI, R, VX, VY};
        const DELTA: usize = NX;
        const TB: usize = NX + 1;
        const FN: usize = NX + 2;
        let (vx, vy, psi, r) = (x[VX], x[VY], x[PSI], x[R]);
        let (sd, cd) = (held.sd, held.cd);
        let (lf, lr) = (self.lf, self.lr);
        let (sp, cp) = psi.sin_cos();

        // Longitudinal wheel forces (brakes, throttle, powertrain).
        let [fxf, fxr, dfxf_dvx, dfxr_dvx, dfxf_dtb, dfxr_dtb] = self.longitudinal(vx, tb);
        // Tyre lateral forces and the contact.
        let ff = front_lateral_d(&self.axles.front, lf, vx, vy, r, sd, cd);
        let fr = rear_lateral_d(&self.axles.rear, lr, vx, vy, r);
        let ct = held.contact.terms(sp, cp);

        // Front axle force in the body frame, and its gradient.
        let ffx = fxf * cd - ff.fy * sd;
        let ffy = fxf * sd + ff.fy * cd;
        let mut gfx = [0.0; NJ];
        let mut gfy = [0.0; NJ];
        gfx[VX] = dfxf_dvx * cd - ff.d_vx * sd;
        gfx[VY] = -ff.d_vy * sd;
        gfx[R] = -ff.d_r * sd;
        gfx[DELTA] = -ffy - ff.d_delta * sd;
        gfx[TB] = dfxf_dtb * cd;
        gfy[VX] = dfxf_dvx * sd + ff.d_vx * cd;
        gfy[VY] = ff.d_vy * cd;
        gfy[R] = ff.d_r * cd;
        gfy[DELTA] = ffx + ff.d_delta * cd;
        gfy[TB] = dfxf_dtb * sd;

        // Gradients of ΣF_x, ΣF_y, ΣM_z and the roll moment M_φ.
        let (fres, dfres) = self.resistance(vx);
        let mut gx = gfx;
        gx[VX] += dfxr_dvx + dfres;
        gx[TB] += dfxr_dtb;
        gx[PSI] = ct.df_dpsi.x;
        let mut gy = gfy;
        gy[VX] += fr.d_vx;
        gy[VY] += fr.d_vy;
        gy[R] += fr.d_r;
        gy[PSI] = ct.df_dpsi.y;
        let mut gm = gfy.map(|g| lf * g);
        gm[VX] -= lr * fr.d_vx;
        gm[VY] -= lr * fr.d_vy;
        gm[R] -= lr * fr.d_r;
        gm[PSI] = ct.dm_dpsi;
        let mut gr = [0.0; NJ];
        gr[PHI] = self.roll_k;
        gr[P] = -self.roll_c;
        gr[PSI] = ct.df_dpsi.y * self.h_contact;
        for k in 0..2 {
            gx[FN + k] = ct.df_dfc[(0, k)];
            gy[FN + k] = ct.df_dfc[(1, k)];
            gm[FN + k] = ct.dm_dfc[k];
            gr[FN + k] = ct.df_dfc[(1, k)] * self.h_contact;
        }

        let sfx = ffx + fxr + fres + ct.f.x;
        let sfy = ffy + fr.fy + ct.f.y;
        let smz = lf * ffy - lr * fr.fy + ct.m;
        let (ixx, ms_h, m) = (
            self.ixx * self.inv_det,
            self.ms_h * self.inv_det,
            self.mass * self.inv_det,
        );

        // Dynamics: v̇x, v̇y = a − vx r, ṙ, ṗ with (a, ṗ) from the 2 × 2 lateral/roll system.
        for col in 0..NJ {
            j[(VX, col)] = gx[col] * self.inv_mass;
            j[(VY, col)] = ixx * gy[col] - ms_h * gr[col];
            j[(R, col)] = gm[col] * self.inv_iz;
            j[(P, col)] = m * gr[col] - ms_h * gy[col];
        }
        j[(VX, VY)] += r;
        j[(VX, R)] += vy;
        j[(VY, VX)] -= r;
        j[(VY, R)] -= vx;
        // Kinematics.
        j[(PSI, R)] = 1.0;
        j[(PHI, P)] = 1.0;
        j[(idx::X, VX)] = cp;
        j[(idx::X, VY)] = -sp;
        j[(idx::X, PSI)] = -vx * sp - vy * cp;
        j[(idx::Y, VX)] = sp;
        j[(idx::Y, VY)] = cp;
        j[(idx::Y, PSI)] = vx * cp - vy * sp;

        self.rates(x, sp, cp, [sfx, sfy, smz, ct.f.y])
    }
}

impl TargetModel for FourDofTarget {
    fn name(&self) -> &str {
        "4dof"
    }

    fn dt(&self) -> f64 {
        self.dt
    }

    fn param_count(&self) -> usize {
        0
    }

    /// Classic RK4 over `dt` (in `substeps` sub-steps) with `u` and `c` held.
    fn step(&mut self, x: &TargetState, u: &TargetInput, c: &ContactInput) -> TargetState {
        let held = Held::new(u[0], c, 1.0);
        rk4_substeps(x, self.dt, self.substeps, |xs| self.eval(xs, &held, u[1]))
    }

    /// The step with the exact Jacobians of the discrete map; returns bit for bit the state
    /// [`TargetModel::step`] returns.
    fn step_jac(
        &mut self,
        x: &TargetState,
        u: &TargetInput,
        c: &ContactInput,
        jac: &mut TargetJacobians,
    ) -> TargetState {
        let held = Held::new(u[0], c, 1.0);
        let mut j = SMatrix::<f64, NX, NJ>::zeros();
        // The columns X, Y of ∂f/∂x are zero.
        let xn = rk4_jac_substeps(x, self.dt, self.substeps, 0..idx::X, &mut j, |xs, js| {
            self.eval_jac(xs, &held, u[1], js)
        });
        split_columns(&j, &mut jac.a, &mut jac.b, &mut jac.f);
        xn
    }
}
