//! The closed-loop episode runner: one scenario, one controller configuration, one seed.
//!
//! The plant ([`Plant`], 1 kHz) is the truth. The scenario gives the road, the obstacles,
//! both initial states and the target driver; the hierarchical controller
//! ([`PitController`]) runs every control period (the MPC's `dt`, 0.05 s) on what the
//! sensors report and drives the bullet through [`Plant::set_bullet_command_blended`]. The
//! success test ([`Monitor`]) sees the truth: it latches the plant after every plant step
//! and observes once per control step. The episode stops as soon as the outcome is decided
//! (or at `T_max`, which is a decision: no termination).
//!
//! Optional uncertainty ([`Uncertainty`]): Gaussian sensing noise on the states the
//! controller sees, a sensing latency, and actuator gain and steer-bias errors drawn once
//! per episode. All randomness comes from one RNG seeded by the episode seed
//! ([`run_episode`]) or injected ([`run_episode_with_rng`]).
//!
//! Planning and control times are read from the controller's own clock: the wall clock by
//! default, or a simulated tick clock ([`ClockKind::Simulated`]), with which an episode is
//! bit-for-bit reproducible (the solvers' wall-clock limits are lifted in that mode).

pub use crate::config::{ClockKind, EpisodeConfig, EpisodeError, ModelKind, Uncertainty};
use crate::outcome::{FailureCause, Metrics, Outcome, Status};
use crate::scenario::Scenario;
use crate::vehicle::{bullet_array, SimVehicle};
use dynamics::geometry::Vec2;
use dynamics::params::ParamSet;
use dynamics::target4dof::FourDofTarget;
use dynamics::{ContactInput, TargetInput, TargetModel};
use mpc::{MpcStatus, TickClock};
use planner::{AbortReason, ControllerInput, Phase, PitController};
use rand::{RngCore, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};
use std::path::Path;
use std::time::Instant;

/// Median, 99th percentile and maximum of a set of times (ms); NaN when empty. Percentiles
/// interpolate linearly between order statistics (numpy's default).
#[derive(Serialize, Deserialize, Clone, Copy, Debug, PartialEq)]
pub struct TimeStats {
    pub count: usize,
    pub median_ms: f64,
    pub p99_ms: f64,
    pub max_ms: f64,
}

impl TimeStats {
    /// Statistics of `times_ms` (sorted in place).
    #[must_use]
    pub fn of(times_ms: &mut [f64]) -> Self {
        times_ms.sort_by(f64::total_cmp);
        Self {
            count: times_ms.len(),
            median_ms: percentile(times_ms, 50.0),
            p99_ms: percentile(times_ms, 99.0),
            max_ms: times_ms.last().copied().unwrap_or(f64::NAN),
        }
    }
}

/// Percentile `q` (0–100) of sorted values, linear interpolation; NaN when empty.
#[must_use]
pub fn percentile(sorted: &[f64], q: f64) -> f64 {
    match sorted.len() {
        0 => f64::NAN,
        1 => sorted[0],
        n => {
            let pos = (q / 100.0).clamp(0.0, 1.0) * (n - 1) as f64;
            let lo = pos.floor() as usize;
            let hi = (lo + 1).min(n - 1);
            let w = pos - lo as f64;
            sorted[lo] * (1.0 - w) + sorted[hi] * w
        }
    }
}

/// One control step of a recorded episode (the truth after the step's plant steps, and
/// what was commanded during it).
#[derive(Serialize, Deserialize, Clone, Copy, Debug, PartialEq)]
pub struct Sample {
    /// Time at the end of the step (s).
    pub time: f64,
    /// Target `[vx, vy, ψ, r, p, φ, X, Y]`.
    pub target: [f64; 8],
    /// Bullet `[X, Y, ψ, vx, vy, r]`.
    pub bullet: [f64; 6],
    /// The controller's command `[δ_f, T_r]` over the step.
    pub command: [f64; 2],
    /// The target driver's command `[δ, T_b]` over the step.
    pub target_command: [f64; 2],
    /// Contact force `[F_n, F_t]` averaged over the step (N; zero apart).
    pub contact_force: [f64; 2],
    /// The averaged contact's normal, world heading γ (rad), and its point of action in the
    /// target's body frame relative to its c.g. (m): with `contact_force` the
    /// [`ContactInput`] a target model takes for the step (zeros apart).
    #[serde(default)]
    pub contact_gamma: f64,
    #[serde(default)]
    pub contact_point: [f64; 2],
    pub phase: Phase,
    pub replanned: bool,
    /// Planning and control times of the step (ms).
    pub plan_ms: f64,
    pub ctrl_ms: f64,
}

