//! The 4-DOF analytic target model: longitudinal, lateral, yaw and roll, with planar
//! kinematics, the driver's steer and brake, Magic Formula axle curves and the contact
//! force. It is the first [`TargetModel`] and the physics prior of the PINN.
//!
//! State `x_T = [vx, vy, ψ, r, p, φ, X, Y]`, input `u_T = [δ, T_b]` (front steer, total
//! brake torque at the wheels), contact `f_c = [F_n, F_t]` (the target receives `+f_c`):
//!
//! ```text
//! F_x,f = −β T_b/R_w · s(vx),  F_x,r = −(1−β) T_b/R_w · s(vx),  s(v) = v/sqrt(v² + v_b²)   (v_b = 0.5 m/s)
//! ΣF_x = F_x,f cosδ − F_y,f sinδ + F_x,r + F_cx
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

    /// The continuous-time dynamics `ẋ = f(x, u, f_c)`.
    #[must_use]
    pub fn derivative(&self, x: &TargetState, u: &TargetInput, c: &ContactInput) -> TargetState {
        self.eval(x, &Held::new(u[0], c, 1.0), u[1] * self.inv_rw)
    }

    /// `f(x)` with the steer and contact held in `held` and `fb_max = T_b / R_w`.
    #[inline]
    fn eval(&self, x: &TargetState, held: &Held, fb_max: f64) -> TargetState {
        let (vx, vy, psi, r) = (x[idx::VX], x[idx::VY], x[idx::PSI], x[idx::R]);
        let (sd, cd) = (held.sd, held.cd);
        let (sp, cp) = psi.sin_cos();
        let (t, _) = Self::brake_factor(vx);
        let fb = -fb_max * t;
        let fxf = self.bias * fb;
        let fxr = (1.0 - self.bias) * fb;
        let fyf = front_lateral(&self.axles.front, self.lf, vx, vy, r, sd, cd);
        let fyr = rear_lateral(&self.axles.rear, self.lr, vx, vy, r);
        let (fc, mc) = held.contact.force(sp, cp);
        let ffx = fxf * cd - fyf * sd;
        let ffy = fxf * sd + fyf * cd;
        let sfx = ffx + fxr + fc.x;
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
        fb_max: f64,
        j: &mut SMatrix<f64, NX, NJ>,
    ) -> TargetState {
        use idx::{P, PHI, PSI, R, VX, VY};
        const DELTA: usize = NX;
        const TB: usize = NX + 1;
        const FN: usize = NX + 2;
        let (vx, vy, psi, r) = (x[VX], x[VY], x[PSI], x[R]);
        let (sd, cd) = (held.sd, held.cd);
        let (lf, lr, beta) = (self.lf, self.lr, self.bias);
        let (sp, cp) = psi.sin_cos();

        // Brake forces F_x = −share · (T_b/R_w) · s(vx).
        let (t, dt_dvx) = Self::brake_factor(vx);
        let fb = -fb_max * t;
        let dfb_dvx = -fb_max * dt_dvx;
        let dfb_dtb = -self.inv_rw * t;
        let (fxf, fxr) = (beta * fb, (1.0 - beta) * fb);
        // Tyre lateral forces and the contact.
        let ff = front_lateral_d(&self.axles.front, lf, vx, vy, r, sd, cd);
        let fr = rear_lateral_d(&self.axles.rear, lr, vx, vy, r);
        let ct = held.contact.terms(sp, cp);

        // Front axle force in the body frame, and its gradient.
        let ffx = fxf * cd - ff.fy * sd;
        let ffy = fxf * sd + ff.fy * cd;
        let mut gfx = [0.0; NJ];
        let mut gfy = [0.0; NJ];
        gfx[VX] = beta * dfb_dvx * cd - ff.d_vx * sd;
        gfx[VY] = -ff.d_vy * sd;
        gfx[R] = -ff.d_r * sd;
        gfx[DELTA] = -ffy - ff.d_delta * sd;
        gfx[TB] = beta * dfb_dtb * cd;
        gfy[VX] = beta * dfb_dvx * sd + ff.d_vx * cd;
        gfy[VY] = ff.d_vy * cd;
        gfy[R] = ff.d_r * cd;
        gfy[DELTA] = ffx + ff.d_delta * cd;
        gfy[TB] = beta * dfb_dtb * sd;

        // Gradients of ΣF_x, ΣF_y, ΣM_z and the roll moment M_φ.
        let mut gx = gfx;
        gx[VX] += (1.0 - beta) * dfb_dvx;
        gx[TB] += (1.0 - beta) * dfb_dtb;
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

        let sfx = ffx + fxr + ct.f.x;
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
        let fb_max = u[1] * self.inv_rw;
        rk4_substeps(x, self.dt, self.substeps, |xs| self.eval(xs, &held, fb_max))
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
        let fb_max = u[1] * self.inv_rw;
        let mut j = SMatrix::<f64, NX, NJ>::zeros();
        // The columns X, Y of ∂f/∂x are zero.
        let xn = rk4_jac_substeps(x, self.dt, self.substeps, 0..idx::X, &mut j, |xs, js| {
            self.eval_jac(xs, &held, fb_max, js)
        });
        split_columns(&j, &mut jac.a, &mut jac.b, &mut jac.f);
        xn
    }
}
