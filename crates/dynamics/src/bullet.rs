//! The bullet's control model: a front-steer, rear-drive single-track ("bicycle") model
//! with Magic Formula axle curves and the contact force, integrated with classic RK4 over
//! the MPC step, with the *exact* Jacobians of that discrete step.
//!
//! State `x_B = [X, Y, ψ, vx, vy, r]`, input `u_B = [δ_f, T_r]`, contact `f_c = [F_n, F_t]`
//! (the bullet receives `−f_c`):
//!
//! ```text
//! Ẋ = vx cosψ − vy sinψ        Ẏ = vx sinψ + vy cosψ        ψ̇ = r
//! m (v̇x − r vy) = F_x,r − F_y,f sinδ + F_cx
//! m (v̇y + r vx) = F_y,f cosδ + F_y,r + F_cy
//! I_z ṙ          = l_f F_y,f cosδ − l_r F_y,r + M_c
//! ```
//!
//! with `F_x,r = η_d i_g T_r / R_w`, `F_y,f = C_f(α_f)`, `α_f` the slip angle of the front
//! wheel velocity `R(−δ)·(vx, vy + l_f r)`, `F_y,r = C_r(α_r)`, `α_r = α(vx, vy − l_r r)`
//! ([`tyre::tan_slip`](crate::tyre::tan_slip), [`AxleCurve`] at the static axle loads),
//! and `(F_cx, F_cy, M_c) = −R(γ − ψ) f_c` with its moment, as
//! [`ContactInput::body_force`]`(ψ, −1)`.
//!
//! This module also holds the pieces shared with the 4-DOF target model
//! ([`crate::target4dof`]): slip angles with their partial derivatives, the axle lateral
//! forces with theirs, and the contact force with its derivatives in ψ and `f_c`. RK4 with
//! exact Jacobian propagation lives in `crate::integrate`.

use crate::geometry::{cross, Vec2};
use crate::integrate::{rk4_jac_substeps, rk4_substeps, split_columns};
use crate::params::{TyreParams, VehicleParams};
use crate::target::ContactInput;
use crate::tyre::{tan_slip, AxleCurve, V_LOW};
use nalgebra::{Matrix2, RowVector2, SMatrix, SVector};

/// Bullet state `[X, Y, ψ, vx, vy, r]`.
pub type BulletState = SVector<f64, 6>;
/// Bullet input `[δ_f, T_r]`: front steer (rad) and drive torque before the gear (N m,
/// negative brakes through the drivetrain).
pub type BulletInput = SVector<f64, 2>;

/// Indices into [`BulletState`].
pub mod idx {
    pub const X: usize = 0;
    pub const Y: usize = 1;
    pub const PSI: usize = 2;
    pub const VX: usize = 3;
    pub const VY: usize = 4;
    pub const R: usize = 5;
}

/// Number of bullet states.
const NX: usize = 6;
/// Columns of the stacked continuous Jacobian `[∂f/∂x | ∂f/∂u | ∂f/∂f_c]`.
const NJ: usize = NX + 4;

/// Jacobians of one discrete bullet step `x⁺ = F(x, u, f_c)`.
#[derive(Debug, Clone, PartialEq)]
pub struct BulletJacobians {
    /// ∂x⁺/∂x (6 × 6).
    pub a: SMatrix<f64, 6, 6>,
    /// ∂x⁺/∂u (6 × 2).
    pub b: SMatrix<f64, 6, 2>,
    /// ∂x⁺/∂f_c (6 × 2), with γ and the point of action held fixed. `f_c` is the force on
    /// the target; the bullet receives `−f_c`, and that sign is inside this matrix.
    pub f: SMatrix<f64, 6, 2>,
}

impl Default for BulletJacobians {
    fn default() -> Self {
        Self {
            a: SMatrix::zeros(),
            b: SMatrix::zeros(),
            f: SMatrix::zeros(),
        }
    }
}

/// The bullet's single-track control model (see the module docs for the equations).
#[derive(Debug, Clone)]
pub struct BulletModel {
    mass: f64,
    inv_mass: f64,
    inv_iz: f64,
    lf: f64,
    lr: f64,
    /// η_d i_g / R_w (1/m).
    drive_gain: f64,
    axles: Axles,
    dt: f64,
    substeps: usize,
}

