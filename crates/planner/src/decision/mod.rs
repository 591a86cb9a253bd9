//! The upper virtual-PIT decision layer.
//!
//! For each candidate (contact side × contact-window start), the target surrogate is rolled
//! out over the look-ahead under a virtual interaction u_T^vir = [F_n, F_t] that acts on the
//! rear-quarter contact point during the window, and the forces are optimised by sequential
//! convex programming: each iteration linearises the rollout (the surrogate's Jacobians,
//! chained into the sensitivity of every predicted state to every force), and solves one
//! QP in the forces with Clarabel (`mpc::qp`, a fixed pattern updated in place):
//!
//! ```text
//! min  λ_T [ w_ψ (ψ_N + τ r_N − ψ_rev)² + w_v ‖v_N‖² + w_c Σ dist(F, C_F)² ]
//!      + w_e Σ (F_n/S)² + w_s Σ (ΔF/S)² + w_p ‖δF/S‖² + ρ Σ slacks + w_t t_0
//! s.t. 0 ≤ F_n ≤ F_max, |F_t| ≤ μ_c F_n, |δF| ≤ trust               (hard)
//!      road edges of the target's footprint at every step          (soft, linearised)
//!      clearance d_safe to every predicted obstacle at every step  (soft, linearised)
//!      the post-PIT stopping point inside the road (S_post)        (soft, linearised)
//! ```
//!
//! The best feasible candidate becomes the decision package Π; none feasible is a real
//! outcome, reported with its reason. The search is deterministic and allocates nothing
//! after construction.

use crate::approach::{Profile, BRAKE_MARGIN};
use crate::chase;
use crate::package::{DecisionPackage, Infeasible, Mode, PlanStep, TerminalSet};
use crate::race;
use crate::settings::{length_scale, PlannerSettings};
use dynamics::bullet::BulletState;
use dynamics::driver::LaneKeeper;
use dynamics::geometry::{rotate, Obb, Pose2, Vec2};
use dynamics::params::ParamSet;
use dynamics::road::{Obstacle, Road};
use dynamics::target::idx;
use dynamics::{ContactInput, TargetInput, TargetJacobians, TargetModel, TargetState};
use mpc::geom::{edge_row, gap_gradient, pair_geometry, PairGeometry};
use mpc::qp::{clarabel_settings, Emitter, Pattern, Qp};
use mpc::reference::{pit_stage_at, rear_quarter_x};
use mpc::{QpStatus, Side};

mod judging;
mod prediction;
mod program;
mod stations;
use stations::Drift;

use program::{assemble, DummyRows};

const GRAVITY: f64 = 9.81;
/// Right-hand side of a row that cannot bind.
const FAR: f64 = 1.0e3;

/// How far along the target (m, full size; × the length scale) from the band of contact
/// stations a waiting bullet counts as arrived for the earliest arrival
/// ([`Planner::plan`]'s windows).
const ARRIVAL_TOL: f64 = 1.0;
/// How fast along the target (m/s, full size; × the square root of the length scale) a
/// bullet may sway and still count as waiting.
const WAITING_SPEED: f64 = 0.3;
/// Most obstacles a package carries.
pub const MAX_OBSTACLES: usize = 32;

/// The friction coefficient at and above which the projected heading's τ is `yaw_decay`
/// ([`Planner::yaw_decay`]). Measured: the 1/μ scaling from μ 0.9 down cost as many mid-μ
/// scenes as it saved on low μ; from 0.6 down it pays (docs/planner.md, "Terminal set").
pub(super) const YAW_DECAY_MU: f64 = 0.6;

/// What the decision layer sees.
#[derive(Debug, Clone, Copy)]
pub struct PlannerInput<'a> {
    /// Time now (s), on the clock the obstacles' motion refers to.
    pub time: f64,
    pub target: TargetState,
    pub bullet: BulletState,
    /// The target driver's input, predicted constant.
    pub target_input: TargetInput,
    pub road: &'a Road,
    pub obstacles: &'a [Obstacle],
    /// Restrict the search to this side (a committed PIT); `None` tries the sides the
    /// settings allow.
    pub side: Option<Side>,
    /// During a PIT under way, disengaging is not an option: when no candidate is
    /// feasible, the best one is still returned as [`Mode::Pit`] (with the reason set).
    pub best_effort: bool,
}

