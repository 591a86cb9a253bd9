//! Settings of the decision layer, the phase machine and the controller: serde structs with
//! defaults, validated when the controller is built, loadable from TOML.

use dynamics::params::ParamSet;
use mpc::MpcSettings;
use serde::{Deserialize, Serialize};
use thiserror::Error;

/// Length (m) of the bullet the built-in lengths of the reference, the approach model and
/// the phase machine were tuned with: the full-size set's (`full_size.toml`, 4.508 m).
pub const TUNED_BULLET_LENGTH: f64 = 4.508;

/// The vehicles' length scale: the bullet's length over [`TUNED_BULLET_LENGTH`] (exactly 1
/// for the full-size set, ≈ 0.47 for the half-scale platform). The built-in lengths of the
/// controller (how far behind the target the bullet waits, the fall-back pose, the
/// "at the contact pose" radius, …) are multiplied by it, speeds by its square root
/// (Froude similarity); the lengths in the settings are given in metres as they are.
#[must_use]
pub fn length_scale(params: &ParamSet) -> f64 {
    params.bullet.length / TUNED_BULLET_LENGTH
}

/// A setting that cannot be used; the message names the field.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum SettingsError {
    #[error("planner settings: `{field}` {problem}")]
    Invalid { field: String, problem: String },
    #[error("planner settings: {0}")]
    Parse(String),
    #[error(transparent)]
    Mpc(#[from] mpc::SettingsError),
}

/// The largest share of the road's μ g the approach's floor `approach_accel_min` may ask
/// for ([`PlannerSettings::approach_accel`]): the rest of the grip is left for steering.
pub const APPROACH_GRIP_MAX: f64 = 0.6;

fn invalid(field: &str, problem: impl Into<String>) -> SettingsError {
    SettingsError::Invalid {
        field: field.to_owned(),
        problem: problem.into(),
    }
}

/// Weights of the virtual-PIT objective `J_plan + λ_T J_T` (dimensionless: each applies to
/// a quantity divided by its scale).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PlanWeights {
    /// λ_T: weight of the target-response objective J_T.
    pub lambda_t: f64,
    /// w_ψ: projected terminal heading error (per rad²).
    pub heading: f64,
    /// w_v: terminal target speed (per (m/s)²).
    pub speed: f64,
    /// w_c: squared distance of u_T^vir to the comfortable corridor C_F (per force_scale²).
    pub corridor: f64,
    /// J_plan: interaction effort Σ (F_n / force_scale)² (a gentler push is preferred).
    pub effort: f64,
    /// J_plan: smoothness Σ (ΔF / force_scale)² between consecutive steps.
    pub smooth: f64,
    /// J_plan: cost per second of delay of the contact window (earlier is preferred).
    pub delay: f64,
    /// Exact-penalty weight of the soft road, obstacle and post-PIT rows (per metre).
    pub penalty: f64,
    /// Proximal weight on the force step (per force_scale²).
    pub proximal: f64,
}

impl Default for PlanWeights {
    fn default() -> Self {
        Self {
            lambda_t: 1.0,
            heading: 40.0,
            speed: 0.05,
            corridor: 5.0,
            effort: 0.05,
            smooth: 0.2,
            delay: 1.0,
            penalty: 200.0,
            proximal: 0.05,
        }
    }
}

