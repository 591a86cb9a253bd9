//! The target-model interface shared by the 4-DOF analytic model and the learned
//! surrogates (PINN, PicoPINN). The MPC and the planner see only this trait.

use crate::geometry::{cross, rotate, Vec2};
use nalgebra::{SMatrix, SVector};

/// Target state in the paper's order `[vx, vy, ψ, r, p, φ, X, Y]`.
pub type TargetState = SVector<f64, 8>;
/// Target input `[δ, T_b]`: the target driver's front steer (rad) and total brake torque
/// at the wheels (N m, ≥ 0).
pub type TargetInput = SVector<f64, 2>;

/// Indices into [`TargetState`].
pub mod idx {
    pub const VX: usize = 0;
    pub const VY: usize = 1;
    pub const PSI: usize = 2;
    pub const R: usize = 3;
    pub const P: usize = 4;
    pub const PHI: usize = 5;
    pub const X: usize = 6;
    pub const Y: usize = 7;
}

/// A contact force in the contact frame, with where and how it acts.
///
/// `fc = [F_n, F_t]` is the force on the *target* (`+f_c`); the bullet receives `−f_c`.
/// `gamma` is the world heading of the contact normal `n` (from bullet into target).
/// `point_in_body` is the point of action in the receiving vehicle's body frame, relative
/// to its c.g.; it is a material point, held fixed over one step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ContactInput {
    pub fc: Vec2,
    pub gamma: f64,
    pub point_in_body: Vec2,
}

impl ContactInput {
    /// No contact.
    #[must_use]
    pub fn none() -> Self {
        Self {
            fc: Vec2::zeros(),
            gamma: 0.0,
            point_in_body: Vec2::zeros(),
        }
    }

    /// The force `sign · f_c` in the body frame of a vehicle with heading ψ,
    /// `R(γ − ψ) f_c`, and its yaw moment about the c.g.
    #[inline]
    #[must_use]
    pub fn body_force(&self, psi: f64, sign: f64) -> (Vec2, f64) {
        let f = rotate(self.gamma - psi, self.fc) * sign;
        (f, cross(self.point_in_body, f))
    }
}

/// Jacobians of one discrete step `x⁺ = f(x, u, f_c)`.
#[derive(Debug, Clone, PartialEq)]
pub struct TargetJacobians {
    /// ∂x⁺/∂x (8 × 8).
    pub a: SMatrix<f64, 8, 8>,
    /// ∂x⁺/∂u (8 × 2).
    pub b: SMatrix<f64, 8, 2>,
    /// ∂x⁺/∂f_c (8 × 2), with γ and the point of action held fixed.
    pub f: SMatrix<f64, 8, 2>,
}

impl Default for TargetJacobians {
    fn default() -> Self {
        Self {
            a: SMatrix::zeros(),
            b: SMatrix::zeros(),
            f: SMatrix::zeros(),
        }
    }
}

/// A discrete-time prediction model of the target vehicle.
///
/// Implementations own whatever scratch memory they need, so `step` and `step_jac` take
/// `&mut self` and must not allocate.
pub trait TargetModel {
    /// A short name for reports (`4dof`, `pinn`, `picopinn`).
    fn name(&self) -> &str;
    /// The step length the model predicts over (s).
    fn dt(&self) -> f64;
    /// Number of trainable parameters (0 for the analytic model).
    fn param_count(&self) -> usize;
    /// One step: the next state.
    fn step(&mut self, x: &TargetState, u: &TargetInput, c: &ContactInput) -> TargetState;
    /// One step with its Jacobians written into `jac`; returns the next state.
    fn step_jac(
        &mut self,
        x: &TargetState,
        u: &TargetInput,
        c: &ContactInput,
        jac: &mut TargetJacobians,
    ) -> TargetState;
}