/// Bad input to the planner (never a numerical outcome: that is a [`Mode`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum PlanError {
    #[error("planner input: a state is not finite")]
    NonFiniteState,
    #[error("planner input: more than {MAX_OBSTACLES} obstacles")]
    TooManyObstacles,
    #[error(
        "planner input: more forces than the window has steps, or a window past the look-ahead"
    )]
    TooManyForces,
}

/// Construction errors.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PlannerError {
    #[error(transparent)]
    Settings(#[from] crate::settings::SettingsError),
    #[error("planner: the target model steps {model} s but the planner {planner} s")]
    StepMismatch { model: f64, planner: f64 },
    #[error("planner: QP solver: {0}")]
    Solver(String),
}

/// One candidate's outcome.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Outcome {
    side: Side,
    k0: usize,
    contact_x: f64,
    objective: f64,
    heading_error: f64,
    road_margin: f64,
    clearance: f64,
    stop_margin: f64,
}

/// When the closed loop of the push lets go ([`Planner::push_done`]): the target left alone
/// must reach the terminal set with its projected heading within `heading_tol` of the
/// reversed heading; if the free rollout ends slower than `rest_speed`, within
/// `rest_heading_tol`.
///
/// A target that will have all but stopped at the end of the look-ahead has no spin left
/// beyond it, so its projected heading is where it comes to rest, and the success test asks
/// for that within ε_ψ (0.349 rad); a faster one goes on turning past the look-ahead. With
/// one tolerance for both (0.6 rad), braking targets stopped 20–45° short of reversed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Release {
    /// Largest projected heading error of the free rollout (rad).
    pub heading_tol: f64,
    /// Below this speed at the end of the look-ahead (m/s; 0: never) ...
    pub rest_speed: f64,
    /// ... the largest heading error is this instead, if smaller (rad).
    pub rest_heading_tol: f64,
}

impl Release {
    /// One tolerance whatever the predicted speed.
    #[must_use]
    pub fn heading(heading_tol: f64) -> Self {
        Self {
            heading_tol,
            rest_speed: 0.0,
            rest_heading_tol: heading_tol,
        }
    }
}

/// How the upper layer judges a given push ([`Planner::judge`]): the plan's own terminal
/// and safety criteria on its rollout, without optimising anything.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Judgement {
    /// `|wrap(ψ_N + τ r_N − ψ_rev)|` at the end of the look-ahead (rad).
    pub heading_error: f64,
    /// Least road margin of the footprint over the look-ahead, beyond `road_margin` (m).
    pub road_margin: f64,
    /// Least obstacle gap over the look-ahead (m).
    pub clearance: f64,
    /// Road margin of the predicted stopping point (m).
    pub stop_margin: f64,
    /// Whether a candidate with this outcome would be feasible (in the terminal set, inside
    /// the road, clear of obstacles, each within `violation_tol`).
    pub feasible: bool,
}

