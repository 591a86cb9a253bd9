//! The upper virtual-PIT decision layer of picopit, the decision package Π it hands to the
//! coupled MPC, the phase machine, and the one controller that runs a whole maneuver.
//!
//! * [`decision`]: [`Planner`], the virtual PIT rollout optimised over the interaction
//!   descriptor u_T^vir = [F_n, F_t], the contact window and the contact side.
//! * [`package`]: [`DecisionPackage`] (Π), its [`Mode`] and the [`Infeasible`] reasons.
//! * [`href`]: h_ref, the MPC's reference from Π; [`approach`]: the bullet's approach.
//! * [`phase`]: [`PhaseMachine`]: chasing → PIT → stabilisation → done, abort.
//! * [`controller`]: [`PitController`]: planner + MPC + phase machine; the upper layer
//!   switchable off for the paper's ablation.
//! * [`settings`]: [`ControllerSettings`] (TOML, validated).
//!
//! `docs/planner.md` gives the formulation and the measurements.

pub mod approach;
mod chase;
pub mod controller;
pub mod decision;
pub mod href;
pub mod package;
pub mod phase;
mod race;
pub mod settings;

pub use controller::{
    ControllerError, ControllerInput, ControllerOutput, PitController, StepError,
};
pub use decision::{
    Judgement, PlanError, Planner, PlannerError, PlannerInput, Release, MAX_OBSTACLES,
};
pub use package::{DecisionPackage, Infeasible, Mode, PlanStep, TerminalSet};
pub use phase::{AbortReason, Phase, PhaseMachine, PhaseObservation};
pub use settings::{
    length_scale, ControllerSettings, PhaseSettings, PlanWeights, PlannerSettings, SettingsError,
    TUNED_BULLET_LENGTH,
};
