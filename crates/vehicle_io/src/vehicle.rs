//! The vehicle side: the [`VehicleBridge`] a real car's CAN gateway would implement, the
//! shipped simulator bridge ([`SimBridge`]: the plant for both vehicles, with sensing noise,
//! latency and actuator errors), and the vehicle's own watchdog ([`CommandGate`]).

use crate::msg::{ActuatorCommand, CommandMode, StateEstimate, STATE_CONTACT, STATE_SAFE_STOP};
use dynamics::bullet::{brake_along_road, BulletState};
use dynamics::ContactInput;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::Serialize;
use sim::episode::{EpisodeError, Uncertainty};
use sim::vehicle::SimVehicle;
use sim::{Metrics, Scenario, Status};

/// Where a vehicle plugs in. The shipped implementation is [`SimBridge`]; on a car this is
/// the CAN gateway (state estimation in, steer and torque requests out).
pub trait VehicleBridge {
    /// The vehicle clock: nanoseconds since the run started.
    fn now_ns(&self) -> u64;
    /// The newest state estimate: fill `target`, `bullet`, `target_input`,
    /// `bullet_applied`, `stamp_ns` (measurement time), the `STATE_CONTACT` flag and, when
    /// known, the `contact_*` fields; the caller fills sequence numbers and send stamps.
    fn measure(&mut self, out: &mut StateEstimate);
    /// Request steer (rad) and rear-axle torque (N·m, negative brakes).
    fn actuate(&mut self, steer: f64, torque: f64);
    /// The vehicle's own safe stop, requested every period while it is latched: controlled
    /// braking along the road, whatever the controller says.
    fn safe_stop(&mut self);
    /// Let `steps` plant steps (of [`VehicleBridge::step_ns`]) pass: the simulator steps its
    /// plant, a real vehicle has nothing to do (its time passes by itself).
    fn step(&mut self, steps: usize);
    /// Close a control period; returns whether the run is over (the simulator's judge has
    /// decided; a real vehicle: the operator ended it).
    fn end_period(&mut self) -> bool;
    /// Duration of one [`VehicleBridge::step`] (ns).
    fn step_ns(&self) -> u64;
    /// The bullet's speed over ground (m/s).
    fn bullet_speed(&self) -> f64;
    /// Start the scenario over (a soak); the clock runs on. Returns false when the bridge
    /// cannot (a real vehicle).
    fn restart(&mut self) -> bool {
        false
    }
    /// The vehicle time the current run started (ns).
    fn run_start_ns(&self) -> u64 {
        0
    }
    /// The controller's status `events` bits (`msg::event`), as they arrive: a simulator's
    /// judge needs to know when stabilisation began; a real vehicle ignores them.
    fn controller_events(&mut self, _events: u32) {}
}

/// The plant as the vehicle pair ([`SimVehicle`]): the truth, judged by the success test.
pub struct SimBridge {
    scenario: Scenario,
    uncertainty: Uncertainty,
    period: f64,
    sim: SimVehicle,
    rng: ChaCha8Rng,
    /// Vehicle time at the start of the current run (ns).
    epoch_ns: u64,
    safe_brake: f64,
    finished: bool,
}

impl SimBridge {
    /// The scenario's vehicles with `uncertainty` (noise and actuator errors seeded by
    /// `seed`), periods of `period` seconds; the safe stop brakes at `safe_brake` μ g.
    ///
    /// # Errors
    /// [`EpisodeError`] for a bad scenario or uncertainty (naming the field).
    pub fn new(
        sc: &Scenario,
        uncertainty: Uncertainty,
        period: f64,
        seed: u64,
        safe_brake: f64,
    ) -> Result<Self, EpisodeError> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let sim = SimVehicle::new(sc, uncertainty, period, &mut rng)?;
        Ok(Self {
            scenario: sc.clone(),
            uncertainty,
            period,
            sim,
            rng,
            epoch_ns: 0,
            safe_brake,
            finished: false,
        })
    }

    #[must_use]
    pub fn sim(&self) -> &SimVehicle {
        &self.sim
    }

    /// The judge's metrics so far.
    #[must_use]
    pub fn metrics(&self) -> Metrics {
        self.sim.metrics()
    }

    /// The bullet's smallest distance to a road edge now (m; negative outside).
    #[must_use]
    pub fn bullet_road_margin(&self) -> f64 {
        let fp = self.sim.plant().footprints()[0];
        let road = self.sim.road();
        fp.corners()
            .iter()
            .map(|c| road.half_width() - road.project(*c).d.abs())
            .fold(f64::INFINITY, f64::min)
    }
}