impl Sample {
    /// Column names of [`Sample::row`].
    pub const COLUMNS: [&'static str; 29] = [
        "time",
        "target_vx",
        "target_vy",
        "target_psi",
        "target_r",
        "target_p",
        "target_phi",
        "target_x",
        "target_y",
        "bullet_x",
        "bullet_y",
        "bullet_psi",
        "bullet_vx",
        "bullet_vy",
        "bullet_r",
        "cmd_steer",
        "cmd_torque",
        "target_steer",
        "target_brake",
        "contact_fn",
        "contact_ft",
        "phase",
        "replanned",
        "plan_ms",
        "ctrl_ms",
        "decided",
        "contact_gamma",
        "contact_px",
        "contact_py",
    ];

    /// The contact averaged over the step as the target model's input (none apart).
    #[must_use]
    pub fn contact(&self) -> ContactInput {
        if self.contact_force[0] <= 0.0 {
            return ContactInput::none();
        }
        ContactInput {
            fc: Vec2::new(self.contact_force[0], self.contact_force[1]),
            gamma: self.contact_gamma,
            point_in_body: Vec2::new(self.contact_point[0], self.contact_point[1]),
        }
    }

    /// The sample as numbers in [`Sample::COLUMNS`] order (phase as its index: chasing 0,
    /// PIT 1, stabilising 2, done 3, aborted 4; `decided` is filled by the caller; the
    /// contact's normal heading and point last, zeros apart).
    #[must_use]
    pub fn row(&self, decided: bool) -> [f64; 29] {
        let mut r = [0.0; 29];
        r[0] = self.time;
        r[1..9].copy_from_slice(&self.target);
        r[9..15].copy_from_slice(&self.bullet);
        r[15..17].copy_from_slice(&self.command);
        r[17..19].copy_from_slice(&self.target_command);
        r[19..21].copy_from_slice(&self.contact_force);
        r[21] = phase_index(self.phase);
        r[22] = f64::from(u8::from(self.replanned));
        r[23] = self.plan_ms;
        r[24] = self.ctrl_ms;
        r[25] = f64::from(u8::from(decided));
        r[26] = self.contact_gamma;
        r[27..29].copy_from_slice(&self.contact_point);
        r
    }
}

/// A phase's name in reports: `chasing`, `pit`, `stabilising`, `done`, `aborted`.
#[must_use]
pub fn phase_name(p: Phase) -> &'static str {
    match p {
        Phase::Chasing => "chasing",
        Phase::Pit => "pit",
        Phase::Stabilising => "stabilising",
        Phase::Done => "done",
        Phase::Aborted => "aborted",
    }
}

/// Index of a phase in recorded trajectories.
#[must_use]
pub fn phase_index(p: Phase) -> f64 {
    match p {
        Phase::Chasing => 0.0,
        Phase::Pit => 1.0,
        Phase::Stabilising => 2.0,
        Phase::Done => 3.0,
        Phase::Aborted => 4.0,
    }
}

/// One plan of a recorded episode: what the upper layer predicted when it planned, to set
/// against what then happened (`picopit trace` lists them).
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct PlanRecord {
    /// When the plan was made (s).
    pub time: f64,
    pub mode: planner::Mode,
    /// Why no feasible decision exists, when the plan is an abort for want of one.
    #[serde(default)]
    pub infeasible: Option<planner::Infeasible>,
    /// The plan gave up because the race is lost (the target fails on its own first).
    #[serde(default)]
    pub race_lost: bool,
    /// The reversed heading ψ_rev of the plan's terminal set (rad).
    pub reversed_heading: f64,
    /// The plan's predicted heading error at the end of its look-ahead (rad).
    pub predicted_heading_error: f64,
    /// Per plan step: its start time (s), the predicted target `[vx, vy, ψ, r, p, φ, X, Y]`
    /// at that time and the planned virtual force `[F_n, F_t]` over the step (N).
    pub predicted: Vec<(f64, [f64; 8], [f64; 2])>,
    /// The pushed side's sign (left +1, right −1): the planned force's normal is the
    /// target's side normal, world heading ψ − sign·π/2.
    #[serde(default)]
    pub side_sign: f64,
    /// The planned point of action in the target's body frame, relative to its c.g. (m).
    #[serde(default)]
    pub contact_point: [f64; 2],
    /// The target driver's command `[δ, T_b]` the plan held.
    #[serde(default)]
    pub target_input: [f64; 2],
    /// The bullet was held back behind the target: its stand-off pose, or its way there,
    /// would run into an obstacle (`planner::DecisionPackage::hold_back`).
    #[serde(default)]
    pub hold_back: bool,
}

