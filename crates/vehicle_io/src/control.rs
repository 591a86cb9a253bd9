//! The controller's cycle, without the transport: watchdog, delay compensation, the
//! hierarchical controller and the safe fallback. `pit-controller` feeds it the newest state
//! and publishes what it returns; tests drive it directly.
//!
//! Per cycle ([`ControlLoop::step`]):
//!
//! 1. **Watchdog.** No state yet, a state older than the stale limit at the command's time,
//!    a non-finite state or a dead peer → the safe fallback (controlled braking along the
//!    road from the newest state, [`CommandMode::Fallback`]) with the fault flagged. Without
//!    any state at all the vehicle is asked to stop itself ([`CommandMode::SafeStop`]).
//! 2. **Delay compensation** (beyond the paper, whose scaled tests suffered communication
//!    delay): the newest states are predicted forward by their age at the command's time
//!    (sensing latency + transport) plus the configured actuation delay, at most
//!    `max_compensation`: the bullet with its bicycle model under the command in force when
//!    it was measured, the target with the 4-DOF model under its driver's input, and the
//!    contact between the two footprints by the plant's compliant law (the parameter set's
//!    `[contact]`). Steps of 1 ms, the plant's, which the contact's stiffness needs.
//! 3. **Control.** [`PitController::step`] at the predicted time (planner every replanning
//!    period, MPC every step).
//! 4. **Deadline.** A cycle longer than `deadline` (wall time) replaces its command by the
//!    fallback and counts a miss; an MPC QP failure is flagged (the controller already
//!    returned its own safe command).
//!
//! Memory: the controller (see `PitController`), two prediction models and a copy of the
//! road and obstacles, all allocated by [`ControlLoop::new`]; `step` allocates nothing
//! (`tests/alloc.rs`).

use crate::config::{secs_to_ns, ControllerIoSettings};
use crate::msg::{event, fault, ActuatorCommand, CommandMode, ControllerStatus, StateEstimate};
use dynamics::bullet::{brake_along_road, BulletInput, BulletModel, BulletState};
use dynamics::contact::{obb_contact, ContactLaw};
use dynamics::geometry::{rotate, Obb, Pose2, Vec2};
use dynamics::params::ParamSet;
use dynamics::road::{Obstacle, Road};
use dynamics::target::idx;
use dynamics::target4dof::FourDofTarget;
use dynamics::{ContactInput, TargetInput, TargetModel, TargetState};
use mpc::{Clock, MonotonicClock, MpcStatus};
use planner::{AbortReason, ControllerInput, Phase, PitController};

/// Prediction step of the delay compensation (s): the plant's, which the contact's
/// stiffness needs (`Plant::new` refuses contacts with ω·dt > 0.5 at this step).
const PREDICT_DT: f64 = 0.001;

/// What one cycle sees.
#[derive(Debug, Clone, Copy)]
pub struct CycleInput<'a> {
    /// The newest state estimate (None before the first).
    pub state: Option<&'a StateEstimate>,
    /// "Now" on the vehicle clock (ns): when the command will take effect.
    pub now_ns: u64,
    /// `CLOCK_MONOTONIC` when the state arrived (ns; copied into the command).
    pub wall_received_ns: u64,
    /// Whether the vehicle's heartbeat is alive.
    pub peer_alive: bool,
}

/// Counters since construction.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct Counters {
    pub cycles: u64,
    pub solves: u64,
    pub deadline_misses: u32,
    pub fallbacks: u32,
    pub stale_states: u32,
    pub solver_failures: u32,
}

/// The controller's cycle (see the module docs).
pub struct ControlLoop {
    settings: ControllerIoSettings,
    ctl: PitController,
    params: ParamSet,
    mu: f64,
    road: Road,
    obstacles: Vec<Obstacle>,
    bullet_model: BulletModel,
    target_model: FourDofTarget,
    contact_law: ContactLaw,
    clock: Box<dyn Clock + Send>,
    seq: u64,
    counters: Counters,
    last_faults: u32,
}

