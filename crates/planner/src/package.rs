//! The decision package Π that the upper layer hands to the coupled MPC: plain data.

use crate::approach::Profile;
use dynamics::geometry::Vec2;
use dynamics::road::Obstacle;
use dynamics::TargetState;
use mpc::Side;

/// The mode decision m_PIT.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Mode {
    /// No contact is reachable within the look-ahead: close in, no force.
    Chase,
    /// A PIT is decided: approach, then push over the contact window.
    Pit,
    /// The PIT is over: separate, keep clear, let the target settle.
    Stabilise,
    /// No safe PIT exists (or a safety monitor tripped): stop the maneuver.
    Abort,
}

/// Why no feasible PIT decision exists (the paper's "decision infeasible in chasing").
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Infeasible {
    /// No virtual push over any tried window reaches the reversed-heading terminal set.
    TerminalSetUnreachable,
    /// Every push that reverses the target takes it (or its stopping point) over a road edge,
    /// or the road leaves the bullet no room to line up beside the target on either side.
    RoadBoundary,
    /// Every push that reverses the target brings it within d_safe of an obstacle.
    ObstacleClearance,
    /// The rollout or the QP failed numerically for every candidate.
    Numerical,
}

impl Infeasible {
    /// A short description for reports.
    #[must_use]
    pub fn describe(self) -> &'static str {
        match self {
            Self::TerminalSetUnreachable => "no push reaches the reversed heading",
            Self::RoadBoundary => "every reversing push leaves the road",
            Self::ObstacleClearance => "every reversing push comes too close to an obstacle",
            Self::Numerical => "the virtual rollout or its QP failed",
        }
    }
}

/// The target terminal set X_T,f ∩ S_post: the projected heading within `heading_tol` of
/// the reversed heading, and the stopping point inside the road.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TerminalSet {
    /// ψ_T,rev (unwrapped, rad).
    pub heading: f64,
    pub heading_tol: f64,
    /// Time constant τ of the projection `ψ_N + τ r_N` (s).
    pub yaw_decay: f64,
}

/// One step of the planned virtual interaction and the predicted target.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlanStep {
    /// Time of the step's start (s, absolute).
    pub time: f64,
    /// u_T^vir = [F_n, F_t] over the step (N); zero outside the window.
    pub force: Vec2,
    /// The admissible corridor C_F,k for F_n (N): `[lo, hi]`, zero outside the window.
    pub corridor: (f64, f64),
    /// Predicted target state at the step's start.
    pub target: TargetState,
}

/// The decision package Π = {m, R(t), Ô(t), X_T,f, C_F, C_B, T_c, S_post}.
///
/// R(t) is the road the controller was given (not copied: it is fixed for the episode) with
/// the margin below; Ô(t) the obstacles at planning time, predicted at constant velocity.
#[derive(Debug, Clone, PartialEq)]
pub struct DecisionPackage {
    pub mode: Mode,
    /// Set when `mode` is [`Mode::Abort`] because no feasible decision exists.
    pub infeasible: Option<Infeasible>,
    /// The race is lost (with `mode` [`Mode::Abort`]): the target's free motion leaves the
    /// road or hits an obstacle before the bullet can begin a push on any side, so no
    /// later plan can do better and the controller gives up at once.
    pub race_lost: bool,
    /// While chasing (`mode` [`Mode::Chase`] or [`Mode::Abort`]): the stand-off pose beside
    /// the target runs into an obstacle before the push could be over, so
    /// the bullet holds back behind the target ([`crate::href::HOLD_BACK`]) instead of
    /// waiting beside it.
    pub hold_back: bool,
    /// Planning time (s).
    pub time: f64,
    pub side: Side,
    /// Contact point on the target's rear quarter, in the target's body frame (m).
    pub contact_point: Vec2,
    /// C_B: the bullet's contact pose relative to the target (target frame) and the lateral
    /// envelope around it (m).
    pub contact_rel_pos: Vec2,
    pub contact_rel_heading: f64,
    pub push_speed: f64,
    pub envelope_lat: f64,
    /// The bullet's approach along the target, planned at `time` from its relative position
    /// and speed then to the contact station (the body x of `contact_rel_pos`), at rest
    /// relative to the target there: the reference follows it until the next plan.
    pub approach: Profile,
    /// How fast the approach moves across relative to the target (m/s): the settings'
    /// `lateral_speed`, more while the target drifts across the bullet's line towards the
    /// far side it crosses to.
    pub lateral_speed: f64,
    /// The bullet's stand-off beside the contact line while it waits (m): wider on the
    /// outside of a curve (`PlannerSettings::outside_standoff`).
    pub standoff: f64,
    /// T_c = [t0, t1] (absolute s); empty (t1 < t0) when no window is planned.
    pub window: (f64, f64),
    /// X_T,f and S_post.
    pub terminal: TerminalSet,
    /// Road-edge margin and obstacle clearance d_safe the plan keeps (m).
    pub road_margin: f64,
    pub obstacle_clearance: f64,
    /// Ô(t): the obstacles at planning time (constant-velocity prediction from `time`).
    pub obstacles: Vec<Obstacle>,
    /// The planned interaction and the predicted target, one entry per step (`N + 1`
    /// states: the last entry has no force).
    pub steps: Vec<PlanStep>,
    /// Predicted at the end of the look-ahead: heading error of the projected heading
    /// (rad), least road-edge margin (m, negative = over the edge), least obstacle
    /// clearance (m) and the stopping point's road margin (m).
    pub predicted_heading_error: f64,
    pub predicted_road_margin: f64,
    pub predicted_clearance: f64,
    pub predicted_stop_margin: f64,
    /// Objective of the chosen candidate (J_plan + λ_T J_T + penalties).
    pub objective: f64,
    /// How many candidates were evaluated and how many were feasible.
    pub candidates: u32,
    pub feasible_candidates: u32,
}

