//! The success test and the single first failure cause of an episode (DESIGN.md,
//! "Scenarios and the benchmark").
//!
//! A [`Monitor`] is fed once per control step (0.05 s) with the plant's state; optionally
//! also after every plant step through [`Monitor::latch`] so that contacts shorter than a
//! control step are seen and the closing speed of a contact is taken at its first touch.
//!
//! * **Success**: `|wrap(ψ_T − ψ_rev)| ≤ ε_ψ` with `ψ_rev` the road heading at the target's
//!   foot point plus π (either direction of spin counts), with no failure before, and the
//!   target either
//!   - **at rest**: speed ≤ `rest_speed` and `|r|` ≤ `rest_yaw_rate`, both held for `dwell`
//!     seconds (consecutive observations): decided at once ([`Metrics::at_rest`]); or
//!   - **settled at `T_max`**: reversed (heading within ε_ψ) over the last `dwell` seconds
//!     before `T_max`, however fast it still rolls. This is the paper's test (the heading
//!     at the terminal time within ε_ψ and no violation throughout), with the dwell so that
//!     a target spinning through the reversed heading does not count. The episode runs to
//!     `T_max`, so a reversed target still rolling must stay inside the road and clear of
//!     everything until then.
//! * **Boundary violation**: a footprint (target or bullet) crosses a road edge
//!   (`Road::edge_distance < 0`: a corner, or on a curve the bulge of a side, is beyond it).
//! * **Secondary collision**: the target or the bullet touches an obstacle (the plant's
//!   obstacle contacts, or footprints overlapping an obstacle at an observation).
//! * **Unsafe rebound**: a bullet–target contact episode that starts after stabilisation
//!   began, with a closing speed above `rebound_speed` at first touch. A contact episode
//!   starts when the vehicles touch after at least `separation_time` apart (chattering
//!   within a push is one episode). Stabilisation begins when the controller says so
//!   ([`Monitor::enter_stabilisation`]) or, failing that, when the first contact episode
//!   ends (`separation_time` without contact).
//! * **No termination**: `T_max` reached with neither success nor failure (the target not
//!   reversed at `T_max`).
//! * **Decision infeasible in chasing**: reported by the controller
//!   ([`Monitor::decision_infeasible`]).
//!
//! The first cause in time wins; within one observation the order is boundary violation,
//! secondary collision, unsafe rebound (DESIGN.md's order), and any of them beats success
//! and `T_max`. Once decided, the outcome and the metrics are frozen. Nothing allocates
//! after construction.

use crate::scenario::{ParamSetName, Scenario, ScenarioError};
use dynamics::contact::obb_signed_distance;
use dynamics::geometry::{Obb, Vec2};
use dynamics::plant::{Plant, Which};
use dynamics::road::{Obstacle, Road};
use dynamics::{wrap_angle, TargetState};
use serde::{Deserialize, Serialize};
use thiserror::Error;

/// Why an episode failed.
#[derive(Serialize, Deserialize, Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[serde(rename_all = "snake_case")]
pub enum FailureCause {
    DecisionInfeasible,
    NoTermination,
    BoundaryViolation,
    SecondaryCollision,
    UnsafeRebound,
}

impl FailureCause {
    pub const ALL: [FailureCause; 5] = [
        Self::DecisionInfeasible,
        Self::NoTermination,
        Self::BoundaryViolation,
        Self::SecondaryCollision,
        Self::UnsafeRebound,
    ];

    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            Self::DecisionInfeasible => "decision_infeasible",
            Self::NoTermination => "no_termination",
            Self::BoundaryViolation => "boundary_violation",
            Self::SecondaryCollision => "secondary_collision",
            Self::UnsafeRebound => "unsafe_rebound",
        }
    }
}

/// The decided outcome of an episode.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Outcome {
    Success { time: f64 },
    Failure { cause: FailureCause, time: f64 },
}

/// The monitor's answer after an observation.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Status {
    Running,
    Done(Outcome),
}