/// The two axle curves of a control model: the Magic Formula control curves at the static
/// axle loads, rebuilt when the road μ changes. Shared by the bullet and the 4-DOF target.
#[derive(Debug, Clone)]
pub(crate) struct Axles {
    tyre: TyreParams,
    fz_front: f64,
    fz_rear: f64,
    pub front: AxleCurve,
    pub rear: AxleCurve,
}

impl Axles {
    pub(crate) fn new(p: &VehicleParams, mu: f64) -> Self {
        let (fz_front, fz_rear) = p.static_axle_loads();
        Self {
            tyre: p.tyre.clone(),
            fz_front,
            fz_rear,
            front: AxleCurve::control(&p.tyre, fz_front, mu),
            rear: AxleCurve::control(&p.tyre, fz_rear, mu),
        }
    }

    pub(crate) fn set_mu(&mut self, mu: f64) {
        self.front = AxleCurve::control(&self.tyre, self.fz_front, mu);
        self.rear = AxleCurve::control(&self.tyre, self.fz_rear, mu);
    }

    /// `C_f + C_r` (N/rad), μ-independent.
    pub(crate) fn cornering_sum(&self) -> f64 {
        self.front.cornering_stiffness() + self.rear.cornering_stiffness()
    }
}

/// Speed (m/s) down to which the default sub-stepping keeps the explicit step stable.
pub const STABLE_DOWN_TO: f64 = 1.0;

/// The number of RK4 sub-steps that keeps a step of `dt` inside RK4's stability region for
/// the tyre eigenvalue `(C_f + C_r) / (m_eff v)` down to [`STABLE_DOWN_TO`], with margin
/// (`|λ h| ≤ 2.5`; RK4's real-axis limit is 2.785). `m_eff` is the effective lateral mass.
#[must_use]
pub fn stable_substeps(dt: f64, cornering_sum: f64, m_eff: f64) -> usize {
    let n = (dt * cornering_sum / (m_eff * STABLE_DOWN_TO * 2.5)).ceil();
    if n.is_finite() && n >= 1.0 {
        n as usize
    } else {
        1
    }
}

impl BulletModel {
    /// The model of vehicle `p` on a road of adhesion `mu`, stepping over `dt` seconds.
    /// The axle curves are the Magic Formula at the static axle loads. The step is split
    /// into [`stable_substeps`] RK4 sub-steps so that it stays stable down to
    /// [`STABLE_DOWN_TO`]; override with [`BulletModel::with_substeps`].
    #[must_use]
    pub fn new(p: &VehicleParams, mu: f64, dt: f64) -> Self {
        let axles = Axles::new(p, mu);
        let substeps = stable_substeps(dt, axles.cornering_sum(), p.mass);
        Self {
            mass: p.mass,
            inv_mass: 1.0 / p.mass,
            inv_iz: 1.0 / p.iz,
            lf: p.lf,
            lr: p.lr,
            drive_gain: p.drive_force_gain(),
            axles,
            dt,
            substeps,
        }
    }

    /// Split every step into `n` equal RK4 sub-steps (0 is treated as 1), replacing the
    /// default [`stable_substeps`]. The Jacobians stay exact (chained through the sub-steps).
    ///
    /// Explicit RK4 is stable only while the sub-step times the tyre eigenvalue
    /// `≈ (C_f + C_r)/(m v_x)` stays inside its stability region; at 0.05 s a single step
    /// is stable above about 3.4 m/s, 4 sub-steps above about 0.8 m/s (`docs/models.md`).
    #[must_use]
    pub fn with_substeps(mut self, n: usize) -> Self {
        self.substeps = n.max(1);
        self
    }

    /// Change the road adhesion: rebuilds both axle curves.
    pub fn set_mu(&mut self, mu: f64) {
        self.axles.set_mu(mu);
    }

    /// The step length (s).
    #[must_use]
    pub fn dt(&self) -> f64 {
        self.dt
    }

    /// Number of RK4 sub-steps per step.
    #[must_use]
    pub fn substeps(&self) -> usize {
        self.substeps
    }

    /// Front and rear axle lateral force curves.
    #[must_use]
    pub fn axle_curves(&self) -> (AxleCurve, AxleCurve) {
        (self.axles.front, self.axles.rear)
    }