impl PlanRecord {
    /// The target model's contact input for a force `f = [F_n, F_t]` on the plan's side and
    /// contact point with the target at heading `psi` (the normal is the side normal, as the
    /// planner's rollout has it); no contact for a zero force.
    #[must_use]
    pub fn contact_with(&self, f: [f64; 2], psi: f64) -> ContactInput {
        if f == [0.0; 2] {
            return ContactInput::none();
        }
        ContactInput {
            fc: Vec2::new(f[0], f[1]),
            gamma: psi - self.side_sign * std::f64::consts::FRAC_PI_2,
            point_in_body: Vec2::new(self.contact_point[0], self.contact_point[1]),
        }
    }

    fn of(p: &planner::DecisionPackage, target_input: [f64; 2]) -> Self {
        Self {
            time: p.time,
            mode: p.mode,
            infeasible: p.infeasible,
            race_lost: p.race_lost,
            reversed_heading: p.terminal.heading,
            predicted_heading_error: p.predicted_heading_error,
            predicted: p
                .steps
                .iter()
                .map(|s| {
                    let mut x = [0.0; 8];
                    x.copy_from_slice(s.target.as_slice());
                    (s.time, x, [s.force.x, s.force.y])
                })
                .collect(),
            side_sign: p.side.sign(),
            contact_point: [p.contact_point.x, p.contact_point.y],
            target_input,
            hold_back: p.hold_back,
        }
    }
}

/// Everything one episode produced.
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct EpisodeResult {
    pub scenario: String,
    pub config: String,
    pub seed: u64,
    /// The target model's name and trainable-parameter count (0 for the 4-DOF model).
    pub model: String,
    pub param_count: usize,
    pub upper_layer: bool,
    /// The success test's metrics (success, first cause, heading error, margins, contacts).
    pub metrics: Metrics,
    /// Simulated time at the end (s).
    pub sim_time: f64,
    pub control_steps: u64,
    /// Planning times over the steps that planned; control times over the steps the MPC
    /// ran (the safe stop after the maneuver is excluded).
    pub plan: TimeStats,
    pub ctrl: TimeStats,
    /// The controller's phase at the end, and its abort reason if it aborted.
    pub final_phase: Phase,
    pub abort: Option<String>,
    /// MPC steps that returned the safe fallback / ran out of their time budget.
    pub mpc_failures: u32,
    pub mpc_time_budget: u32,
    /// The time (s) of the last plan that held the bullet back behind the target for an
    /// obstacle in the way of its stand-off pose (`planner::DecisionPackage::hold_back`);
    /// `None` if no plan did.
    #[serde(default)]
    pub held_back_until: Option<f64>,
    /// Wall-clock time of the whole episode (s): not deterministic.
    pub wall_time: f64,
    /// Every plan and control time (ms), for pooled statistics.
    pub plan_times_ms: Vec<f64>,
    pub ctrl_times_ms: Vec<f64>,
    /// One sample per control step when recording.
    pub trajectory: Vec<Sample>,
    /// Every plan of the upper layer when recording.
    pub plans: Vec<PlanRecord>,
}

impl EpisodeResult {
    #[must_use]
    pub fn success(&self) -> bool {
        self.metrics.success
    }

    #[must_use]
    pub fn cause(&self) -> Option<FailureCause> {
        self.metrics.cause
    }
}

/// Run one episode with the RNG seeded by `seed`.
///
/// # Errors
/// [`EpisodeError`] for a configuration, scenario or model file that cannot be used.
pub fn run_episode(
    scenario: &Scenario,
    config: &EpisodeConfig,
    seed: u64,
) -> Result<EpisodeResult, EpisodeError> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut r = run_episode_with_rng(scenario, config, &mut rng)?;
    r.seed = seed;
    Ok(r)
}

/// Load one target model for the controller: the MPC's (`planner = false`) or the upper
/// layer's. `model_path` replaces the file of `config.model` only.
fn load_model(
    config: &EpisodeConfig,
    sc: &Scenario,
    params: &ParamSet,
    dt: f64,
    planner: bool,
) -> Result<Box<dyn TargetModel + Send + Sync>, EpisodeError> {
    let kind = match config.planner_model {
        Some(k) if planner => k,
        _ => config.model,
    };
    let path = config
        .model_path
        .as_deref()
        .filter(|_| kind == config.model);
    target_model(kind, &config.models_dir, path, sc, params, dt)
}