/// The upper layer: owns its target model, its QP and every buffer.
///
/// Memory: the rollout (`N + 1` states, `N` Jacobians), the sensitivities (`(N + 1)·8·2W`
/// doubles), the forces of the current and best candidate (`2W` each), and one Clarabel QP
/// with `3W + 2M + 1` variables and `10W + 4M + 2` rows (N steps, W window steps, M = N /
/// `row_stride` constrained steps); the
/// package holds `N + 1` steps and up to [`MAX_OBSTACLES`] obstacles.
pub struct Planner {
    settings: PlannerSettings,
    params: ParamSet,
    mu: f64,
    model: Box<dyn TargetModel + Send + Sync>,
    n: usize,
    w: usize,
    /// Force scale S (N) and the target weight m_T g (N).
    scale: f64,
    weight: f64,
    force_max: f64,
    /// The vehicles' length scale ([`length_scale`]) for the built-in lengths.
    len_scale: f64,
    // Rollout at the linearisation.
    xs: Vec<TargetState>,
    jac: TargetJacobians,
    jac_a: Vec<nalgebra::SMatrix<f64, 8, 8>>,
    jac_f: Vec<nalgebra::SMatrix<f64, 8, 2>>,
    /// Sensitivities `∂x_k/∂y` (8 × 2W per step, row-major per state), y = δF / S.
    sens: Vec<f64>,
    /// Forces over the window (N): current linearisation, candidate, best.
    forces: Vec<Vec2>,
    trial: Vec<Vec2>,
    best: Vec<Vec2>,
    // Linearised soft rows per step: coefficients on [X, Y, ψ] and right-hand sides.
    road_rows: Vec<([f64; 3], f64)>,
    obs_rows: Vec<([f64; 3], f64)>,
    /// The stopping-point row: coefficients on the 8 terminal states and its rhs.
    stop_row: ([f64; 8], f64),
    qp: Qp,
    package: DecisionPackage,
    // Per-candidate context.
    side: Side,
    k0: usize,
    contact_point: Vec2,
    /// The current candidate's contact point along the target (body x, m).
    contact_x: f64,
    psi_rev: f64,
    /// The side the bullet works on: the inside of the curve the target is on or coming
    /// to, if the bullet has room there ([`Planner::curve_side`]); on a straight, against
    /// a driverless target's drift, else the roomier side ([`Planner::roomier_side`]).
    inside: Option<Side>,
    /// The inside of the curve the target is on or coming to ([`Planner::curve_side`]),
    /// taken by the calls that fill the package (`plan`, `predict`; not the closed loop's
    /// `push_done`, every control step in contact, which does not need it).
    curve: Option<Side>,
    /// The side against a driverless target's drift on a straight, decided once per
    /// maneuver ([`Planner::against_drift`]).
    drift: Drift,
    input_u: TargetInput,
    /// The target driver of the rollout: `None` holds `input_u` (the push's rollouts); the
    /// race test rolls the free motion out under a lane keeper too.
    lane_keeper: Option<LaneKeeper>,
    time: f64,
}

impl std::fmt::Debug for Planner {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Planner")
            .field("target_model", &self.model.name())
            .field("steps", &self.n)
            .field("window_steps", &self.w)
            .field("qp", &(self.qp.n, self.qp.m))
            .finish_non_exhaustive()
    }
}

/// Layout of the planner QP's variables: the force steps, the corridor excesses, one road
/// and one obstacle slack per constrained step (every `stride`-th step), the stop slack.
#[derive(Debug, Clone, Copy)]
struct Layout {
    n: usize,
    w: usize,
    stride: usize,
}

impl Layout {
    fn new(s: &PlannerSettings) -> Self {
        Self {
            n: s.steps(),
            w: s.window_steps(),
            stride: s.row_stride,
        }
    }
    /// Number of constrained steps.
    fn soft(&self) -> usize {
        self.n.div_ceil(self.stride)
    }
    /// The step of the i-th constrained step (the last is always N).
    fn soft_step(&self, i: usize) -> usize {
        ((i + 1) * self.stride).min(self.n)
    }
    fn force(&self, j: usize) -> usize {
        2 * j
    }
    fn excess(&self, j: usize) -> usize {
        2 * self.w + j
    }
    fn s_road(&self, i: usize) -> usize {
        3 * self.w + i
    }
    fn s_obs(&self, i: usize) -> usize {
        3 * self.w + self.soft() + i
    }
    fn s_stop(&self) -> usize {
        3 * self.w + 2 * self.soft()
    }
    fn vars(&self) -> usize {
        3 * self.w + 2 * self.soft() + 1
    }
    fn rows(&self) -> usize {
        10 * self.w + 4 * self.soft() + 2
    }
}

