//! One controller for the whole maneuver: the upper decision layer (every `replan_period`
//! and on each phase change), the coupled MPC (every step) and the phase machine.

use crate::decision::{wrap, PlanError, Planner, PlannerError, PlannerInput};
use crate::href::fill_reference;
use crate::package::{DecisionPackage, Mode};
use crate::phase::{AbortReason, Phase, PhaseMachine, PhaseObservation};
use crate::settings::ControllerSettings;
use dynamics::bullet::{BulletInput, BulletState};
use dynamics::geometry::{Obb, Pose2, Vec2};
use dynamics::params::ParamSet;
use dynamics::road::{Obstacle, Road};
use dynamics::target::idx;
use dynamics::{TargetInput, TargetModel, TargetState};
use mpc::geom::pair_geometry;
use mpc::reference::DefaultPit;
use mpc::{Clock, CoupledMpc, MonotonicClock, MpcError, MpcInput, MpcStatus, Reference, Side};

/// What the controller sees each control step.
#[derive(Debug, Clone, Copy)]
pub struct ControllerInput<'a> {
    /// Time now (s), on the clock the obstacles' motion refers to.
    pub time: f64,
    pub target: TargetState,
    pub bullet: BulletState,
    /// The target driver's input as estimated (predicted constant).
    pub target_input: TargetInput,
    pub road: &'a Road,
    pub obstacles: &'a [Obstacle],
}

/// Whether the target is on an open road ([`crate::PhaseSettings::open_road_half_width`]
/// and the fields after it): the road at least that wide, straight and clear of obstacles
/// `open_road_clear` before and after the target, and the target no faster than
/// `open_road_speed`.
#[must_use]
pub fn open_road(s: &crate::PhaseSettings, input: &ControllerInput<'_>) -> bool {
    /// Sampling step along the road (m) and the largest curvature (1/m) of a straight.
    const STEP: f64 = 10.0;
    const STRAIGHT: f64 = 1e-4;
    let xt = &input.target;
    let at = Vec2::new(xt[idx::X], xt[idx::Y]);
    if input.road.half_width() < s.open_road_half_width
        || xt[idx::VX].hypot(xt[idx::VY]) > s.open_road_speed
    {
        return false;
    }
    let s0 = input.road.project(at).s;
    let samples = (s.open_road_clear / STEP).ceil() as i64;
    let straight = input
        .road
        .sharpest_curvature(s0, STEP, -samples..=samples)
        .abs()
        < STRAIGHT;
    straight
        && input
            .obstacles
            .iter()
            .all(|o| (o.position_at(input.time) - at).norm() > s.open_road_clear)
}

impl<'a> ControllerInput<'a> {
    /// The upper layer's view of this step: on `side` if committed, with the planner's best
    /// effort (in contact) or not.
    fn planner_input(&self, side: Option<Side>, best_effort: bool) -> PlannerInput<'a> {
        PlannerInput {
            time: self.time,
            target: self.target,
            bullet: self.bullet,
            target_input: self.target_input,
            road: self.road,
            obstacles: self.obstacles,
            side,
            best_effort,
        }
    }
}

/// What one control step decided.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ControllerOutput {
    /// The command to apply now: `[δ_f, T_r]` (negative T_r brakes). Always finite.
    pub command: BulletInput,
    pub phase: Phase,
    /// The upper layer's current mode (None when it is off).
    pub mode: Option<Mode>,
    pub abort: Option<AbortReason>,
    /// The MPC's status, when it ran this step.
    pub mpc_status: Option<MpcStatus>,
    /// Whether the upper layer planned this step, and how long it took (s).
    pub replanned: bool,
    pub plan_time: f64,
    /// Time of the whole control step, planning excluded (s).
    pub ctrl_time: f64,
}