/// The controller's target model of kind `model` for scenario `sc` (its parameter set and
/// μ) with step `dt`: the 4-DOF model, or the surrogate file under `models_dir` (or
/// `model_path` instead, when given).
///
/// # Errors
/// [`EpisodeError::Model`] naming the file that cannot be loaded, does not cover μ, or was
/// trained on another parameter set than the scenario's.
pub fn target_model(
    model: ModelKind,
    models_dir: &Path,
    model_path: Option<&Path>,
    sc: &Scenario,
    params: &ParamSet,
    dt: f64,
) -> Result<Box<dyn TargetModel + Send + Sync>, EpisodeError> {
    let path = match (model_path, model.file(models_dir, sc.params)) {
        (_, None) => return Ok(Box::new(FourDofTarget::new(&params.target, sc.mu, dt))),
        (Some(p), Some(_)) => p.to_path_buf(),
        (None, Some(p)) => p,
    };
    let model = pico_nn::SurrogateModel::from_path(&path)
        .and_then(|m| m.with_mu(sc.mu))
        .map_err(|e| EpisodeError::Model {
            path: path.clone(),
            message: e.to_string(),
        })?;
    // A model learned on one parameter set says nothing about another's vehicles.
    let trained_on = model.metadata().get("param_set").map_or("", String::as_str);
    if trained_on != sc.params.name() {
        return Err(EpisodeError::Model {
            path,
            message: format!(
                "param_set = {trained_on:?}, but scenario {} runs the {} parameter set",
                sc.id,
                sc.params.name()
            ),
        });
    }
    Ok(Box::new(model))
}

/// Run one episode drawing all randomness (sensing noise, actuator errors) from `rng`.
///
/// # Errors
/// As [`run_episode`]. The result's `seed` is 0 (the caller knows how `rng` was seeded).
#[allow(clippy::too_many_lines)]
pub fn run_episode_with_rng<R: RngCore + ?Sized>(
    scenario: &Scenario,
    config: &EpisodeConfig,
    rng: &mut R,
) -> Result<EpisodeResult, EpisodeError> {
    let wall0 = Instant::now();
    config.validate()?;
    let sc = scenario;
    let params = sc.params.load()?;
    let road = sc.build_road()?;
    let obstacles = sc.obstacles();
    let mut settings = config.controller_for(sc.params).clone();
    if config.clock == ClockKind::Simulated {
        // The solvers' own wall-clock limits would make the episode machine-dependent.
        settings.mpc.qp.time_limit = 1.0e6;
        settings.planner.qp.time_limit = 1.0e6;
    }
    let dt = settings.mpc.dt;
    let mpc_model = load_model(config, sc, &params, dt, false)?;
    let planner_model = load_model(config, sc, &params, dt, true)?;
    let mut ctl = PitController::new(&params, sc.mu, mpc_model, planner_model, settings)
        .map_err(|e| EpisodeError::Controller(e.to_string()))?;
    if config.clock == ClockKind::Simulated {
        ctl = ctl.with_clock(
            Box::new(TickClock::new(config.clock_tick)),
            Box::new(TickClock::new(config.clock_tick)),
        );
    }
    let model = ctl.target_model_name().to_owned();
    let param_count = ctl.target_param_count();

    let mut vehicle = SimVehicle::new(sc, config.uncertainty, dt, rng)?;
    vehicle.set_target_gear(config.target_gear)?;
    let n_steps = (sc.t_max / dt).ceil() as u64 + 1;

    let mut plan_times = Vec::new();
    let mut ctrl_times = Vec::with_capacity(n_steps as usize);
    let mut trajectory = Vec::new();
    let mut plans = Vec::new();
    let mut stabilising_reported = false;
    let (mut mpc_failures, mut mpc_time_budget) = (0u32, 0u32);
    let mut held_back_until = None;
    let mut phase = ctl.phase();
    let mut steps = 0u64;
    let mut status = Status::Running;

    while steps < n_steps {
        let t = vehicle.time();
        let sensed = vehicle.sense(rng);
        let [t_steer, t_brake] = sensed.target_input;
        let prev_phase = phase;
        let out = ctl
            .step(&ControllerInput {
                // On the nanosecond grid of the vehicle I/O's stamps, so that a lock-step
                // run over IPC sees the very same times.
                time: ns_time(t),
                target: sensed.target,
                bullet: sensed.bullet.into(),
                target_input: TargetInput::new(t_steer, t_brake),
                road: &road,
                obstacles: &obstacles,
            })
            .map_err(|e| EpisodeError::Step {
                time: t,
                message: e.to_string(),
            })?;
        phase = out.phase;
        steps += 1;
        if out.replanned {
            plan_times.push(out.plan_time * 1e3);
            if ctl.package().is_some_and(|p| p.hold_back) {
                held_back_until = Some(t);
            }
            if config.record {
                plans.extend(ctl.package().map(|p| PlanRecord::of(p, [t_steer, t_brake])));
            }
        }
        if let Some(st) = out.mpc_status {
            ctrl_times.push(out.ctrl_time * 1e3);
            match st {
                MpcStatus::QpFailure => mpc_failures += 1,
                MpcStatus::TimeBudget => mpc_time_budget += 1,
                _ => {}
            }
        }
        if prev_phase == Phase::Pit && phase == Phase::Chasing {
            vehicle.push_retried();
        }
        if phase == Phase::Stabilising && !stabilising_reported {
            stabilising_reported = true;
            vehicle.enter_stabilisation(t);
        }
        if prev_phase == Phase::Chasing
            && matches!(out.abort, Some(AbortReason::DecisionInfeasible(_)))
        {
            status = vehicle.decision_infeasible(t);
        }
        if let Status::Done(_) = status {
            if config.record {
                trajectory.push(sample(&vehicle, &out, None, t));
            }
            break;
        }
        vehicle.actuate([out.command[0], out.command[1]]);
        status = vehicle.advance();
        if config.record {
            trajectory.push(sample(&vehicle, &out, vehicle.contact(), vehicle.time()));
        }
        if let Status::Done(_) = status {
            break;
        }
    }
    debug_assert!(
        matches!(status, Status::Done(_)),
        "the monitor decides no termination at T_max"
    );
    let metrics = vehicle.metrics();
    let plan = TimeStats::of(&mut plan_times.clone());
    let ctrl = TimeStats::of(&mut ctrl_times.clone());
    Ok(EpisodeResult {
        scenario: sc.id.clone(),
        config: config.name.clone(),
        seed: 0,
        model,
        param_count,
        upper_layer: ctl.settings().upper_layer,
        metrics,
        sim_time: vehicle.time(),
        control_steps: steps,
        plan,
        ctrl,
        final_phase: ctl.phase(),
        abort: ctl.abort_reason().map(|a| format!("{a:?}")),
        mpc_failures,
        mpc_time_budget,
        held_back_until,
        wall_time: wall0.elapsed().as_secs_f64(),
        plan_times_ms: plan_times,
        ctrl_times_ms: ctrl_times,
        trajectory,
        plans,
    })
}