/// Thresholds of the success test. Serde with defaults; validated by [`JudgeSettings::validate`].
#[derive(Serialize, Deserialize, Clone, Copy, Debug, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct JudgeSettings {
    /// Target speed (|v| of the c.g.) at or below which it counts as at rest (m/s).
    pub rest_speed: f64,
    /// Yaw rate at or below which it counts as settled (rad/s).
    pub rest_yaw_rate: f64,
    /// How long the settled, reversed state must hold (s).
    pub dwell: f64,
    /// Closing speed at first touch above which a re-contact in stabilisation is an unsafe
    /// rebound (m/s).
    pub rebound_speed: f64,
    /// Time apart after which a new touch starts a new contact episode (s).
    pub separation_time: f64,
    /// A push tried again ([`Monitor::push_retried`]) starts a new first contact only while
    /// the target has turned less than `retry_turn` (rad) since the first touch and yaws
    /// slower than `retry_yaw_rate` (rad/s): a target the first contact did not spin.
    pub retry_turn: f64,
    pub retry_yaw_rate: f64,
}

impl Default for JudgeSettings {
    fn default() -> Self {
        Self::full_size()
    }
}

/// A judge setting out of range.
#[derive(Debug, Error, Clone, PartialEq)]
#[error("judge.{field} = {value}: {reason}")]
pub struct JudgeError {
    pub field: &'static str,
    pub value: f64,
    pub reason: &'static str,
}

impl JudgeSettings {
    /// Full-size thresholds: rest below 0.5 m/s and 0.1 rad/s for 0.5 s; unsafe re-contact
    /// above 1.0 m/s closing speed; contact episodes 0.3 s apart.
    #[must_use]
    pub fn full_size() -> Self {
        Self {
            rest_speed: 0.5,
            rest_yaw_rate: 0.1,
            dwell: 0.5,
            rebound_speed: 1.0,
            separation_time: 0.3,
            retry_turn: 0.3,
            retry_yaw_rate: 0.5,
        }
    }

    /// Half-scale thresholds: speeds scale with the platform (target ≈ 2.2 m/s): rest below
    /// 0.15 m/s, unsafe re-contact above 0.3 m/s.
    #[must_use]
    pub fn half_scale() -> Self {
        Self {
            rest_speed: 0.15,
            rest_yaw_rate: 0.1,
            dwell: 0.5,
            rebound_speed: 0.3,
            separation_time: 0.3,
            retry_turn: 0.3,
            retry_yaw_rate: 0.5,
        }
    }

    #[must_use]
    pub fn for_params(params: ParamSetName) -> Self {
        match params {
            ParamSetName::FullSize => Self::full_size(),
            ParamSetName::HalfScale => Self::half_scale(),
        }
    }

    /// # Errors
    /// [`JudgeError`] naming the first bad field (all must be finite and positive).
    pub fn validate(&self) -> Result<(), JudgeError> {
        for (field, value) in [
            ("rest_speed", self.rest_speed),
            ("rest_yaw_rate", self.rest_yaw_rate),
            ("dwell", self.dwell),
            ("rebound_speed", self.rebound_speed),
            ("separation_time", self.separation_time),
            ("retry_turn", self.retry_turn),
            ("retry_yaw_rate", self.retry_yaw_rate),
        ] {
            if !(value.is_finite() && value > 0.0) {
                return Err(JudgeError {
                    field,
                    value,
                    reason: "must be finite and positive",
                });
            }
        }
        Ok(())
    }
}