    /// Understeer gradient `K_us = (m/L)(l_r/C_f − l_f/C_r)` (rad per m/s²), with `C_f`,
    /// `C_r` the axle cornering stiffnesses. In a steady turn of radius R at lateral
    /// acceleration a_y, `δ = L/R + K_us a_y` (linear range).
    #[must_use]
    pub fn understeer_gradient(&self) -> f64 {
        let l = self.lf + self.lr;
        let cf = self.axles.front.cornering_stiffness();
        let cr = self.axles.rear.cornering_stiffness();
        self.mass / l * (self.lr / cf - self.lf / cr)
    }

    /// The continuous-time dynamics `ẋ = f(x, u, f_c)`.
    #[must_use]
    pub fn derivative(&self, x: &BulletState, u: &BulletInput, c: &ContactInput) -> BulletState {
        self.eval(x, &Held::new(u[0], c, -1.0), self.drive_gain * u[1])
    }

    /// `f(x)` with the inputs held in `held` and the rear drive force `fxr`.
    #[inline]
    fn eval(&self, x: &BulletState, held: &Held, fxr: f64) -> BulletState {
        let (psi, vx, vy, r) = (x[idx::PSI], x[idx::VX], x[idx::VY], x[idx::R]);
        let (sd, cd) = (held.sd, held.cd);
        let (sp, cp) = psi.sin_cos();
        let fyf = front_lateral(&self.axles.front, self.lf, vx, vy, r, sd, cd);
        let fyr = rear_lateral(&self.axles.rear, self.lr, vx, vy, r);
        let (fc, mc) = held.contact.force(sp, cp);
        BulletState::new(
            vx * cp - vy * sp,
            vx * sp + vy * cp,
            r,
            (fxr - fyf * sd + fc.x) * self.inv_mass + r * vy,
            (fyf * cd + fyr + fc.y) * self.inv_mass - r * vx,
            (self.lf * fyf * cd - self.lr * fyr + mc) * self.inv_iz,
        )
    }

    /// `f(x)` and its stacked Jacobian `[∂f/∂x | ∂f/∂u | ∂f/∂f_c]` (6 × 10) in `j`.
    ///
    /// Writes every structurally nonzero entry, unconditionally; the others are never
    /// touched, so `j` must come zero-initialised (as `rk4_jac` provides it) and can then be
    /// reused for every stage without clearing.
    #[inline]
    fn eval_jac(
        &self,
        x: &BulletState,
        held: &Held,
        fxr: f64,
        j: &mut SMatrix<f64, NX, NJ>,
    ) -> BulletState {
        use idx::{PSI, R, VX, VY};
        const DELTA: usize = NX;
        const TR: usize = NX + 1;
        const FN: usize = NX + 2;
        const FT: usize = NX + 3;
        let (psi, vx, vy, r) = (x[PSI], x[VX], x[VY], x[R]);
        let (sd, cd) = (held.sd, held.cd);
        let (lf, lr, inv_m, inv_iz) = (self.lf, self.lr, self.inv_mass, self.inv_iz);
        let (sp, cp) = psi.sin_cos();
        let ff = front_lateral_d(&self.axles.front, lf, vx, vy, r, sd, cd);
        let fr = rear_lateral_d(&self.axles.rear, lr, vx, vy, r);
        let ct = held.contact.terms(sp, cp);

        // Kinematics.
        j[(idx::X, PSI)] = -vx * sp - vy * cp;
        j[(idx::X, VX)] = cp;
        j[(idx::X, VY)] = -sp;
        j[(idx::Y, PSI)] = vx * cp - vy * sp;
        j[(idx::Y, VX)] = sp;
        j[(idx::Y, VY)] = cp;
        j[(PSI, R)] = 1.0;
        // m v̇x = F_x,r − F_y,f sinδ + F_cx + m r vy.
        j[(VX, PSI)] = ct.df_dpsi.x * inv_m;
        j[(VX, VX)] = -ff.d_vx * sd * inv_m;
        j[(VX, VY)] = -ff.d_vy * sd * inv_m + r;
        j[(VX, R)] = -ff.d_r * sd * inv_m + vy;
        j[(VX, DELTA)] = -(ff.d_delta * sd + ff.fy * cd) * inv_m;
        j[(VX, TR)] = self.drive_gain * inv_m;
        j[(VX, FN)] = ct.df_dfc[(0, 0)] * inv_m;
        j[(VX, FT)] = ct.df_dfc[(0, 1)] * inv_m;
        // m v̇y = F_y,f cosδ + F_y,r + F_cy − m r vx.
        j[(VY, PSI)] = ct.df_dpsi.y * inv_m;
        j[(VY, VX)] = (ff.d_vx * cd + fr.d_vx) * inv_m - r;
        j[(VY, VY)] = (ff.d_vy * cd + fr.d_vy) * inv_m;
        j[(VY, R)] = (ff.d_r * cd + fr.d_r) * inv_m - vx;
        j[(VY, DELTA)] = (ff.d_delta * cd - ff.fy * sd) * inv_m;
        j[(VY, FN)] = ct.df_dfc[(1, 0)] * inv_m;
        j[(VY, FT)] = ct.df_dfc[(1, 1)] * inv_m;
        // I_z ṙ = l_f F_y,f cosδ − l_r F_y,r + M_c.
        j[(R, PSI)] = ct.dm_dpsi * inv_iz;
        j[(R, VX)] = (lf * ff.d_vx * cd - lr * fr.d_vx) * inv_iz;
        j[(R, VY)] = (lf * ff.d_vy * cd - lr * fr.d_vy) * inv_iz;
        j[(R, R)] = (lf * ff.d_r * cd - lr * fr.d_r) * inv_iz;
        j[(R, DELTA)] = lf * (ff.d_delta * cd - ff.fy * sd) * inv_iz;
        j[(R, FN)] = ct.dm_dfc[0] * inv_iz;
        j[(R, FT)] = ct.dm_dfc[1] * inv_iz;

        BulletState::new(
            vx * cp - vy * sp,
            vx * sp + vy * cp,
            r,
            (fxr - ff.fy * sd + ct.f.x) * inv_m + r * vy,
            (ff.fy * cd + fr.fy + ct.f.y) * inv_m - r * vx,
            (lf * ff.fy * cd - lr * fr.fy + ct.m) * inv_iz,
        )
    }