/// The upper virtual-PIT decision layer.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PlannerSettings {
    /// Look-ahead of the virtual PIT rollout (s); a multiple of `dt`.
    pub horizon: f64,
    /// Step of the rollout (s); must equal the target model's.
    pub dt: f64,
    /// Replanning period (s); the controller also replans on every phase change.
    pub replan_period: f64,
    /// Replanning period while in contact (s): the contact is where the prediction is
    /// least certain, so the window and forces are refreshed more often there.
    pub replan_period_pit: f64,
    /// Longest contact window (s): the virtual force may act over this long.
    pub window: f64,
    /// Window starts tried after the earliest arrival (s, ≥ 0, ascending).
    pub start_offsets: Vec<f64>,
    /// Contact points tried along the target's side (m, body x relative to the rear-quarter
    /// point 0.3 m behind the rear axle; negative is further back), on the best side and
    /// window.
    pub contact_offsets: Vec<f64>,
    /// SCP iterations per candidate.
    pub scp_iterations: u32,
    /// The road, obstacle rows are imposed at every `row_stride`-th step (and the last).
    pub row_stride: usize,
    /// Largest normal force of the virtual interaction and its scale in the weights, in
    /// units of the target's weight m_T g (so that one setting serves both vehicle sizes).
    pub force_max_g: f64,
    pub force_scale_g: f64,
    /// Upper edge of the comfortable corridor C_F as a fraction of `force_max`.
    pub corridor_fraction: f64,
    /// Body-panel friction μ_c of the cone |F_t| ≤ μ_c F_n.
    pub friction: f64,
    /// Trust region on the force step per SCP iteration (× m_T g).
    pub trust_force_g: f64,
    /// Scale of the initial-guess grid: constant pushes up to twice this (× m_T g).
    pub force_guess_g: f64,
    /// Contact geometry on the target's rear quarter: the bullet's contact angle (rad), its
    /// overlap (m) and its relative push speed (m/s), as in `mpc::reference::pit_stage`.
    pub contact_angle: f64,
    pub overlap: f64,
    pub push_speed: f64,
    /// The bullet's approach ([`crate::approach::Profile`]): the largest relative closing
    /// speed (m/s) and the relative acceleration as a share of the road's μ g (the approach
    /// brakes as well as it closes, to arrive at rest beside the target); the lateral speed
    /// (m/s) and a settling time (s) of the earliest arrival.
    pub approach_speed: f64,
    pub approach_accel_g: f64,
    /// The least relative acceleration of the approach (m/s²), where `approach_accel_g`
    /// of μ g is less (low adhesion), itself no more than [`APPROACH_GRIP_MAX`] of μ g:
    /// see [`Self::approach_accel`].
    pub approach_accel_min: f64,
    pub lateral_speed: f64,
    /// The lateral speed (m/s) of a bullet crossing behind the target to its far side (the
    /// inside of a curve, the side against the target's drift): it is held behind the
    /// target's rear bumper while it crosses, clear of it, so it changes lanes briskly; no
    /// less than `lateral_speed`, which closes in beside the target.
    pub crossing_speed: f64,
    pub settle_time: f64,
    /// Stand-off outside the contact line while closing in (m).
    pub standoff: f64,
    /// The stand-off on the outside of a curve (m; `Planner`'s side choice): turning in
    /// towards the inside, the bullet has the curve's share of its grip less for the turn-in
    /// (on the inside, more), and from `standoff` it touches shallower and slower than the
    /// push needs. The extra width is closed by the turn-in: the earliest arrival does not
    /// count it. `standoff` or more.
    pub outside_standoff: f64,
    /// The road adhesion μ from which the bullet waits `outside_standoff` wide; below it,
    /// `standoff`. On a slippery road the turn-in does not close the extra width before the
    /// window: the window opens and slides on, plan after plan, and the bullet never
    /// touches.
    pub outside_standoff_mu: f64,
    /// Time before the window at which the bullet turns in (s).
    pub turn_in: f64,
    /// Terminal set X_T,f: the projected heading `ψ_N + τ r_N` within `heading_tol` of the
    /// reversed heading (the yaw goes on after the look-ahead; τ is its decay time).
    pub heading_tol: f64,
    /// The push turns the target round by itself: a slow target (the half-scale platform
    /// at 2 m/s) yaws only while it is pushed, and stops turning the moment it is let go.
    /// Over the window the contact pose is then held at the target's rear-quarter point,
    /// turning with the target (the bullet's heading still held in the push-start frame, as
    /// [`crate::href::fill_reference`] says), so that the bullet keeps pushing the tail round
    /// instead of the target's side; and the push goes on until the target has turned
    /// `phases.pit_yaw_done` (or `phases.pit_timeout` runs out). No prediction of the free
    /// motion ends it (the planner's "reverses by itself", the closed loop's release,
    /// `phases.let_go_turn`), nor a lost contact or the window's end.
    /// Off at full size, where the target's own momentum completes the spin after a short
    /// push (`docs/planner.md`, "Half scale").
    pub push_round: bool,
    /// τ (s) of the projected heading ψ_N + τ r_N of the terminal set from μ 0.6 up; on a
    /// more slippery road the planner lengthens it by 0.6 / μ, at most to twice this
    /// (`Planner`'s yaw decay: the spin left at the look-ahead's end dies away under the
    /// tyres' friction moment, which scales with μ).
    pub yaw_decay: f64,
    /// Deceleration of the spun target for the post-PIT stopping point while its tyres slide
    /// sideways (fraction of μ g; rolling along its body it slows only by its rolling
    /// resistance and driveline, `Planner`'s stopping model).
    pub stop_decel_fraction: f64,
    /// Road-edge margin of the target's footprint (m). 0 at full size: the success test asks
    /// for the footprint inside the road, and a 0.2 m margin made the PicoPINN's planner
    /// refuse twice as often and save 110 instead of 127 of 704 scenes (`docs/planner.md`,
    /// "Road margin").
    pub road_margin: f64,
    /// Obstacle clearance d_safe (m).
    pub obstacle_clearance: f64,
    /// A candidate is feasible when no soft row is violated by more than this (m).
    pub violation_tol: f64,
    pub weights: PlanWeights,
    /// Clarabel settings of the planner's QPs.
    pub qp: mpc::settings::QpSettings,
}

