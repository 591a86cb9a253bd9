//! The vehicle side: the [`VehicleBridge`] a real car's CAN gateway would implement, the
//! shipped simulator bridge ([`SimBridge`]: the plant for both vehicles, with sensing noise,
//! latency and actuator errors), and the vehicle's own watchdog ([`CommandGate`]).

use crate::msg::{ActuatorCommand, CommandMode, StateEstimate, STATE_CONTACT, STATE_SAFE_STOP};
use dynamics::bullet::{brake_along_road, BulletState};
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
    /// `bullet_applied`, `stamp_ns` (measurement time) and the `STATE_CONTACT` flag; the
    /// caller fills sequence numbers and send stamps.
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

/// The vehicle's watchdog on commands: which command applies now, and when to take over.
#[derive(Debug, Clone, Copy)]
pub struct CommandGate {
    timeout_ns: u64,
    /// A valid command not yet applied, the newest sequence number seen and when the last
    /// valid command arrived (vehicle clock).
    pending: Option<ActuatorCommand>,
    last_seq: Option<u64>,
    last_valid_ns: u64,
    latched: Option<(SafeStopReason, u64)>,
    pub received: u64,
    pub applied: u64,
    pub stale: u64,
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
    /// `start_ns` before the first).
    #[must_use]
    pub fn new(timeout_ns: u64, start_ns: u64) -> Self {
        Self {
            timeout_ns,
            pending: None,
            last_seq: None,
            last_valid_ns: start_ns,
            latched: None,
            received: 0,
            applied: 0,
            stale: 0,
        }
    }

    /// Offer a received command at vehicle time `now_ns`.
    pub fn offer(&mut self, cmd: &ActuatorCommand, now_ns: u64) {
        self.received += 1;
        let finite = cmd.steer.is_finite() && cmd.torque.is_finite();
        if !finite || cmd.valid_until_ns < now_ns {
            self.stale += 1;
            return;
        }
        if self.last_seq.is_some_and(|s| s >= cmd.seq) {
            return;
        }
        if cmd.mode() == CommandMode::SafeStop && self.latched.is_none() {
            self.latched = Some((SafeStopReason::ControllerRequest, now_ns));
        }
        self.last_seq = Some(cmd.seq);
        self.pending = Some(*cmd);
        self.last_valid_ns = now_ns;
    }

    /// What to actuate at `now_ns`.
    pub fn decide(&mut self, now_ns: u64) -> Actuation {
        if self.latched.is_none() && now_ns.saturating_sub(self.last_valid_ns) > self.timeout_ns {
            self.latched = Some((SafeStopReason::CommandTimeout, now_ns));
        }
        if self.latched.is_some() {
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