impl Planner {
    /// Build the planner for a parameter set, road friction μ and target model.
    ///
    /// # Errors
    /// Invalid settings (named), a model whose step differs from the planner's, or a QP
    /// Clarabel refuses.
    pub fn new(
        params: &ParamSet,
        mu: f64,
        model: Box<dyn TargetModel + Send + Sync>,
        settings: PlannerSettings,
    ) -> Result<Self, PlannerError> {
        settings.validate()?;
        if (model.dt() - settings.dt).abs() > 1e-12 {
            return Err(PlannerError::StepMismatch {
                model: model.dt(),
                planner: settings.dt,
            });
        }
        let n = settings.steps();
        let w = settings.window_steps();
        let weight = params.target.mass * GRAVITY;
        let l = Layout::new(&settings);
        let mut me = Self {
            scale: settings.force_scale_g * weight,
            force_max: settings.force_max_g * weight,
            weight,
            len_scale: length_scale(params),
            params: params.clone(),
            mu,
            model,
            n,
            w,
            xs: vec![TargetState::zeros(); n + 1],
            jac: TargetJacobians::default(),
            jac_a: vec![nalgebra::SMatrix::zeros(); n],
            jac_f: vec![nalgebra::SMatrix::zeros(); n],
            sens: vec![0.0; (n + 1) * 8 * 2 * w],
            forces: vec![Vec2::zeros(); w],
            trial: vec![Vec2::zeros(); w],
            best: vec![Vec2::zeros(); w],
            road_rows: vec![([0.0; 3], FAR); n + 1],
            obs_rows: vec![([0.0; 3], FAR); n + 1],
            stop_row: ([0.0; 8], FAR),
            qp: Self::build_qp(&settings, l)?,
            package: DecisionPackage::with_capacity(n + 1, MAX_OBSTACLES),
            side: Side::Left,
            k0: 0,
            contact_point: Vec2::zeros(),
            contact_x: rear_quarter_x(params),
            psi_rev: 0.0,
            curve: None,
            inside: None,
            drift: Drift::Unseen,
            input_u: TargetInput::zeros(),
            lane_keeper: None,
            time: 0.0,
            settings,
        };
        // Warm up Clarabel's internal buffers (its first solve builds its timer maps).
        me.qp.solve();
        Ok(me)
    }

    fn build_qp(s: &PlannerSettings, l: Layout) -> Result<Qp, PlannerError> {
        let mut pp = Vec::new();
        let mut ap = Vec::new();
        let mut q = vec![0.0; l.vars()];
        let mut b = vec![0.0; l.rows()];
        let dummy = DummyRows::new(l);
        {
            let mut ep = Emitter::pattern(&mut pp, true);
            let mut ea = Emitter::pattern(&mut ap, false);
            assemble(&dummy.view(s), &mut ep, &mut ea, &mut q, &mut b);
            ep.finish();
            ea.finish();
        }
        let p = Pattern::build(l.vars(), l.vars(), &pp);
        let a = Pattern::build(l.rows(), l.vars(), &ap);
        Qp::new(p, a, 0, clarabel_settings(&s.qp), s.qp.time_limit).map_err(PlannerError::Solver)
    }

    #[must_use]
    pub fn settings(&self) -> &PlannerSettings {
        &self.settings
    }

    #[must_use]
    pub fn target_model_name(&self) -> &str {
        self.model.name()
    }

    #[must_use]
    pub fn target_param_count(&self) -> usize {
        self.model.param_count()
    }

    /// Set the road friction μ (the stopping-distance model uses it).
    pub fn set_mu(&mut self, mu: f64) {
        self.mu = mu;
    }

    /// τ of the projected heading ψ_N + τ r_N: `yaw_decay` from μ = [`YAW_DECAY_MU`] up,
    /// longer on a more slippery road. The target's yaw rate left at the end of the
    /// look-ahead dies away under its tyres' friction moment, which scales with μ, so the
    /// turn it still adds scales with 1/μ: τ = `yaw_decay` · [`YAW_DECAY_MU`] / μ, at least
    /// `yaw_decay` and at most twice it (docs/planner.md, "Terminal set").
    #[must_use]
    pub(super) fn yaw_decay(&self) -> f64 {
        self.settings.yaw_decay * (YAW_DECAY_MU / self.mu.max(1e-3)).clamp(1.0, 2.0)
    }

    /// The last package.
    #[must_use]
    pub fn package(&self) -> &DecisionPackage {
        &self.package
    }

    /// Keep `o` if it is the best feasible candidate so far (or, while none is feasible, the
    /// best infeasible one), with its forces.
    fn rank(
        &mut self,
        o: Outcome,
        best: &mut Option<Outcome>,
        best_any: &mut Option<Outcome>,
        feasible: &mut u32,
    ) {
        if self.acceptable(o.heading_error, [o.road_margin, o.stop_margin], o.clearance) {
            *feasible += 1;
            // On a curve a feasible push from the inside beats any from the outside.
            let inside = |c: &Outcome| self.inside == Some(c.side);
            if best.is_none_or(|b| (inside(&o), -o.objective) > (inside(&b), -b.objective)) {
                *best = Some(o);
                self.best.copy_from_slice(&self.forces);
            }
        } else if best.is_none() && best_any.is_none_or(|b| o.objective < b.objective) {
            *best_any = Some(o);
            self.best.copy_from_slice(&self.forces);
        }
    }