impl Default for PlannerSettings {
    fn default() -> Self {
        Self {
            horizon: 2.0,
            dt: 0.05,
            replan_period: 1.0,
            replan_period_pit: 0.25,
            window: 0.8,
            start_offsets: vec![0.0, 0.3],
            contact_offsets: vec![0.0, -0.4],
            scp_iterations: 3,
            row_stride: 2,
            force_max_g: 3.0,
            force_scale_g: 0.7,
            corridor_fraction: 0.8,
            friction: 0.3,
            trust_force_g: 0.8,
            force_guess_g: 0.5,
            contact_angle: 12f64.to_radians(),
            overlap: 0.05,
            push_speed: 1.0,
            approach_speed: 8.0,
            approach_accel_g: 0.25,
            approach_accel_min: 1.5,
            lateral_speed: 1.0,
            crossing_speed: 1.5,
            settle_time: 0.3,
            standoff: 0.6,
            outside_standoff: 1.2,
            outside_standoff_mu: 0.6,
            turn_in: 0.4,
            heading_tol: 0.9,
            push_round: false,
            yaw_decay: 0.4,
            stop_decel_fraction: 0.7,
            road_margin: 0.0,
            obstacle_clearance: 0.5,
            violation_tol: 0.05,
            weights: PlanWeights::default(),
            qp: mpc::settings::QpSettings {
                time_limit: 0.02,
                ..mpc::settings::QpSettings::default()
            },
        }
    }
}

impl PlannerSettings {
    /// Parse and validate TOML (missing fields take their defaults).
    ///
    /// # Errors
    /// [`SettingsError::Parse`] for malformed TOML or unknown fields, otherwise the first bad
    /// value.
    pub fn from_toml_str(text: &str) -> Result<Self, SettingsError> {
        let s: Self = toml::from_str(text).map_err(|e| SettingsError::Parse(e.to_string()))?;
        s.validate()?;
        Ok(s)
    }

    /// The settings as TOML.
    #[must_use]
    pub fn to_toml_string(&self) -> String {
        toml::to_string(self).expect("settings serialise")
    }

    /// The approach's relative acceleration (m/s²) on a road of adhesion `mu`:
    /// `approach_accel_g · μ g`, but at least `approach_accel_min` where the grip allows it
    /// (up to [`APPROACH_GRIP_MAX`] · μ g). On low adhesion a quarter of μ g is 0.4–1 m/s²:
    /// the bullet then takes seconds to correct a metre off its station, swings about it,
    /// and the window never fits the look-ahead (`picopit trace sc-00271`, μ 0.25: six
    /// seconds to settle).
    #[must_use]
    pub fn approach_accel(&self, mu: f64) -> f64 {
        let grip = mu * dynamics::GRAVITY;
        (self.approach_accel_g * grip).max(self.approach_accel_min.min(APPROACH_GRIP_MAX * grip))
    }

    /// Steps of the rollout.
    #[must_use]
    pub fn steps(&self) -> usize {
        (self.horizon / self.dt).round().max(0.0) as usize
    }

