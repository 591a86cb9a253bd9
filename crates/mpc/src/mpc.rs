//! The coupled collision MPC (see the crate docs and `docs/mpc.md`).

use crate::clock::{Clock, MonotonicClock};
use crate::geom::{edge_row, gap_gradient, pair_geometry, EdgeRow};
use crate::plan::{rollout, Plan, RolloutCtx, Shapes};
use crate::qp::{clarabel_settings, Emitter, Pattern, Qp, QpStatus};
use crate::reference::Reference;
use crate::settings::{MpcSettings, QpSettings, ScpMode, SettingsError};
use dynamics::bullet::{BulletInput, BulletModel, BulletState};
use dynamics::contact::obb_signed_distance;
use dynamics::geometry::{Pose2, Vec2};
use dynamics::params::ParamSet;
use dynamics::road::{Obstacle, Road};
use dynamics::{wrap_angle, TargetInput, TargetModel, TargetState};
use thiserror::Error;

const NT: usize = 8;
const NB: usize = 6;
/// The target's states in QP order: QP position `i` holds model state `TQ[i]`
/// (`[vx, vy, ψ, r, X, Y]`, then the roll states `[p, φ]`, which the planar layout leaves
/// out of the QP).
const TQ: [usize; NT] = [0, 1, 2, 3, 6, 7, 4, 5];
/// Target pose columns (X, Y, ψ) within the QP's δx_T, bullet pose columns within x_B.
const T_POSE: [usize; 3] = [4, 5, 2];
const B_POSE: [usize; 3] = [0, 1, 2];
/// Tracked state entries: X_T, Y_T, ψ_T, vx_T (QP positions within δx_T), X_B, Y_B, ψ_B,
/// vx_B (within x_B).
const TRACKED_T: [usize; 4] = [4, 5, 2, 0];
const TRACKED_B: [usize; 4] = [0, 1, 2, 3];

/// Where the variables and rows of one stage sit in a QP.
///
/// Two QPs are built. The *coupled* one carries both vehicles and the contact force:
/// columns `[ũ (2), f̃ (2), s (1), δx_T (8), δx_B (6)]`, 14 dynamics rows and 19 inequality
/// rows per stage. The target is driven by nothing but f_c, so when no force is admissible
/// anywhere over the horizon (every stage of the linearisation farther apart than
/// `gap_release`, or a reference that plans no force at all) its prediction is exact and
/// fixed: the *bullet-only* QP then drops the
/// target's states and the forces, `[ũ (2), s (1), δx_B (6)]`, 6 dynamics rows and 12
/// inequality rows per stage, about a third of the work.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Layout {
    coupled: bool,
    /// Target states carried by the QP (the first `nt` of [`TQ`]; 0 in the bullet-only QP).
    nt: usize,
    stage: usize,
    o_u: usize,
    o_f: usize,
    o_s: usize,
    o_xt: usize,
    o_xb: usize,
    dyn_rows: usize,
    rows: usize,
}

const COUPLED: Layout = Layout {
    coupled: true,
    nt: NT,
    stage: 19,
    o_u: 0,
    o_f: 2,
    o_s: 4,
    o_xt: 5,
    o_xb: 13,
    dyn_rows: NT + NB,
    rows: 19,
};

/// The coupled QP without the target's roll states (`QpSettings::target_roll = false`):
/// 17 columns and 12 dynamics rows per stage.
const COUPLED_PLANAR: Layout = Layout {
    coupled: true,
    nt: NT - 2,
    stage: 17,
    o_u: 0,
    o_f: 2,
    o_s: 4,
    o_xt: 5,
    o_xb: 11,
    dyn_rows: NT - 2 + NB,
    rows: 19,
};

const BULLET_ONLY: Layout = Layout {
    coupled: false,
    nt: 0,
    stage: 9,
    o_u: 0,
    o_f: usize::MAX,
    o_s: 2,
    o_xt: usize::MAX,
    o_xb: 3,
    dyn_rows: NB,
    rows: 12,
};

impl Layout {
    fn columns(&self, n: usize) -> usize {
        self.stage * n
    }
    fn row_count(&self, n: usize) -> usize {
        (self.dyn_rows + self.rows) * n
    }
    fn col(&self, k: usize, off: usize) -> usize {
        k * self.stage + off
    }
}
/// A right-hand side that makes a row inactive.
const FAR: f64 = 1.0e4;

/// Bad construction input or settings.
#[derive(Debug, Error)]
pub enum MpcError {
    #[error(transparent)]
    Settings(#[from] SettingsError),
    #[error("mpc: the target model steps {model} s but the MPC step is {mpc} s")]
    StepMismatch { model: f64, mpc: f64 },
    #[error("mpc: road adhesion mu must be in (0, 1.5] (got {0})")]
    Mu(f64),
    #[error("mpc: the QP solver could not be set up: {0}")]
    Solver(String),
}

/// Bad input to one control step (small and `Copy`: the hot path's error).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Error)]
pub enum SolveError {
    #[error("mpc input: the target state is not finite")]
    TargetState,
    #[error("mpc input: the bullet state is not finite")]
    BulletState,
    #[error("mpc input: the target input is not finite")]
    TargetInput,
    #[error("mpc input: the last command is not finite")]
    LastCommand,
    #[error("mpc input: the reference has the wrong length or a non-finite value")]
    Reference,
}

/// How a control step ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MpcStatus {
    /// Converged mode: the step fell below the tolerance (or the merit stopped decreasing).
    Converged,
    /// RTI mode: the one QP of this step was solved and its step taken.
    RtiStep,
    /// Converged mode: the SCP iteration cap was reached with an accepted plan.
    IterationCap,
    /// The time budget ran out; the best accepted plan is used.
    TimeBudget,
    /// No usable QP solution: the command is the safe fallback.
    QpFailure,
}

/// Which safe command was issued when no new plan is usable.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Fallback {
    /// The previous plan shifted by one step.
    ShiftedPlan,
    /// Controlled braking: steer held straight to the target's side of the lane, torque at
    /// half the braking limit.
    Brake,
}

/// Wall-clock times of one control step (s).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct StepTimes {
    /// Rollouts with Jacobians and geometry.
    pub linearise: f64,
    /// Filling P, q, A, b.
    pub assemble: f64,
    /// Clarabel (all QPs of the step).
    pub qp: f64,
    pub total: f64,
}

/// The result of one control step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MpcOutput {
    pub status: MpcStatus,
    /// The command to apply now: `[δ_f, T_r]`. Always finite.
    pub command: BulletInput,
    pub fallback: Option<Fallback>,
    pub scp_iterations: u32,
    pub qp_iterations: u32,
    /// Merit (cost + exact penalty) of the plan the command comes from.
    pub merit: f64,
    /// Largest soft-constraint violation along that plan (m).
    pub max_violation: f64,
    pub times: StepTimes,
}

/// The input of one control step.
#[derive(Debug, Clone, Copy)]
pub struct MpcInput<'a> {
    /// Time now (s), on the clock the obstacles' motion refers to.
    pub time: f64,
    pub target: TargetState,
    pub bullet: BulletState,
    /// The target driver's input, predicted constant over the horizon.
    pub target_input: TargetInput,
    /// The command applied over the last period (the start of the rate limits).
    pub last_command: BulletInput,
    pub road: Option<&'a Road>,
    pub obstacles: &'a [Obstacle],
    pub reference: &'a Reference,
}