fn phase_code(p: Phase) -> u32 {
    match p {
        Phase::Chasing => 0,
        Phase::Pit => 1,
        Phase::Stabilising => 2,
        Phase::Done => 3,
        Phase::Aborted => 4,
    }
}

fn mpc_code(s: Option<MpcStatus>) -> u32 {
    match s {
        None => 0,
        Some(MpcStatus::Converged) => 1,
        Some(MpcStatus::RtiStep) => 2,
        Some(MpcStatus::IterationCap) => 3,
        Some(MpcStatus::TimeBudget) => 4,
        Some(MpcStatus::QpFailure) => 5,
    }
}

impl ControlLoop {
    /// A loop around `ctl` for the road and obstacles the controller knows, on the wall
    /// clock (for the deadline).
    #[must_use]
    pub fn new(
        settings: ControllerIoSettings,
        ctl: PitController,
        params: &ParamSet,
        mu: f64,
        road: Road,
        obstacles: Vec<Obstacle>,
    ) -> Self {
        Self {
            ctl,
            params: params.clone(),
            mu,
            road,
            obstacles,
            bullet_model: BulletModel::new(&params.bullet, mu, PREDICT_DT),
            target_model: FourDofTarget::new(&params.target, mu, PREDICT_DT),
            contact_law: ContactLaw::from_params(&params.contact),
            clock: Box::new(MonotonicClock::new()),
            seq: 0,
            counters: Counters::default(),
            last_faults: 0,
            settings,
        }
    }

    /// Measure the cycle time (for the deadline) with `clock` instead of the wall clock.
    #[must_use]
    pub fn with_clock(mut self, clock: Box<dyn Clock + Send>) -> Self {
        self.clock = clock;
        self
    }

    #[must_use]
    pub fn counters(&self) -> Counters {
        self.counters
    }

    #[must_use]
    pub fn controller(&self) -> &PitController {
        &self.ctl
    }

    #[must_use]
    pub fn settings(&self) -> &ControllerIoSettings {
        &self.settings
    }

    /// Start over (a new run): the controller forgets its plan and phase.
    pub fn reset(&mut self) {
        self.ctl.reset();
    }

    /// The fault bits of the last cycle.
    #[must_use]
    pub fn last_faults(&self) -> u32 {
        self.last_faults
    }

    /// The delay compensation's prediction: the measured states of `s` carried forward by
    /// `dt` seconds in steps of 1 ms, the bullet with its bicycle model under the command in
    /// force when it was measured (`bullet_applied`), the target with the 4-DOF model under
    /// its driver's input (`target_input`), and where their footprints overlap the contact
    /// force of the plant's law between them (from the predicted states, not the measured
    /// force: a car has no force sensor). `tests/predict.rs` sets it against the plant.
    pub fn predict(&mut self, s: &StateEstimate, dt: f64) -> (TargetState, BulletState) {
        let mut xt = TargetState::from_column_slice(&s.target);
        let mut xb = BulletState::from_column_slice(&s.bullet);
        let n = (dt / PREDICT_DT).round() as usize;
        let ub = BulletInput::new(s.bullet_applied[0], s.bullet_applied[1]);
        let ut = TargetInput::new(s.target_input[0], s.target_input[1]);
        for _ in 0..n {
            let (ct, cb) = self.predicted_contact(&xt, &xb);
            xb = self.bullet_model.step(&xb, &ub, &cb);
            xt = self.target_model.step(&xt, &ut, &ct);
        }
        (xt, xb)
    }