    /// Steps of the longest window.
    #[must_use]
    pub fn window_steps(&self) -> usize {
        (self.window / self.dt).round().max(1.0) as usize
    }

    /// The first plan step at or after `t` s from now: where a window that may open at `t`
    /// begins.
    #[must_use]
    pub fn step_at(&self, t: f64) -> usize {
        (t / self.dt - 1e-9).ceil().max(0.0) as usize
    }

    /// Check every field.
    ///
    /// # Errors
    /// [`SettingsError::Invalid`] naming the first bad field.
    pub fn validate(&self) -> Result<(), SettingsError> {
        let positive = [
            ("horizon", self.horizon),
            ("dt", self.dt),
            ("replan_period", self.replan_period),
            ("replan_period_pit", self.replan_period_pit),
            ("window", self.window),
            ("force_max_g", self.force_max_g),
            ("force_scale_g", self.force_scale_g),
            ("corridor_fraction", self.corridor_fraction),
            ("trust_force_g", self.trust_force_g),
            ("approach_speed", self.approach_speed),
            ("approach_accel_g", self.approach_accel_g),
            ("lateral_speed", self.lateral_speed),
            ("crossing_speed", self.crossing_speed),
            ("heading_tol", self.heading_tol),
            ("stop_decel_fraction", self.stop_decel_fraction),
            ("violation_tol", self.violation_tol),
            ("weights.penalty", self.weights.penalty),
            ("weights.proximal", self.weights.proximal),
            ("qp.tol_gap", self.qp.tol_gap),
            ("qp.tol_feas", self.qp.tol_feas),
            ("qp.time_limit", self.qp.time_limit),
        ];
        for (name, v) in positive {
            if !(v.is_finite() && v > 0.0) {
                return Err(invalid(name, format!("must be finite and > 0 (got {v})")));
            }
        }
        let w = &self.weights;
        let non_negative = [
            ("approach_accel_min", self.approach_accel_min),
            ("friction", self.friction),
            ("force_guess_g", self.force_guess_g),
            ("contact_angle", self.contact_angle),
            ("overlap", self.overlap),
            ("push_speed", self.push_speed),
            ("settle_time", self.settle_time),
            ("standoff", self.standoff),
            ("outside_standoff", self.outside_standoff),
            ("outside_standoff_mu", self.outside_standoff_mu),
            ("turn_in", self.turn_in),
            ("yaw_decay", self.yaw_decay),
            ("road_margin", self.road_margin),
            ("obstacle_clearance", self.obstacle_clearance),
            ("weights.lambda_t", w.lambda_t),
            ("weights.heading", w.heading),
            ("weights.speed", w.speed),
            ("weights.corridor", w.corridor),
            ("weights.effort", w.effort),
            ("weights.smooth", w.smooth),
            ("weights.delay", w.delay),
        ];
        for (name, v) in non_negative {
            if !(v.is_finite() && v >= 0.0) {
                return Err(invalid(name, format!("must be finite and >= 0 (got {v})")));
            }
        }
        if self.outside_standoff < self.standoff {
            return Err(invalid(
                "outside_standoff",
                format!(
                    "must be at least standoff ({} m; got {})",
                    self.standoff, self.outside_standoff
                ),
            ));
        }
        let steps = self.horizon / self.dt;
        if (steps - steps.round()).abs() > 1e-9 || !(4.0..=400.0).contains(&steps.round()) {
            return Err(invalid(
                "horizon",
                "must be a whole number (4 to 400) of steps dt",
            ));
        }
        if self.window_steps() + 1 >= self.steps() {
            return Err(invalid("window", "must be shorter than the horizon"));
        }
        if self.start_offsets.is_empty() || self.start_offsets.len() > 8 {
            return Err(invalid("start_offsets", "needs 1 to 8 entries"));
        }
        if self
            .start_offsets
            .windows(2)
            .any(|p| p[1] <= p[0] || !p[0].is_finite())
            || self
                .start_offsets
                .iter()
                .any(|v| !(v.is_finite() && *v >= 0.0))
        {
            return Err(invalid(
                "start_offsets",
                "must be finite, >= 0 and strictly ascending",
            ));
        }
        // A bullet waiting on its stand-off line arrives `settle_time + standoff /
        // lateral_speed` from now (`Planner::earliest_arrival`); a window that does not fit
        // the horizon after that is never planned, and the bullet chases until `T_max`.
        let wait = self.settle_time + self.standoff / self.lateral_speed;
        if self.step_at(wait + self.start_offsets[0]) + self.window_steps() > self.steps() {
            return Err(invalid(
                "window",
                format!(
                    "must fit the {} s horizon after a waiting bullet's arrival, {wait:.2} s \
                     (settle_time + standoff / lateral_speed); got {} s",
                    self.horizon, self.window
                ),
            ));
        }
        if self.row_stride == 0 || self.row_stride > self.steps() {
            return Err(invalid("row_stride", "must be in 1..=steps"));
        }
        if self.contact_offsets.is_empty()
            || self.contact_offsets.len() > 4
            || self
                .contact_offsets
                .iter()
                .any(|v| !(v.is_finite() && v.abs() <= 3.0))
        {
            return Err(invalid(
                "contact_offsets",
                "needs 1 to 4 finite entries within 3 m of the rear quarter",
            ));
        }
        if self.scp_iterations == 0 || self.scp_iterations > 20 {
            return Err(invalid("scp_iterations", "must be in 1..=20"));
        }
        if self.corridor_fraction > 1.0 {
            return Err(invalid("corridor_fraction", "must be at most 1"));
        }
        if self.force_guess_g > self.force_max_g {
            return Err(invalid("force_guess_g", "must not exceed force_max_g"));
        }
        if self.qp.max_iter == 0 {
            return Err(invalid("qp.max_iter", "must be at least 1"));
        }
        Ok(())
    }
}