    /// One step of length `dt`: classic RK4 (in `substeps` sub-steps) with `u` and `c`
    /// held.
    #[must_use]
    pub fn step(&self, x: &BulletState, u: &BulletInput, c: &ContactInput) -> BulletState {
        let held = Held::new(u[0], c, -1.0);
        let fxr = self.drive_gain * u[1];
        rk4_substeps(x, self.dt, self.substeps, |xs| self.eval(xs, &held, fxr))
    }

    /// One step with the exact Jacobians of the discrete map written into `jac`; returns
    /// the next state (bit for bit the state [`BulletModel::step`] returns).
    pub fn step_jac(
        &self,
        x: &BulletState,
        u: &BulletInput,
        c: &ContactInput,
        jac: &mut BulletJacobians,
    ) -> BulletState {
        let held = Held::new(u[0], c, -1.0);
        let fxr = self.drive_gain * u[1];
        let mut j = SMatrix::<f64, NX, NJ>::zeros();
        // Only the columns ψ, vx, vy, r of ∂f/∂x can be nonzero.
        let xn = rk4_jac_substeps(x, self.dt, self.substeps, idx::PSI..NX, &mut j, |xs, js| {
            self.eval_jac(xs, &held, fxr, js)
        });
        split_columns(&j, &mut jac.a, &mut jac.b, &mut jac.f);
        xn
    }
}

// ---------------------------------------------------------------------------------------
// Shared pieces (also used by the 4-DOF target model).
// ---------------------------------------------------------------------------------------

/// What is held over one step: the steer angle's sine and cosine and the contact.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Held {
    pub sd: f64,
    pub cd: f64,
    pub contact: HeldContact,
}

impl Held {
    #[inline]
    pub(crate) fn new(delta: f64, c: &ContactInput, sign: f64) -> Self {
        let (sd, cd) = delta.sin_cos();
        Self {
            sd,
            cd,
            contact: HeldContact::new(c, sign),
        }
    }
}

