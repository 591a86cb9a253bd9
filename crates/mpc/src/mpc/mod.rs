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

mod assembly;
mod linearise;
mod solve;

use assembly::AssemblyView;
use linearise::check_input;

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