/// Timeouts and thresholds of the phase machine and its safety monitor.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PhaseSettings {
    /// Longest time in each phase (s).
    pub chase_timeout: f64,
    pub pit_timeout: f64,
    pub stabilise_timeout: f64,
    /// Gap (m) at or below which the vehicles count as in contact.
    pub contact_gap: f64,
    /// Gap (m) beyond which, held for `release_dwell` (s) after a contact, the PIT counts
    /// as over.
    pub release_gap: f64,
    pub release_dwell: f64,
    /// The PIT ends once the target has turned this far (rad) since the push began.
    pub pit_yaw_done: f64,
    /// The PIT also ends when, after a contact and once the target has turned this far
    /// (rad) since the push began, a replan finds no push that meets the terminal set: the
    /// bullet lets go instead of pressing on with the planner's best effort (pressing on
    /// into a spinning target is what ends in unsafe rebounds; docs/RESULTS.md). Above π it
    /// never applies.
    pub let_go_turn: f64,
    /// The closed loop of the push: in contact, the bullet lets go the first control step
    /// the target left alone would meet the planner's terminal set with its projected
    /// heading within this of the reversed heading (rad; the planner's `heading_tol` bounds
    /// it as well).
    pub release_heading_tol: f64,
    /// The same on an open road (rad): a push begun on a straight, wide road with no
    /// obstacle near and the target no faster than the PIT is done at
    /// ([`Self::open_road_speed`]) is held until the target is predicted this near
    /// reversed. There the longer push's extra turn costs nothing (room on both sides), and a
    /// lane-keeping target, which steers back towards its lane while it rolls backwards after
    /// the spin and takes 10–25° of the turn back, then stops inside ε_ψ (docs/planner.md,
    /// "Release on an open road").
    pub open_road_release_heading_tol: f64,
    /// An open road: at least this far (m) from the road's reference line to either edge
    /// (three 3.5 m lanes and 2 m shoulders give 7.25 m) ...
    pub open_road_half_width: f64,
    /// ... straight (curvature below 1e-4 1/m) and clear of obstacles this far (m) before
    /// and after the target ...
    pub open_road_clear: f64,
    /// ... and the target no faster (m/s) than this when the push begins: agencies restrict
    /// the PIT to about 45 mph (20.1 m/s; docs/planner.md); faster targets pushed longer
    /// over-rotate.
    pub open_road_speed: f64,
    /// ... and if the target left alone would end the look-ahead slower than
    /// `release_rest_speed` (m/s; 0: never), with it within `release_rest_heading_tol`
    /// (rad) instead: it has no spin left to come ([`crate::Release`]).
    pub release_rest_speed: f64,
    pub release_rest_heading_tol: f64,
    /// The target counts as settled below this speed (m/s) and yaw rate (rad/s).
    pub settle_speed: f64,
    pub settle_yaw_rate: f64,
    /// Safety monitor: the bullet's largest yaw rate (rad/s) and side-slip angle (rad, above
    /// `monitor_speed` m/s) before the maneuver is aborted.
    pub bullet_yaw_rate_max: f64,
    pub bullet_slip_max: f64,
    pub monitor_speed: f64,
    /// Safety monitor: the bullet's least clearance to an obstacle (m).
    pub bullet_clearance_min: f64,
    /// Braking of the safe stop (stabilisation, done, abort) as a fraction of μ g: all the
    /// road gives by default, so that the bullet drops back out of the spinning target's
    /// sweep (a spun target slows at up to μ g).
    pub abort_brake: f64,
    /// Infeasible decisions while chasing before the maneuver is aborted (the situation
    /// often changes within a replanning period: a curve ends, the target slows). A plan
    /// that finds a push ends the count; a chase plan (no window fits the look-ahead yet)
    /// neither counts nor ends it.
    pub infeasible_patience: u32,
    /// A push that did nothing is tried again: when the bullet comes apart from the target
    /// (or the window ends) with the target turned less than `retry_turn` (rad) since the
    /// push began and yawing slower than `retry_yaw_rate` (rad/s), the maneuver goes back
    /// to chasing instead of stabilising, at most `retries` times. A brush of the rear
    /// bumper while the bullet moves across behind the target, or a push whose
    /// rear tyres held, leaves a target that carries on as before, which a driver would
    /// PIT again.
    pub retries: u32,
    pub retry_turn: f64,
    pub retry_yaw_rate: f64,
    /// The same `retry_after` (s) after the push's first touch, in contact or not, if the
    /// target has not turned by then (its rear tyres held the push).
    pub retry_after: f64,
}