/// Per-stage linearisation of the soft constraints at a plan.
#[derive(Debug, Clone, Copy, Default)]
struct SoftRows {
    /// Gap gradients on bullet / target poses and the gap at x_{k+1}.
    gap_b: [f64; 3],
    gap_t: [f64; 3],
    gap: f64,
    /// The normal-force bound of f_k (N): `force_max` near contact, 0 apart.
    fn_max: f64,
    /// Whether the compliance band's upper side (row 18) is active at this stage.
    band: bool,
    road_b: EdgeRowC,
    road_t: EdgeRowC,
    obs_b: EdgeRowC,
    obs_t: EdgeRowC,
    /// Bullet position in the target frame and its gradients.
    rel: Vec2Copy,
    /// The contact frame of step k at the linearisation: γ and the points of action in
    /// each body (held over the step).
    gamma: f64,
    point_target: Vec2Copy,
    point_bullet: Vec2Copy,
}

/// One stage's linearisation of the contact and the soft constraints, as the last QP used
/// it (for diagnostics and for peers that must solve the identical problem). Rows read
/// `grad · [δX, δY, δψ] − s ≤ rhs`; the gap is at x_{k+1}.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StageLinearisation {
    pub gamma: f64,
    pub point_target: Vec2,
    pub point_bullet: Vec2,
    pub gap: f64,
    pub gap_grad_bullet: [f64; 3],
    pub gap_grad_target: [f64; 3],
    /// The normal-force bound of f_k (N).
    pub fn_max: f64,
    /// Whether the compliance band's upper side is active.
    pub band: bool,
    pub road_bullet: ([f64; 3], f64),
    pub road_target: ([f64; 3], f64),
    pub obstacle_bullet: ([f64; 3], f64),
    pub obstacle_target: ([f64; 3], f64),
}

#[derive(Debug, Clone, Copy)]
struct EdgeRowC {
    grad: [f64; 3],
    rhs: f64,
}

impl Default for EdgeRowC {
    fn default() -> Self {
        Self {
            grad: [0.0; 3],
            rhs: FAR,
        }
    }
}

impl From<EdgeRow> for EdgeRowC {
    fn from(r: EdgeRow) -> Self {
        Self {
            grad: r.grad,
            rhs: r.rhs,
        }
    }
}

#[derive(Debug, Clone, Copy, Default)]
struct Vec2Copy {
    x: f64,
    y: f64,
}

/// The largest drive torque (N m) the MPC may plan: the actuator's limit, or the torque that
/// uses `fraction` of the rear axle's static traction μ m g l_f / L, whichever is smaller. The
/// bullet model has no combined-slip limit, so without this bound it plans full drive torque
/// on a slippery road and the real rear axle breaks away (power oversteer).
fn traction_limited_torque(b: &dynamics::params::VehicleParams, mu: f64, fraction: f64) -> f64 {
    let rear_load = b.mass * 9.81 * b.lf / (b.lf + b.lr);
    let torque = fraction * mu * rear_load * b.wheel_radius / (b.drive_efficiency * b.gear_ratio);
    b.drive_torque_max.min(torque)
}

/// The coupled collision MPC: both vehicles' states, the bullet's inputs and the shared
/// contact force over the horizon, solved by SCP over Clarabel QPs.
///
/// Memory: four [`Plan`]s (each about `N·(2·8·8 + 2·6·8 + 60)` doubles), two QPs (coupled:
/// `19 N` columns, `33 N` rows; bullet-only: `9 N` columns, `18 N` rows) with their Clarabel
/// workspaces, all allocated in [`CoupledMpc::new`] (which also runs one warm-up solve of
/// each QP). [`CoupledMpc::solve`] allocates nothing, Clarabel included (`docs/mpc.md`).
pub struct CoupledMpc {
    settings: MpcSettings,
    n: usize,
    bullet: BulletModel,
    target: Box<dyn TargetModel + Send + Sync>,
    shapes: Shapes,
    lim: Limits,
    lin: Plan,
    cand: Plan,
    prev: Plan,
    /// The linearisation point of the last QP (states, inputs, forces), kept for
    /// diagnostics and peers after `lin` has moved on.
    lin_snapshot: Plan,
    have_prev: bool,
    /// Largest difference between the QP's predicted states and the nonlinear rollout of
    /// its inputs at the last QP (a diagnostic of the linearisation).
    model_error: f64,
    stage_error: Vec<(f64, usize)>,
    soft: Vec<SoftRows>,
    /// The coupled QP and the bullet-only QP (see [`Layout`]).
    qp_coupled: Qp,
    qp_bullet: Qp,
    /// Whether the last QP was the coupled one.
    coupled: bool,
    /// Whether the bullet pushes ([`Self::set_pushing`]): the gap up to which a force may
    /// be planned is `gap_release` then, `gap_engage` before.
    pushing: bool,
    clock: Box<dyn Clock + Send + Sync>,
}

impl std::fmt::Debug for CoupledMpc {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("CoupledMpc")
            .field("horizon", &self.n)
            .field("target_model", &self.target.name())
            .field("qp_coupled", &(self.qp_coupled.n, self.qp_coupled.m))
            .field("qp_bullet_only", &(self.qp_bullet.n, self.qp_bullet.m))
            .finish_non_exhaustive()
    }
}

/// Everything the assembly reads (borrowed apart from the QP buffers it writes).
struct AssemblyView<'a> {
    layout: Layout,
    s: &'a MpcSettings,
    lin: &'a Plan,
    soft: &'a [SoftRows],
    reference: &'a Reference,
    last_command: BulletInput,
    lim: Limits,
}

/// The bullet's input limits and the QP's variable scales.
#[derive(Debug, Clone, Copy)]
struct Limits {
    steer_max: f64,
    steer_rate: f64,
    torque_min: f64,
    torque_max: f64,
    /// The speed-dependent steer bound `(wheelbase / v² + understeer) · lateral_accel`
    /// (see [`Limits::steer_at`]).
    wheelbase: f64,
    understeer: f64,
    lateral_accel: f64,
    /// μ g (m/s²), for `CoupledMpc::set_pushing`.
    grip: f64,
    /// Variable scales: torque (N m) and force (N).
    t_scale: f64,
    f_scale: f64,
}

impl Limits {
    /// The largest steer (rad) the MPC may plan at forward speed `vx`: the steady-turn steer
    /// `(L / v² + K_us) · a` at the lateral acceleration `a = lateral_fraction · μ g`, never
    /// more than the actuator's `steer_max`. The bullet model has no combined slip, so it
    /// would plan steer far past the grip while braking or driving (a swerve at 20 m/s with
    /// 0.17 rad asks for three times μ g) and the real car breaks away and spins.
    fn steer_at(&self, vx: f64) -> f64 {
        let v = vx.abs().max(1.0);
        ((self.wheelbase / (v * v) + self.understeer) * self.lateral_accel).min(self.steer_max)
    }
}