    /// Start a new maneuver: forget the side chosen against the target's drift.
    pub fn reset(&mut self) {
        self.drift = Drift::Unseen;
    }

    /// Take the call's time, the target driver's command and its model, and the
    /// rear-quarter contact point; return the heading of the road at the target (the
    /// reversed heading's reference).
    fn begin(&mut self, input: &PlannerInput<'_>) -> f64 {
        self.time = input.time;
        self.input_u = input.target_input;
        self.lane_keeper = None;
        self.contact_x = self.contact_x_at(0.0);
        input
            .road
            .project(Vec2::new(input.target[idx::X], input.target[idx::Y]))
            .heading
    }

    /// Plan from the current state: search the candidates and fill the package.
    ///
    /// # Errors
    /// [`PlanError`] for bad input (a non-finite state, too many obstacles).
    pub fn plan(&mut self, input: &PlannerInput<'_>) -> Result<&DecisionPackage, PlanError> {
        check_input(input)?;
        let lane = self.begin(input);
        self.curve = self.curve_side(input);
        // The target reverses without further push (a PIT under way that has done its
        // work, or a target spinning out by itself): the decision is to stop pushing. The
        // package still reports the predicted margins. A push that turns the target round
        // (`push_round`) is not ended by a prediction while it is under way.
        let free_failure = {
            let pushing_round = input.best_effort && self.settings.push_round;
            if !pushing_round && self.free_rollout_reverses(input, lane) {
                self.package.candidates = 0;
                self.package.feasible_candidates = 0;
                self.fill_package(Mode::Stabilise, None, None, lane, input);
                return Ok(&self.package);
            }
            // The race is judged against two drivers, the command held and a lane keeper:
            // the target fails only when it fails under both (the later of the two).
            let held = self.free_failure();
            held.and_then(|h| {
                let model = self.lane_keeper.replace(self.lane_keeper_of(input));
                self.rollout(Some(input.road), &input.target, false, false);
                self.linearise_rows(input.road, input.obstacles);
                self.lane_keeper = model;
                self.free_failure()
                    .map(|l| if l.step > h.step { l } else { h })
            })
        };
        // Sides on which the bullet cannot begin a push before the target's free motion
        // fails (while chasing): the race there is lost.
        let mut lost_sides = 0usize;
        let mut best: Option<Outcome> = None;
        let mut best_any: Option<Outcome> = None;
        let mut closed_sides = 0usize;
        let mut candidates = 0u32;
        let mut feasible = 0u32;
        let sides: &[Side] = match input.side {
            Some(Side::Left) => &[Side::Left],
            Some(Side::Right) => &[Side::Right],
            // Both sides; in practice the far side's windows seldom fit the look-ahead (the
            // bullet would have to cross behind the target first), so the chase, which
            // brings the bullet to one side, decides the side (docs/planner.md).
            None => &[Side::Left, Side::Right],
        };
        // Where the vehicles touch, if they do: the contact point of a plan in contact.
        let pair = self.pair(&input.target, &input.bullet);
        let touching = pair.gap < 0.1 * self.len_scale;
        for &side in sides {
            // No room for the bullet beside the target on this side: not a candidate (a
            // committed side in contact is kept).
            if input.side.is_none() && !self.side_open(side, input) {
                closed_sides += 1;
                continue;
            }
            let (t_arr, x_arr) =
                self.earliest_arrival(side, input.road, &input.target, &input.bullet);
            if input.side.is_none()
                && free_failure.is_some_and(|f| t_arr >= f.step as f64 * self.settings.dt)
            {
                lost_sides += 1;
                continue;
            }
            // In contact already: the window starts now.
            let offsets = if t_arr == 0.0 {
                1
            } else {
                self.settings.start_offsets.len()
            };
            for oi in 0..offsets {
                let t0 = t_arr + self.settings.start_offsets[oi];
                let k0 = self.settings.step_at(t0);
                if k0 + self.w > self.n {
                    continue;
                }
                candidates += 1;
                self.contact_x = x_arr;
                if let Some(o) = self.evaluate(side, k0, lane, input) {
                    self.rank(o, &mut best, &mut best_any, &mut feasible);
                }
            }
        }
        // The contact point along the rear quarter: the other offsets, tried on the best
        // side and window only (one more candidate each); not while in contact, where the
        // contact point is wherever the bullet touches.
        if let Some(o) = best.or(best_any).filter(|_| !touching) {
            for i in 0..self.settings.contact_offsets.len() {
                let off = self.settings.contact_offsets[i];
                let x = self.contact_x_at(off);
                if (x - o.contact_x).abs() < 1e-9 {
                    continue;
                }
                candidates += 1;
                self.contact_x = x;
                if let Some(c) = self.evaluate(o.side, o.k0, lane, input) {
                    self.rank(c, &mut best, &mut best_any, &mut feasible);
                }
            }
        }
        self.package.candidates = candidates;
        self.package.feasible_candidates = feasible;
        // An abort reports the free prediction; `best_any` only ranks the failures.
        let chosen = best.or(best_any);
        // No side leaves the bullet room to line up: no PIT is possible here.
        let no_room = closed_sides == sides.len();
        // Every open side's race is lost: the target fails before any push can begin.
        let race_lost = !no_room && closed_sides + lost_sides == sides.len();
        let mode = if no_room || race_lost {
            Mode::Abort
        } else if candidates == 0 {
            Mode::Chase
        } else if best.is_some() || (input.best_effort && best_any.is_some()) {
            Mode::Pit
        } else {
            Mode::Abort
        };
        // The reason is what binds the best infeasible candidate: a violated or active
        // (within `BINDING` m) obstacle or road row explains why the heading was not
        // reached; otherwise the push itself falls short (or overshoots).
        const BINDING: f64 = 0.25;
        let infeasible = if no_room {
            Some(Infeasible::RoadBoundary)
        } else if race_lost {
            free_failure.map(|f| f.reason)
        } else if best.is_none() && candidates > 0 {
            Some(match best_any {
                None => Infeasible::Numerical,
                Some(o) if o.clearance < self.settings.obstacle_clearance + BINDING => {
                    Infeasible::ObstacleClearance
                }
                Some(o) if o.road_margin < BINDING || o.stop_margin < BINDING => {
                    Infeasible::RoadBoundary
                }
                Some(_) => Infeasible::TerminalSetUnreachable,
            })
        } else {
            None
        };
        match chosen.filter(|_| mode == Mode::Pit) {
            Some(o) => {
                self.forces.copy_from_slice(&self.best);
                self.fill_package(mode, infeasible, Some(o), lane, input);
            }
            None => {
                // Chase (nothing reachable) or every candidate failed numerically: the
                // package carries the free (no-force) prediction. On a curve the bullet
                // chases on the inside.
                let side = self.inside.unwrap_or_else(|| self.bullet_side(input));
                self.setup_candidate(side, self.n, lane);
                self.forces.iter_mut().for_each(|f| *f = Vec2::zeros());
                self.fill_package(mode, infeasible, None, lane, input);
                // `self.xs` is the free prediction now.
                if self.stand_off_blocked(side, input) {
                    self.hold_back(input);
                }
            }
        }
        self.package.race_lost = race_lost;
        Ok(&self.package)
    }