impl DecisionPackage {
    /// An empty package with room for `steps` steps and `obstacles` obstacles (no
    /// allocation when it is refilled within those sizes).
    #[must_use]
    pub fn with_capacity(steps: usize, obstacles: usize) -> Self {
        Self {
            mode: Mode::Chase,
            infeasible: None,
            race_lost: false,
            hold_back: false,
            time: 0.0,
            side: Side::Left,
            contact_point: Vec2::zeros(),
            contact_rel_pos: Vec2::new(-10.0, 0.0),
            contact_rel_heading: 0.0,
            push_speed: 0.0,
            envelope_lat: 1.0,
            approach: Profile::new(0.0, 0.0, 0.0, 1.0, 1.0),
            lateral_speed: 1.0,
            standoff: 0.6,
            window: (f64::INFINITY, f64::NEG_INFINITY),
            terminal: TerminalSet {
                heading: 0.0,
                heading_tol: 0.0,
                yaw_decay: 0.0,
            },
            road_margin: 0.0,
            obstacle_clearance: 0.0,
            obstacles: Vec::with_capacity(obstacles),
            steps: Vec::with_capacity(steps),
            predicted_heading_error: f64::NAN,
            predicted_road_margin: f64::NAN,
            predicted_clearance: f64::NAN,
            predicted_stop_margin: f64::NAN,
            objective: f64::INFINITY,
            candidates: 0,
            feasible_candidates: 0,
        }
    }

    /// Whether a contact window is planned.
    #[must_use]
    pub fn has_window(&self) -> bool {
        self.window.1 >= self.window.0
    }

    /// The plan step at absolute time `t` (clamped to the look-ahead), if any.
    #[must_use]
    pub fn step_at(&self, t: f64) -> Option<&PlanStep> {
        let first = self.steps.first()?;
        let dt = if self.steps.len() > 1 {
            self.steps[1].time - first.time
        } else {
            return Some(first);
        };
        let k = ((t - first.time) / dt).floor().max(0.0) as usize;
        self.steps.get(k.min(self.steps.len() - 1))
    }

    /// The predicted target heading at absolute time `t`, interpolated (clamped to the
    /// look-ahead).
    #[must_use]
    pub fn heading_at(&self, t: f64) -> Option<f64> {
        let first = self.steps.first()?;
        let n = self.steps.len();
        if n == 1 {
            return Some(first.target[dynamics::target::idx::PSI]);
        }
        let dt = self.steps[1].time - first.time;
        let x = ((t - first.time) / dt).clamp(0.0, (n - 1) as f64);
        let k = (x.floor() as usize).min(n - 2);
        let a = x - k as f64;
        let psi = dynamics::target::idx::PSI;
        Some(self.steps[k].target[psi] * (1.0 - a) + self.steps[k + 1].target[psi] * a)
    }
}