/// Per-episode metrics (frozen when the outcome is decided).
#[derive(Serialize, Deserialize, Clone, Copy, Debug, PartialEq)]
pub struct Metrics {
    pub success: bool,
    /// The single first failure cause; `None` on success or while running.
    pub cause: Option<FailureCause>,
    /// Time of the decision (s); `None` while running.
    pub decided_at: Option<f64>,
    /// `|wrap(ψ_T − ψ_rev)|` at the last observation (rad).
    pub terminal_heading_error: f64,
    /// Smallest distance of either footprint to a road edge or an obstacle over the
    /// episode (m); negative when something was crossed or hit.
    pub min_margin: f64,
    pub boundary_violation: bool,
    pub secondary_collision: bool,
    /// Bullet–target contact episodes.
    pub contacts: u32,
    /// Observations made.
    pub observations: u64,
    /// The success was the target coming to rest reversed (not only settled, still rolling,
    /// at `T_max`).
    #[serde(default)]
    pub at_rest: bool,
    /// Which vehicle crossed the edge or hit the obstacle that decided a boundary violation
    /// or secondary collision (`None` otherwise).
    #[serde(default)]
    pub failed_vehicle: Option<Party>,
    /// Relative speed at the first bullet–target contact (m/s): `|v_B − v_T|` of the two
    /// centres of gravity in the world frame at the first plant step in contact (`None`
    /// without contact).
    #[serde(default)]
    pub impact_speed: Option<f64>,
    /// Time of the first bullet–target contact (s; `None` without contact).
    #[serde(default)]
    pub contact_at: Option<f64>,
    /// Impact angle at the first contact (rad): `|wrap(ψ_B − ψ_T)|` (`None` without
    /// contact).
    #[serde(default)]
    pub impact_angle: Option<f64>,
    /// Point of action of the first contact in the target's body frame, relative to its
    /// c.g. (m; x forward, y left): the rear quarter is behind the rear axle (`None` without
    /// contact).
    #[serde(default)]
    pub impact_point: Option<[f64; 2]>,
    /// Time (s) of the first observation with the target within ε_ψ of the reversed
    /// heading, and its speed |v| then (m/s): how much of its speed a spun target keeps
    /// (`None` if it never reversed).
    #[serde(default)]
    pub reversed_at: Option<f64>,
    #[serde(default)]
    pub reversed_speed: Option<f64>,
}

/// A vehicle of the episode (for [`Metrics::failed_vehicle`]).
#[derive(Serialize, Deserialize, Clone, Copy, Debug, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum Party {
    Bullet,
    Target,
    Both,
}

impl Party {
    fn of(bullet: bool, target: bool) -> Option<Self> {
        match (bullet, target) {
            (true, true) => Some(Self::Both),
            (true, false) => Some(Self::Bullet),
            (false, true) => Some(Self::Target),
            (false, false) => None,
        }
    }
}

/// What the monitor needs of one control step. [`Monitor::observe_plant`] fills it from a
/// [`Plant`]; a runner with another source fills it directly.
#[derive(Clone, Copy, Debug)]
pub struct Observation {
    /// Time (s).
    pub time: f64,
    /// Target state `[vx, vy, ψ, r, p, φ, X, Y]`.
    pub target: TargetState,
    /// Footprints (bullet, target).
    pub footprints: [Obb; 2],
    /// Whether the vehicles touch now (ignored once [`Monitor::latch`] is in use).
    pub vehicle_contact: bool,
    /// Closing speed at the contact point if they touch (m/s, positive approaching).
    pub closing_speed: f64,
    /// Whether the bullet / the target touch an obstacle now.
    pub obstacle_contact: [bool; 2],
}

/// Contact episodes from a stream of (time, touching, closing speed) samples.
#[derive(Clone, Copy, Debug, Default)]
struct ContactTracker {
    last_touch: Option<f64>,
    episodes: u32,
    /// End of the first episode (first sample `separation_time` after its last touch).
    first_ended: Option<f64>,
    /// Episodes before the current push's first (a push tried again starts anew).
    attempt_start: u32,
    /// A new episode (after the first) began in stabilisation with a high closing speed.
    unsafe_at: Option<f64>,
}

impl ContactTracker {
    fn sample(
        &mut self,
        t: f64,
        touching: bool,
        closing: f64,
        settings: &JudgeSettings,
        stabilising_since: Option<f64>,
    ) {
        if touching {
            let new_episode = self
                .last_touch
                .is_none_or(|t0| t - t0 >= settings.separation_time);
            if new_episode {
                if self.episodes > self.attempt_start && self.first_ended.is_none() {
                    self.first_ended = self.last_touch.map(|t0| t0 + settings.separation_time);
                }
                self.episodes += 1;
                let stab = stabilising_since.or(self.first_ended);
                let in_stabilisation = stab.is_some_and(|ts| t >= ts);
                if in_stabilisation && closing > settings.rebound_speed && self.unsafe_at.is_none()
                {
                    self.unsafe_at = Some(t);
                }
            }
            self.last_touch = Some(t);
        } else if self.first_ended.is_none() && self.episodes == self.attempt_start + 1 {
            if let Some(t0) = self.last_touch {
                if t - t0 >= settings.separation_time {
                    self.first_ended = Some(t);
                }
            }
        }
    }
}