    /// The free prediction (no force) as a package of the given mode: for the
    /// stabilisation phase, and for the ablation without the upper layer.
    ///
    /// # Errors
    /// [`PlanError`] for bad input.
    pub fn predict(
        &mut self,
        mode: Mode,
        input: &PlannerInput<'_>,
    ) -> Result<&DecisionPackage, PlanError> {
        if input.target.iter().any(|v| !v.is_finite()) {
            return Err(PlanError::NonFiniteState);
        }
        if input.obstacles.len() > MAX_OBSTACLES {
            return Err(PlanError::TooManyObstacles);
        }
        let lane = self.begin(input);
        self.curve = self.curve_side(input);
        let side = self.bullet_side(input);
        self.setup_candidate(side, self.n, lane);
        self.forces.iter_mut().for_each(|f| *f = Vec2::zeros());
        self.package.candidates = 0;
        self.package.feasible_candidates = 0;
        self.fill_package(mode, None, None, lane, input);
        Ok(&self.package)
    }

    /// +1 when the bullet slides forward along the target's side (its push speed ≥ 0).
    fn friction_sign(&self) -> f64 {
        if self.settings.push_speed >= 0.0 {
            1.0
        } else {
            -1.0
        }
    }
}

/// The input a plan needs: finite states and driver command, at most `MAX_OBSTACLES`.
fn check_input(input: &PlannerInput<'_>) -> Result<(), PlanError> {
    if input.target.iter().any(|v| !v.is_finite())
        || input.bullet.iter().any(|v| !v.is_finite())
        || input.target_input.iter().any(|v| !v.is_finite())
    {
        return Err(PlanError::NonFiniteState);
    }
    if input.obstacles.len() > MAX_OBSTACLES {
        return Err(PlanError::TooManyObstacles);
    }
    Ok(())
}