    /// The contact of the predicted states as each vehicle's model takes it (the same force
    /// and normal, the point in each body frame; none apart).
    fn predicted_contact(
        &self,
        xt: &TargetState,
        xb: &BulletState,
    ) -> (ContactInput, ContactInput) {
        let (pt, pb) = (&self.params.target, &self.params.bullet);
        let (t_pos, b_pos) = (Vec2::new(xt[idx::X], xt[idx::Y]), Vec2::new(xb[0], xb[1]));
        let (t_psi, b_psi) = (xt[idx::PSI], xb[2]);
        let ft = Obb::vehicle_footprint(
            &Pose2::new(t_pos.x, t_pos.y, t_psi),
            pt.length,
            pt.width,
            pt.cg_to_front,
        );
        let fb = Obb::vehicle_footprint(
            &Pose2::new(b_pos.x, b_pos.y, b_psi),
            pb.length,
            pb.width,
            pb.cg_to_front,
        );
        // The bullet is body A, the target B: the normal points into the target.
        let Some(geom) = obb_contact(&fb, &ft) else {
            return (ContactInput::none(), ContactInput::none());
        };
        let point_velocity = |pos: Vec2, psi: f64, v: Vec2, r: f64| {
            let arm = geom.point - pos;
            rotate(psi, v) + Vec2::new(-r * arm.y, r * arm.x)
        };
        let v_t = point_velocity(
            t_pos,
            t_psi,
            Vec2::new(xt[idx::VX], xt[idx::VY]),
            xt[idx::R],
        );
        let v_b = point_velocity(b_pos, b_psi, Vec2::new(xb[3], xb[4]), xb[5]);
        let fc = self.contact_law.force(
            &geom,
            v_t - v_b,
            [
                (1.0 / pb.mass, 1.0 / pb.iz, geom.point - b_pos),
                (1.0 / pt.mass, 1.0 / pt.iz, geom.point - t_pos),
            ],
        );
        let gamma = geom.gamma();
        let at = |pos: Vec2, psi: f64| ContactInput {
            fc,
            gamma,
            point_in_body: rotate(-psi, geom.point - pos),
        };
        (at(t_pos, t_psi), at(b_pos, b_psi))
    }

    fn fallback(&self, s: &StateEstimate) -> BulletInput {
        let xb = BulletState::from_column_slice(&s.bullet);
        brake_along_road(
            &self.road,
            &xb,
            &self.params.bullet,
            self.mu,
            self.settings.fallback_brake,
        )
    }

