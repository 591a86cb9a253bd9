//! The simulated vehicle pair: the plant (the truth), the target's driver, the sensors the
//! controller reads (latency and noise), the bullet's actuators (gain and bias errors) and
//! the success test, one control period at a time.
//!
//! Both the in-process episode runner and the vehicle side of the IPC (`pit-vehicle`) drive
//! a [`SimVehicle`], so the two see the same physics, noise and judging. Per control
//! period: [`SimVehicle::sense`] (what the sensors report; the target driver decides its
//! input), then [`SimVehicle::actuate`] (the bullet command, through the actuator errors),
//! then [`SimVehicle::advance`] (the plant steps one period; the monitor judges).
//!
//! Randomness is injected: actuator errors are drawn once at construction, in the order
//! steer gain, steer bias, torque gain; sensing noise per [`SimVehicle::sense`], in the order
//! target vx vy ψ r p X Y, bullet X Y ψ vx vy r.

use crate::config::{EpisodeError, Uncertainty};
use crate::outcome::{Metrics, Monitor, Status};
use crate::scenario::{Scenario, TargetDriver};
use dynamics::params::ParamSet;
use dynamics::plant::{Gear, Plant, PlantConfig, VehicleInit};
use dynamics::road::{Obstacle, Road};
use dynamics::{ContactInput, TargetState};
use rand::{Rng, RngCore};
use std::collections::VecDeque;

/// What the sensors report at one control step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sensed {
    /// Target `[vx, vy, ψ, r, p, φ, X, Y]`, delayed and noisy.
    pub target: TargetState,
    /// Bullet `[X, Y, ψ, vx, vy, r]`, delayed and noisy.
    pub bullet: [f64; 6],
    /// The target driver's input now `[δ_f, T_b]` (the truth: the benchmark's controller is
    /// told it; a real vehicle would estimate it).
    pub target_input: [f64; 2],
    /// Age of the reported states (s): the sensing latency, rounded to plant steps.
    pub age: f64,
}

/// A delay line of true states: what the sensors report is `delay_steps` plant steps old.
#[derive(Debug, Clone)]
struct Sensor {
    buf: VecDeque<(TargetState, [f64; 6])>,
    delay_steps: usize,
}

impl Sensor {
    fn new(delay_steps: usize, target: TargetState, bullet: [f64; 6]) -> Self {
        let mut buf = VecDeque::with_capacity(delay_steps + 2);
        buf.push_back((target, bullet));
        Self { buf, delay_steps }
    }

    fn push(&mut self, target: TargetState, bullet: [f64; 6]) {
        if self.buf.len() > self.delay_steps {
            self.buf.pop_front();
        }
        self.buf.push_back((target, bullet));
    }

    /// The delayed states (the oldest kept sample).
    fn read(&self) -> (TargetState, [f64; 6]) {
        self.buf
            .front()
            .copied()
            .unwrap_or_else(|| unreachable!("the sensor buffer always holds the initial sample"))
    }
}

