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
use crate::settings::{length_scale, ContactPointModel, PlannerSettings, TargetDriverModel};
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

const GRAVITY: f64 = 9.81;
/// Right-hand side of a row that cannot bind.
const FAR: f64 = 1.0e3;

/// How far along the target (m, full size; × the length scale) from the band of contact
/// stations, and how fast relative to it (m/s; × the square root of the length scale), a
/// waiting bullet counts as arrived for the earliest arrival ([`Planner::plan`]'s windows).
const ARRIVAL_TOL: f64 = 0.3;
/// Most obstacles a package carries.
pub const MAX_OBSTACLES: usize = 32;

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
    /// Least road margin of the free slide after the look-ahead (`check_horizon`).
    slide_margin: f64,
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
    /// Least road margin of the free slide after the look-ahead (`check_horizon`; +∞ off).
    pub slide_margin: f64,
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
    input_u: TargetInput,
    /// The target driver of the rollout (`PlannerSettings::target_driver`): `None` holds
    /// `input_u`.
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

    /// The last package.
    #[must_use]
    pub fn package(&self) -> &DecisionPackage {
        &self.package
    }

    /// The bullet's contact pose on `side` (target frame) at the current candidate's contact
    /// point.
    fn contact_pose(&self, side: Side) -> mpc::StageReference {
        self.contact_pose_at(side, self.contact_x)
    }

    /// The bullet's contact pose on `side` (target frame) at the contact point's body x `x_c`.
    fn contact_pose_at(&self, side: Side, x_c: f64) -> mpc::StageReference {
        let s = &self.settings;
        pit_stage_at(
            &self.params,
            side,
            x_c,
            s.contact_angle,
            s.overlap,
            s.push_speed,
            (0.0, self.force_max),
        )
    }

    /// The contact point's body x for offset `offset` from the rear quarter (clamped as
    /// [`Self::clamp_contact_x`]).
    fn contact_x_at(&self, offset: f64) -> f64 {
        self.clamp_contact_x(rear_quarter_x(&self.params) + offset)
    }

    /// A contact point's body x clamped to the target's side, at least 0.2 m (full size;
    /// × the length scale) from either bumper.
    fn clamp_contact_x(&self, x: f64) -> f64 {
        let t = &self.params.target;
        let clear = 0.2 * self.len_scale;
        x.clamp(-(t.length - t.cg_to_front) + clear, t.cg_to_front - clear)
    }

    /// Where the bullet touches the target now (`pair`: the footprints' geometry, bullet
    /// first), as the contact point's body x (clamped as [`Self::clamp_contact_x`]), when a
    /// plan in contact puts its force there (`contact_point_in_contact = touch`) and the
    /// footprints are within 0.1 m (× the length scale); `None` otherwise.
    fn touch_x(&self, pair: &PairGeometry, xt: &TargetState) -> Option<f64> {
        if self.settings.contact_point_in_contact != ContactPointModel::Touch
            || pair.gap >= 0.1 * self.len_scale
        {
            return None;
        }
        let x = Pose2::new(xt[idx::X], xt[idx::Y], xt[idx::PSI])
            .body_from_world(pair.point_b)
            .x;
        Some(self.clamp_contact_x(x))
    }

    /// Earliest time (s from now) the bullet can be at a contact pose on `side`, and the
    /// contact point's body x there. The contact point is the one of the band the planner
    /// tries (`contact_offsets` from the rear quarter) nearest to where the bullet would come
    /// to rest relative to the target if it braked now: a bullet waiting a little behind the
    /// rear-quarter station, or one that will stop a little short of it, is already at a
    /// station. The time is the approach along the target ([`Profile`], from the bullet's
    /// relative position and speed, arriving at rest relative to the target), moving across
    /// at `lateral_speed` at the same time, plus a settling time; crossing behind the target
    /// to the other side first drops back behind its rear bumper.
    fn earliest_arrival(&self, side: Side, xt: &TargetState, xb: &BulletState) -> (f64, f64) {
        let s = &self.settings;
        let x0 = self.contact_x_at(0.0);
        let (lo, hi) = s
            .contact_offsets
            .iter()
            .map(|&o| self.contact_x_at(o))
            .fold((x0, x0), |(lo, hi), x| (lo.min(x), hi.max(x)));
        let c = self.contact_pose_at(side, x0);
        let rel = crate::href::relative_position(xt, xb);
        let rel_vel = crate::href::relative_velocity(xt, xb);
        let (a, cap) = (s.approach_accel(self.mu), s.approach_speed);
        let stop = rel.x + rel_vel.x * rel_vel.x.abs() / (2.0 * a);
        let x_c = (x0 + stop - c.rel_pos.x).clamp(lo, hi);
        let goal = c.rel_pos.x + x_c - x0;
        let dx = (goal - rel.x).abs();
        let dy = (c.rel_pos.y - rel.y).abs();
        let k = self.len_scale;
        // A bullet waiting within `ARRIVAL_TOL` of the band (the MPC holds it a few tenths of
        // a metre off its station, drifting at a few tenths of a metre per second) has
        // arrived along the target once it stops: the turn-in closes the rest; at the
        // approach's gentle acceleration on low adhesion, closing it first would take longer
        // than the look-ahead leaves for a window. One still closing in has not.
        let tol = ARRIVAL_TOL * k;
        let (band_lo, band_hi) = (c.rel_pos.x + lo - x0 - tol, c.rel_pos.x + hi - x0 + tol);
        let waiting = rel_vel.x.abs() < ARRIVAL_TOL * k.sqrt();
        let goal_along = if waiting && (band_lo..=band_hi).contains(&rel.x) {
            stop.clamp(band_lo, band_hi)
        } else {
            goal
        };
        if dx.hypot(dy) < 0.3 * k || self.gap(xt, xb) < 0.1 * k {
            // At the contact pose, or touching already: a PIT under way.
            return (0.0, x_c);
        }
        let along = if side.sign() * rel.y < 0.0 {
            // On the other side: drop back behind the target's rear first.
            let behind = -(self.params.target.length - self.params.target.cg_to_front)
                - self.params.bullet.cg_to_front
                - 0.5 * k;
            Profile::new(rel.x, rel_vel.x, behind.min(rel.x), a, cap).time()
                + Profile::new(behind.min(rel.x), 0.0, goal_along, a, cap).time()
        } else {
            Profile::new(rel.x, rel_vel.x, goal_along, a, cap).time()
        };
        (s.settle_time + along.max(dy / s.lateral_speed), x_c)
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
        if self.acceptable(
            o.heading_error,
            [o.road_margin, o.stop_margin, o.slide_margin],
            o.clearance,
        ) {
            *feasible += 1;
            if best.is_none_or(|b| o.objective < b.objective) {
                *best = Some(o);
                self.best.copy_from_slice(&self.forces);
            }
        } else if best.is_none() && best_any.is_none_or(|b| o.objective < b.objective) {
            *best_any = Some(o);
            self.best.copy_from_slice(&self.forces);
        }
    }

    /// Take the call's time, the target driver's command and its model, and the
    /// rear-quarter contact point; return the heading of the road at the target (the
    /// reversed heading's reference).
    fn begin(&mut self, input: &PlannerInput<'_>) -> f64 {
        self.time = input.time;
        self.input_u = input.target_input;
        self.lane_keeper = self.driver_model(input);
        self.contact_x = self.contact_x_at(0.0);
        input
            .road
            .project(Vec2::new(input.target[idx::X], input.target[idx::Y]))
            .heading
    }

    /// The feasibility test of a candidate: terminal heading within `heading_tol`, road,
    /// stopping-point and free-slide margins and obstacle clearance within
    /// `violation_tol`.
    fn acceptable(&self, heading_error: f64, margins: [f64; 3], clearance: f64) -> bool {
        let tol = self.settings.violation_tol;
        heading_error <= self.settings.heading_tol
            && margins.iter().all(|&m| m >= -tol)
            && clearance >= self.settings.obstacle_clearance - tol
    }

    /// Judge a given push on the plan's criteria, without optimising it: the forces
    /// `forces[j] = [F_n, F_t]` (N) act over plan steps `start + j` (at most the window's
    /// steps; the rest of the window is free) on `side` at the rear-quarter point, the
    /// target's driver as the settings say. The planner's package is left as it was. For
    /// diagnostics (`examples/oracle_surrogate`: which single shoves the upper layer would
    /// call feasible).
    ///
    /// # Errors
    /// [`PlanError`] for bad input, and [`PlanError::TooManyForces`] for more forces than
    /// the window has steps, or a window past the look-ahead.
    pub fn judge(
        &mut self,
        input: &PlannerInput<'_>,
        side: Side,
        start: usize,
        forces: &[Vec2],
    ) -> Result<Judgement, PlanError> {
        if input.target.iter().any(|v| !v.is_finite())
            || input.target_input.iter().any(|v| !v.is_finite())
            || forces.iter().any(|f| !f.x.is_finite() || !f.y.is_finite())
        {
            return Err(PlanError::NonFiniteState);
        }
        if input.obstacles.len() > MAX_OBSTACLES {
            return Err(PlanError::TooManyObstacles);
        }
        if forces.len() > self.w || start + self.w > self.n {
            return Err(PlanError::TooManyForces);
        }
        let lane = self.begin(input);
        self.setup_candidate(side, start, lane);
        self.forces.iter_mut().for_each(|f| *f = Vec2::zeros());
        self.forces[..forces.len()].copy_from_slice(forces);
        self.rollout(Some(input.road), &input.target, false, false);
        self.linearise_rows(input.road, input.obstacles);
        let (_, _, road_margin, clearance, stop_margin) = self.merit(false);
        let heading_error =
            projected_heading_error(&self.xs[self.n], self.settings.yaw_decay, self.psi_rev);
        let slide_margin = self.slide_margin(input.road);
        Ok(Judgement {
            heading_error,
            road_margin,
            clearance,
            stop_margin,
            slide_margin,
            feasible: self.acceptable(
                heading_error,
                [road_margin, stop_margin, slide_margin],
                clearance,
            ),
        })
    }

    /// Plan from the current state: search the candidates and fill the package.
    ///
    /// # Errors
    /// [`PlanError`] for bad input (a non-finite state, too many obstacles).
    pub fn plan(&mut self, input: &PlannerInput<'_>) -> Result<&DecisionPackage, PlanError> {
        if input.target.iter().any(|v| !v.is_finite())
            || input.bullet.iter().any(|v| !v.is_finite())
            || input.target_input.iter().any(|v| !v.is_finite())
        {
            return Err(PlanError::NonFiniteState);
        }
        if input.obstacles.len() > MAX_OBSTACLES {
            return Err(PlanError::TooManyObstacles);
        }
        let lane = self.begin(input);
        // The target reverses without further push (a PIT under way that has done its
        // work, or a target spinning out by itself): the decision is to stop pushing. The
        // package still reports the predicted margins.
        let free_failure = {
            let side = input.side.unwrap_or_else(|| self.bullet_side(input));
            self.setup_candidate(side, self.n, lane);
            self.forces.iter_mut().for_each(|f| *f = Vec2::zeros());
            self.rollout(Some(input.road), &input.target, false, false);
            self.linearise_rows(input.road, input.obstacles);
            let (_, heading_error, road_margin, clearance, stop_margin) = self.merit(false);
            // (The free slide is not asked of a push already done.)
            if self.acceptable(heading_error, [road_margin, stop_margin, 0.0], clearance) {
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
            None if self.settings.try_both_sides => &[Side::Left, Side::Right],
            // Only the side the bullet is on.
            None => match self.bullet_side(input) {
                Side::Left => &[Side::Left],
                Side::Right => &[Side::Right],
            },
        };
        // Where the vehicles touch, if they do: the contact point of a plan in contact.
        let pair = self.pair(&input.target, &input.bullet);
        let touching = pair.gap < 0.1 * self.len_scale;
        let touch_x = self.touch_x(&pair, &input.target);
        for &side in sides {
            // No room for the bullet beside the target on this side: not a candidate (a
            // committed side in contact is kept).
            if input.side.is_none() && !self.side_open(side, input) {
                closed_sides += 1;
                continue;
            }
            let (t_arr, x_arr) = self.earliest_arrival(side, &input.target, &input.bullet);
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
                let k0 = (t0 / self.settings.dt - 1e-9).ceil().max(0.0) as usize;
                if k0 + self.w > self.n {
                    continue;
                }
                candidates += 1;
                self.contact_x = touch_x.unwrap_or(x_arr);
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
                Some(o)
                    if o.road_margin < BINDING
                        || o.stop_margin < BINDING
                        || o.slide_margin < BINDING =>
                {
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
                // package carries the free (no-force) prediction.
                let side = self.bullet_side(input);
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

    /// Lateral room (m) the bullet has on `side` at its stand-off pose beside the target's
    /// rear quarter: the road margin of that pose's outer edge (negative: over the edge).
    fn side_room(&self, side: Side, input: &PlannerInput<'_>) -> f64 {
        let c = self.contact_pose(side);
        let pose = Pose2::new(
            input.target[idx::X],
            input.target[idx::Y],
            input.target[idx::PSI],
        );
        let outer =
            c.rel_pos.y + side.sign() * (self.settings.standoff + 0.5 * self.params.bullet.width);
        let p = pose.world_from_body(Vec2::new(c.rel_pos.x, outer));
        input.road.half_width() - input.road.project(p).d.abs()
    }

    /// Whether the bullet's stand-off pose on `side` beside the predicted target
    /// (`self.xs`: the free prediction) would come within the obstacle clearance of an
    /// obstacle while the bullet is beside the target: from [`chase::BESIDE`] before its
    /// earliest arrival until the push it chases for is over (the window and
    /// [`chase::FALL_BACK`] after the arrival, at most [`chase::LOOK`] ahead).
    fn stand_off_blocked(&self, side: Side, input: &PlannerInput<'_>) -> bool {
        let s = &self.settings;
        let (t_arr, x_c) = self.earliest_arrival(side, &input.target, &input.bullet);
        let horizon = (t_arr + self.w as f64 * s.dt + chase::FALL_BACK).min(chase::LOOK);
        let c = self.contact_pose_at(side, x_c);
        let path = chase::Path {
            xs: &self.xs,
            dt: s.dt,
            time: input.time,
            obstacles: input.obstacles,
        };
        let stand = chase::StandOff {
            rel_pos: Vec2::new(c.rel_pos.x, c.rel_pos.y + side.sign() * s.standoff),
            rel_heading: 0.0,
        };
        let from = (t_arr - chase::BESIDE).clamp(0.0, horizon);
        path.blocked_at(&self.params, stand, (from, horizon), s.obstacle_clearance)
            .is_some()
    }

    /// Make the package's chase hold back behind the target: its approach goes to
    /// [`crate::href::HOLD_BACK`] behind the contact station.
    fn hold_back(&mut self, input: &PlannerInput<'_>) {
        let s = &self.settings;
        let p = &mut self.package;
        p.hold_back = true;
        p.approach = Profile::with_brake_margin(
            crate::href::relative_position(&input.target, &input.bullet).x,
            crate::href::relative_velocity(&input.target, &input.bullet).x,
            p.contact_rel_pos.x - crate::href::HOLD_BACK * self.len_scale,
            s.approach_accel(self.mu),
            s.approach_speed,
            BRAKE_MARGIN,
        );
    }

    /// Whether the bullet can line up on `side` inside the road (with the road margin).
    fn side_open(&self, side: Side, input: &PlannerInput<'_>) -> bool {
        self.side_room(side, input) >= self.settings.road_margin
    }

    /// The side the bullet works on when no candidate decides it: the side it is on, unless
    /// the road leaves no room there and does on the other side.
    fn bullet_side(&self, input: &PlannerInput<'_>) -> Side {
        let rel = Pose2::new(
            input.target[idx::X],
            input.target[idx::Y],
            input.target[idx::PSI],
        )
        .body_from_world(Vec2::new(input.bullet[0], input.bullet[1]));
        let own = if rel.y >= 0.0 {
            Side::Left
        } else {
            Side::Right
        };
        let other = if own == Side::Left {
            Side::Right
        } else {
            Side::Left
        };
        if !self.side_open(own, input) && self.side_open(other, input) {
            other
        } else {
            own
        }
    }

    fn setup_candidate(&mut self, side: Side, k0: usize, lane: f64) {
        self.side = side;
        self.k0 = k0;
        let t = &self.params.target;
        self.contact_point = Vec2::new(self.contact_x, side.sign() * 0.5 * t.width);
        // Pushing the rear quarter to the right (bullet on the left) yaws the target
        // counter-clockwise: the reversed heading is reached by spinning that way.
        self.psi_rev = lane + side.sign() * std::f64::consts::PI;
    }

    /// The contact input of step k for the force f (N): the normal is the target's side
    /// normal (from the bullet into the target) at the step's heading.
    fn contact(&self, k: usize, f: Vec2, psi: f64) -> ContactInput {
        if k < self.k0 || k >= self.k0 + self.w {
            return ContactInput::none();
        }
        ContactInput {
            fc: f,
            gamma: psi - self.side.sign() * std::f64::consts::FRAC_PI_2,
            point_in_body: self.contact_point,
        }
    }

    /// The rollout's target driver for this plan: a lane keeper of the lane centre nearest
    /// the target (gain 1), or `None` to hold the current command.
    fn driver_model(&self, input: &PlannerInput<'_>) -> Option<LaneKeeper> {
        match self.settings.target_driver {
            TargetDriverModel::Held => None,
            TargetDriverModel::LaneKeep => Some(self.lane_keeper_of(input)),
        }
    }

    /// A lane keeper (gain 1) of the lane centre nearest to the target now.
    fn lane_keeper_of(&self, input: &PlannerInput<'_>) -> LaneKeeper {
        let road = input.road;
        let d = road
            .project(Vec2::new(input.target[idx::X], input.target[idx::Y]))
            .d;
        let lanes = road.spec().lanes;
        let offset = (0..lanes)
            .map(|l| road.lane_center_offset(l))
            .min_by(|a, b| (a - d).abs().total_cmp(&(b - d).abs()))
            .unwrap_or(0.0);
        LaneKeeper {
            offset,
            gain: 1.0,
            wheelbase: self.params.target.wheelbase(),
        }
    }

    /// How the rollout the rows were last linearised at fails first ([`race::first_failure`]).
    fn free_failure(&self) -> Option<race::Failure> {
        let s = &self.settings;
        race::first_failure(
            &self.road_rows,
            &self.obs_rows,
            s.road_margin,
            s.obstacle_clearance,
            s.violation_tol,
        )
    }

    /// Roll out with `forces` from `x0`; with `jac`, store the Jacobians and sensitivities.
    /// With a lane keeper and a road, the driver's steer follows the predicted state (and
    /// its gradient enters ∂x⁺/∂x); otherwise the command `input_u` is held.
    fn rollout(&mut self, road: Option<&Road>, x0: &TargetState, use_trial: bool, jac: bool) {
        self.xs[0] = *x0;
        let mut hint = f64::NAN;
        for k in 0..self.n {
            let f = if k >= self.k0 && k < self.k0 + self.w {
                let j = k - self.k0;
                if use_trial {
                    self.trial[j]
                } else {
                    self.forces[j]
                }
            } else {
                Vec2::zeros()
            };
            let c = self.contact(k, f, self.xs[k][idx::PSI]);
            let x = self.xs[k];
            let (u, grad) = match (self.lane_keeper, road) {
                (Some(lk), Some(road)) => {
                    let p = Vec2::new(x[idx::X], x[idx::Y]);
                    let fr = if hint.is_finite() {
                        road.project_with_hint(p, hint)
                    } else {
                        road.project(p)
                    };
                    hint = fr.s;
                    let (steer, g) = lk.steer_and_gradient(&x, &fr);
                    (TargetInput::new(steer, self.input_u[1]), Some(g))
                }
                _ => (self.input_u, None),
            };
            if jac {
                let next = self.model.step_jac(&x, &u, &c, &mut self.jac);
                let mut a = self.jac.a;
                if let Some(g) = grad {
                    // The driver's steer follows the state: ∂x⁺/∂x += ∂x⁺/∂δ · ∂δ/∂x.
                    a += self.jac.b.column(0) * g.transpose();
                }
                if k >= self.k0 && k < self.k0 + self.w {
                    // γ turns with ψ: add ∂x⁺/∂γ = F · (J f_c) to the heading column.
                    let jf = Vec2::new(-c.fc.y, c.fc.x);
                    for r in 0..8 {
                        a[(r, idx::PSI)] += self.jac.f[(r, 0)] * jf.x + self.jac.f[(r, 1)] * jf.y;
                    }
                }
                self.jac_a[k] = a;
                self.jac_f[k] = self.jac.f;
                self.xs[k + 1] = next;
            } else {
                self.xs[k + 1] = self.model.step(&x, &u, &c);
            }
        }
        if jac {
            self.propagate_sensitivities();
        }
    }

    fn propagate_sensitivities(&mut self) {
        let cols = 2 * self.w;
        let stride = 8 * cols;
        self.sens[..stride].fill(0.0);
        for k in 0..self.n {
            let (head, tail) = self.sens.split_at_mut((k + 1) * stride);
            let g = &head[k * stride..];
            let next = &mut tail[..stride];
            let a = &self.jac_a[k];
            for r in 0..8 {
                for c in 0..cols {
                    let mut v = 0.0;
                    for i in 0..8 {
                        v += a[(r, i)] * g[i * cols + c];
                    }
                    next[r * cols + c] = v;
                }
            }
            if k >= self.k0 && k < self.k0 + self.w {
                let j = k - self.k0;
                let f = &self.jac_f[k];
                for r in 0..8 {
                    next[r * cols + 2 * j] += f[(r, 0)] * self.scale;
                    next[r * cols + 2 * j + 1] += f[(r, 1)] * self.scale;
                }
            }
        }
    }

    /// Signed distance between the two vehicles' footprints (m).
    fn gap(&self, xt: &TargetState, xb: &BulletState) -> f64 {
        self.pair(xt, xb).gap
    }

    /// The two vehicles' footprint geometry (bullet first).
    fn pair(&self, xt: &TargetState, xb: &BulletState) -> PairGeometry {
        let b = &self.params.bullet;
        let fb = Obb::vehicle_footprint(
            &Pose2::new(xb[0], xb[1], xb[2]),
            b.length,
            b.width,
            b.cg_to_front,
        );
        pair_geometry(&fb, &self.footprint(xt))
    }

    fn footprint(&self, x: &TargetState) -> Obb {
        let t = &self.params.target;
        Obb::vehicle_footprint(
            &Pose2::new(x[idx::X], x[idx::Y], x[idx::PSI]),
            t.length,
            t.width,
            t.cg_to_front,
        )
    }

    /// Where the target comes to rest if it slides on from `x` at a constant deceleration
    /// (a fraction of μ g), its pose `[X, Y, ψ]`: the slide is split into its components
    /// along and across the road at the target, and carried along the road's reference line
    /// (so that on a curve a target sliding along the lane stays in it), heading turning
    /// with the road.
    fn stop_pose(&self, road: &Road, x: &TargetState) -> [f64; 3] {
        let v = rotate(x[idx::PSI], Vec2::new(x[idx::VX], x[idx::VY]));
        let decel = self.stop_decel(x);
        let t = v.norm() / (2.0 * decel);
        let f = road.project(Vec2::new(x[idx::X], x[idx::Y]));
        let (sh, ch) = f.heading.sin_cos();
        let v_s = v.x * ch + v.y * sh;
        let v_d = -v.x * sh + v.y * ch;
        let s_stop = f.s + v_s * t;
        let p = road.to_world(s_stop, f.d + v_d * t);
        let turn = road.pose_at(s_stop).heading - f.heading;
        [p.x, p.y, x[idx::PSI] + turn]
    }

    /// The deceleration (m/s²) of a target rolling on without force from state `x`: its tyres
    /// sliding sideways take `stop_decel_fraction` of μ g; rolling along its body it keeps
    /// only rolling resistance and its driveline (in gear: the engine's drag rolling forwards,
    /// the stalled engine's hold rolling backwards); in between by the sine of the body slip.
    fn stop_decel(&self, x: &TargetState) -> f64 {
        let slide = self.settings.stop_decel_fraction * self.mu.max(0.05) * GRAVITY;
        let speed = x[idx::VX].hypot(x[idx::VY]);
        if speed < 1e-6 {
            return slide;
        }
        let t = &self.params.target;
        let per_nm = t.gear_ratio / (t.wheel_radius * t.mass);
        let driveline = t.powertrain.as_ref().map_or(0.0, |pt| {
            per_nm
                * if x[idx::VX] < 0.0 {
                    pt.stall_torque
                } else {
                    pt.engine_drag_torque
                }
        });
        let roll = t.rolling_resistance * GRAVITY + driveline;
        let sin_slip = x[idx::VY].abs() / speed;
        roll.min(slide) + (slide - roll).max(0.0) * sin_slip
    }

    /// The least road margin (beyond `road_margin`) of the target's footprint while it rolls
    /// on without force from the end of the look-ahead for `check_horizon` seconds.
    fn slide_margin(&mut self, road: &Road) -> f64 {
        let s = &self.settings;
        let steps = (s.check_horizon / s.dt).round() as usize;
        let mut x = self.xs[self.n];
        let mut least = f64::INFINITY;
        for _ in 0..steps {
            let c = self.contact(self.n, Vec2::zeros(), x[idx::PSI]);
            x = self.model.step(&x, &self.input_u, &c);
            if !x.iter().all(|v| v.is_finite()) {
                return f64::NEG_INFINITY;
            }
            let cg = Vec2::new(x[idx::X], x[idx::Y]);
            least = least.min(edge_row(road, &self.footprint(&x), cg, s.road_margin).rhs);
            if x[idx::VX].hypot(x[idx::VY]) < 0.5 * self.len_scale.sqrt() {
                break;
            }
        }
        least
    }

    /// Linearise the soft rows at the current rollout.
    fn linearise_rows(&mut self, road: &Road, obstacles: &[Obstacle]) {
        let s = &self.settings;
        for k in 1..=self.n {
            let x = self.xs[k];
            let fp = self.footprint(&x);
            let cg = Vec2::new(x[idx::X], x[idx::Y]);
            let r = edge_row(road, &fp, cg, s.road_margin);
            self.road_rows[k] = (r.grad, r.rhs);
            let t = self.time + k as f64 * s.dt;
            let mut row = ([0.0; 3], FAR);
            for o in obstacles {
                let ofp = o.footprint_at(t);
                let g = pair_geometry(&ofp, &fp);
                let rhs = g.gap - s.obstacle_clearance;
                if rhs < row.1 {
                    let (_, gb) = gap_gradient(&ofp, &fp, ofp.center, cg, &g);
                    row = ([-gb[0], -gb[1], -gb[2]], rhs);
                }
            }
            self.obs_rows[k] = row;
        }
        // The stopping point: its road row, chained through the stop pose's Jacobian
        // (central differences of a closed-form map).
        let xn = self.xs[self.n];
        let sp = self.stop_pose(road, &xn);
        let fp = Obb::vehicle_footprint(
            &Pose2::new(sp[0], sp[1], sp[2]),
            self.params.target.length,
            self.params.target.width,
            self.params.target.cg_to_front,
        );
        let r = edge_row(road, &fp, Vec2::new(sp[0], sp[1]), s.road_margin);
        let mut coeff = [0.0; 8];
        for (i, c) in coeff.iter_mut().enumerate() {
            let h = 1e-6 * (1.0 + xn[i].abs());
            let mut xp = xn;
            xp[i] += h;
            let mut xm = xn;
            xm[i] -= h;
            let (p, m) = (self.stop_pose(road, &xp), self.stop_pose(road, &xm));
            *c = (0..3).map(|d| r.grad[d] * (p[d] - m[d]) / (2.0 * h)).sum();
        }
        self.stop_row = (coeff, r.rhs);
    }

    /// The nonlinear objective and violations of the current rollout with `forces`
    /// (or `trial`).
    fn merit(&self, use_trial: bool) -> (f64, f64, f64, f64, f64) {
        let s = &self.settings;
        let w = &s.weights;
        let f = if use_trial { &self.trial } else { &self.forces };
        let xn = &self.xs[self.n];
        let h = xn[idx::PSI] + s.yaw_decay * xn[idx::R] - self.psi_rev;
        let v2 = xn[idx::VX].powi(2) + xn[idx::VY].powi(2);
        let hi = s.corridor_fraction * self.force_max;
        let mut j = w.lambda_t * (w.heading * h * h + w.speed * v2);
        let mut prev = Vec2::zeros();
        for fj in f.iter() {
            let e = ((fj.x - hi) / self.scale).max(0.0);
            j += w.lambda_t * w.corridor * e * e + w.effort * (fj.x / self.scale).powi(2);
            j += w.smooth * ((fj - prev) / self.scale).norm_squared();
            prev = *fj;
        }
        j += w.smooth * (prev / self.scale).norm_squared();
        // The rows' right-hand sides are the exact margins at the rollout they were
        // linearised at (call after `linearise_rows`): road margin beyond `road_margin`,
        // obstacle gap beyond d_safe, the stopping point's road margin.
        let mut road_margin = f64::INFINITY;
        let mut clearance = f64::INFINITY;
        let mut pen = 0.0;
        for k in 1..=self.n {
            road_margin = road_margin.min(self.road_rows[k].1);
            clearance = clearance.min(self.obs_rows[k].1 + s.obstacle_clearance);
            pen += (-self.road_rows[k].1).max(0.0) + (-self.obs_rows[k].1).max(0.0);
        }
        let stop_margin = self.stop_row.1;
        pen += (-stop_margin).max(0.0);
        let objective = j + w.penalty * pen;
        (
            objective,
            wrap(h).abs(),
            road_margin,
            clearance,
            stop_margin,
        )
    }

    /// Optimise the forces of one candidate; `None` if the rollout or the QP fails.
    fn evaluate(
        &mut self,
        side: Side,
        k0: usize,
        lane: f64,
        input: &PlannerInput<'_>,
    ) -> Option<Outcome> {
        self.setup_candidate(side, k0, lane);
        self.initial_guess(input);
        self.rollout(Some(input.road), &input.target, false, true);
        self.linearise_rows(input.road, input.obstacles);
        let mut current = self.merit(false);
        if !current.0.is_finite() {
            return None;
        }
        let mut trust = self.settings.trust_force_g * self.weight;
        for _ in 0..self.settings.scp_iterations {
            self.fill_qp(trust);
            let st = self.qp.solve();
            if !st.usable() {
                if st == QpStatus::MaxTime || st == QpStatus::MaxIterations {
                    break;
                }
                return None;
            }
            let l = Layout::new(&self.settings);
            for j in 0..self.w {
                let y = self.qp.x();
                let d = Vec2::new(y[l.force(j)], y[l.force(j) + 1]) * self.scale;
                let f = self.forces[j] + d;
                // Project onto the hard corridor (the QP holds it to its tolerance).
                let fx = f.x.clamp(0.0, self.force_max);
                let mu_c = self.settings.friction;
                let ft = self.friction_sign() * f.y;
                self.trial[j] = Vec2::new(fx, self.friction_sign() * ft.clamp(0.0, mu_c * fx));
            }
            // Evaluate the candidate step on the nonlinear rollout.
            self.rollout(Some(input.road), &input.target, true, true);
            self.linearise_rows(input.road, input.obstacles);
            let cand = self.merit(true);
            if cand.0.is_finite() && cand.0 <= current.0 {
                self.forces.copy_from_slice(&self.trial);
                current = cand;
            } else {
                // Rejected: back to the accepted forces, a smaller trust region.
                trust *= 0.3;
                self.rollout(Some(input.road), &input.target, false, true);
                self.linearise_rows(input.road, input.obstacles);
            }
        }
        let delay = self.settings.weights.delay * k0 as f64 * self.settings.dt;
        Some(Outcome {
            side,
            k0,
            contact_x: self.contact_x,
            objective: current.0 + delay,
            heading_error: projected_heading_error(
                &self.xs[self.n],
                self.settings.yaw_decay,
                self.psi_rev,
            ),
            road_margin: current.2,
            clearance: current.3,
            stop_margin: current.4,
            slide_margin: self.slide_margin(input.road),
        })
    }

    /// The SCP's starting point: the best of a small grid of constant pushes (level ×
    /// duration from the window's start) by the nonlinear merit, rolled out without
    /// Jacobians. The yaw response to a push is strongly nonlinear (the tyres saturate), so
    /// one fixed guess can start the SCP far beyond the reversed heading.
    fn initial_guess(&mut self, input: &PlannerInput<'_>) {
        const LEVELS: [f64; 6] = [0.0, 0.15, 0.3, 0.5, 0.75, 1.0];
        const DURATIONS: [f64; 3] = [0.34, 0.67, 1.0];
        let top = self.settings.force_guess_g * self.weight * 2.0;
        let mut best = (f64::INFINITY, 0.0, 0usize);
        for &d in &DURATIONS {
            let m = ((d * self.w as f64).round() as usize).clamp(1, self.w);
            for &lv in &LEVELS[1..] {
                let f = (lv * top).min(self.force_max);
                for (j, t) in self.trial.iter_mut().enumerate() {
                    *t = if j < m {
                        Vec2::new(f, 0.0)
                    } else {
                        Vec2::zeros()
                    };
                }
                self.rollout(Some(input.road), &input.target, true, false);
                self.linearise_rows(input.road, input.obstacles);
                let merit = self.merit(true).0;
                if merit < best.0 {
                    best = (merit, f, m);
                }
            }
        }
        let (_, f, m) = best;
        for (j, t) in self.forces.iter_mut().enumerate() {
            *t = if j < m {
                Vec2::new(f, 0.0)
            } else {
                Vec2::zeros()
            };
        }
    }

    /// Write the QP's data at the current linearisation (values mode).
    fn fill_qp(&mut self, trust: f64) {
        let view = RowsView {
            l: Layout::new(&self.settings),
            s: &self.settings,
            scale: self.scale,
            force_max: self.force_max,
            trust,
            friction_sign: self.friction_sign(),
            forces: &self.forces,
            xn: &self.xs[self.n],
            psi_rev: self.psi_rev,
            sens: &self.sens,
            road_rows: &self.road_rows,
            obs_rows: &self.obs_rows,
            stop_row: &self.stop_row,
        };
        let qp = &mut self.qp;
        let mut ep = Emitter::values(&qp.p_slots, &mut qp.p_val, true);
        let mut ea = Emitter::values(&qp.a_slots, &mut qp.a_val, false);
        assemble(&view, &mut ep, &mut ea, &mut qp.q, &mut qp.b);
        ep.finish();
        ea.finish();
    }

    fn fill_package(
        &mut self,
        mode: Mode,
        infeasible: Option<Infeasible>,
        chosen: Option<Outcome>,
        lane: f64,
        input: &PlannerInput<'_>,
    ) {
        if let Some(o) = chosen {
            self.contact_x = o.contact_x;
            self.setup_candidate(o.side, o.k0, lane);
        }
        self.rollout(Some(input.road), &input.target, false, false);
        self.linearise_rows(input.road, input.obstacles);
        let merit = self.merit(false);
        let s = &self.settings;
        let c = self.contact_pose(self.side);
        let p = &mut self.package;
        p.mode = mode;
        p.infeasible = infeasible;
        p.race_lost = false;
        p.hold_back = false;
        p.time = input.time;
        p.side = self.side;
        p.contact_point = self.contact_point;
        p.contact_rel_pos = c.rel_pos;
        p.contact_rel_heading = c.rel_heading;
        p.push_speed = s.push_speed;
        p.envelope_lat = c.envelope_lat;
        p.approach = Profile::with_brake_margin(
            crate::href::relative_position(&input.target, &input.bullet).x,
            crate::href::relative_velocity(&input.target, &input.bullet).x,
            c.rel_pos.x,
            s.approach_accel(self.mu),
            s.approach_speed,
            BRAKE_MARGIN,
        );
        p.window = match chosen {
            Some(o) => (
                input.time + o.k0 as f64 * s.dt,
                input.time + (o.k0 + self.w) as f64 * s.dt,
            ),
            None => (f64::INFINITY, f64::NEG_INFINITY),
        };
        p.terminal = TerminalSet {
            heading: self.psi_rev,
            heading_tol: s.heading_tol,
            yaw_decay: s.yaw_decay,
        };
        p.road_margin = s.road_margin;
        p.obstacle_clearance = s.obstacle_clearance;
        p.obstacles.clear();
        p.obstacles.extend(input.obstacles.iter().cloned());
        p.steps.clear();
        let hi_comfort = s.corridor_fraction * self.force_max;
        for k in 0..=self.n {
            let in_window = chosen.is_some() && k >= self.k0 && k < self.k0 + self.w;
            let f = if in_window {
                self.forces[k - self.k0]
            } else {
                Vec2::zeros()
            };
            let corridor = if in_window {
                (
                    0.5 * f.x,
                    (1.5 * f.x)
                        .max(f.x + 0.1 * self.force_max)
                        .min(hi_comfort.max(f.x)),
                )
            } else {
                (0.0, 0.0)
            };
            p.steps.push(PlanStep {
                time: input.time + k as f64 * s.dt,
                force: f,
                corridor,
                target: self.xs[k],
            });
        }
        p.predicted_heading_error =
            projected_heading_error(&self.xs[self.n], s.yaw_decay, self.psi_rev);
        p.predicted_road_margin = merit.2;
        p.predicted_clearance = merit.3;
        p.predicted_stop_margin = merit.4;
        p.objective = chosen.map_or(merit.0, |o| o.objective);
    }
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

/// What the QP assembly reads.
struct RowsView<'a> {
    l: Layout,
    s: &'a PlannerSettings,
    scale: f64,
    force_max: f64,
    trust: f64,
    friction_sign: f64,
    forces: &'a [Vec2],
    xn: &'a TargetState,
    psi_rev: f64,
    sens: &'a [f64],
    road_rows: &'a [([f64; 3], f64)],
    obs_rows: &'a [([f64; 3], f64)],
    stop_row: &'a ([f64; 8], f64),
}

impl RowsView<'_> {
    fn sens(&self, k: usize, state: usize, c: usize) -> f64 {
        let cols = 2 * self.l.w;
        self.sens[k * 8 * cols + state * cols + c]
    }
}

/// Placeholder data of the right sizes for the pattern pass.
struct DummyRows {
    l: Layout,
    forces: Vec<Vec2>,
    xn: TargetState,
    sens: Vec<f64>,
    rows: Vec<([f64; 3], f64)>,
    stop: ([f64; 8], f64),
}

impl DummyRows {
    fn new(l: Layout) -> Self {
        Self {
            l,
            forces: vec![Vec2::zeros(); l.w],
            xn: TargetState::zeros(),
            sens: vec![0.0; (l.n + 1) * 8 * 2 * l.w],
            rows: vec![([0.0; 3], FAR); l.n + 1],
            stop: ([0.0; 8], FAR),
        }
    }

    fn view<'a>(&'a self, s: &'a PlannerSettings) -> RowsView<'a> {
        RowsView {
            l: self.l,
            s,
            scale: 1.0,
            force_max: 1.0,
            trust: 1.0,
            friction_sign: 1.0,
            forces: &self.forces,
            xn: &self.xn,
            psi_rev: 0.0,
            sens: &self.sens,
            road_rows: &self.rows,
            obs_rows: &self.rows,
            stop_row: &self.stop,
        }
    }
}

/// The QP in the scaled force steps y = δF / S: one code path writes the pattern (at
/// construction) and the values (every iteration), every entry unconditionally.
fn assemble(
    v: &RowsView<'_>,
    ep: &mut Emitter<'_>,
    ea: &mut Emitter<'_>,
    q: &mut [f64],
    b: &mut [f64],
) {
    let l = v.l;
    let s = v.s;
    let w = &s.weights;
    let cols = 2 * l.w;
    q.fill(0.0);
    b.fill(0.0);
    // --- Objective. Terminal rows: projected heading, vx, vy (each a row g over y, value h).
    let tau = s.yaw_decay;
    let h_psi = v.xn[idx::PSI] + tau * v.xn[idx::R] - v.psi_rev;
    let terms = [
        (w.lambda_t * w.heading, h_psi, 0usize),
        (w.lambda_t * w.speed, v.xn[idx::VX], 1),
        (w.lambda_t * w.speed, v.xn[idx::VY], 2),
    ];
    let n = l.n;
    let g = |which: usize, c: usize| -> f64 {
        match which {
            0 => v.sens(n, idx::PSI, c) + tau * v.sens(n, idx::R, c),
            1 => v.sens(n, idx::VX, c),
            _ => v.sens(n, idx::VY, c),
        }
    };
    // P over the force block: Σ 2 w g gᵀ (dense upper triangle), plus the diagonal terms.
    for c2 in 0..cols {
        for c1 in 0..=c2 {
            let mut val = 0.0;
            for &(wt, _, which) in &terms {
                val += 2.0 * wt * g(which, c1) * g(which, c2);
            }
            ep.put(c1, c2, val);
        }
    }
    for &(wt, h, which) in &terms {
        for (c, qc) in q.iter_mut().enumerate().take(cols) {
            *qc += 2.0 * wt * h * g(which, c);
        }
    }
    // Effort, proximal and smoothness on the forces (scaled units).
    for j in 0..l.w {
        let f = v.forces[j] / v.scale;
        let (cn, ct) = (l.force(j), l.force(j) + 1);
        ep.put(cn, cn, 2.0 * (w.effort + w.proximal));
        ep.put(ct, ct, 2.0 * w.proximal);
        q[cn] += 2.0 * w.effort * f.x;
        // Smoothness: (F_j − F_{j−1})² with F_{−1} = F_W = 0.
        for d in 0..2 {
            let c = l.force(j) + d;
            let fj = if d == 0 { f.x } else { f.y };
            let prev = if j > 0 {
                let p = v.forces[j - 1] / v.scale;
                if d == 0 {
                    p.x
                } else {
                    p.y
                }
            } else {
                0.0
            };
            let next = if j + 1 < l.w {
                let p = v.forces[j + 1] / v.scale;
                if d == 0 {
                    p.x
                } else {
                    p.y
                }
            } else {
                0.0
            };
            ep.put(c, c, 4.0 * w.smooth);
            q[c] += 2.0 * w.smooth * (2.0 * fj - prev - next);
            if j + 1 < l.w {
                ep.put(c, c + 2, -2.0 * w.smooth);
            }
        }
        // Corridor excess e_j ≥ F_n − F_hi, cost λ w_c e².
        ep.put(l.excess(j), l.excess(j), 2.0 * w.lambda_t * w.corridor);
    }
    // Slacks: linear penalty.
    for i in 0..l.soft() {
        q[l.s_road(i)] = w.penalty;
        q[l.s_obs(i)] = w.penalty;
    }
    q[l.s_stop()] = w.penalty;
    // --- Constraints A y ≤ b.
    let mut row = 0usize;
    let mu = s.friction;
    let trust = v.trust / v.scale;
    let fmax = v.force_max / v.scale;
    let hi = s.corridor_fraction * fmax;
    for j in 0..l.w {
        let f = v.forces[j] / v.scale;
        let (cn, ct) = (l.force(j), l.force(j) + 1);
        // 0 ≤ F_n ≤ F_max.
        ea.put(row, cn, -1.0);
        b[row] = f.x;
        row += 1;
        ea.put(row, cn, 1.0);
        b[row] = fmax - f.x;
        row += 1;
        // Friction: 0 ≤ σ F_t ≤ μ F_n, σ the sign of the bullet's sliding along the target's
        // side (its push speed): friction drags the target the way the bullet moves.
        let sg = v.friction_sign;
        ea.put(row, ct, sg);
        ea.put(row, cn, -mu);
        b[row] = mu * f.x - sg * f.y;
        row += 1;
        ea.put(row, ct, -sg);
        b[row] = sg * f.y;
        row += 1;
        // Trust region.
        for (c, sign) in [(cn, 1.0), (cn, -1.0), (ct, 1.0), (ct, -1.0)] {
            ea.put(row, c, sign);
            b[row] = trust;
            row += 1;
        }
        // Corridor excess: F_n − e ≤ F_hi, e ≥ 0.
        ea.put(row, cn, 1.0);
        ea.put(row, l.excess(j), -1.0);
        b[row] = hi - f.x;
        row += 1;
        ea.put(row, l.excess(j), -1.0);
        row += 1;
    }
    // Road and obstacle rows per step: grad · (∂pose_k/∂y) y − s_k ≤ rhs_k.
    let pose = [idx::X, idx::Y, idx::PSI];
    for (rows, slack) in [(v.road_rows, 0usize), (v.obs_rows, 1)] {
        for i in 0..l.soft() {
            let k = l.soft_step(i);
            let (grad, rhs) = rows[k];
            for c in 0..cols {
                let mut val = 0.0;
                for d in 0..3 {
                    val += grad[d] * v.sens(k, pose[d], c);
                }
                ea.put(row, c, val);
            }
            let sc = if slack == 0 { l.s_road(i) } else { l.s_obs(i) };
            ea.put(row, sc, -1.0);
            b[row] = rhs;
            row += 1;
        }
    }
    // The stopping point.
    let (coeff, rhs) = v.stop_row;
    for c in 0..cols {
        let mut val = 0.0;
        for (i, ci) in coeff.iter().enumerate() {
            val += ci * v.sens(n, i, c);
        }
        ea.put(row, c, val);
    }
    ea.put(row, l.s_stop(), -1.0);
    b[row] = *rhs;
    row += 1;
    // Slacks ≥ 0.
    for i in 0..l.soft() {
        ea.put(row, l.s_road(i), -1.0);
        row += 1;
        ea.put(row, l.s_obs(i), -1.0);
        row += 1;
    }
    ea.put(row, l.s_stop(), -1.0);
    row += 1;
    debug_assert_eq!(row, l.rows());
    let _ = cols;
}

#[cfg(test)]
mod tests {
    use super::*;
    use dynamics::target4dof::FourDofTarget;

    /// The free slide after the look-ahead (`check_horizon`): a target rolling along the
    /// road keeps its margin, one heading off at 0.3 rad crosses the edge within 4 s.
    #[test]
    fn free_slide_check_sees_the_edge() {
        let params = ParamSet::builtin("full_size").unwrap();
        let s = PlannerSettings {
            check_horizon: 4.0,
            ..PlannerSettings::default()
        };
        let model = Box::new(FourDofTarget::new(&params.target, 0.9, s.dt));
        let mut p = Planner::new(&params, 0.9, model, s).unwrap();
        let road = Road::straight(2000.0, 3, 3.5, 1.0);
        let margin = |p: &mut Planner, psi: f64| {
            let mut x0 = TargetState::zeros();
            x0[idx::VX] = 15.0;
            x0[idx::X] = 100.0;
            x0[idx::PSI] = psi;
            p.setup_candidate(Side::Left, p.n, 0.0);
            p.forces.iter_mut().for_each(|f| *f = Vec2::zeros());
            p.rollout(None, &x0, false, false);
            p.slide_margin(&road)
        };
        let along = margin(&mut p, 0.0);
        let off = margin(&mut p, 0.3);
        assert!(along > 1.0, "along the road: margin {along}");
        assert!(off < -1.0, "heading off the road: margin {off}");
        p.settings.check_horizon = 0.0;
        assert_eq!(margin(&mut p, 0.3), f64::INFINITY, "off: no check");
    }

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