impl Default for PhaseSettings {
    fn default() -> Self {
        Self {
            chase_timeout: 12.0,
            pit_timeout: 2.0,
            stabilise_timeout: 10.0,
            contact_gap: 0.05,
            release_gap: 0.2,
            release_dwell: 0.15,
            pit_yaw_done: 1.05,
            let_go_turn: 0.35,
            release_heading_tol: 0.9,
            open_road_release_heading_tol: 0.2,
            open_road_half_width: 7.0,
            open_road_clear: 150.0,
            open_road_speed: 20.5,
            release_rest_speed: 6.0,
            release_rest_heading_tol: 0.3,
            settle_speed: 0.5,
            settle_yaw_rate: 0.1,
            bullet_yaw_rate_max: 1.5,
            bullet_slip_max: 0.35,
            monitor_speed: 3.0,
            bullet_clearance_min: 0.2,
            abort_brake: 1.0,
            infeasible_patience: 3,
            retries: 1,
            retry_turn: 0.15,
            retry_yaw_rate: 0.3,
            retry_after: 1.2,
        }
    }
}

impl PhaseSettings {
    /// The closed loop's release test ([`crate::Planner::push_done`]), for a push begun on
    /// an open road or not.
    #[must_use]
    pub fn release(&self, open_road: bool) -> crate::Release {
        crate::Release {
            heading_tol: if open_road {
                self.open_road_release_heading_tol
            } else {
                self.release_heading_tol
            },
            rest_speed: self.release_rest_speed,
            rest_heading_tol: self.release_rest_heading_tol,
        }
    }