/// A standard normal draw (Box–Muller; two uniforms per draw, for a simple fixed order).
pub(crate) fn gauss<R: RngCore + ?Sized>(rng: &mut R) -> f64 {
    let u1: f64 = 1.0 - rng.random::<f64>();
    let u2: f64 = rng.random::<f64>();
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

/// Uniform in `±half` (no draw when `half` is 0).
pub(crate) fn uniform_pm<R: RngCore + ?Sized>(rng: &mut R, half: f64) -> f64 {
    if half > 0.0 {
        half * (2.0 * rng.random::<f64>() - 1.0)
    } else {
        0.0
    }
}

fn add_noise<R: RngCore + ?Sized>(
    u: &Uncertainty,
    rng: &mut R,
    xt: &mut TargetState,
    xb: &mut [f64; 6],
) {
    let mut draw = |std: f64| std * gauss(rng);
    xt[0] += draw(u.speed_std);
    xt[1] += draw(u.speed_std);
    xt[2] += draw(u.heading_std);
    xt[3] += draw(u.yaw_rate_std);
    xt[4] += draw(u.yaw_rate_std);
    xt[6] += draw(u.position_std);
    xt[7] += draw(u.position_std);
    xb[0] += draw(u.position_std);
    xb[1] += draw(u.position_std);
    xb[2] += draw(u.heading_std);
    xb[3] += draw(u.speed_std);
    xb[4] += draw(u.speed_std);
    xb[5] += draw(u.yaw_rate_std);
}

/// The bullet's `[X, Y, ψ, vx, vy, r]` from the plant.
#[must_use]
pub fn bullet_array(plant: &Plant) -> [f64; 6] {
    let b = plant.bullet_state();
    [b[0], b[1], b[2], b[3], b[4], b[5]]
}

/// The simulated vehicle pair of one scenario (see the module docs).
///
/// Memory: the plant, the road and obstacles of the scenario, and a sensor delay line of
/// `latency / plant dt + 2` samples, all allocated at construction; the per-period calls
/// allocate nothing.
#[derive(Debug, Clone)]
pub struct SimVehicle {
    params: ParamSet,
    mu: f64,
    road: Road,
    obstacles: Vec<Obstacle>,
    plant: Plant,
    driver: TargetDriver,
    monitor: Monitor,
    sensor: Sensor,
    uncertainty: Uncertainty,
    delay_steps: usize,
    steps_per: usize,
    steer_gain: f64,
    steer_bias: f64,
    torque_gain: f64,
    first_contact: Option<f64>,
    target_command: [f64; 2],
    applied: [f64; 2],
    contact: Option<ContactInput>,
    status: Status,
    /// The scenario's initial states (bullet, target).
    initial: (VehicleInit, VehicleInit),
}

impl SimVehicle {
    /// The scenario's vehicles at their initial states, with `uncertainty`, advancing
    /// `control_dt` per period; actuator errors are drawn from `rng` now.
    ///
    /// # Errors
    /// [`EpisodeError`] for a scenario whose road, parameters or judge settings are bad, or
    /// bad uncertainty values (naming the field).
    pub fn new<R: RngCore + ?Sized>(
        sc: &Scenario,
        uncertainty: Uncertainty,
        control_dt: f64,
        rng: &mut R,
    ) -> Result<Self, EpisodeError> {
        uncertainty.validate()?;
        if !(control_dt.is_finite() && control_dt > 0.0 && control_dt <= 1.0) {
            return Err(EpisodeError::Config {
                field: "control_dt".to_owned(),
                message: format!("{control_dt}: must lie in (0, 1] s"),
            });
        }
        let params = sc.params.load()?;
        let road = sc.build_road()?;
        let obstacles = sc.obstacles();
        let mut plant = Plant::new(
            &params,
            PlantConfig {
                mu: sc.mu,
                ..PlantConfig::default()
            },
        )
        .map_err(|e| EpisodeError::Plant(e.to_string()))?;
        plant.set_obstacles(obstacles.clone());
        let (bi, ti) = sc.initial_states(&road);
        plant.reset(&bi, &ti);
        let initial = (bi, ti);
        let driver = sc.target_driver(&params);
        let monitor = Monitor::for_scenario(sc)?;
        let plant_dt = plant.dt();
        let steps_per = (control_dt / plant_dt).round().max(1.0) as usize;
        let delay_steps = (uncertainty.latency / plant_dt).round() as usize;
        let sensor = Sensor::new(delay_steps, plant.target_state(), bullet_array(&plant));
        let steer_gain = 1.0 + uniform_pm(rng, uncertainty.steer_gain);
        let steer_bias = uniform_pm(rng, uncertainty.steer_bias);
        let torque_gain = 1.0 + uniform_pm(rng, uncertainty.torque_gain);
        Ok(Self {
            params,
            mu: sc.mu,
            road,
            obstacles,
            plant,
            driver,
            monitor,
            sensor,
            uncertainty,
            delay_steps,
            steps_per,
            steer_gain,
            steer_bias,
            torque_gain,
            first_contact: None,
            target_command: [0.0; 2],
            applied: [0.0; 2],
            contact: None,
            status: Status::Running,
            initial,
        })
    }

    /// Put the target in `gear` (the plant starts again from the scenario's initial states;
    /// call before the first period). The default is [`Gear::Forward`].
    ///
    /// # Errors
    /// [`EpisodeError::Plant`] when the target has no powertrain for a forward gear.
    pub fn set_target_gear(&mut self, gear: Gear) -> Result<(), EpisodeError> {
        if self.plant.config().target_gear == gear {
            return Ok(());
        }
        let mut plant = Plant::new(
            &self.params,
            PlantConfig {
                target_gear: gear,
                ..*self.plant.config()
            },
        )
        .map_err(|e| EpisodeError::Plant(e.to_string()))?;
        plant.set_obstacles(self.obstacles.clone());
        let (bi, ti) = self.initial;
        plant.reset(&bi, &ti);
        self.plant = plant;
        Ok(())
    }

    /// What the sensors report now; the target driver decides its input for this period
    /// (from the true target state) and the plant takes it.
    pub fn sense<R: RngCore + ?Sized>(&mut self, rng: &mut R) -> Sensed {
        let t = self.plant.time();
        let truth = self.plant.target_state();
        let (mut xt, mut xb) = self.sensor.read();
        if self.uncertainty.has_noise() {
            add_noise(&self.uncertainty, rng, &mut xt, &mut xb);
        }
        let (steer, brake) = self
            .driver
            .command(t, self.first_contact, &truth, &self.road);
        self.plant.set_target_command(steer, brake);
        self.target_command = [steer, brake];
        Sensed {
            target: xt,
            bullet: xb,
            target_input: [steer, brake],
            age: self.delay_steps as f64 * self.plant.dt(),
        }
    }

    /// Apply the bullet command `[δ_f, T_r]` through the actuators (gain and bias errors;
    /// negative torque brakes through the blended brakes).
    pub fn actuate(&mut self, command: [f64; 2]) {
        let steer = self.steer_gain * command[0] + self.steer_bias;
        let torque = self.torque_gain * command[1];
        self.plant.set_bullet_command_blended(steer, torque);
        self.applied = command;
    }

    /// Step the plant over one control period, judge, and return the status.
    pub fn advance(&mut self) -> Status {
        self.step_plant(self.steps_per);
        self.end_period()
    }

    /// Plant steps per control period.
    #[must_use]
    pub fn steps_per_period(&self) -> usize {
        self.steps_per
    }

    /// Step the plant `n` times (part of a period: a real-time bridge applies commands as
    /// they arrive); the judge latches every step. Close the period with
    /// [`SimVehicle::end_period`].
    pub fn step_plant(&mut self, n: usize) {
        for _ in 0..n {
            self.plant.step();
            self.monitor.latch(&self.plant);
            if self.first_contact.is_none() && self.plant.contact().is_some() {
                self.first_contact = Some(self.plant.time());
            }
            if self.delay_steps > 0 {
                self.sensor
                    .push(self.plant.target_state(), bullet_array(&self.plant));
            }
        }
    }

    /// Close a control period: the sensors sample (without latency), the judge observes.
    pub fn end_period(&mut self) -> Status {
        if self.delay_steps == 0 {
            self.sensor
                .push(self.plant.target_state(), bullet_array(&self.plant));
        }
        self.contact = self.plant.take_contact_average().map(|c| ContactInput {
            fc: c.fc,
            gamma: c.gamma,
            point_in_body: c.point_in_target,
        });
        self.status = self.monitor.observe_plant(&self.plant);
        self.status
    }

    /// Tell the judge the controller has entered stabilisation at `time`.
    pub fn enter_stabilisation(&mut self, time: f64) {
        self.monitor.enter_stabilisation(time);
    }

    /// Tell the judge the controller went back to chasing for another push
    /// ([`crate::outcome::Monitor::push_retried`]); returns whether the judge took it.
    pub fn push_retried(&mut self) -> bool {
        self.monitor.push_retried()
    }

    /// Tell the judge the controller found no feasible decision at `time`.
    pub fn decision_infeasible(&mut self, time: f64) -> Status {
        self.status = self.monitor.decision_infeasible(time);
        self.status
    }

    /// The plant's time (s).
    #[must_use]
    pub fn time(&self) -> f64 {
        self.plant.time()
    }

    #[must_use]
    pub fn plant(&self) -> &Plant {
        &self.plant
    }

    #[must_use]
    pub fn params(&self) -> &ParamSet {
        &self.params
    }

    /// The road's adhesion coefficient.
    #[must_use]
    pub fn mu(&self) -> f64 {
        self.mu
    }

    #[must_use]
    pub fn road(&self) -> &Road {
        &self.road
    }

    #[must_use]
    pub fn obstacles(&self) -> &[Obstacle] {
        &self.obstacles
    }

    /// The status after the last [`SimVehicle::advance`].
    #[must_use]
    pub fn status(&self) -> Status {
        self.status
    }

    #[must_use]
    pub fn metrics(&self) -> Metrics {
        self.monitor.metrics()
    }

    /// The command last given to [`SimVehicle::actuate`] (before actuator errors).
    #[must_use]
    pub fn applied(&self) -> [f64; 2] {
        self.applied
    }

    /// The target driver's input this period.
    #[must_use]
    pub fn target_command(&self) -> [f64; 2] {
        self.target_command
    }

    /// The mean bullet–target contact force `[F_n, F_t]` over the last period (0 apart).
    #[must_use]
    pub fn contact_force(&self) -> [f64; 2] {
        self.contact.map_or([0.0; 2], |c| [c.fc.x, c.fc.y])
    }

    /// The bullet–target contact averaged over the last period as the target model's input
    /// (`None` apart): `dynamics::Plant::take_contact_average` with the point in the
    /// target's body frame.
    #[must_use]
    pub fn contact(&self) -> Option<ContactInput> {
        self.contact
    }

    /// Time of the first bullet–target contact (s).
    #[must_use]
    pub fn first_contact(&self) -> Option<f64> {
        self.first_contact
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_sensor_reports_the_state_of_delay_steps_ago() {
        let x = |v: f64| (TargetState::from_element(v), [v; 6]);
        let (t0, b0) = x(0.0);
        let mut s = Sensor::new(3, t0, b0);
        for k in 1..=10 {
            let (t, b) = x(f64::from(k));
            s.push(t, b);
            assert_eq!(s.read().1[0], f64::from((k - 3).max(0)), "after {k} pushes");
        }
        let mut s = Sensor::new(0, t0, b0);
        let (t, b) = x(5.0);
        s.push(t, b);
        assert_eq!(s.read().0[0], 5.0);
    }
}