impl CoupledMpc {
    /// Build the controller: the bullet model from `params.bullet` at road adhesion `mu`,
    /// the given target surrogate (its step must equal `settings.dt`), the QP pattern and
    /// the Clarabel solver.
    ///
    /// # Errors
    /// Invalid settings, a step mismatch, μ out of range, or a solver that cannot be built.
    pub fn new(
        params: &ParamSet,
        mu: f64,
        target: Box<dyn TargetModel + Send + Sync>,
        settings: MpcSettings,
    ) -> Result<Self, MpcError> {
        settings.validate()?;
        if !(mu.is_finite() && mu > 0.0 && mu <= 1.5) {
            return Err(MpcError::Mu(mu));
        }
        if (target.dt() - settings.dt).abs() > 1e-12 {
            return Err(MpcError::StepMismatch {
                model: target.dt(),
                mpc: settings.dt,
            });
        }
        let n = settings.horizon;
        let b = &params.bullet;
        let bullet = BulletModel::new(b, mu, settings.dt);
        let understeer = bullet.understeer_gradient().max(0.0);
        let t_scale = b.drive_torque_max.abs().max(b.drive_torque_min.abs());
        let f_scale = 0.25 * settings.contact.force_max;
        let mut me = Self {
            n,
            bullet,
            target,
            shapes: Shapes::new(&params.bullet, &params.target),
            lim: Limits {
                steer_max: b.steer_max,
                steer_rate: b.steer_rate_max,
                torque_min: b.drive_torque_min,
                torque_max: traction_limited_torque(b, mu, settings.traction_fraction),
                wheelbase: b.lf + b.lr,
                understeer,
                lateral_accel: settings.lateral_fraction * mu * 9.81,
                grip: mu * 9.81,
                t_scale,
                f_scale,
            },
            lin: Plan::new(n),
            cand: Plan::new(n),
            prev: Plan::new(n),
            lin_snapshot: Plan::new(n),
            have_prev: false,
            model_error: 0.0,
            stage_error: vec![(0.0, 0); n],
            soft: vec![SoftRows::default(); n],
            qp_coupled: Self::build_qp(&settings, n, Self::coupled_layout(&settings))?,
            qp_bullet: Self::build_qp(&settings, n, BULLET_ONLY)?,
            coupled: true,
            pushing: false,
            clock: Box::new(MonotonicClock::new()),
            settings,
        };
        me.warm_up();
        Ok(me)
    }

    /// Whether the bullet is pushing rather than chasing or falling back: selects the steer
    /// bound's share of the grip, `lateral_fraction_push` or `lateral_fraction`, and the gap
    /// up to which a force may be planned, `contact.gap_release` or `contact.gap_engage`.
    /// Cheap; call it every control step.
    pub fn set_pushing(&mut self, pushing: bool) {
        self.pushing = pushing;
        let f = if pushing {
            self.settings.lateral_fraction_push
        } else {
            self.settings.lateral_fraction
        };
        self.lim.lateral_accel = f * self.lim.grip;
    }

    /// Change the QP solver's settings between control steps (validated; allocates, so not
    /// from inside the real-time loop).
    ///
    /// # Errors
    /// [`MpcError::Settings`] naming a bad field, [`MpcError::Solver`] if Clarabel refuses.
    pub fn set_qp_settings(&mut self, qp: QpSettings) -> Result<(), MpcError> {
        let mut s = self.settings.clone();
        s.qp = qp;
        s.validate()?;
        let cs = clarabel_settings(&s.qp);
        for qp in [&mut self.qp_coupled, &mut self.qp_bullet] {
            qp.update_settings(cs.clone()).map_err(MpcError::Solver)?;
            qp.set_time_limit(s.qp.time_limit);
        }
        self.settings = s;
        Ok(())
    }

    /// Replace the clock the time budget and the step times are read from.
    #[must_use]
    pub fn with_clock(mut self, clock: Box<dyn Clock + Send + Sync>) -> Self {
        self.clock = clock;
        self
    }

    #[must_use]
    pub fn settings(&self) -> &MpcSettings {
        &self.settings
    }

    /// The target surrogate's name (`4dof`, `pinn`, `picopinn`).
    #[must_use]
    pub fn target_model_name(&self) -> &str {
        self.target.name()
    }

    /// The target surrogate's trainable parameter count.
    #[must_use]
    pub fn target_param_count(&self) -> usize {
        self.target.param_count()
    }

    /// QP sizes (columns, rows): the coupled QP and the bullet-only QP.
    #[must_use]
    pub fn qp_sizes(&self) -> ((usize, usize), (usize, usize)) {
        (
            (self.qp_coupled.n, self.qp_coupled.m),
            (self.qp_bullet.n, self.qp_bullet.m),
        )
    }

    /// Whether the last control step's QP carried the target and the contact force (false:
    /// no force was admissible over the horizon and the bullet-only QP was solved).
    #[must_use]
    pub fn last_qp_coupled(&self) -> bool {
        self.coupled
    }

    fn qp(&self) -> &Qp {
        if self.coupled {
            &self.qp_coupled
        } else {
            &self.qp_bullet
        }
    }

    fn coupled_layout(settings: &MpcSettings) -> Layout {
        if settings.qp.target_roll {
            COUPLED
        } else {
            COUPLED_PLANAR
        }
    }

    fn layout(&self) -> Layout {
        if self.coupled {
            Self::coupled_layout(&self.settings)
        } else {
            BULLET_ONLY
        }
    }

    /// The plan of the last control step (inputs, forces, both vehicles' predicted states).
    #[must_use]
    pub fn plan(&self) -> &Plan {
        &self.prev
    }

    /// Forget the previous plan (the next step starts from holding the last command).
    pub fn reset(&mut self) {
        self.have_prev = false;
    }

    fn build_qp(settings: &MpcSettings, n: usize, layout: Layout) -> Result<Qp, MpcError> {
        let dummy = Plan::new(n);
        let soft = vec![SoftRows::default(); n];
        let reference = Reference::new(n);
        let view = AssemblyView {
            layout,
            s: settings,
            lin: &dummy,
            soft: &soft,
            reference: &reference,
            last_command: BulletInput::zeros(),
            // Only the pattern is read at construction; the values are placeholders.
            lim: Limits {
                steer_max: 1.0,
                steer_rate: 1.0,
                torque_min: -1.0,
                torque_max: 1.0,
                wheelbase: 1.0,
                understeer: 0.0,
                lateral_accel: 1.0,
                grip: 1.0,
                t_scale: 1.0,
                f_scale: 1.0,
            },
        };
        let (ncol, m) = (layout.columns(n), layout.row_count(n));
        let mut q = vec![0.0; ncol];
        let mut b = vec![0.0; m];
        let mut pairs = Vec::new();
        view.cost(&mut Emitter::pattern(&mut pairs, true), &mut q);
        let p = Pattern::build(ncol, ncol, &pairs);
        view.constraints(&mut Emitter::pattern(&mut pairs, false), &mut b);
        let a = Pattern::build(m, ncol, &pairs);
        let cs = clarabel_settings(&settings.qp);
        Qp::new(p, a, layout.dyn_rows * n, cs, settings.qp.time_limit).map_err(MpcError::Solver)
    }

    /// Solve both QPs once (vehicles apart: bullet-only; overlapping: coupled) so that
    /// every lazily sized buffer, Clarabel's included, reaches its working size before the
    /// first real control step.
    fn warm_up(&mut self) {
        let reference = Reference::new(self.n);
        for gap_x in [-30.0, -4.0] {
            let mut xt = TargetState::zeros();
            xt[0] = 10.0;
            let mut xb = BulletState::zeros();
            xb[0] = gap_x;
            xb[1] = 1.5;
            xb[3] = 10.0;
            let input = MpcInput {
                time: 0.0,
                target: xt,
                bullet: xb,
                target_input: TargetInput::zeros(),
                last_command: BulletInput::zeros(),
                road: None,
                obstacles: &[],
                reference: &reference,
            };
            let _ = self.solve(&input);
            self.have_prev = false;
        }
    }