    /// Check every field.
    ///
    /// # Errors
    /// [`SettingsError::Invalid`] naming the first bad field.
    pub fn validate(&self) -> Result<(), SettingsError> {
        let positive = [
            ("phases.chase_timeout", self.chase_timeout),
            ("phases.pit_timeout", self.pit_timeout),
            ("phases.stabilise_timeout", self.stabilise_timeout),
            ("phases.release_gap", self.release_gap),
            ("phases.release_dwell", self.release_dwell),
            ("phases.pit_yaw_done", self.pit_yaw_done),
            ("phases.settle_speed", self.settle_speed),
            ("phases.settle_yaw_rate", self.settle_yaw_rate),
            ("phases.bullet_yaw_rate_max", self.bullet_yaw_rate_max),
            ("phases.bullet_slip_max", self.bullet_slip_max),
            ("phases.abort_brake", self.abort_brake),
            ("phases.retry_after", self.retry_after),
        ];
        for (name, v) in positive {
            if !(v.is_finite() && v > 0.0) {
                return Err(invalid(name, format!("must be finite and > 0 (got {v})")));
            }
        }
        for (name, v) in [
            ("phases.contact_gap", self.contact_gap),
            ("phases.monitor_speed", self.monitor_speed),
            ("phases.bullet_clearance_min", self.bullet_clearance_min),
            ("phases.let_go_turn", self.let_go_turn),
            ("phases.release_heading_tol", self.release_heading_tol),
            (
                "phases.open_road_release_heading_tol",
                self.open_road_release_heading_tol,
            ),
            ("phases.open_road_half_width", self.open_road_half_width),
            ("phases.open_road_clear", self.open_road_clear),
            ("phases.open_road_speed", self.open_road_speed),
            ("phases.release_rest_speed", self.release_rest_speed),
            (
                "phases.release_rest_heading_tol",
                self.release_rest_heading_tol,
            ),
            ("phases.retry_turn", self.retry_turn),
            ("phases.retry_yaw_rate", self.retry_yaw_rate),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(invalid(name, format!("must be finite and >= 0 (got {v})")));
            }
        }
        if self.release_gap <= self.contact_gap {
            return Err(invalid("phases.release_gap", "must exceed contact_gap"));
        }
        if self.infeasible_patience == 0 {
            return Err(invalid("phases.infeasible_patience", "must be at least 1"));
        }
        if self.abort_brake > 1.0 {
            return Err(invalid("phases.abort_brake", "must be at most 1"));
        }
        Ok(())
    }
}

/// Everything the controller needs: the upper layer (switchable off for the ablation), the
/// phase machine and the MPC.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ControllerSettings {
    /// Run the upper virtual-PIT decision layer; off, the MPC follows the fixed default
    /// reference (`mpc::reference::DefaultPit`), the paper's "without upper layer".
    pub upper_layer: bool,
    pub planner: PlannerSettings,
    pub phases: PhaseSettings,
    pub mpc: MpcSettings,
}

impl Default for ControllerSettings {
    fn default() -> Self {
        Self {
            upper_layer: true,
            planner: PlannerSettings::default(),
            phases: PhaseSettings::default(),
            mpc: MpcSettings::default(),
        }
    }
}

/// The half-scale platform's controller settings (`configs/controller_half_scale.toml`,
/// built in): what [`ControllerSettings::builtin`] gives for `half_scale`.
pub const HALF_SCALE_TOML: &str = include_str!("../../../configs/controller_half_scale.toml");

impl ControllerSettings {
    /// The built-in settings of a parameter set: `full_size` (the defaults) or `half_scale`
    /// ([`HALF_SCALE_TOML`]); `None` for any other name.
    #[must_use]
    pub fn builtin(param_set: &str) -> Option<Self> {
        match param_set {
            "full_size" => Some(Self::default()),
            "half_scale" => {
                Some(Self::from_toml_str(HALF_SCALE_TOML).expect("built-in half-scale settings"))
            }
            _ => None,
        }
    }

    /// Parse and validate TOML (missing fields take their defaults).
    ///
    /// # Errors
    /// [`SettingsError::Parse`] for malformed TOML or unknown fields, otherwise the first bad
    /// value.
    pub fn from_toml_str(text: &str) -> Result<Self, SettingsError> {
        let s: Self = toml::from_str(text).map_err(|e| SettingsError::Parse(e.to_string()))?;
        s.validate()?;
        Ok(s)
    }

    /// The settings as TOML.
    #[must_use]
    pub fn to_toml_string(&self) -> String {
        toml::to_string(self).expect("settings serialise")
    }