/// Construction errors.
#[derive(Debug, thiserror::Error)]
pub enum ControllerError {
    #[error(transparent)]
    Settings(#[from] crate::settings::SettingsError),
    #[error(transparent)]
    Planner(#[from] PlannerError),
    #[error(transparent)]
    Mpc(#[from] MpcError),
}

/// Bad input to a control step.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum StepError {
    #[error(transparent)]
    Plan(#[from] PlanError),
    #[error("controller input: {0}")]
    Mpc(#[from] mpc::SolveError),
}

/// The hierarchical PIT controller.
///
/// Memory: the planner and the MPC (see theirs), one [`Reference`] of N stages; nothing is
/// allocated by [`PitController::step`].
pub struct PitController {
    settings: ControllerSettings,
    params: ParamSet,
    mu: f64,
    planner: Planner,
    mpc: CoupledMpc,
    default_pit: DefaultPit,
    reference: Reference,
    phases: PhaseMachine,
    last_command: BulletInput,
    next_replan: f64,
    started: bool,
    /// The target's heading when the PIT phase began (the frame of the push).
    pit_frame: Option<f64>,
    /// Whether the push under way began on an open road (the release it waits for).
    open_road: bool,
    /// Consecutive infeasible decisions while chasing.
    infeasible_count: u32,
    clock: Box<dyn Clock + Send + Sync>,
}

impl std::fmt::Debug for PitController {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("PitController")
            .field("upper_layer", &self.settings.upper_layer)
            .field("planner", &self.planner)
            .field("mpc", &self.mpc)
            .field("phase", &self.phases.phase())
            .finish_non_exhaustive()
    }
}

impl PitController {
    /// Build the controller. The planner and the MPC each get their own instance of the
    /// target model (the same kind: 4-DOF, PINN or PicoPINN).
    ///
    /// # Errors
    /// Invalid settings (named), a model whose step differs, or a QP Clarabel refuses.
    pub fn new(
        params: &ParamSet,
        mu: f64,
        mpc_model: Box<dyn TargetModel + Send + Sync>,
        planner_model: Box<dyn TargetModel + Send + Sync>,
        settings: ControllerSettings,
    ) -> Result<Self, ControllerError> {
        settings.validate()?;
        let planner = Planner::new(params, mu, planner_model, settings.planner.clone())?;
        let mpc = CoupledMpc::new(params, mu, mpc_model, settings.mpc.clone())?;
        Ok(Self {
            reference: Reference::new(settings.mpc.horizon),
            phases: PhaseMachine::new(settings.phases.clone())
                .pushing_round(settings.planner.push_round),
            default_pit: DefaultPit::new(params, Side::Left),
            params: params.clone(),
            mu,
            planner,
            mpc,
            last_command: BulletInput::zeros(),
            next_replan: f64::NEG_INFINITY,
            started: false,
            pit_frame: None,
            open_road: false,
            infeasible_count: 0,
            clock: Box::new(MonotonicClock::new()),
            settings,
        })
    }

    /// Read planning and control times from `clock` (the MPC's time budget too).
    #[must_use]
    pub fn with_clock(
        mut self,
        clock_planner: Box<dyn Clock + Send + Sync>,
        clock_mpc: Box<dyn Clock + Send + Sync>,
    ) -> Self {
        self.clock = clock_planner;
        self.mpc = self.mpc.with_clock(clock_mpc);
        self
    }

    #[must_use]
    pub fn settings(&self) -> &ControllerSettings {
        &self.settings
    }

    #[must_use]
    pub fn phase(&self) -> Phase {
        self.phases.phase()
    }

    #[must_use]
    pub fn abort_reason(&self) -> Option<AbortReason> {
        self.phases.abort_reason()
    }

    /// The last decision package of this maneuver (upper layer on, once it has planned).
    #[must_use]
    pub fn package(&self) -> Option<&DecisionPackage> {
        (self.settings.upper_layer && self.next_replan.is_finite()).then(|| self.planner.package())
    }

    #[must_use]
    pub fn mpc(&self) -> &CoupledMpc {
        &self.mpc
    }

    #[must_use]
    pub fn reference(&self) -> &Reference {
        &self.reference
    }

    #[must_use]
    pub fn target_model_name(&self) -> &str {
        self.mpc.target_model_name()
    }

    #[must_use]
    pub fn target_param_count(&self) -> usize {
        self.mpc.target_param_count()
    }

    /// Start a new maneuver (phase chasing, no plan, MPC warm start dropped); the phase
    /// clock starts at the next step.
    pub fn reset(&mut self) {
        self.phases.reset(0.0);
        self.started = false;
        self.pit_frame = None;
        self.next_replan = f64::NEG_INFINITY;
        self.last_command = BulletInput::zeros();
        self.mpc.reset();
        self.planner.reset();
    }

    fn footprints(&self, xt: &TargetState, xb: &BulletState) -> (Obb, Obb) {
        let t = &self.params.target;
        let b = &self.params.bullet;
        (
            Obb::vehicle_footprint(
                &Pose2::new(xb[0], xb[1], xb[2]),
                b.length,
                b.width,
                b.cg_to_front,
            ),
            Obb::vehicle_footprint(
                &Pose2::new(xt[idx::X], xt[idx::Y], xt[idx::PSI]),
                t.length,
                t.width,
                t.cg_to_front,
            ),
        )
    }

    /// One control step.
    ///
    /// # Errors
    /// [`StepError`] for bad input (a non-finite state, too many obstacles); never for a
    /// numerical outcome, which is a status with a safe command.
    pub fn step(&mut self, input: &ControllerInput<'_>) -> Result<ControllerOutput, StepError> {
        let t0 = self.clock.now();
        if input.target.iter().any(|v| !v.is_finite())
            || input.bullet.iter().any(|v| !v.is_finite())
        {
            return Err(StepError::Plan(PlanError::NonFiniteState));
        }
        if !self.started {
            self.started = true;
            self.pit_frame = None;
            self.infeasible_count = 0;
            self.phases.reset(input.time);
            let rel = crate::href::relative_position(&input.target, &input.bullet);
            let side = if rel.y >= 0.0 {
                Side::Left
            } else {
                Side::Right
            };
            self.default_pit = DefaultPit::new(&self.params, side);
        }
        let (fb, ft) = self.footprints(&input.target, &input.bullet);
        let gap = pair_geometry(&fb, &ft).gap;
        let xb = &input.bullet;
        let bullet_speed = xb[3].hypot(xb[4]);
        let mut clearance = f64::INFINITY;
        for o in input.obstacles {
            clearance = clearance.min(pair_geometry(&o.footprint_at(input.time), &fb).gap);
        }
        let upper = self.settings.upper_layer;
        let pkg = self.planner.package();
        let obs = PhaseObservation {
            time: input.time,
            gap,
            mode: upper
                .then_some(pkg.mode)
                .filter(|_| self.next_replan.is_finite()),
            infeasible: pkg.infeasible,
            window: (upper && pkg.has_window()).then_some(pkg.window),
            target_speed: input.target[idx::VX].hypot(input.target[idx::VY]),
            target_yaw_rate: input.target[idx::R],
            target_turn: self
                .pit_frame
                .map_or(0.0, |f| wrap(input.target[idx::PSI] - f)),
            bullet_speed,
            bullet_yaw_rate: xb[5],
            bullet_slip: if xb[3].abs() > 0.5 {
                xb[4].atan2(xb[3].abs())
            } else {
                0.0
            },
            bullet_clearance: clearance,
        };
        let mut changed = self.phases.update(&obs);
        if changed {
            // A push begins in the target's frame of the moment; a push tried again (back
            // to chasing) begins in a new one.
            match self.phases.phase() {
                Phase::Pit => {
                    self.pit_frame = Some(input.target[idx::PSI]);
                    self.open_road = open_road(&self.settings.phases, input);
                }
                Phase::Chasing => self.pit_frame = None,
                _ => {}
            }
        }
        // The push has turned the target far enough: let go before the spinning body swings
        // back into the bullet (the next touch would be a rebound).
        let turned = self
            .pit_frame
            .map(|f| wrap(input.target[idx::PSI] - f).abs());
        if self.phases.phase() == Phase::Pit
            && turned.is_some_and(|a| a > self.settings.phases.pit_yaw_done)
        {
            self.phases.stabilise(input.time);
            changed = true;
        }
        let phase = self.phases.phase();
        // The upper layer: replan on its period and on every phase change.
        let mut replanned = false;
        let mut plan_time = 0.0;
        // A window that opened while the bullet is still chasing is stale (the bullet is late):
        // replan now rather than follow a plan whose push is under way without contact.
        let stale = phase == Phase::Chasing && {
            let p = self.planner.package();
            p.mode == Mode::Pit && input.time > p.window.0 + self.settings.mpc.dt
        };
        if upper && phase.is_active() && (changed || stale || input.time + 1e-9 >= self.next_replan)
        {
            let tp = self.clock.now();
            // During the PIT the side is committed: only its window and forces are replanned.
            let committed = (phase == Phase::Pit && self.planner.package().mode == Mode::Pit)
                .then(|| self.planner.package().side);
            let pkg = self
                .planner
                .plan(&input.planner_input(committed, phase == Phase::Pit))?;
            if phase == Phase::Chasing && pkg.mode == Mode::Abort {
                self.infeasible_count += 1;
                // A lost race is not a plan that may come right later: give up at once.
                if pkg.race_lost
                    || self.infeasible_count >= self.settings.phases.infeasible_patience
                {
                    let reason = pkg.infeasible.unwrap_or(crate::Infeasible::Numerical);
                    self.phases
                        .abort(AbortReason::DecisionInfeasible(reason), input.time);
                }
            } else if pkg.mode != Mode::Chase {
                // A plan that finds a push (or needs none) ends the count. A chase plan, whose
                // windows do not fit the look-ahead yet, says nothing either way: a bullet
                // swaying about its station alternates it with infeasible plans and would
                // otherwise chase until the time runs out.
                self.infeasible_count = 0;
            }
            if pkg.mode == Mode::Stabilise {
                self.phases.stabilise(input.time);
            }
            // Once the push has turned the target, a replan that finds no push meeting the
            // terminal set ends it: the planner's best effort would keep pressing on a
            // spinning target (`PhaseSettings::let_go_turn`).
            if phase == Phase::Pit
                && !self.settings.planner.push_round
                && pkg.mode == Mode::Pit
                && pkg.infeasible.is_some()
                && self.phases.contacted()
                && turned.is_some_and(|a| a > self.settings.phases.let_go_turn)
            {
                self.phases.stabilise(input.time);
            }
            let period = if phase == Phase::Pit {
                self.settings.planner.replan_period_pit
            } else {
                self.settings.planner.replan_period
            };
            self.next_replan = input.time + period;
            replanned = true;
            plan_time = self.clock.now() - tp;
        }
        // The closed loop of the push: between replans, let go as soon as the target left
        // alone would reverse inside the road (a push that turns the target round goes on to
        // `pit_yaw_done`).
        if upper
            && !replanned
            && !self.settings.planner.push_round
            && self.phases.phase() == Phase::Pit
            && self.phases.contacted()
            && self.planner.package().mode == Mode::Pit
        {
            let pin = input.planner_input(Some(self.planner.package().side), true);
            if self
                .planner
                .push_done(&pin, &self.settings.phases.release(self.open_road))?
            {
                self.phases.stabilise(input.time);
            }
        }
        let phase = self.phases.phase();
        let mut mpc_status = None;
        let command = if phase.is_active() {
            let dt = self.settings.mpc.dt;
            if upper {
                fill_reference(
                    self.planner.package(),
                    &self.settings.planner,
                    &mut self.reference,
                    &input.target,
                    &input.bullet,
                    crate::href::Timing {
                        time: input.time,
                        dt,
                        pit_frame: self.pit_frame,
                        length_scale: crate::settings::length_scale(&self.params),
                        back_off: self.phases.awaiting_apart(),
                    },
                );
            } else {
                let lane = input
                    .road
                    .project(Vec2::new(input.target[idx::X], input.target[idx::Y]))
                    .heading;
                self.default_pit.fill(
                    &mut self.reference,
                    input.target.as_slice(),
                    input.bullet.as_slice(),
                    dt,
                    lane,
                );
            }
            self.mpc.set_pushing(phase == Phase::Pit);
            let out = self.mpc.solve(&MpcInput {
                time: input.time,
                target: input.target,
                bullet: input.bullet,
                target_input: input.target_input,
                last_command: self.last_command,
                road: Some(input.road),
                obstacles: input.obstacles,
                reference: &self.reference,
            })?;
            mpc_status = Some(out.status);
            out.command
        } else {
            self.safe_stop(input)
        };
        self.last_command = command;
        let total = self.clock.now() - t0;
        Ok(ControllerOutput {
            command,
            phase,
            mode: upper.then(|| self.planner.package().mode),
            abort: self.phases.abort_reason(),
            mpc_status,
            replanned,
            plan_time,
            ctrl_time: (total - plan_time).max(0.0),
        })
    }

    /// Controlled braking along the road at `abort_brake` of the road's adhesion (a spun,
    /// sliding target decelerates at up to μ g: a gentler stop runs the bullet into it).
    fn safe_stop(&self, input: &ControllerInput<'_>) -> BulletInput {
        dynamics::bullet::brake_along_road(
            input.road,
            &input.bullet,
            &self.params.bullet,
            self.mu,
            self.settings.phases.abort_brake,
        )
    }
}