impl VehicleBridge for SimBridge {
    fn now_ns(&self) -> u64 {
        self.epoch_ns + crate::config::secs_to_ns(self.sim.time())
    }

    fn measure(&mut self, out: &mut StateEstimate) {
        let sensed = self.sim.sense(&mut self.rng);
        out.target.copy_from_slice(sensed.target.as_slice());
        out.bullet = sensed.bullet;
        out.target_input = sensed.target_input;
        out.bullet_applied = self.sim.applied();
        out.stamp_ns = self.epoch_ns + crate::config::secs_to_ns(self.sim.time() - sensed.age);
        out.run_start_ns = self.epoch_ns;
        if self.sim.plant().contact().is_some() {
            out.flags |= STATE_CONTACT;
        }
        let c = self.sim.contact().unwrap_or_else(ContactInput::none);
        out.contact_force = [c.fc.x, c.fc.y];
        out.contact_gamma = c.gamma;
        out.contact_point = [c.point_in_body.x, c.point_in_body.y];
    }

    fn actuate(&mut self, steer: f64, torque: f64) {
        self.sim.actuate([steer, torque]);
    }

    fn safe_stop(&mut self) {
        let b = self.sim.plant().bullet_state();
        let xb = BulletState::from_column_slice(b.as_slice());
        let u = brake_along_road(
            self.sim.road(),
            &xb,
            &self.sim.params().bullet,
            self.sim.mu(),
            self.safe_brake,
        );
        self.sim.actuate([u[0], u[1]]);
    }

    fn step(&mut self, steps: usize) {
        self.sim.step_plant(steps);
    }

    fn end_period(&mut self) -> bool {
        self.finished |= matches!(self.sim.end_period(), Status::Done(_));
        self.finished
    }

    fn step_ns(&self) -> u64 {
        crate::config::secs_to_ns(self.sim.plant().dt())
    }

    fn bullet_speed(&self) -> f64 {
        let b = self.sim.plant().bullet_state();
        b[3].hypot(b[4])
    }

    fn restart(&mut self) -> bool {
        let now = self.now_ns();
        match SimVehicle::new(&self.scenario, self.uncertainty, self.period, &mut self.rng) {
            Ok(sim) => {
                self.sim = sim;
                self.epoch_ns = now;
                self.finished = false;
                true
            }
            Err(_) => false,
        }
    }

    fn run_start_ns(&self) -> u64 {
        self.epoch_ns
    }

    fn controller_events(&mut self, events: u32) {
        let t = self.sim.time();
        if events & crate::msg::event::PUSH_RETRIED != 0 {
            self.sim.push_retried();
        }
        if events & crate::msg::event::STABILISING != 0 {
            self.sim.enter_stabilisation(t);
        }
        if events & crate::msg::event::DECISION_INFEASIBLE != 0 {
            self.sim.decision_infeasible(t);
        }
    }
}

/// Why the vehicle stopped itself.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum SafeStopReason {
    /// No valid command within `command_timeout`.
    CommandTimeout,
    /// The controller asked for it.
    ControllerRequest,
}