    /// One cycle: the command to publish and the status.
    pub fn step(&mut self, input: &CycleInput<'_>) -> (ActuatorCommand, ControllerStatus) {
        let t0 = self.clock.now();
        self.counters.cycles += 1;
        self.seq += 1;
        let mut faults = 0u32;
        if !input.peer_alive {
            faults |= fault::PEER_DEAD;
        }
        let valid_for = self.settings.stale_ns();
        let mut cmd = ActuatorCommand {
            seq: self.seq,
            stamp_ns: input.now_ns,
            valid_until_ns: input.now_ns.saturating_add(valid_for),
            wall_state_received_ns: input.wall_received_ns,
            ..ActuatorCommand::default()
        };
        let mut status = ControllerStatus {
            seq: self.seq,
            stamp_ns: input.now_ns,
            phase: phase_code(self.ctl.phase()),
            ..ControllerStatus::default()
        };

        let Some(s) = input.state else {
            faults |= fault::NO_STATE;
            cmd.mode = CommandMode::SafeStop as u32;
            self.finish(&mut status, faults, true);
            return (cmd, status);
        };
        cmd.state_seq = s.seq;
        status.state_seq = s.seq;
        let age_ns = input.now_ns.saturating_sub(s.stamp_ns);
        if age_ns > valid_for {
            faults |= fault::STALE_STATE;
            self.counters.stale_states = self.counters.stale_states.saturating_add(1);
        }
        if !s.is_finite() {
            faults |= fault::BAD_STATE;
        }
        if faults & (fault::STALE_STATE | fault::BAD_STATE | fault::PEER_DEAD) != 0 {
            if faults & fault::BAD_STATE == 0 {
                let u = self.fallback(s);
                cmd.steer = u[0];
                cmd.torque = u[1];
                cmd.mode = CommandMode::Fallback as u32;
            } else {
                cmd.mode = CommandMode::SafeStop as u32;
            }
            self.finish(&mut status, faults, true);
            return (cmd, status);
        }

        let comp = if self.settings.compensate_delay {
            (age_ns as f64 * 1e-9 + self.settings.actuation_delay)
                .min(self.settings.max_compensation)
        } else {
            0.0
        };
        let (xt, xb) = self.predict(s, comp);
        let prev_phase = self.ctl.phase();
        status.compensated_ns = secs_to_ns(comp);
        // The controller's time: when the (predicted) states hold; without compensation the
        // states are taken as current, so "now".
        let time = if self.settings.compensate_delay {
            s.stamp_ns.saturating_sub(s.run_start_ns) as f64 * 1e-9 + comp
        } else {
            input.now_ns.saturating_sub(s.run_start_ns) as f64 * 1e-9
        };
        let out = self.ctl.step(&ControllerInput {
            time,
            target: xt,
            bullet: xb,
            target_input: TargetInput::new(s.target_input[0], s.target_input[1]),
            road: &self.road,
            obstacles: &self.obstacles,
        });
        let out = match out {
            Ok(o) => o,
            Err(_) => {
                faults |= fault::BAD_STATE;
                let u = self.fallback(s);
                cmd.steer = u[0];
                cmd.torque = u[1];
                cmd.mode = CommandMode::Fallback as u32;
                self.finish(&mut status, faults, true);
                return (cmd, status);
            }
        };
        self.counters.solves += 1;
        if out.phase == Phase::Stabilising && prev_phase != Phase::Stabilising {
            status.events |= event::STABILISING;
        }
        if prev_phase == Phase::Chasing
            && matches!(out.abort, Some(AbortReason::DecisionInfeasible(_)))
        {
            status.events |= event::DECISION_INFEASIBLE;
        }
        if prev_phase == Phase::Pit && out.phase == Phase::Chasing {
            status.events |= event::PUSH_RETRIED;
        }
        status.phase = phase_code(out.phase);
        status.mpc_status = mpc_code(out.mpc_status);
        status.ctrl_ns = secs_to_ns(out.ctrl_time);
        status.plan_ns = if out.replanned {
            secs_to_ns(out.plan_time)
        } else {
            0
        };
        if out.mpc_status == Some(MpcStatus::QpFailure) {
            faults |= fault::SOLVER_FAILURE;
            self.counters.solver_failures = self.counters.solver_failures.saturating_add(1);
        }
        let elapsed = self.clock.now() - t0;
        let mut fallback = false;
        if elapsed > self.settings.deadline {
            faults |= fault::DEADLINE_MISSED;
            self.counters.deadline_misses = self.counters.deadline_misses.saturating_add(1);
            let u = self.fallback(s);
            cmd.steer = u[0];
            cmd.torque = u[1];
            cmd.mode = CommandMode::Fallback as u32;
            fallback = true;
        } else {
            cmd.steer = out.command[0];
            cmd.torque = out.command[1];
            cmd.mode = if matches!(out.phase, Phase::Aborted) {
                CommandMode::Fallback as u32
            } else {
                CommandMode::Track as u32
            };
        }
        self.finish(&mut status, faults, fallback);
        (cmd, status)
    }

    fn finish(&mut self, status: &mut ControllerStatus, faults: u32, fallback: bool) {
        if fallback {
            self.counters.fallbacks = self.counters.fallbacks.saturating_add(1);
        }
        self.last_faults = faults;
        status.faults = faults;
        status.deadline_misses = self.counters.deadline_misses;
        status.fallbacks = self.counters.fallbacks;
        status.stale_states = self.counters.stale_states;
    }
}