    /// One control step.
    ///
    /// # Errors
    /// [`SolveError`] for non-finite input or a reference of the wrong length; numerical
    /// trouble is a status ([`MpcStatus::QpFailure`] with a safe command), never an error.
    pub fn solve(&mut self, input: &MpcInput<'_>) -> Result<MpcOutput, SolveError> {
        check_input(input, self.n)?;
        let t0 = self.clock.now();
        let mut times = StepTimes::default();
        // The linearisation point: the previous plan shifted by one step, or the last
        // command held; projected onto the input bounds and rate limits.
        self.init_linearisation(input);
        let tl = self.clock.now();
        self.roll(false, &input.target_input, true);
        self.linearise_soft(input);
        times.linearise += self.clock.now() - tl;
        self.coupled = self.soft.iter().any(|r| r.band);
        // Only converged mode tests steps against the merit; RTI takes its one step.
        let converged = self.settings.mode == ScpMode::Converged;
        let mut merit_lin = if converged {
            self.merit(&self.lin, input).0
        } else {
            0.0
        };

        let max_iter = match self.settings.mode {
            ScpMode::Rti => 1,
            ScpMode::Converged => self.settings.max_scp_iter,
        };
        let mut trust = 1.0;
        let mut status = MpcStatus::IterationCap;
        let mut accepted_any = false;
        let mut qp_iterations = 0;
        let mut scp_iterations = 0;
        let mut qp_failed = false;
        for it in 0..max_iter {
            let elapsed = self.clock.now() - t0;
            let per_iter = if it == 0 {
                0.0
            } else {
                elapsed / f64::from(it)
            };
            if it > 0 && elapsed + per_iter > self.settings.time_budget {
                status = MpcStatus::TimeBudget;
                break;
            }
            scp_iterations += 1;
            let ta = self.clock.now();
            self.assemble(input, trust);
            times.assemble += self.clock.now() - ta;
            let obj_lin = if converged {
                self.objective_at_lin(input.reference)
            } else {
                0.0
            };
            self.lin_snapshot.copy_trajectory_from(&self.lin);
            let tq = self.clock.now();
            let qs = if self.coupled {
                self.qp_coupled.solve()
            } else {
                self.qp_bullet.solve()
            };
            times.qp += self.clock.now() - tq;
            qp_iterations += self.qp().iterations();
            if !qs.usable() {
                if qs == QpStatus::MaxTime {
                    status = MpcStatus::TimeBudget;
                }
                qp_failed = !accepted_any;
                break;
            }
            // Candidate: the QP's inputs and forces, rolled out through the nonlinear models.
            let tl = self.clock.now();
            self.candidate_from_qp();
            // RTI never linearises at the candidate (the next step re-linearises from the
            // new measurement), so its rollout skips the Jacobians.
            self.cand.xt[0] = self.lin.xt[0];
            self.cand.xb[0] = self.lin.xb[0];
            self.roll(true, &input.target_input, converged);
            self.model_error = self.qp_model_error();
            times.linearise += self.clock.now() - tl;
            if !converged {
                self.lin.copy_trajectory_from(&self.cand);
                accepted_any = true;
                status = MpcStatus::RtiStep;
                break;
            }
            let merit_cand = self.merit(&self.cand, input).0;
            // The QP models the merit's change: its objective at the linearisation point
            // (zero step, slacks at their smallest feasible value) minus at the solution.
            let predicted = obj_lin - self.qp().objective();
            let step = self.step_size();
            let actual = merit_lin - merit_cand;
            if actual >= 0.1 * predicted.max(0.0) && merit_cand.is_finite() {
                self.lin.copy_from(&self.cand);
                merit_lin = merit_cand;
                accepted_any = true;
                let tl = self.clock.now();
                self.linearise_soft(input);
                self.coupled = self.soft.iter().any(|r| r.band);
                times.linearise += self.clock.now() - tl;
                if step < self.settings.step_tol * trust
                    || predicted.abs() < 1e-6 * (1.0 + merit_lin.abs())
                {
                    status = MpcStatus::Converged;
                    break;
                }
                if actual > 0.75 * predicted {
                    trust = (trust * 2.0).min(1.0);
                }
            } else {
                trust *= 0.25;
                if trust < 1e-3 {
                    status = MpcStatus::Converged;
                    break;
                }
            }
        }
        let out = if qp_failed || !accepted_any && !converged {
            self.fallback(input, qp_iterations, scp_iterations, times)
        } else {
            // Converged mode keeps the linearisation plan (the best accepted one, or the
            // initial guess if nothing was accepted).
            let (merit, viol) = self.merit(&self.lin, input);
            if !self.lin.is_finite() {
                self.fallback(input, qp_iterations, scp_iterations, times)
            } else {
                // Only the inputs and forces of `prev` are used (shifted, next step).
                self.prev.copy_trajectory_from(&self.lin);
                self.have_prev = true;
                MpcOutput {
                    status,
                    command: self.lin.u[0],
                    fallback: None,
                    scp_iterations,
                    qp_iterations,
                    merit,
                    max_violation: viol,
                    times,
                }
            }
        };
        let mut out = out;
        out.times.total = self.clock.now() - t0;
        Ok(out)
    }

    fn fallback(
        &mut self,
        input: &MpcInput<'_>,
        qp_iterations: u32,
        scp_iterations: u32,
        times: StepTimes,
    ) -> MpcOutput {
        let (command, kind) = if self.have_prev && self.prev.is_finite() {
            // Shift the previous plan: drop its first input.
            let n = self.n;
            self.prev.u.copy_within(1..n, 0);
            self.prev.f.copy_within(1..n, 0);
            self.prev.xt.copy_within(1..=n, 0);
            self.prev.xb.copy_within(1..=n, 0);
            (self.prev.u[0], Fallback::ShiftedPlan)
        } else {
            self.have_prev = false;
            let steer = input.last_command[0].clamp(-self.lim.steer_max, self.lim.steer_max) * 0.5;
            (
                BulletInput::new(steer, 0.5 * self.lim.torque_min),
                Fallback::Brake,
            )
        };
        MpcOutput {
            status: MpcStatus::QpFailure,
            command,
            fallback: Some(kind),
            scp_iterations,
            qp_iterations,
            merit: f64::INFINITY,
            max_violation: 0.0,
            times,
        }
    }

    fn init_linearisation(&mut self, input: &MpcInput<'_>) {
        let n = self.n;
        if self.have_prev {
            let (u_last, f_last) = (self.prev.u[n - 1], self.prev.f[n - 1]);
            self.lin.u[..n - 1].copy_from_slice(&self.prev.u[1..]);
            self.lin.f[..n - 1].copy_from_slice(&self.prev.f[1..]);
            self.lin.u[n - 1] = u_last;
            self.lin.f[n - 1] = f_last;
        } else {
            self.lin.u.fill(input.last_command);
            self.lin.f.fill(Vec2::zeros());
        }
        // Project onto the bounds and the steer-rate limit.
        let dmax = self.lim.steer_rate * self.settings.dt;
        let steer_max = self.lim.steer_at(input.bullet[dynamics::bullet::idx::VX]);
        let mut prev = input.last_command[0];
        for u in &mut self.lin.u {
            u[0] = u[0]
                .clamp(-steer_max, steer_max)
                .clamp(prev - dmax, prev + dmax);
            u[1] = u[1].clamp(self.lim.torque_min, self.lim.torque_max);
            prev = u[0];
        }
        self.lin.xt[0] = input.target;
        self.lin.xb[0] = input.bullet;
    }

    /// Roll `lin` (or, with `cand`, the candidate) forward through the nonlinear models from
    /// its first state, with Jacobians if `jac`.
    fn roll(&mut self, cand: bool, target_input: &TargetInput, jac: bool) {
        let c = &self.settings.contact;
        let ctx = RolloutCtx {
            bullet: &self.bullet,
            shapes: &self.shapes,
            target_input,
            force_max: c.force_max,
            release: c.gap_release,
            friction: c.friction,
        };
        let plan = if cand { &mut self.cand } else { &mut self.lin };
        rollout(&ctx, self.target.as_mut(), plan, jac);
    }

