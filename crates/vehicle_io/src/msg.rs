//! The payloads on the wire: `#[repr(C)]`, `Copy`, zero-copy shareable between processes.
//!
//! Every payload is plain old data (numbers and fixed arrays, no pointers), so iceoryx2 can
//! place it in shared memory and the subscriber reads it in place. Times:
//!
//! - `*_ns` stamps on the **vehicle clock**: nanoseconds since the start of the run, as the
//!   vehicle side counts them (the plant's simulated time for the shipped bridge; a real
//!   vehicle's synchronised clock on a car);
//! - `wall_*_ns` stamps on the host's `CLOCK_MONOTONIC`, shared by all processes on one host:
//!   they measure the IPC latency only and never enter the control law.
//!
//! States use the crate-wide orders (DESIGN.md, "State orders"): target
//! `[vx, vy, ψ, r, p, φ, X, Y]` (body velocities, world pose), bullet `[X, Y, ψ, vx, vy, r]`.

use iceoryx2::prelude::ZeroCopySend;
use serde::{Deserialize, Serialize};

/// Who sent a heartbeat.
pub const PEER_CONTROLLER: u32 = 1;
/// Who sent a heartbeat.
pub const PEER_VEHICLE: u32 = 2;

/// [`StateEstimate::flags`]: the vehicle side is in its own safe stop (commands are ignored).
pub const STATE_SAFE_STOP: u32 = 1 << 0;
/// [`StateEstimate::flags`]: the vehicles are in contact (as the plant or a bumper switch says).
pub const STATE_CONTACT: u32 = 1 << 1;
/// [`StateEstimate::flags`]: the first state of a new run (the scenario restarted; the
/// controller resets).
pub const STATE_RESTARTED: u32 = 1 << 3;
/// [`StateEstimate::flags`]: the run is over (the outcome is decided); the controller may exit.
pub const STATE_FINISHED: u32 = 1 << 2;

/// The state estimate of both vehicles, published by the vehicle side once per control
/// period.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend, Serialize, Deserialize)]
pub struct StateEstimate {
    /// Sequence number, from 0, +1 per published estimate.
    pub seq: u64,
    /// When the states were measured (vehicle clock, ns). Older than `sent_ns` by the
    /// sensing latency.
    pub stamp_ns: u64,
    /// The vehicle clock when this estimate was published (ns).
    pub sent_ns: u64,
    /// `CLOCK_MONOTONIC` when this estimate was published (ns; IPC latency only).
    pub wall_sent_ns: u64,
    /// The vehicle time the current run started (ns): scenario time is
    /// `stamp_ns − run_start_ns` (a soak restarts the scenario without resetting the clock).
    pub run_start_ns: u64,
    /// Target `[vx, vy, ψ, r, p, φ, X, Y]`.
    pub target: [f64; 8],
    /// Bullet `[X, Y, ψ, vx, vy, r]`.
    pub bullet: [f64; 6],
    /// The target driver's input as estimated: `[δ_f (rad), T_b (N·m, ≥ 0)]`.
    pub target_input: [f64; 2],
    /// The bullet command in force when the states were measured: `[δ_f, T_r]`.
    pub bullet_applied: [f64; 2],
    /// The bullet–target contact force `[F_n, F_t]` on the target in the contact frame (N),
    /// the mean over the period before publication (not delayed); zero apart. A simulator
    /// knows it; a car without a force sensor leaves it zero. Recorded and drawn, never used
    /// by the controller.
    pub contact_force: [f64; 2],
    /// World heading γ of the contact normal (bullet into target; rad; 0 apart).
    pub contact_gamma: f64,
    /// The contact point in the target's body frame, relative to its c.g. (m; 0 apart).
    pub contact_point: [f64; 2],
    /// `STATE_*` bits.
    pub flags: u32,
    /// Number of commands the vehicle side has applied so far (saturating).
    pub commands_applied: u32,
}

/// What kind of command an [`ActuatorCommand`] is (on the wire as its `u32` value, so a
/// reader never meets an invalid enum discriminant in shared memory).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum CommandMode {
    /// Apply `[δ_f, T_r]` as given.
    #[default]
    Track = 0,
    /// The controller's safe fallback (controlled braking along the road); apply it as given.
    Fallback = 1,
    /// The controller asks the vehicle to take over with its own safe stop.
    SafeStop = 2,
}

impl CommandMode {
    /// The mode of a wire value; unknown values read as [`CommandMode::SafeStop`] (fail safe).
    #[must_use]
    pub fn from_raw(v: u32) -> Self {
        match v {
            0 => Self::Track,
            1 => Self::Fallback,
            _ => Self::SafeStop,
        }
    }
}