/// |wrap(ψ_N + τ r_N − ψ_rev)|.
#[must_use]
pub fn projected_heading_error(x: &TargetState, tau: f64, psi_rev: f64) -> f64 {
    wrap(x[idx::PSI] + tau * x[idx::R] - psi_rev).abs()
}

/// Wrap an angle to (−π, π].
#[must_use]
pub fn wrap(a: f64) -> f64 {
    let t = std::f64::consts::TAU;
    let mut r = a % t;
    if r <= -std::f64::consts::PI {
        r += t;
    } else if r > std::f64::consts::PI {
        r -= t;
    }
    r
}

#[cfg(test)]
mod tests {
    use super::*;
    use dynamics::target4dof::FourDofTarget;

    /// The chained sensitivities ∂x_k/∂F (with γ turning with ψ) against central
    /// differences of the nonlinear rollout.
    #[test]
    fn rollout_sensitivities_match_finite_differences() {
        check_sensitivities(None);
    }

    /// The same with a lane-keeping driver in the rollout, whose steer follows the
    /// predicted state (its gradient enters ∂x⁺/∂x).
    #[test]
    fn rollout_sensitivities_with_a_lane_keeping_driver_match_finite_differences() {
        use dynamics::road::{RoadSpec, SegmentSpec};
        let road = Road::new(RoadSpec {
            segments: vec![SegmentSpec::Arc {
                length: 300.0,
                curvature: 0.01,
            }],
            lanes: 2,
            lane_width: 3.5,
            shoulder: 0.5,
            origin: [0.0, 0.0, 0.0],
        })
        .unwrap();
        check_sensitivities(Some(&road));
    }

    fn check_sensitivities(road: Option<&Road>) {
        let params = ParamSet::builtin("full_size").unwrap();
        let s = PlannerSettings::default();
        let model = Box::new(FourDofTarget::new(&params.target, 0.9, s.dt));
        let mut p = Planner::new(&params, 0.9, model, s).unwrap();
        let mut x0 = TargetState::zeros();
        x0[idx::VX] = 15.0;
        x0[idx::R] = 0.2;
        if road.is_some() {
            p.lane_keeper = Some(LaneKeeper {
                offset: 1.75,
                gain: 1.0,
                wheelbase: params.target.wheelbase(),
            });
        }
        p.setup_candidate(Side::Left, 5, 0.0);
        for (j, f) in p.forces.iter_mut().enumerate() {
            *f = Vec2::new(4000.0 + 500.0 * j as f64, 300.0);
        }
        p.rollout(road, &x0, false, true);
        let sens = p.sens.clone();
        let cols = 2 * p.w;
        let h = 1.0; // N
        for j in [0, 3, p.w - 1] {
            for d in 0..2 {
                let base = p.forces.clone();
                p.trial.copy_from_slice(&base);
                p.trial[j][d] += h;
                p.rollout(road, &x0, true, false);
                let plus = p.xs.clone();
                p.trial.copy_from_slice(&base);
                p.trial[j][d] -= h;
                p.rollout(road, &x0, true, false);
                let minus = p.xs.clone();
                for k in [p.k0 + j + 1, p.n] {
                    for st in [idx::VY, idx::PSI, idx::R, idx::X, idx::Y] {
                        let fd = (plus[k][st] - minus[k][st]) / (2.0 * h) * p.scale;
                        let an = sens[k * 8 * cols + st * cols + 2 * j + d];
                        let tol = 1e-5 + 2e-3 * an.abs().max(fd.abs());
                        assert!(
                            (fd - an).abs() < tol,
                            "∂x{k}[{st}]/∂F{j}[{d}]: analytic {an}, differences {fd}"
                        );
                    }
                }
            }
        }
    }
}