    /// Inputs and forces of the QP solution around `lin`.
    fn candidate_from_qp(&mut self) {
        let l = self.layout();
        let x = if self.coupled {
            self.qp_coupled.x()
        } else {
            self.qp_bullet.x()
        };
        for k in 0..self.n {
            let c = k * l.stage;
            self.cand.u[k] = BulletInput::new(
                self.lin.u[k][0] + x[c + l.o_u],
                self.lin.u[k][1] + self.lim.t_scale * x[c + l.o_u + 1],
            );
            self.cand.f[k] = if l.coupled {
                Vec2::new(
                    self.lim.f_scale * x[c + l.o_f],
                    self.lim.f_scale * x[c + l.o_f + 1],
                )
            } else {
                Vec2::zeros()
            };
        }
    }

    /// Largest |x_QP − x_rollout| over the horizon and both vehicles' states, for the last
    /// QP's step (∞-norm, SI units; positions in m, angles in rad, speeds in m/s).
    #[must_use]
    pub fn linearisation_error(&self) -> f64 {
        self.model_error
    }

    /// Per stage of the last QP: the largest |x_QP − x_rollout| and which state it was
    /// (0–7 target, 8–13 bullet).
    #[must_use]
    pub fn linearisation_error_by_stage(&self) -> &[(f64, usize)] {
        &self.stage_error
    }

    fn qp_model_error(&mut self) -> f64 {
        let l = self.layout();
        let x = if self.coupled {
            self.qp_coupled.x()
        } else {
            self.qp_bullet.x()
        };
        let mut err: f64 = 0.0;
        for k in 0..self.n {
            let c0 = k * l.stage;
            let mut worst = (0.0, 0);
            for (qi, &i) in TQ.iter().enumerate() {
                let dx = if qi < l.nt { x[c0 + l.o_xt + qi] } else { 0.0 };
                let pred = self.lin.xt[k + 1][i] + dx;
                let e = (pred - self.cand.xt[k + 1][i]).abs();
                if e > worst.0 {
                    worst = (e, i);
                }
            }
            for i in 0..NB {
                let pred = self.lin.xb[k + 1][i] + x[c0 + l.o_xb + i];
                let e = (pred - self.cand.xb[k + 1][i]).abs();
                if e > worst.0 {
                    worst = (e, NT + i);
                }
            }
            self.stage_error[k] = worst;
            err = err.max(worst.0);
        }
        err
    }

    /// Size of the QP's input step relative to the trust region (∞-norm).
    fn step_size(&self) -> f64 {
        let l = self.layout();
        let x = self.qp().x();
        let mut s: f64 = 0.0;
        for k in 0..self.n {
            let c = k * l.stage;
            s = s
                .max(x[c + l.o_u].abs() / self.settings.trust_steer)
                .max(x[c + l.o_u + 1].abs() / self.settings.trust_torque);
        }
        s
    }

    /// Linearise the soft constraints along `lin` (states x_1 … x_N).
    fn linearise_soft(&mut self, input: &MpcInput<'_>) {
        let s = &self.settings;
        let force_planned = input.reference.stages.iter().any(|st| st.fn_hi > 0.0);
        for k in 0..self.n {
            let (xt, xb) = (&self.lin.xt[k + 1], &self.lin.xb[k + 1]);
            let pt = Vec2::new(xt[6], xt[7]);
            let pb = Vec2::new(xb[0], xb[1]);
            let g = self.lin.pair[k + 1];
            let fb = self.shapes.bullet_obb(xb);
            let ft = self.shapes.target_obb(xt);
            let (gb, gt) = gap_gradient(&fb, &ft, pb, pt, &g);
            let gap_start = self.lin.pair[k].gap;
            let row = &mut self.soft[k];
            row.gap_b = gb;
            row.gap_t = gt;
            row.gap = g.gap;
            // A force only where the linearisation has the vehicles near, and only if the
            // reference plans one somewhere over the horizon: a reference that plans none
            // (a chase) keeps the bullet clear of the target (ramming its rear is no PIT).
            let release = if self.pushing {
                s.contact.gap_release
            } else {
                s.contact.gap_engage
            };
            let near = gap_start.min(g.gap) <= release && force_planned;
            row.fn_max = if near { s.contact.force_max } else { 0.0 };
            row.band = near;
            if let Some(road) = input.road {
                row.road_b = edge_row(road, &fb, pb, s.road_margin).into();
                row.road_t = edge_row(road, &ft, pt, s.road_margin).into();
            } else {
                row.road_b = EdgeRowC::default();
                row.road_t = EdgeRowC::default();
            }
            let t = input.time + (k + 1) as f64 * s.dt;
            row.obs_b = nearest_obstacle(&fb, pb, input.obstacles, t, s.obstacle_clearance);
            row.obs_t = nearest_obstacle(&ft, pt, input.obstacles, t, s.obstacle_clearance);
            let (sn, cs) = xt[2].sin_cos();
            let d = pb - pt;
            row.rel = Vec2Copy {
                x: cs * d.x + sn * d.y,
                y: -sn * d.x + cs * d.y,
            };
            let (ct, cb) = (self.lin.ct[k], self.lin.cb[k]);
            row.gamma = ct.gamma;
            row.point_target = Vec2Copy {
                x: ct.point_in_body.x,
                y: ct.point_in_body.y,
            };
            row.point_bullet = Vec2Copy {
                x: cb.point_in_body.x,
                y: cb.point_in_body.y,
            };
        }
    }

    /// The trajectory the last QP was linearised at: inputs, forces and both vehicles'
    /// states (the `pair` gaps too; Jacobians are not kept).
    #[must_use]
    pub fn linearisation_point(&self) -> &Plan {
        &self.lin_snapshot
    }

    /// The linearisation of stage `k` of the last control step's (last) QP.
    ///
    /// # Panics
    /// If `k` is not below the horizon.
    #[must_use]
    pub fn stage_linearisation(&self, k: usize) -> StageLinearisation {
        let r = &self.soft[k];
        let pair = |e: &EdgeRowC| (e.grad, e.rhs);
        StageLinearisation {
            gamma: r.gamma,
            point_target: Vec2::new(r.point_target.x, r.point_target.y),
            point_bullet: Vec2::new(r.point_bullet.x, r.point_bullet.y),
            gap: r.gap,
            gap_grad_bullet: r.gap_b,
            gap_grad_target: r.gap_t,
            fn_max: r.fn_max,
            band: r.band,
            road_bullet: pair(&r.road_b),
            road_target: pair(&r.road_t),
            obstacle_bullet: pair(&r.obs_b),
            obstacle_target: pair(&r.obs_t),
        }
    }

    /// The merit (cost + penalty · violations, on the nonlinear models and geometry) and the
    /// largest violation of the plan that `u` and `f` produce from the input's states: the
    /// one yardstick for comparing plans, e.g. picopit's against a peer solver's. Forces are
    /// clipped as in every rollout. Overwrites the internal candidate buffer (not the plan).
    ///
    /// # Errors
    /// Non-finite input, or `u`/`f` not of the horizon's length.
    pub fn evaluate(
        &mut self,
        input: &MpcInput<'_>,
        u: &[BulletInput],
        f: &[Vec2],
    ) -> Result<(f64, f64), SolveError> {
        check_input(input, self.n)?;
        if u.len() != self.n || f.len() != self.n {
            return Err(SolveError::Reference);
        }
        self.cand.u.copy_from_slice(u);
        self.cand.f.copy_from_slice(f);
        self.cand.xt[0] = input.target;
        self.cand.xb[0] = input.bullet;
        self.roll(true, &input.target_input, false);
        Ok(self.merit(&self.cand, input))
    }