/// A contact held over one step: `sign·f_c`, the sine and cosine of γ, the point of action.
#[derive(Debug, Clone, Copy)]
pub(crate) struct HeldContact {
    /// `sign·f_c`.
    fc: Vec2,
    sign: f64,
    sg: f64,
    cg: f64,
    point: Vec2,
}

/// The contact force in a body frame, its yaw moment, and their derivatives in ψ and `f_c`
/// (γ and the point of action held fixed).
#[derive(Debug, Clone, Copy)]
pub(crate) struct ContactTerms {
    /// Force in the body frame.
    pub f: Vec2,
    /// Yaw moment about the c.g.
    pub m: f64,
    pub df_dpsi: Vec2,
    pub dm_dpsi: f64,
    /// ∂f/∂f_c = sign·R(γ − ψ).
    pub df_dfc: Matrix2<f64>,
    pub dm_dfc: RowVector2<f64>,
}

impl HeldContact {
    /// The contact `c` as received with `sign` (+1 target, −1 bullet).
    #[inline]
    pub(crate) fn new(c: &ContactInput, sign: f64) -> Self {
        let (sg, cg) = c.gamma.sin_cos();
        Self {
            fc: c.fc * sign,
            sign,
            sg,
            cg,
            point: c.point_in_body,
        }
    }

    /// `sin(γ − ψ)`, `cos(γ − ψ)` from the heading's sine and cosine.
    #[inline]
    fn rel(&self, sp: f64, cp: f64) -> (f64, f64) {
        (self.sg * cp - self.cg * sp, self.cg * cp + self.sg * sp)
    }

    /// `sign·R(γ − ψ) f_c` and its yaw moment `p × f`, for a heading with sine `sp` and
    /// cosine `cp` (the same as [`ContactInput::body_force`] up to rounding).
    #[inline]
    pub(crate) fn force(&self, sp: f64, cp: f64) -> (Vec2, f64) {
        let (s, c) = self.rel(sp, cp);
        let f = Vec2::new(c * self.fc.x - s * self.fc.y, s * self.fc.x + c * self.fc.y);
        (f, cross(self.point, f))
    }

    /// [`HeldContact::force`] with its derivatives.
    #[inline]
    pub(crate) fn terms(&self, sp: f64, cp: f64) -> ContactTerms {
        let (s, c) = self.rel(sp, cp);
        let (f, m) = self.force(sp, cp);
        let df_dfc = Matrix2::new(c, -s, s, c) * self.sign;
        // d/dψ R(γ − ψ) = −R(γ − ψ + π/2): (f_x, f_y) ↦ (f_y, −f_x).
        let df_dpsi = Vec2::new(f.y, -f.x);
        let p = self.point;
        ContactTerms {
            f,
            m,
            df_dpsi,
            dm_dpsi: cross(p, df_dpsi),
            df_dfc,
            dm_dfc: df_dfc.row(1) * p.x - df_dfc.row(0) * p.y,
        }
    }
}

/// Lateral slip `α* = tan α = v_y / sqrt(v_x² + V_LOW²)` ([`tan_slip`], the slip the
/// Magic Formula is evaluated on, as in the plant and MF-Tyre) and its partials
/// `(∂α*/∂v_x, ∂α*/∂v_y) = (−v_y v_x / s³, 1/s)`, `s = sqrt(v_x² + V_LOW²)`.
#[inline]
#[must_use]
pub(crate) fn tan_slip_d(vx: f64, vy: f64) -> (f64, f64, f64) {
    // Bit-identical to `tan_slip` so that `step_jac` returns exactly the state `step` does.
    let q = tan_slip(vx, vy);
    let inv_s2 = 1.0 / (vx * vx + V_LOW * V_LOW);
    (q, -q * vx * inv_s2, inv_s2.sqrt())
}

/// Front axle lateral force (wheel frame) and its partials.
#[derive(Debug, Clone, Copy)]
pub(crate) struct FrontLateral {
    pub fy: f64,
    pub d_vx: f64,
    pub d_vy: f64,
    pub d_r: f64,
    pub d_delta: f64,
}

/// Rear axle lateral force and its partials.
#[derive(Debug, Clone, Copy)]
pub(crate) struct RearLateral {
    pub fy: f64,
    pub d_vx: f64,
    pub d_vy: f64,
    pub d_r: f64,
}

