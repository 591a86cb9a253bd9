//! The coupled collision MPC of picopit: the bullet's inputs and the shared contact force
//! `f_c = [F_n, F_t]` over a horizon of N steps, with both vehicles' dynamics (the bullet
//! single-track model and any [`dynamics::TargetModel`]: the 4-DOF model, the PINN or
//! PicoPINN), solved by sequential convex programming over Clarabel QPs.
//!
//! * [`settings`]: the validated settings (TOML, defaults).
//! * [`reference`]: what the upper layer hands down: e_ref, the force corridor C_F, the
//!   envelope C_B and the target's reversed heading, per step.
//! * [`mpc`]: [`CoupledMpc`], its input, output and status.
//! * [`plan`]: a predicted trajectory with its inputs, forces, geometry and Jacobians.
//! * [`qp`]: a QP with a fixed sparsity pattern, assembled in place and solved by Clarabel
//!   (also used by the planner).
//! * [`geom`]: the gap, road and obstacle linearisations.
//! * [`clock`]: the injected clock of the time budget.
//!
//! `docs/mpc.md` gives the formulation, the treatment of contact forces and the QP layout.

pub mod clock;
pub mod geom;
pub mod mpc;
pub mod plan;
pub mod qp;
pub mod reference;
pub mod settings;

pub use clock::{Clock, MonotonicClock, TickClock};
pub use mpc::{
    CoupledMpc, Fallback, MpcError, MpcInput, MpcOutput, MpcStatus, SolveError, StageLinearisation,
    StepTimes,
};
pub use plan::Plan;
pub use qp::QpStatus;
pub use reference::{Reference, Side, StageReference};
pub use settings::{MpcSettings, ScpMode, SettingsError};