    fn assemble(&mut self, input: &MpcInput<'_>, trust: f64) {
        let view = AssemblyView {
            layout: self.layout(),
            s: &self.settings,
            lin: &self.lin,
            soft: &self.soft,
            reference: input.reference,
            last_command: input.last_command,
            lim: self.lim,
        };
        let qp = if self.coupled {
            &mut self.qp_coupled
        } else {
            &mut self.qp_bullet
        };
        let mut e = Emitter::values(&qp.p_slots, &mut qp.p_val, true);
        view.cost(&mut e, &mut qp.q);
        e.finish();
        let mut e = Emitter::values(&qp.a_slots, &mut qp.a_val, false);
        view.constraints_trust(&mut e, &mut qp.b, trust);
        e.finish();
    }

    /// The QP objective at the linearisation point: zero steps, the forces of `lin`, each
    /// slack at the largest linearised violation of its stage (the same rows the assembly
    /// writes, evaluated at a zero step).
    fn objective_at_lin(&mut self, reference: &Reference) -> f64 {
        let l = self.layout();
        let c = &self.settings.contact;
        let qp = if self.coupled {
            &mut self.qp_coupled
        } else {
            &mut self.qp_bullet
        };
        qp.z.fill(0.0);
        for k in 0..self.n {
            let c0 = k * l.stage;
            let row = &self.soft[k];
            let f = self.lin.f[k];
            let f_over_k = if l.coupled { f.x / c.stiffness } else { 0.0 };
            if l.coupled {
                qp.z[c0 + l.o_f] = f.x / self.lim.f_scale;
                qp.z[c0 + l.o_f + 1] = f.y / self.lim.f_scale;
            }
            let st = &reference.stages[k];
            let dev = row.rel.y - st.rel_pos.y;
            let mut s: f64 = 0.0;
            s = s.max(-row.gap - f_over_k);
            s = s.max(-row.road_b.rhs).max(-row.obs_b.rhs);
            s = s.max(dev.abs() - st.envelope_lat);
            if l.coupled {
                s = s.max(-row.road_t.rhs).max(-row.obs_t.rhs);
                if row.band {
                    s = s.max(f_over_k + row.gap - c.band);
                }
            }
            qp.z[c0 + l.o_s] = s.max(0.0);
        }
        qp.objective_at_z()
    }

    /// Merit of a plan: smooth cost + penalty · Σ_k (largest soft violation at step k).
    /// Returns (merit, largest violation).
    fn merit(&self, plan: &Plan, input: &MpcInput<'_>) -> (f64, f64) {
        let (smooth, pen, viol) = self.merit_parts(plan, input);
        (smooth + self.settings.weights.penalty * pen, viol)
    }

    fn merit_parts(&self, plan: &Plan, input: &MpcInput<'_>) -> (f64, f64, f64) {
        let s = &self.settings;
        let w = &s.weights;
        let r = input.reference;
        let mut cost = 0.0;
        let mut pen = 0.0;
        let mut worst: f64 = 0.0;
        let mut u_prev = input.last_command;
        for k in 0..self.n {
            let (xt, xb) = (&plan.xt[k + 1], &plan.xb[k + 1]);
            let st = &r.stages[k];
            // Tracking.
            let (sn, cs) = xt[2].sin_cos();
            let d = Vec2::new(xb[0] - xt[6], xb[1] - xt[7]);
            let rel = Vec2::new(cs * d.x + sn * d.y, -sn * d.x + cs * d.y);
            let e = [
                rel.x - st.rel_pos.x,
                rel.y - st.rel_pos.y,
                xb[2] - xt[2] - st.rel_heading,
                xb[3] - xt[0] - st.rel_speed,
            ];
            let we = [w.rel_long, w.rel_lat, w.rel_heading, w.rel_speed];
            for i in 0..4 {
                cost += st.track * we[i] * e[i] * e[i];
            }
            // Corridor.
            let f = plan.f[k];
            let dist = (f.x - f.x.clamp(st.fn_lo, st.fn_hi)) / self.lim.f_scale;
            cost += w.corridor * dist * dist;
            // Effort and rate.
            let u = plan.u[k];
            let tn = u[1] / self.lim.t_scale;
            cost += w.steer * u[0] * u[0] + w.torque * tn * tn;
            let du = u - u_prev;
            let dtn = du[1] / self.lim.t_scale;
            cost += w.steer_rate * du[0] * du[0] + w.torque_rate * dtn * dtn;
            u_prev = u;
            // Soft constraints (nonlinear geometry).
            let g = plan.pair[k + 1].gap;
            let f_over_k = f.x / s.contact.stiffness;
            let mut v: f64 = (-g - f_over_k).max(0.0);
            if f.x > 0.0 {
                v = v.max(f_over_k + g - s.contact.band);
            }
            let fb = self.shapes.bullet_obb(xb);
            let ft = self.shapes.target_obb(xt);
            if let Some(road) = input.road {
                v = v.max(s.road_margin - road.edge_distance(&fb));
                v = v.max(s.road_margin - road.edge_distance(&ft));
            }
            let t = input.time + (k + 1) as f64 * s.dt;
            for o in input.obstacles {
                let of = o.footprint_at(t);
                v = v.max(s.obstacle_clearance - obb_signed_distance(&fb, &of));
                v = v.max(s.obstacle_clearance - obb_signed_distance(&ft, &of));
            }
            v = v.max((rel.y - st.rel_pos.y).abs() - st.envelope_lat);
            let v = v.max(0.0);
            pen += v;
            worst = worst.max(v);
        }
        // Target objective at x_N.
        let xt = &plan.xt[self.n];
        let eh = xt[2] - r.target_heading;
        cost += w.target
            * r.target_weight
            * (w.target_heading * eh * eh + w.target_speed * (xt[0] * xt[0] + xt[1] * xt[1]));
        (cost, pen, worst)
    }
}

fn nearest_obstacle(
    fp: &dynamics::geometry::Obb,
    cg: Vec2,
    obstacles: &[Obstacle],
    t: f64,
    clearance: f64,
) -> EdgeRowC {
    let mut best = f64::INFINITY;
    let mut which = None;
    for (i, o) in obstacles.iter().enumerate() {
        let d = obb_signed_distance(fp, &o.footprint_at(t));
        if d < best {
            best = d;
            which = Some(i);
        }
    }
    match which {
        Some(i) => {
            let of = obstacles[i].footprint_at(t);
            let g = pair_geometry(fp, &of);
            let (gv, _) = gap_gradient(fp, &of, cg, of.center, &g);
            // gap ≥ clearance − s  ⇔  −∇gap·δ − s ≤ gap − clearance.
            EdgeRowC {
                grad: [-gv[0], -gv[1], -gv[2]],
                rhs: g.gap - clearance,
            }
        }
        None => EdgeRowC::default(),
    }
}

fn check_input(input: &MpcInput<'_>, n: usize) -> Result<(), SolveError> {
    let finite = |v: &[f64]| v.iter().all(|x| x.is_finite());
    if !finite(input.target.as_slice()) {
        return Err(SolveError::TargetState);
    }
    if !finite(input.bullet.as_slice()) {
        return Err(SolveError::BulletState);
    }
    if !finite(input.target_input.as_slice()) {
        return Err(SolveError::TargetInput);
    }
    if !finite(input.last_command.as_slice()) {
        return Err(SolveError::LastCommand);
    }
    let r = input.reference;
    let ok = r.stages.len() == n
        && r.target_heading.is_finite()
        && r.target_weight.is_finite()
        && r.stages.iter().all(|s| {
            s.rel_pos.iter().all(|v| v.is_finite())
                && s.rel_heading.is_finite()
                && s.rel_speed.is_finite()
                && s.track.is_finite()
                && s.track >= 0.0
                && s.fn_lo.is_finite()
                && s.fn_hi.is_finite()
                && s.envelope_lat.is_finite()
        });
    if ok {
        Ok(())
    } else {
        Err(SolveError::Reference)
    }
}