/// The bullet command, published by the controller in answer to a [`StateEstimate`].
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend, Serialize, Deserialize)]
pub struct ActuatorCommand {
    pub seq: u64,
    /// The estimate this command answers.
    pub state_seq: u64,
    /// The vehicle time the command was computed for (the state's time + the compensated
    /// latency; ns).
    pub stamp_ns: u64,
    /// Apply no later than this (vehicle clock, ns); an older command is stale and ignored.
    pub valid_until_ns: u64,
    /// `CLOCK_MONOTONIC` when the answered estimate arrived, and when this command left (ns).
    pub wall_state_received_ns: u64,
    pub wall_sent_ns: u64,
    /// Front steer angle (rad).
    pub steer: f64,
    /// Rear-axle torque (N·m; negative brakes, through the blended brakes).
    pub torque: f64,
    /// A [`CommandMode`] as `u32` ([`ActuatorCommand::mode`] decodes it).
    pub mode: u32,
    pub _reserved: u32,
}

/// `ControllerStatus::faults` bits.
pub mod fault {
    /// The newest state was older than the stale limit (two control periods by default).
    pub const STALE_STATE: u32 = 1 << 0;
    /// The control step took longer than its deadline.
    pub const DEADLINE_MISSED: u32 = 1 << 1;
    /// The MPC's QP failed this step.
    pub const SOLVER_FAILURE: u32 = 1 << 2;
    /// No heartbeat from the vehicle side within the peer timeout.
    pub const PEER_DEAD: u32 = 1 << 3;
    /// No state has arrived yet.
    pub const NO_STATE: u32 = 1 << 4;
    /// The state was not finite or the controller refused it.
    pub const BAD_STATE: u32 = 1 << 5;
}

/// `ControllerStatus::events` bits: what the controller decided this step (the simulated
/// vehicle's judge needs them as the in-process runner's does).
pub mod event {
    /// The maneuver entered stabilisation this step.
    pub const STABILISING: u32 = 1 << 0;
    /// The upper layer found no feasible decision while chasing and aborted this step.
    pub const DECISION_INFEASIBLE: u32 = 1 << 1;
    /// The push did nothing and the maneuver went back to chasing for another this step.
    pub const PUSH_RETRIED: u32 = 1 << 2;
}

/// The controller's status, published with every command.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend, Serialize, Deserialize)]
pub struct ControllerStatus {
    pub seq: u64,
    /// The state this status belongs to.
    pub state_seq: u64,
    /// Vehicle time of the command (ns).
    pub stamp_ns: u64,
    /// The latency compensated this step: command time − measurement time (ns).
    pub compensated_ns: u64,
    /// Control-step time, planning excluded, and planning time (ns; 0 when not planned).
    pub ctrl_ns: u64,
    pub plan_ns: u64,
    /// Counters since start (saturating): deadline misses, fallbacks, stale states.
    pub deadline_misses: u32,
    pub fallbacks: u32,
    pub stale_states: u32,
    /// The controller's phase: 0 chasing, 1 pit, 2 stabilising, 3 done, 4 aborted.
    pub phase: u32,
    /// The MPC status this step: 0 not run, 1 converged, 2 RTI step, 3 iteration cap,
    /// 4 time budget, 5 QP failure.
    pub mpc_status: u32,
    /// `fault::*` bits of this step.
    pub faults: u32,
    /// `event::*` bits of this step.
    pub events: u32,
    pub _reserved: u32,
}

/// A liveness beacon, published by both sides every period.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend, Serialize, Deserialize)]
pub struct Heartbeat {
    pub seq: u64,
    /// `CLOCK_MONOTONIC` at publication (ns).
    pub wall_sent_ns: u64,
    /// The vehicle clock at publication (ns; the vehicle side's beacons only, 0 from the
    /// controller): lets the controller's "now" advance while no state arrives.
    pub vehicle_ns: u64,
    /// [`PEER_CONTROLLER`] or [`PEER_VEHICLE`].
    pub peer: u32,
    /// The sender's process id.
    pub pid: u32,
}

impl ActuatorCommand {
    /// The command's mode.
    #[must_use]
    pub fn mode(&self) -> CommandMode {
        CommandMode::from_raw(self.mode)
    }
}

impl StateEstimate {
    /// Whether every number in the estimate is finite.
    #[must_use]
    pub fn is_finite(&self) -> bool {
        self.target
            .iter()
            .chain(&self.bullet)
            .chain(&self.target_input)
            .chain(&self.bullet_applied)
            .all(|v| v.is_finite())
    }
}