/// Seconds on the nanosecond grid (the vehicle I/O's stamps).
fn ns_time(t: f64) -> f64 {
    (t * 1e9).round() * 1e-9
}

fn sample(
    vehicle: &SimVehicle,
    out: &planner::ControllerOutput,
    contact: Option<ContactInput>,
    time: f64,
) -> Sample {
    let c = contact.unwrap_or_else(ContactInput::none);
    let plant = vehicle.plant();
    let xt = plant.target_state();
    let mut target = [0.0; 8];
    target.copy_from_slice(xt.as_slice());
    Sample {
        time,
        target,
        bullet: bullet_array(plant),
        command: [out.command[0], out.command[1]],
        target_command: vehicle.target_command(),
        contact_force: [c.fc.x, c.fc.y],
        contact_gamma: c.gamma,
        contact_point: [c.point_in_body.x, c.point_in_body.y],
        phase: out.phase,
        replanned: out.replanned,
        plan_ms: out.plan_time * 1e3,
        ctrl_ms: out.ctrl_time * 1e3,
    }
}

/// The outcome's name for reports: `success`, a failure cause's name, or `running`.
#[must_use]
pub fn outcome_name(o: Option<Outcome>) -> &'static str {
    match o {
        Some(Outcome::Success { .. }) => "success",
        Some(Outcome::Failure { cause, .. }) => cause.name(),
        None => "running",
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn percentiles_interpolate_like_numpy() {
        let v: Vec<f64> = (1..=10).map(f64::from).collect();
        assert!((percentile(&v, 50.0) - 5.5).abs() < 1e-12);
        assert!((percentile(&v, 99.0) - 9.91).abs() < 1e-12);
        assert!(percentile(&[], 50.0).is_nan());
        let s = TimeStats::of(&mut [3.0, 1.0, 2.0]);
        assert_eq!((s.count, s.median_ms, s.max_ms), (3, 2.0, 3.0));
    }
}