impl ContactTracker {
    /// The next contact episode is the first of a new push.
    fn restart(&mut self) {
        self.attempt_start = self.episodes;
        self.first_ended = None;
    }
}

/// The success test of one episode.
#[derive(Clone, Debug)]
pub struct Monitor {
    road: Road,
    obstacles: Vec<Obstacle>,
    eps_psi: f64,
    t_max: f64,
    settings: JudgeSettings,
    s_hint: f64,
    settled_since: Option<f64>,
    /// Start of the current run of observations with the heading within ε_ψ.
    reversed_since: Option<f64>,
    stabilising_since: Option<f64>,
    /// The target's heading at the first touch, and its heading and yaw rate at the last
    /// observation (for [`Monitor::push_retried`]).
    first_touch_heading: Option<f64>,
    last_heading_rate: (f64, f64),
    contacts: ContactTracker,
    latched: bool,
    latched_obstacle: [bool; 2],
    outcome: Option<Outcome>,
    metrics: Metrics,
}

impl Monitor {
    /// A monitor for a road, obstacles, the goal tolerance `eps_psi` (rad) and `t_max` (s).
    ///
    /// # Errors
    /// [`JudgeError`] for bad settings, a non-positive or non-finite `eps_psi` or `t_max`.
    pub fn new(
        road: Road,
        obstacles: Vec<Obstacle>,
        eps_psi: f64,
        t_max: f64,
        settings: JudgeSettings,
    ) -> Result<Self, JudgeError> {
        settings.validate()?;
        for (field, value) in [("eps_psi", eps_psi), ("t_max", t_max)] {
            if !(value.is_finite() && value > 0.0) {
                return Err(JudgeError {
                    field,
                    value,
                    reason: "must be finite and positive",
                });
            }
        }
        Ok(Self {
            road,
            obstacles,
            eps_psi,
            t_max,
            settings,
            s_hint: 0.0,
            settled_since: None,
            reversed_since: None,
            stabilising_since: None,
            first_touch_heading: None,
            last_heading_rate: (0.0, 0.0),
            contacts: ContactTracker::default(),
            latched: false,
            latched_obstacle: [false; 2],
            outcome: None,
            metrics: Metrics {
                success: false,
                cause: None,
                decided_at: None,
                terminal_heading_error: f64::NAN,
                min_margin: f64::INFINITY,
                boundary_violation: false,
                secondary_collision: false,
                contacts: 0,
                observations: 0,
                at_rest: false,
                failed_vehicle: None,
                impact_speed: None,
                contact_at: None,
                impact_angle: None,
                impact_point: None,
                reversed_at: None,
                reversed_speed: None,
            },
        })
    }

    /// The monitor of a scenario, with the thresholds of its parameter set.
    ///
    /// # Errors
    /// If the scenario's road cannot be built.
    pub fn for_scenario(sc: &Scenario) -> Result<Self, ScenarioError> {
        let road = sc.build_road()?;
        let mut m = Self::new(
            road,
            sc.obstacles(),
            sc.eps_psi,
            sc.t_max,
            JudgeSettings::for_params(sc.params),
        )
        .map_err(|e| ScenarioError::Field {
            line: 0,
            field: e.field.to_owned(),
            message: e.to_string(),
        })?;
        m.s_hint = sc.target.s;
        Ok(m)
    }

    #[must_use]
    pub fn road(&self) -> &Road {
        &self.road
    }

    #[must_use]
    pub fn settings(&self) -> &JudgeSettings {
        &self.settings
    }

    #[must_use]
    pub fn outcome(&self) -> Option<Outcome> {
        self.outcome
    }

    #[must_use]
    pub fn metrics(&self) -> Metrics {
        self.metrics
    }

    /// The reversed heading goal `ψ_rev` at the target's position and the wrapped error.
    fn heading_error(&mut self, target: &TargetState) -> f64 {
        let f = self
            .road
            .project_with_hint(Vec2::new(target[6], target[7]), self.s_hint);
        self.s_hint = f.s;
        let psi_rev = f.heading + std::f64::consts::PI;
        wrap_angle(target[2] - psi_rev).abs()
    }