/// The vehicle's watchdog on commands: which command applies now, when to take over, and
/// when a controller that came back may have the vehicle again.
///
/// - **Latch.** No valid command for `timeout_ns` (vehicle clock), or a command in
///   [`CommandMode::SafeStop`]: the vehicle's own safe stop, whatever the queued commands say.
/// - **Resume** (a late but alive peer: the controller was paused, its host stalled, or it
///   was restarted). A safe stop latched on the timeout is released by `resume_after`
///   consecutive *fresh* commands: finite, not expired, in track or fallback mode, and
///   answering a state published after the latch (so the controller has seen the vehicle
///   braking). A stale command in between starts the count again. `resume_after = 0` keeps
///   the latch until the run ends. A safe stop the controller asked for is never released.
/// - **Sequence numbers.** A command older than or equal to the newest one is ignored,
///   except that a sequence number that goes *back* means a new controller process (one
///   publisher, delivered in order: a restarted controller counts from 1 again). Its commands
///   are taken, and the restart is counted.
#[derive(Debug, Clone, Copy)]
pub struct CommandGate {
    timeout_ns: u64,
    resume_after: u32,
    /// A valid command not yet applied, the newest sequence number seen and when the last
    /// valid command arrived (vehicle clock).
    pending: Option<ActuatorCommand>,
    last_seq: Option<u64>,
    last_valid_ns: u64,
    latched: Option<(SafeStopReason, u64)>,
    /// The newest state published, and the first state a command must answer to count
    /// toward a resume.
    published_seq: Option<u64>,
    resume_from_seq: u64,
    fresh: u32,
    pub received: u64,
    pub applied: u64,
    pub stale: u64,
    /// Safe stops latched, and how many of them were released.
    pub latches: u64,
    pub resumes: u64,
    /// Sequence numbers that went back (a new controller process).
    pub controller_restarts: u64,
    /// The largest delay of a timeout latch past its deadline (ns, vehicle clock).
    pub latch_late_max_ns: u64,
}

/// What the gate decided.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Actuation {
    /// Apply this `[δ_f, T_r]`.
    Command([f64; 2]),
    /// Nothing new: keep what is applied.
    Hold,
    /// The vehicle's own safe stop.
    SafeStop,
}

impl CommandGate {
    /// A gate that takes over `timeout_ns` after the last valid command (counted from
    /// `start_ns` before the first) and lets go after `resume_after` fresh commands.
    #[must_use]
    pub fn new(timeout_ns: u64, resume_after: u32, start_ns: u64) -> Self {
        Self {
            timeout_ns,
            resume_after,
            pending: None,
            last_seq: None,
            last_valid_ns: start_ns,
            latched: None,
            published_seq: None,
            resume_from_seq: 0,
            fresh: 0,
            received: 0,
            applied: 0,
            stale: 0,
            latches: 0,
            resumes: 0,
            controller_restarts: 0,
            latch_late_max_ns: 0,
        }
    }

    /// The vehicle published state `seq` (commands answering later states are fresh).
    pub fn published(&mut self, seq: u64) {
        self.published_seq = Some(seq);
    }

    /// A new run (a soak restart) at `now_ns`: unlatched, nothing pending, the timeout
    /// counted from now. The counters and the newest sequence number stay.
    pub fn restart(&mut self, now_ns: u64) {
        self.pending = None;
        self.latched = None;
        self.fresh = 0;
        self.last_valid_ns = now_ns;
    }

    /// Offer a received command at vehicle time `now_ns`.
    pub fn offer(&mut self, cmd: &ActuatorCommand, now_ns: u64) {
        self.received += 1;
        let finite = cmd.steer.is_finite() && cmd.torque.is_finite();
        if !finite || cmd.valid_until_ns < now_ns {
            self.stale += 1;
            self.fresh = 0;
            return;
        }
        match self.last_seq {
            Some(s) if cmd.seq == s => return,
            Some(s) if cmd.seq < s => self.controller_restarts += 1,
            _ => {}
        }
        let mode = cmd.mode();
        if mode == CommandMode::SafeStop
            && !matches!(self.latched, Some((SafeStopReason::ControllerRequest, _)))
        {
            if self.latched.is_none() {
                self.latches += 1;
            }
            self.latched = Some((SafeStopReason::ControllerRequest, now_ns));
        }
        self.last_seq = Some(cmd.seq);
        self.pending = Some(*cmd);
        self.last_valid_ns = now_ns;
        if let Some((SafeStopReason::CommandTimeout, _)) = self.latched {
            if cmd.state_seq >= self.resume_from_seq {
                self.fresh += 1;
                if self.resume_after > 0 && self.fresh >= self.resume_after {
                    self.latched = None;
                    self.resumes += 1;
                    self.fresh = 0;
                }
            }
        }
    }