impl AssemblyView<'_> {
    /// P (upper triangle) and q. Every `put` is unconditional for a given layout: the
    /// pattern is fixed.
    fn cost(&self, e: &mut Emitter<'_>, q: &mut [f64]) {
        let l = self.layout;
        let n = self.lin.len();
        let w = &self.s.weights;
        let r = self.reference;
        q.fill(0.0);
        let prox = 2.0 * w.proximal;
        for k in 0..n {
            let c0 = k * l.stage;
            let st = &r.stages[k];
            let (xt, xb) = (&self.lin.xt[k + 1], &self.lin.xb[k + 1]);
            // --- Tracking residuals r_i = r̄_i + Σ c_ij δ_j over the tracked entries
            // X_T, Y_T, ψ_T, vx_T, X_B, Y_B, ψ_B, vx_B.
            let (sn, cs) = xt[2].sin_cos();
            let d = Vec2::new(xb[0] - xt[6], xb[1] - xt[7]);
            let rel = Vec2::new(cs * d.x + sn * d.y, -sn * d.x + cs * d.y);
            let jac: [[f64; 8]; 4] = [
                [-cs, -sn, rel.y, 0.0, cs, sn, 0.0, 0.0],
                [sn, -cs, -rel.x, 0.0, -sn, cs, 0.0, 0.0],
                [0.0, 0.0, -1.0, 0.0, 0.0, 0.0, 1.0, 0.0],
                [0.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0, 1.0],
            ];
            let res = [
                rel.x - st.rel_pos.x,
                rel.y - st.rel_pos.y,
                xb[2] - xt[2] - st.rel_heading,
                xb[3] - xt[0] - st.rel_speed,
            ];
            let we = [w.rel_long, w.rel_lat, w.rel_heading, w.rel_speed].map(|v| v * st.track);
            let mut h = [[0.0; 8]; 8];
            let mut g = [0.0; 8];
            for i in 0..4 {
                for a in 0..8 {
                    g[a] += 2.0 * we[i] * res[i] * jac[i][a];
                    for b in a..8 {
                        h[a][b] += 2.0 * we[i] * jac[i][a] * jac[i][b];
                    }
                }
            }
            // Target objective at the last stage.
            if k == n - 1 {
                let wt = w.target * r.target_weight;
                let eh = xt[2] - r.target_heading;
                h[2][2] += 2.0 * wt * w.target_heading;
                g[2] += 2.0 * wt * w.target_heading * eh;
                h[3][3] += 2.0 * wt * w.target_speed;
                g[3] += 2.0 * wt * w.target_speed * xt[0];
            }
            let mut cols = [0usize; 8];
            for i in 0..4 {
                // The bullet-only layout has no target columns (their entries are unused).
                if l.coupled {
                    cols[i] = c0 + l.o_xt + TRACKED_T[i];
                }
                cols[4 + i] = c0 + l.o_xb + TRACKED_B[i];
            }
            // The bullet-only QP holds the target fixed: only the bullet's entries.
            let first = if l.coupled { 0 } else { 4 };
            for a in first..8 {
                q[cols[a]] += g[a];
                for b in a..8 {
                    e.put(cols[a], cols[b], h[a][b]);
                }
            }
            if l.coupled {
                // vy_T (terminal speed) and the proximal term on the target's states.
                let vy_t = c0 + l.o_xt + 1;
                let wvy = if k == n - 1 {
                    2.0 * w.target * r.target_weight * w.target_speed
                } else {
                    0.0
                };
                e.put(vy_t, vy_t, wvy);
                q[vy_t] += wvy * xt[1];
                for j in 0..l.nt {
                    e.put(c0 + l.o_xt + j, c0 + l.o_xt + j, prox);
                }
            }
            for j in 0..NB {
                e.put(c0 + l.o_xb + j, c0 + l.o_xb + j, prox);
            }
            // --- Inputs: effort, rate (coupled to the previous stage), proximal.
            let u = self.lin.u[k];
            let u_prev = if k == 0 {
                self.last_command
            } else {
                self.lin.u[k - 1]
            };
            let scales = [1.0, self.lim.t_scale];
            let wu = [w.steer, w.torque];
            let wr = [w.steer_rate, w.torque_rate];
            for i in 0..2 {
                let col = c0 + l.o_u + i;
                let ubar = u[i] / scales[i];
                let dbar = (u[i] - u_prev[i]) / scales[i];
                // Effort wu (ū + ũ)²; rate wr (ū_k + ũ_k − ū_{k−1} − ũ_{k−1})².
                let mut diag = 2.0 * wu[i] + 2.0 * wr[i] + prox;
                q[col] += 2.0 * wu[i] * ubar + 2.0 * wr[i] * dbar;
                if k + 1 < n {
                    diag += 2.0 * wr[i];
                    let un = self.lin.u[k + 1];
                    q[col] -= 2.0 * wr[i] * (un[i] - u[i]) / scales[i];
                }
                e.put(col, col, diag);
                if k > 0 {
                    e.put(l.col(k - 1, l.o_u + i), col, -2.0 * wr[i]);
                }
            }
            if l.coupled {
                // --- Force: corridor (Gauss–Newton on the squared distance), proximal.
                let f = self.lin.f[k];
                let fs = self.lim.f_scale;
                let proj = f.x.clamp(st.fn_lo, st.fn_hi);
                let outside = if (f.x - proj).abs() > 0.0 { 1.0 } else { 0.0 };
                let wc = 2.0 * w.corridor * outside;
                let fcol = c0 + l.o_f;
                e.put(fcol, fcol, wc + prox);
                q[fcol] += -wc * proj / fs - prox * f.x / fs;
                e.put(fcol + 1, fcol + 1, prox);
                q[fcol + 1] += -prox * f.y / fs;
            }
            // --- Slack: exact L1 penalty plus a little curvature.
            e.put(c0 + l.o_s, c0 + l.o_s, prox);
            q[c0 + l.o_s] += w.penalty;
        }
    }

    fn constraints(&self, e: &mut Emitter<'_>, b: &mut [f64]) {
        self.constraints_trust(e, b, 1.0);
    }

    /// A and b: dynamics (equalities) then the inequality rows of every stage.
    fn constraints_trust(&self, e: &mut Emitter<'_>, b: &mut [f64], trust: f64) {
        let l = self.layout;
        let n = self.lin.len();
        let s = self.s;
        let fs = self.lim.f_scale;
        let ts = self.lim.t_scale;
        let n_eq = l.dyn_rows * n;
        for k in 0..n {
            let c0 = k * l.stage;
            let mut r = l.dyn_rows * k;
            let jb = &self.lin.jb[k];
            let f = self.lin.f[k];
            if l.coupled {
                let jt = &self.lin.jt[k];
                for (qi, &i) in TQ[..l.nt].iter().enumerate() {
                    e.put(r, c0 + l.o_xt + qi, 1.0);
                    if k > 0 {
                        for (qj, &j) in TQ[..l.nt].iter().enumerate() {
                            e.put(r, l.col(k - 1, l.o_xt + qj), -jt.a[(i, j)]);
                        }
                    }
                    for c in 0..2 {
                        e.put(r, c0 + l.o_f + c, -jt.f[(i, c)] * fs);
                    }
                    b[r] = -(jt.f[(i, 0)] * f.x + jt.f[(i, 1)] * f.y);
                    r += 1;
                }
            }
            for i in 0..NB {
                e.put(r, c0 + l.o_xb + i, 1.0);
                if k > 0 {
                    for j in 0..NB {
                        e.put(r, l.col(k - 1, l.o_xb + j), -jb.a[(i, j)]);
                    }
                }
                e.put(r, c0 + l.o_u, -jb.b[(i, 0)]);
                e.put(r, c0 + l.o_u + 1, -jb.b[(i, 1)] * ts);
                if l.coupled {
                    for c in 0..2 {
                        e.put(r, c0 + l.o_f + c, -jb.f[(i, c)] * fs);
                    }
                    b[r] = -(jb.f[(i, 0)] * f.x + jb.f[(i, 1)] * f.y);
                } else {
                    b[r] = 0.0;
                }
                r += 1;
            }
        }
        for k in 0..n {
            let c0 = k * l.stage;
            let mut r = n_eq + l.rows * k;
            let u = self.lin.u[k];
            let soft = &self.soft[k];
            let st = &self.reference.stages[k];
            let o_s = c0 + l.o_s;
            let mut row =
                |e: &mut Emitter<'_>, b: &mut [f64], entries: &[(usize, f64)], rhs: f64| {
                    for &(c, v) in entries {
                        e.put(r, c, v);
                    }
                    b[r] = rhs;
                    r += 1;
                };
            // Input bounds ∩ trust region, on ũ.
            let (ts_steer, ts_torque) = (s.trust_steer * trust, s.trust_torque * trust);
            let (cu, ct) = (c0 + l.o_u, c0 + l.o_u + 1);
            let steer_max = self.lim.steer_at(self.lin.xb[k][dynamics::bullet::idx::VX]);
            row(
                e,
                b,
                &[(cu, 1.0)],
                (steer_max - u[0]).min(ts_steer).max(0.0),
            );
            row(
                e,
                b,
                &[(cu, -1.0)],
                (steer_max + u[0]).min(ts_steer).max(0.0),
            );
            row(
                e,
                b,
                &[(ct, 1.0)],
                ((self.lim.torque_max - u[1]) / ts).min(ts_torque).max(0.0),
            );
            row(
                e,
                b,
                &[(ct, -1.0)],
                ((u[1] - self.lim.torque_min) / ts).min(ts_torque).max(0.0),
            );
            // Steer rate.
            let dmax = self.lim.steer_rate * s.dt;
            let u_prev = if k == 0 {
                self.last_command[0]
            } else {
                self.lin.u[k - 1][0]
            };
            let dbar = u[0] - u_prev;
            let prev = l.col(k.saturating_sub(1), l.o_u);
            let couple = if k > 0 { 1.0 } else { 0.0 };
            row(e, b, &[(cu, 1.0), (prev, -couple)], (dmax - dbar).max(0.0));
            row(e, b, &[(cu, -1.0), (prev, couple)], (dmax + dbar).max(0.0));
            // Gap rows on the poses (the target's only in the coupled QP).
            let mut gap_entries = [(0usize, 0.0); 8];
            for j in 0..3 {
                gap_entries[j] = (c0 + l.o_xb + B_POSE[j], soft.gap_b[j]);
                gap_entries[3 + j] = if l.coupled {
                    (c0 + l.o_xt + T_POSE[j], soft.gap_t[j])
                } else {
                    (o_s, 0.0)
                };
            }
            let neg = |v: &[(usize, f64)]| {
                let mut out = [(0usize, 0.0); 8];
                for (o, &(c, x)) in out.iter_mut().zip(v) {
                    *o = (c, -x);
                }
                out
            };
            if l.coupled {
                let (cn, cf) = (c0 + l.o_f, c0 + l.o_f + 1);
                let mu = s.contact.friction;
                // Force bounds and friction cone on f̃ = f / f_scale.
                row(e, b, &[(cn, -1.0)], 0.0);
                row(e, b, &[(cn, 1.0)], soft.fn_max / fs);
                row(e, b, &[(cf, 1.0), (cn, -mu)], 0.0);
                row(e, b, &[(cf, -1.0), (cn, -mu)], 0.0);
                // Penetration law at x_{k+1}: −∇gap·δ − (f_s/k) f̃_n − s ≤ gap.
                let mut ent = neg(&gap_entries);
                ent[6] = (cn, -fs / s.contact.stiffness);
                ent[7] = (o_s, -1.0);
                row(e, b, &ent, soft.gap);
                // Compliance band's upper side, near contact only:
                // F_n/k + gap ≤ band + s.
                let mut ent = gap_entries;
                ent[6] = (cn, fs / s.contact.stiffness);
                ent[7] = (o_s, -1.0);
                let rhs = if soft.band {
                    s.contact.band - soft.gap
                } else {
                    FAR
                };
                row(e, b, &ent, rhs);
            } else {
                // No force: the bullet may not run into the (fixed) target.
                let mut ent = neg(&gap_entries[..3]);
                ent[3] = (o_s, -1.0);
                row(e, b, &ent[..4], soft.gap);
            }
            // Road edges and obstacles, bullet then target.
            let pose_row = |row: &EdgeRowC, off: usize, pose: [usize; 3]| {
                [
                    (c0 + off + pose[0], row.grad[0]),
                    (c0 + off + pose[1], row.grad[1]),
                    (c0 + off + pose[2], row.grad[2]),
                    (o_s, -1.0),
                ]
            };
            row(
                e,
                b,
                &pose_row(&soft.road_b, l.o_xb, B_POSE),
                soft.road_b.rhs,
            );
            row(e, b, &pose_row(&soft.obs_b, l.o_xb, B_POSE), soft.obs_b.rhs);
            if l.coupled {
                row(
                    e,
                    b,
                    &pose_row(&soft.road_t, l.o_xt, T_POSE),
                    soft.road_t.rhs,
                );
                row(e, b, &pose_row(&soft.obs_t, l.o_xt, T_POSE), soft.obs_t.rhs);
            }
            // Envelope on the lateral position in the target frame.
            let xt = &self.lin.xt[k + 1];
            let (sn, cs) = xt[2].sin_cos();
            let mut up = [(0usize, 0.0); 6];
            let mut down = [(0usize, 0.0); 6];
            let gy = [(c0 + l.o_xb, -sn), (c0 + l.o_xb + 1, cs)];
            let gt = [sn, -cs, -soft.rel.x];
            let n_ent = if l.coupled { 6 } else { 3 };
            for (j, &(c, v)) in gy.iter().enumerate() {
                up[j] = (c, v);
                down[j] = (c, -v);
            }
            up[2] = (o_s, -1.0);
            down[2] = (o_s, -1.0);
            if l.coupled {
                for j in 0..3 {
                    let c = c0 + l.o_xt + T_POSE[j];
                    up[3 + j] = (c, gt[j]);
                    down[3 + j] = (c, -gt[j]);
                }
            }
            let dev = soft.rel.y - st.rel_pos.y;
            row(e, b, &up[..n_ent], st.envelope_lat - dev);
            row(e, b, &down[..n_ent], st.envelope_lat + dev);
            // s ≥ 0.
            row(e, b, &[(o_s, -1.0)], 0.0);
            debug_assert_eq!(r, n_eq + l.rows * (k + 1));
        }
    }
}

/// The relative heading of two headings, wrapped (for reports).
#[must_use]
pub fn heading_error(psi: f64, psi_ref: f64) -> f64 {
    wrap_angle(psi - psi_ref)
}

/// A pose helper for tests and callers.
#[must_use]
pub fn bullet_pose(x: &BulletState) -> Pose2 {
    Pose2::new(x[0], x[1], x[2])
}