    fn decide(&mut self, outcome: Outcome) -> Status {
        if self.outcome.is_none() {
            self.outcome = Some(outcome);
            match outcome {
                Outcome::Success { time } => {
                    self.metrics.success = true;
                    self.metrics.decided_at = Some(time);
                }
                Outcome::Failure { cause, time } => {
                    self.metrics.cause = Some(cause);
                    self.metrics.decided_at = Some(time);
                }
            }
        }
        Status::Done(self.outcome.unwrap_or(outcome))
    }

    /// The controller found no feasible PIT decision while chasing (at time `t`).
    pub fn decision_infeasible(&mut self, t: f64) -> Status {
        if let Some(o) = self.outcome {
            return Status::Done(o);
        }
        self.decide(Outcome::Failure {
            cause: FailureCause::DecisionInfeasible,
            time: t,
        })
    }

    /// The controller entered its stabilisation phase at time `t` (first call counts).
    pub fn enter_stabilisation(&mut self, t: f64) {
        if self.stabilising_since.is_none() {
            self.stabilising_since = Some(t);
        }
    }

    /// The controller went back to chasing for another push, the first having
    /// done nothing: the next contact is judged as a first contact, not as a rebound,
    /// provided the target is still unspun (turned less than `retry_turn` since the first
    /// touch and yawing slower than `retry_yaw_rate` at the last observation). Ignored once
    /// the controller has entered stabilisation. Returns whether it was taken.
    pub fn push_retried(&mut self) -> bool {
        let (psi, r) = self.last_heading_rate;
        let unspun = self
            .first_touch_heading
            .is_some_and(|p0| wrap_angle(psi - p0).abs() < self.settings.retry_turn)
            && r.abs() < self.settings.retry_yaw_rate;
        let take = unspun && self.stabilising_since.is_none() && self.outcome.is_none();
        if take {
            self.contacts.restart();
        }
        take
    }

    /// Record the plant's contacts of its last step (call after every plant step, or not
    /// at all). Closing speed is taken at the contact point along the contact normal.
    pub fn latch(&mut self, plant: &Plant) {
        if self.outcome.is_some() {
            return;
        }
        self.latched = true;
        let t = plant.time();
        let (touching, closing) = match plant.contact() {
            Some(c) => (true, closing_speed(plant, c.point_in_world, c.gamma)),
            None => (false, 0.0),
        };
        if touching {
            self.record_impact(plant);
        }
        self.contacts
            .sample(t, touching, closing, &self.settings, self.stabilising_since);
        let oc = plant.obstacle_contacts();
        for (latched, contact) in self.latched_obstacle.iter_mut().zip(oc) {
            *latched |= contact.is_some();
        }
    }

    /// The relative speed, angle and point of the first contact (kept once recorded).
    fn record_impact(&mut self, plant: &Plant) {
        if self.metrics.impact_speed.is_none() {
            let (b, t) = (plant.body(Which::Bullet), plant.body(Which::Target));
            self.metrics.contact_at = Some(plant.time());
            self.first_touch_heading = Some(t.yaw);
            self.metrics.impact_speed = Some((b.vel - t.vel).norm());
            self.metrics.impact_angle = Some(wrap_angle(b.yaw - t.yaw).abs());
            self.metrics.impact_point = plant
                .contact()
                .map(|c| [c.point_in_target.x, c.point_in_target.y]);
        }
    }

    /// Observe the plant at a control step.
    pub fn observe_plant(&mut self, plant: &Plant) -> Status {
        let (touching, closing) = match plant.contact() {
            Some(c) => (true, closing_speed(plant, c.point_in_world, c.gamma)),
            None => (false, 0.0),
        };
        if touching && self.outcome.is_none() {
            self.record_impact(plant);
        }
        let oc = plant.obstacle_contacts();
        let obs = Observation {
            time: plant.time(),
            target: plant.target_state(),
            footprints: plant.footprints(),
            vehicle_contact: touching,
            closing_speed: closing,
            obstacle_contact: [oc[0].is_some(), oc[1].is_some()],
        };
        self.observe(&obs)
    }