    /// What to actuate at `now_ns`.
    pub fn decide(&mut self, now_ns: u64) -> Actuation {
        let deadline = self.last_valid_ns.saturating_add(self.timeout_ns);
        if self.latched.is_none() && now_ns > deadline {
            self.latched = Some((SafeStopReason::CommandTimeout, now_ns));
            self.latches += 1;
            self.fresh = 0;
            self.resume_from_seq = self.published_seq.map_or(0, |s| s + 1);
            self.latch_late_max_ns = self.latch_late_max_ns.max(now_ns - deadline);
        }
        if self.latched.is_some() {
            // A command from before (or during) the latch is never applied later.
            self.pending = None;
            return Actuation::SafeStop;
        }
        match self.pending.take() {
            Some(c) => {
                self.applied += 1;
                Actuation::Command([c.steer, c.torque])
            }
            None => Actuation::Hold,
        }
    }

    /// The safe stop, if latched: why and when (vehicle clock, ns).
    #[must_use]
    pub fn latched(&self) -> Option<(SafeStopReason, u64)> {
        self.latched
    }

    /// The `STATE_SAFE_STOP` flag when latched.
    #[must_use]
    pub fn flags(&self) -> u32 {
        if self.latched.is_some() {
            STATE_SAFE_STOP
        } else {
            0
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: u64 = 1_000_000;

    fn cmd(seq: u64, state_seq: u64, now_ns: u64, mode: CommandMode) -> ActuatorCommand {
        ActuatorCommand {
            seq,
            state_seq,
            stamp_ns: now_ns,
            valid_until_ns: now_ns + 100 * MS,
            steer: 0.01,
            torque: 10.0,
            mode: mode as u32,
            ..ActuatorCommand::default()
        }
    }

    /// A gate with a 150 ms timeout that has applied one command at t = 0 (state 0) and then
    /// heard nothing until it latched at t = 200 ms, with states 0..=4 published.
    fn latched_gate(resume_after: u32) -> CommandGate {
        let mut g = CommandGate::new(150 * MS, resume_after, 0);
        g.published(0);
        g.offer(&cmd(1, 0, 0, CommandMode::Track), 0);
        assert_eq!(g.decide(0), Actuation::Command([0.01, 10.0]));
        for k in 1..=4 {
            g.published(k);
        }
        assert_eq!(g.decide(155 * MS), Actuation::SafeStop);
        assert_eq!(
            g.latched(),
            Some((SafeStopReason::CommandTimeout, 155 * MS))
        );
        g
    }

    #[test]
    fn a_timeout_latches_and_its_lateness_is_measured() {
        let g = latched_gate(3);
        assert_eq!(g.latches, 1);
        assert_eq!(g.latch_late_max_ns, 5 * MS);
        assert_eq!(g.flags(), STATE_SAFE_STOP);
    }

    #[test]
    fn fresh_commands_release_a_timeout_latch_and_old_answers_do_not() {
        let mut g = latched_gate(3);
        // Late answers to states from before the latch (state 4 was the newest then).
        for (seq, state) in [(2, 3), (3, 4)] {
            g.offer(&cmd(seq, state, 160 * MS, CommandMode::Track), 160 * MS);
            assert_eq!(g.decide(160 * MS), Actuation::SafeStop);
        }
        g.published(5);
        g.published(6);
        // Two fresh answers: still stopped; a stale one starts the count again.
        g.offer(&cmd(4, 5, 200 * MS, CommandMode::Fallback), 200 * MS);
        g.offer(&cmd(5, 6, 250 * MS, CommandMode::Track), 250 * MS);
        let mut old = cmd(6, 6, 0, CommandMode::Track);
        old.valid_until_ns = 10 * MS;
        g.offer(&old, 260 * MS);
        assert_eq!(g.decide(260 * MS), Actuation::SafeStop);
        for (seq, t) in [(7, 300), (8, 350)] {
            g.offer(&cmd(seq, 6, t * MS, CommandMode::Track), t * MS);
            assert_eq!(g.decide(t * MS), Actuation::SafeStop);
        }
        // The third fresh one in a row releases the latch, and it is what applies.
        g.offer(&cmd(9, 6, 400 * MS, CommandMode::Track), 400 * MS);
        assert_eq!(g.latched(), None);
        assert_eq!(g.decide(400 * MS), Actuation::Command([0.01, 10.0]));
        assert_eq!((g.latches, g.resumes), (1, 1));
        // The watchdog runs again from the last valid command.
        assert_eq!(g.decide(549 * MS), Actuation::Hold);
        assert_eq!(g.decide(551 * MS), Actuation::SafeStop);
        assert_eq!(g.latches, 2);
    }

    #[test]
    fn resume_after_zero_keeps_the_latch() {
        let mut g = latched_gate(0);
        g.published(5);
        for seq in 2..20 {
            let t = seq * 50 * MS;
            g.offer(&cmd(seq, 5, t, CommandMode::Track), t);
            assert_eq!(g.decide(t), Actuation::SafeStop);
        }
        assert_eq!(g.resumes, 0);
    }

    #[test]
    fn a_safe_stop_the_controller_asked_for_is_never_released() {
        let mut g = CommandGate::new(150 * MS, 3, 0);
        g.published(0);
        g.offer(&cmd(1, 0, 0, CommandMode::SafeStop), 0);
        assert_eq!(g.decide(0), Actuation::SafeStop);
        for seq in 2..10 {
            g.published(seq);
            let t = seq * 50 * MS;
            g.offer(&cmd(seq, seq, t, CommandMode::Track), t);
            assert_eq!(g.decide(t), Actuation::SafeStop);
        }
        assert_eq!(
            g.latched().map(|l| l.0),
            Some(SafeStopReason::ControllerRequest)
        );
        // Asked for while already stopped on the timeout: it becomes the controller's.
        let mut g = latched_gate(3);
        g.published(5);
        g.offer(&cmd(2, 5, 200 * MS, CommandMode::SafeStop), 200 * MS);
        for seq in 3..10 {
            g.offer(&cmd(seq, 5, 200 * MS, CommandMode::Track), 200 * MS);
        }
        assert_eq!(
            g.latched().map(|l| l.0),
            Some(SafeStopReason::ControllerRequest)
        );
        assert_eq!(g.latches, 1);
    }

    #[test]
    fn a_restarted_controller_counting_from_one_is_heard() {
        let mut g = CommandGate::new(150 * MS, 3, 0);
        g.published(0);
        for seq in 1..=40 {
            g.offer(&cmd(seq, 0, 0, CommandMode::Track), 0);
        }
        assert_eq!(g.decide(0), Actuation::Command([0.01, 10.0]));
        // A duplicate is ignored; a sequence that starts again is a new controller.
        g.offer(&cmd(40, 0, 10 * MS, CommandMode::Track), 10 * MS);
        assert_eq!(g.decide(10 * MS), Actuation::Hold);
        let mut c = cmd(1, 0, 20 * MS, CommandMode::Track);
        c.steer = -0.02;
        g.offer(&c, 20 * MS);
        assert_eq!(g.decide(20 * MS), Actuation::Command([-0.02, 10.0]));
        assert_eq!(g.controller_restarts, 1);
        g.offer(&cmd(2, 0, 30 * MS, CommandMode::Track), 30 * MS);
        assert_eq!(g.decide(30 * MS), Actuation::Command([0.01, 10.0]));
    }

    #[test]
    fn a_soak_restart_unlatches_the_gate() {
        let mut g = latched_gate(0);
        g.restart(300 * MS);
        assert_eq!(g.latched(), None);
        assert_eq!(g.decide(400 * MS), Actuation::Hold);
        assert_eq!(g.decide(451 * MS), Actuation::SafeStop);
    }
}