/// Front-wheel velocity in the wheel frame, `R(−δ)·(v_x, v_y + l_f r)`.
#[inline]
fn front_wheel_velocity(lf: f64, vx: f64, vy: f64, r: f64, sd: f64, cd: f64) -> (f64, f64) {
    let vyf = vy + lf * r;
    (cd * vx + sd * vyf, -sd * vx + cd * vyf)
}

/// Front axle lateral force in the wheel frame, `F_y,f = C_f(α_f)`, for steer angle δ
/// given by its sine `sd` and cosine `cd`.
#[inline]
#[must_use]
pub(crate) fn front_lateral(
    curve: &AxleCurve,
    lf: f64,
    vx: f64,
    vy: f64,
    r: f64,
    sd: f64,
    cd: f64,
) -> f64 {
    let (vxw, vyw) = front_wheel_velocity(lf, vx, vy, r, sd, cd);
    curve.force(tan_slip(vxw, vyw))
}

/// [`front_lateral`] with its partials in `v_x, v_y, r, δ`.
#[inline]
#[must_use]
pub(crate) fn front_lateral_d(
    curve: &AxleCurve,
    lf: f64,
    vx: f64,
    vy: f64,
    r: f64,
    sd: f64,
    cd: f64,
) -> FrontLateral {
    let (vxw, vyw) = front_wheel_velocity(lf, vx, vy, r, sd, cd);
    let (alpha, da_dvxw, da_dvyw) = tan_slip_d(vxw, vyw);
    let (fy, dfy) = curve.force_d(alpha);
    // ∂(vxw, vyw)/∂(vx, vy, r, δ) = [[cδ, sδ, l_f sδ, vyw], [−sδ, cδ, l_f cδ, −vxw]].
    let d_vx = dfy * (da_dvxw * cd - da_dvyw * sd);
    let d_vy = dfy * (da_dvxw * sd + da_dvyw * cd);
    FrontLateral {
        fy,
        d_vx,
        d_vy,
        d_r: lf * d_vy,
        d_delta: dfy * (da_dvxw * vyw - da_dvyw * vxw),
    }
}

/// Rear axle lateral force, `F_y,r = C_r(α(v_x, v_y − l_r r))`.
#[inline]
#[must_use]
pub(crate) fn rear_lateral(curve: &AxleCurve, lr: f64, vx: f64, vy: f64, r: f64) -> f64 {
    curve.force(tan_slip(vx, vy - lr * r))
}

/// [`rear_lateral`] with its partials in `v_x, v_y, r`.
#[inline]
#[must_use]
pub(crate) fn rear_lateral_d(curve: &AxleCurve, lr: f64, vx: f64, vy: f64, r: f64) -> RearLateral {
    let (alpha, da_dvx, da_dvy) = tan_slip_d(vx, vy - lr * r);
    let (fy, dfy) = curve.force_d(alpha);
    RearLateral {
        fy,
        d_vx: dfy * da_dvx,
        d_vy: dfy * da_dvy,
        d_r: -lr * dfy * da_dvy,
    }
}

/// Controlled braking along the road, the safe command of every fallback (the controller's
/// abort, the I/O watchdog, the vehicle side's own safe stop): steer the bullet's heading
/// onto the road's (`δ = 0.8 e_ψ − 0.1 r`, at most half the steer range) and brake with the
/// force `fraction · μ m g` through the blended brakes (the rear-axle torque of that force,
/// negative), released below 0.2 m/s so the car stays at rest.
#[must_use]
pub fn brake_along_road(
    road: &crate::road::Road,
    x: &BulletState,
    p: &VehicleParams,
    mu: f64,
    fraction: f64,
) -> BulletInput {
    let road_heading = road.project(Vec2::new(x[idx::X], x[idx::Y])).heading;
    let err = crate::wrap_angle(road_heading - x[idx::PSI]);
    let delta = (0.8 * err - 0.1 * x[idx::R]).clamp(-0.5 * p.steer_max, 0.5 * p.steer_max);
    let force = fraction * mu * p.mass * 9.81;
    let brake = if x[idx::VX] > 0.2 {
        -force * p.wheel_radius / (p.drive_efficiency * p.gear_ratio)
    } else {
        0.0
    };
    BulletInput::new(delta, brake)
}