    /// Observe one control step.
    pub fn observe(&mut self, obs: &Observation) -> Status {
        if let Some(o) = self.outcome {
            return Status::Done(o);
        }
        let t = obs.time;
        self.metrics.observations += 1;
        self.last_heading_rate = (obs.target[2], obs.target[3]);
        if obs.vehicle_contact && self.first_touch_heading.is_none() {
            self.first_touch_heading = Some(obs.target[2]);
        }
        if !self.latched {
            self.contacts.sample(
                t,
                obs.vehicle_contact,
                obs.closing_speed,
                &self.settings,
                self.stabilising_since,
            );
        }
        self.metrics.contacts = self.contacts.episodes;

        // Margins: road edges and obstacles, both vehicles.
        let mut edge = f64::INFINITY;
        let mut obstacle = f64::INFINITY;
        let mut over = [false; 2];
        let mut touching = [false; 2];
        for (i, fp) in obs.footprints.iter().enumerate() {
            let e = self.road.edge_distance(fp);
            edge = edge.min(e);
            over[i] = e < 0.0;
            for o in &self.obstacles {
                let d = obb_signed_distance(fp, &o.footprint_at(t));
                obstacle = obstacle.min(d);
                touching[i] |= d < 0.0;
            }
            touching[i] |= obs.obstacle_contact[i] || self.latched_obstacle[i];
        }
        self.metrics.min_margin = self.metrics.min_margin.min(edge.min(obstacle));
        let boundary = edge < 0.0;
        let hit = obstacle < 0.0
            || obs.obstacle_contact.iter().any(|&c| c)
            || self.latched_obstacle.iter().any(|&c| c);
        self.latched_obstacle = [false; 2];
        self.metrics.boundary_violation |= boundary;
        self.metrics.secondary_collision |= hit;

        let err = self.heading_error(&obs.target);
        self.metrics.terminal_heading_error = err;
        if err <= self.eps_psi && self.metrics.reversed_at.is_none() {
            self.metrics.reversed_at = Some(t);
            self.metrics.reversed_speed = Some(obs.target[0].hypot(obs.target[1]));
        }

        if boundary {
            self.metrics.failed_vehicle = Party::of(over[0], over[1]);
            return self.decide(Outcome::Failure {
                cause: FailureCause::BoundaryViolation,
                time: t,
            });
        }
        if hit {
            self.metrics.failed_vehicle = Party::of(touching[0], touching[1]);
            return self.decide(Outcome::Failure {
                cause: FailureCause::SecondaryCollision,
                time: t,
            });
        }
        if let Some(tu) = self.contacts.unsafe_at {
            return self.decide(Outcome::Failure {
                cause: FailureCause::UnsafeRebound,
                time: tu.min(t),
            });
        }

        let x = &obs.target;
        let speed = x[0].hypot(x[1]);
        // A small tolerance so that a dwell of k control steps is met on the k-th.
        let dwell = self.settings.dwell - 1e-9;
        let reversed = err <= self.eps_psi;
        let at_rest = reversed
            && speed <= self.settings.rest_speed
            && x[3].abs() <= self.settings.rest_yaw_rate;
        if at_rest {
            let since = *self.settled_since.get_or_insert(t);
            if t - since >= dwell {
                self.metrics.at_rest = true;
                return self.decide(Outcome::Success { time: t });
            }
        } else {
            self.settled_since = None;
        }
        if reversed {
            self.reversed_since.get_or_insert(t);
        } else {
            self.reversed_since = None;
        }
        if t >= self.t_max - 1e-9 {
            if self.reversed_since.is_some_and(|since| t - since >= dwell) {
                return self.decide(Outcome::Success { time: t });
            }
            return self.decide(Outcome::Failure {
                cause: FailureCause::NoTermination,
                time: t,
            });
        }
        Status::Running
    }
}

/// Closing speed of the bullet toward the target at a contact point along the normal
/// (bullet → target) of heading `gamma`: positive while they approach.
#[must_use]
pub fn closing_speed(plant: &Plant, point: Vec2, gamma: f64) -> f64 {
    let n = Vec2::new(gamma.cos(), gamma.sin());
    let vb = plant.body(Which::Bullet).point_velocity(point);
    let vt = plant.body(Which::Target).point_velocity(point);
    (vb - vt).dot(&n)
}