    /// Check every field, and that the planner and the MPC share their step.
    ///
    /// # Errors
    /// The first bad value, named.
    pub fn validate(&self) -> Result<(), SettingsError> {
        self.planner.validate()?;
        self.phases.validate()?;
        self.mpc.validate()?;
        if (self.planner.dt - self.mpc.dt).abs() > 1e-12 {
            return Err(invalid("planner.dt", "must equal mpc.dt"));
        }
        let mpc_span = self.mpc.horizon as f64 * self.mpc.dt;
        if self.planner.horizon + 1e-9 < mpc_span + self.planner.replan_period.min(mpc_span) {
            return Err(invalid(
                "planner.horizon",
                "must cover the MPC horizon after a full replanning period",
            ));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_are_valid_and_round_trip_through_toml() {
        let s = ControllerSettings::default();
        s.validate().unwrap();
        let back = ControllerSettings::from_toml_str(&s.to_toml_string()).unwrap();
        assert_eq!(s, back);
    }

    /// The approach accelerates at a quarter of μ g, but at least 1.5 m/s² where the grip
    /// leaves room for it (at most 0.6 μ g): dry roads keep the quarter, low adhesion gets
    /// the floor, the most slippery roads the grip's share.
    #[test]
    fn the_approach_accelerates_at_a_floor_the_grip_allows() {
        let s = PlannerSettings::default();
        let g = dynamics::GRAVITY;
        let close = |a: f64, b: f64| (a - b).abs() < 1e-12;
        assert!(close(s.approach_accel(0.9), 0.25 * 0.9 * g));
        assert!(close(s.approach_accel(0.4), 1.5));
        assert!(close(s.approach_accel(0.2), APPROACH_GRIP_MAX * 0.2 * g));
        // Monotone in μ across the three regimes.
        let mut last = 0.0;
        for i in 1..=100 {
            let a = s.approach_accel(f64::from(i) * 0.01);
            assert!(a >= last, "μ {}: {a} < {last}", f64::from(i) * 0.01);
            last = a;
        }
        let off = PlannerSettings {
            approach_accel_min: 0.0,
            ..PlannerSettings::default()
        };
        assert!(close(off.approach_accel(0.2), 0.25 * 0.2 * g));
    }

    #[test]
    fn bad_values_name_their_field() {
        let cases = [
            ("[planner]\nhorizon = 2.01", "horizon"),
            ("[planner]\nwindow = 3.0", "window"),
            ("[planner]\nwindow = 1.2", "window"),
            (
                "[planner]\nsettle_time = 0.6\nlateral_speed = 0.5",
                "window",
            ),
            ("[planner]\nstart_offsets = [0.3, 0.1]", "start_offsets"),
            ("[planner]\nforce_max_g = -1.0", "force_max_g"),
            ("[planner.weights]\npenalty = 0.0", "weights.penalty"),
            ("[phases]\nrelease_gap = 0.01", "phases.release_gap"),
            ("[phases]\nlet_go_turn = -0.1", "phases.let_go_turn"),
            (
                "[phases]\nrelease_heading_tol = -0.1",
                "phases.release_heading_tol",
            ),
            (
                "[phases]\nopen_road_half_width = -1.0",
                "phases.open_road_half_width",
            ),
            ("[phases]\nopen_road_speed = nan", "phases.open_road_speed"),
            (
                "[phases]\nrelease_rest_speed = nan",
                "phases.release_rest_speed",
            ),
            (
                "[phases]\nrelease_rest_heading_tol = -0.1",
                "phases.release_rest_heading_tol",
            ),
            ("[planner]\ndt = 0.1", "planner.dt"),
            ("[planner]\napproach_accel_min = -1.0", "approach_accel_min"),
            (
                "[planner]\nstandoff = 0.6\noutside_standoff = 0.5",
                "outside_standoff",
            ),
            ("[mpc]\nhorizon = 1", "horizon"),
        ];
        for (text, field) in cases {
            let e = ControllerSettings::from_toml_str(text)
                .unwrap_err()
                .to_string();
            assert!(e.contains(field), "{text:?} gave {e:?}");
        }
        let e = ControllerSettings::from_toml_str("[planner]\nhorizn = 2.0")
            .unwrap_err()
            .to_string();
        assert!(e.contains("horizn"), "{e}");
    }
}
