//! Binding of the upper decision layer and the whole-maneuver controller (`crates/planner`):
//! `Planner` (one decision package Π per call) and `PitController` (planner + coupled MPC +
//! phase machine, one control step per call). Numpy in, dicts of numpy out, the GIL released
//! around every plan and step. Every bad input raises `PlannerError` naming the argument or
//! the settings field; numerical outcomes (no feasible PIT, a failed QP) are values, not
//! errors.

use crate::vec_arg;
use dynamics::params::ParamSet;
use dynamics::road::{Obstacle, Road, RoadSpec, SegmentSpec};
use dynamics::target4dof::FourDofTarget;
use dynamics::{TargetInput, TargetModel};
use mpc::Side;
use nalgebra::SVector;
use numpy::{PyArray1, PyArrayMethods};
use planner::{
    AbortReason, ControllerInput, ControllerSettings, DecisionPackage, Infeasible, Mode, Phase,
    PitController as CoreController, Planner as CorePlanner, PlannerInput, PlannerSettings,
    MAX_OBSTACLES,
};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::path::PathBuf;

pyo3::create_exception!(
    picopit,
    PlannerError,
    PyValueError,
    "Bad planner or controller settings (the message names the field), a bad array shape, a \
     non-finite input, an unknown target model or a missing road."
);

fn plan_err(e: impl std::fmt::Display) -> PyErr {
    PlannerError::new_err(e.to_string())
}

/// A shared helper's `ValueError` re-raised as `PlannerError` (same message).
fn as_plan_err(py: Python<'_>, e: PyErr) -> PyErr {
    PlannerError::new_err(e.value(py).to_string())
}

fn vec_in<const N: usize>(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<SVector<f64, N>> {
    vec_arg::<N>(obj, name).map_err(|e| as_plan_err(obj.py(), e))
}

fn finite_in(value: f64, name: &str) -> PyResult<f64> {
    if value.is_finite() {
        Ok(value)
    } else {
        Err(PlannerError::new_err(format!(
            "{name} = {value}: must be finite"
        )))
    }
}

/// Road friction for the target models: the range the plant accepts.
fn mu_in(mu: f64) -> PyResult<f64> {
    if mu.is_finite() && mu > 0.0 && mu <= 1.5 {
        Ok(mu)
    } else {
        Err(PlannerError::new_err(format!(
            "mu = {mu}: must be finite and in (0, 1.5]"
        )))
    }
}

fn side_in(side: Option<&str>) -> PyResult<Option<Side>> {
    match side {
        None => Ok(None),
        Some("left") => Ok(Some(Side::Left)),
        Some("right") => Ok(Some(Side::Right)),
        Some(other) => Err(PlannerError::new_err(format!(
            "side = {other:?}: must be None, \"left\" or \"right\""
        ))),
    }
}

fn mode_in(mode: &str) -> PyResult<Mode> {
    match mode {
        "chase" => Ok(Mode::Chase),
        "pit" => Ok(Mode::Pit),
        "stabilise" => Ok(Mode::Stabilise),
        "abort" => Ok(Mode::Abort),
        other => Err(PlannerError::new_err(format!(
            "mode = {other:?}: must be \"chase\", \"pit\", \"stabilise\" or \"abort\""
        ))),
    }
}

fn mode_str(m: Mode) -> &'static str {
    match m {
        Mode::Chase => "chase",
        Mode::Pit => "pit",
        Mode::Stabilise => "stabilise",
        Mode::Abort => "abort",
    }
}

fn side_str(s: Side) -> &'static str {
    match s {
        Side::Left => "left",
        Side::Right => "right",
    }
}

fn infeasible_str(i: Infeasible) -> &'static str {
    match i {
        Infeasible::TerminalSetUnreachable => "terminal_set_unreachable",
        Infeasible::RoadBoundary => "road_boundary",
        Infeasible::ObstacleClearance => "obstacle_clearance",
        Infeasible::Numerical => "numerical",
    }
}

fn phase_str(p: Phase) -> &'static str {
    match p {
        Phase::Chasing => "chasing",
        Phase::Pit => "pit",
        Phase::Stabilising => "stabilising",
        Phase::Done => "done",
        Phase::Aborted => "aborted",
    }
}

/// `chase_timeout`, `bullet_unstable`, `bullet_clearance` or
/// `decision_infeasible:<reason>` (the reason as in the package's `infeasible`).
fn abort_str(a: AbortReason) -> String {
    match a {
        AbortReason::DecisionInfeasible(i) => format!("decision_infeasible:{}", infeasible_str(i)),
        AbortReason::ChaseTimeout => "chase_timeout".to_owned(),
        AbortReason::BulletUnstable => "bullet_unstable".to_owned(),
        AbortReason::BulletClearance => "bullet_clearance".to_owned(),
    }
}

/// The target model by name: `4dof`, or the path of a surrogate file. An unknown name (not
/// `4dof` and no such file) is a `PlannerError`; a file that does not load is a `ModelError`.
fn target_model(
    py: Python<'_>,
    name: &str,
    params: &ParamSet,
    mu: f64,
    dt: f64,
) -> PyResult<Box<dyn TargetModel + Send + Sync>> {
    if name == "4dof" {
        return Ok(Box::new(FourDofTarget::new(&params.target, mu, dt)));
    }
    let path = PathBuf::from(name);
    if !path.is_file() {
        return Err(PlannerError::new_err(format!(
            "target_model = {name:?}: unknown; expected \"4dof\" or the path of a surrogate \
             (.safetensors) file"
        )));
    }
    // The surrogate predicts at the road's μ, as the 4-DOF model does.
    let m = py
        .detach(move || pico_nn::SurrogateModel::from_path(path).and_then(|m| m.with_mu(mu)))
        .map_err(|e| crate::surrogate::ModelError::new_err(e.to_string()))?;
    Ok(Box::new(m))
}

/// The road and obstacles a planner or controller works with (fixed between calls).
#[derive(Default)]
struct Scene {
    road: Option<Road>,
    obstacles: Vec<Obstacle>,
}

impl Scene {
    fn set_road(&mut self, road_toml: &str) -> PyResult<()> {
        let spec = RoadSpec::from_toml_str(road_toml, "road").map_err(plan_err)?;
        self.road = Some(Road::new(spec).map_err(plan_err)?);
        Ok(())
    }

    fn set_straight_road(
        &mut self,
        length: f64,
        lanes: i64,
        lane_width: f64,
        shoulder: f64,
    ) -> PyResult<()> {
        let lanes = u32::try_from(lanes)
            .ok()
            .filter(|&n| n > 0)
            .ok_or_else(|| PlannerError::new_err(format!("lanes = {lanes}: must be >= 1")))?;
        let spec = RoadSpec {
            segments: vec![SegmentSpec::Straight { length }],
            lanes,
            lane_width,
            shoulder,
            origin: [0.0, 0.0, 0.0],
        };
        // `Road::new` validates (and names) every field; `Road::straight` would panic.
        self.road = Some(Road::new(spec).map_err(plan_err)?);
        Ok(())
    }

    fn set_obstacles(&mut self, obstacles: &Bound<'_, PyAny>) -> PyResult<()> {
        let out = crate::obstacles_arg(obstacles).map_err(PlannerError::new_err)?;
        if out.len() > MAX_OBSTACLES {
            return Err(PlannerError::new_err(format!(
                "obstacles: {} rows, at most {MAX_OBSTACLES}",
                out.len()
            )));
        }
        self.obstacles = out;
        Ok(())
    }

    fn road(&self) -> PyResult<&Road> {
        self.road.as_ref().ok_or_else(|| {
            PlannerError::new_err("no road: call set_straight_road() or set_road() first")
        })
    }
}

/// The per-call state arguments, checked and copied.
struct StateArgs {
    time: f64,
    target: dynamics::TargetState,
    bullet: dynamics::bullet::BulletState,
    target_input: TargetInput,
}

impl StateArgs {
    fn parse(
        time: f64,
        target: &Bound<'_, PyAny>,
        bullet: &Bound<'_, PyAny>,
        target_input: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<Self> {
        Ok(Self {
            time: finite_in(time, "time")?,
            target: vec_in::<8>(target, "target")?,
            bullet: vec_in::<6>(bullet, "bullet")?,
            target_input: target_input
                .map(|a| vec_in::<2>(a, "target_input"))
                .transpose()?
                .unwrap_or_else(TargetInput::zeros),
        })
    }
}

/// A flat float vector as an (n, cols) array.
pub(crate) fn rows_out<'py>(
    py: Python<'py>,
    flat: Vec<f64>,
    cols: usize,
) -> PyResult<Bound<'py, numpy::PyArray2<f64>>> {
    let n = flat.len() / cols;
    PyArray1::from_vec(py, flat).reshape([n, cols])
}

/// The decision package Π as a dict (see `PlanPackage` in `_core.pyi`).
fn package_dict<'py>(py: Python<'py>, p: &DecisionPackage) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("mode", mode_str(p.mode))?;
    d.set_item("infeasible", p.infeasible.map(infeasible_str))?;
    d.set_item("time", p.time)?;
    d.set_item("side", side_str(p.side))?;
    d.set_item(
        "contact_point",
        PyArray1::from_slice(py, p.contact_point.as_slice()),
    )?;
    d.set_item(
        "contact_rel_pos",
        PyArray1::from_slice(py, p.contact_rel_pos.as_slice()),
    )?;
    d.set_item("contact_rel_heading", p.contact_rel_heading)?;
    d.set_item("push_speed", p.push_speed)?;
    d.set_item("envelope_lat", p.envelope_lat)?;
    d.set_item("window", p.has_window().then_some(p.window))?;
    let t = PyDict::new(py);
    t.set_item("heading", p.terminal.heading)?;
    t.set_item("heading_tol", p.terminal.heading_tol)?;
    t.set_item("yaw_decay", p.terminal.yaw_decay)?;
    d.set_item("terminal", t)?;
    d.set_item("road_margin", p.road_margin)?;
    d.set_item("obstacle_clearance", p.obstacle_clearance)?;
    let obs: Vec<f64> = p
        .obstacles
        .iter()
        .flat_map(|o| [o.x, o.y, o.heading, o.vx, o.vy, o.length, o.width])
        .collect();
    d.set_item("obstacles", rows_out(py, obs, 7)?)?;
    d.set_item("predicted_heading_error", p.predicted_heading_error)?;
    d.set_item("predicted_road_margin", p.predicted_road_margin)?;
    d.set_item("predicted_clearance", p.predicted_clearance)?;
    d.set_item("predicted_stop_margin", p.predicted_stop_margin)?;
    d.set_item("objective", p.objective)?;
    d.set_item("candidates", p.candidates)?;
    d.set_item("feasible_candidates", p.feasible_candidates)?;
    let times: Vec<f64> = p.steps.iter().map(|s| s.time).collect();
    let forces: Vec<f64> = p
        .steps
        .iter()
        .flat_map(|s| [s.force.x, s.force.y])
        .collect();
    let corridor: Vec<f64> = p
        .steps
        .iter()
        .flat_map(|s| [s.corridor.0, s.corridor.1])
        .collect();
    let targets: Vec<f64> = p
        .steps
        .iter()
        .flat_map(|s| s.target.iter().copied())
        .collect();
    d.set_item("times", PyArray1::from_vec(py, times))?;
    d.set_item("forces", rows_out(py, forces, 2)?)?;
    d.set_item("corridor", rows_out(py, corridor, 2)?)?;
    d.set_item("targets", rows_out(py, targets, 8)?)?;
    Ok(d)
}

/// The upper virtual-PIT decision layer.
#[pyclass(module = "picopit._core", name = "Planner")]
pub struct PyPlanner {
    core: CorePlanner,
    params: String,
    scene: Scene,
}

impl PyPlanner {
    /// Run `f` on the core with these arguments and the stored road and obstacles, the GIL
    /// released; returns the package as a dict.
    fn detached<'py>(
        &mut self,
        py: Python<'py>,
        a: &StateArgs,
        side: Option<Side>,
        best_effort: bool,
        f: impl FnOnce(&mut CorePlanner, &PlannerInput<'_>) -> Result<(), planner::PlanError> + Send,
    ) -> PyResult<Bound<'py, PyDict>> {
        let Self { core, scene, .. } = self;
        let road = scene.road()?;
        let obstacles = &scene.obstacles;
        py.detach(|| {
            f(
                core,
                &PlannerInput {
                    time: a.time,
                    target: a.target,
                    bullet: a.bullet,
                    target_input: a.target_input,
                    road,
                    obstacles,
                    side,
                    best_effort,
                },
            )
        })
        .map_err(plan_err)?;
        package_dict(py, core.package())
    }
}

#[pymethods]
impl PyPlanner {
    /// `params`: a built-in set name or a TOML path; `mu`: road friction; `target_model`:
    /// `4dof` or a surrogate file; `settings`: TOML of `PlannerSettings` (missing fields
    /// default).
    #[new]
    #[pyo3(signature = (params = "full_size", mu = 0.9, target_model = "4dof", settings = None))]
    fn new(
        py: Python<'_>,
        params: &str,
        mu: f64,
        target_model: &str,
        settings: Option<&str>,
    ) -> PyResult<Self> {
        let mu = mu_in(mu)?;
        let settings = match settings {
            Some(text) => {
                let s: PlannerSettings = toml::from_str(text)
                    .map_err(|e| plan_err(planner::SettingsError::Parse(e.to_string())))?;
                s.validate().map_err(plan_err)?;
                s
            }
            None => PlannerSettings::default(),
        };
        let set = ParamSet::load(params).map_err(|e| crate::param_err(&e))?;
        let model = self::target_model(py, target_model, &set, mu, settings.dt)?;
        let core = py
            .detach(move || CorePlanner::new(&set, mu, model, settings))
            .map_err(plan_err)?;
        Ok(Self {
            core,
            params: params.to_owned(),
            scene: Scene::default(),
        })
    }

    /// The settings in use, as TOML (`PlannerSettings`).
    fn settings_toml(&self) -> PyResult<String> {
        toml::to_string(self.core.settings()).map_err(plan_err)
    }

    #[getter]
    fn target_model(&self) -> String {
        self.core.target_model_name().to_owned()
    }

    /// The road, a TOML road specification (`dynamics::road::RoadSpec`).
    fn set_road(&mut self, road_toml: &str) -> PyResult<()> {
        self.scene.set_road(road_toml)
    }

    /// A straight road of `length` m, `lanes` lanes of `lane_width` m and `shoulder` m on
    /// each side, starting at the origin along +X.
    #[pyo3(signature = (length = 2000.0, lanes = 3, lane_width = 3.5, shoulder = 1.0))]
    fn set_straight_road(
        &mut self,
        length: f64,
        lanes: i64,
        lane_width: f64,
        shoulder: f64,
    ) -> PyResult<()> {
        self.scene
            .set_straight_road(length, lanes, lane_width, shoulder)
    }

    /// Obstacles as an (n, 7) array of `[x, y, heading, vx, vy, length, width]` (the centre
    /// at time 0 and a constant world velocity); at most 32.
    fn set_obstacles(&mut self, obstacles: &Bound<'_, PyAny>) -> PyResult<()> {
        self.scene.set_obstacles(obstacles)
    }

    /// One decision: search the candidates (sides × window starts) and return the decision
    /// package. `side` restricts the search to a committed side; `best_effort` returns the
    /// best infeasible candidate as a PIT (a PIT under way). The GIL is released meanwhile.
    #[pyo3(signature = (time, target, bullet, target_input = None, side = None, best_effort = false))]
    #[allow(clippy::too_many_arguments)]
    fn plan<'py>(
        &mut self,
        py: Python<'py>,
        time: f64,
        target: &Bound<'py, PyAny>,
        bullet: &Bound<'py, PyAny>,
        target_input: Option<&Bound<'py, PyAny>>,
        side: Option<&str>,
        best_effort: bool,
    ) -> PyResult<Bound<'py, PyDict>> {
        let args = StateArgs::parse(time, target, bullet, target_input)?;
        let side = side_in(side)?;
        self.detached(py, &args, side, best_effort, |core, input| {
            core.plan(input).map(|_| ())
        })
    }

    /// The free prediction (no force) as a package of `mode` (`chase`, `pit`, `stabilise`
    /// or `abort`).
    #[pyo3(signature = (mode, time, target, bullet, target_input = None))]
    fn predict<'py>(
        &mut self,
        py: Python<'py>,
        mode: &str,
        time: f64,
        target: &Bound<'py, PyAny>,
        bullet: &Bound<'py, PyAny>,
        target_input: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let mode = mode_in(mode)?;
        let args = StateArgs::parse(time, target, bullet, target_input)?;
        self.detached(py, &args, None, false, move |core, input| {
            core.predict(mode, input).map(|_| ())
        })
    }

    fn __repr__(&self) -> String {
        format!(
            "Planner(params={:?}, target_model={:?}, steps={})",
            self.params,
            self.core.target_model_name(),
            self.core.settings().steps()
        )
    }
}

/// The whole-maneuver controller: upper layer, coupled MPC and phase machine.
#[pyclass(module = "picopit._core", name = "PitController")]
pub struct PyPitController {
    core: CoreController,
    params: String,
    scene: Scene,
}

#[pymethods]
impl PyPitController {
    /// `settings`: TOML of `ControllerSettings` (tables `planner`, `phases`, `mpc`; missing
    /// fields default). `upper_layer=False` is the ablation without the decision layer; a
    /// settings text that sets `upper_layer` to the other value is an error.
    #[new]
    #[pyo3(signature = (params = "full_size", mu = 0.9, target_model = "4dof", settings = None, upper_layer = true))]
    fn new(
        py: Python<'_>,
        params: &str,
        mu: f64,
        target_model: &str,
        settings: Option<&str>,
        upper_layer: bool,
    ) -> PyResult<Self> {
        let mu = mu_in(mu)?;
        let mut settings = match settings {
            Some(text) => {
                let s = ControllerSettings::from_toml_str(text).map_err(plan_err)?;
                let table: toml::Table = toml::from_str(text).map_err(plan_err)?;
                if table.contains_key("upper_layer") && s.upper_layer != upper_layer {
                    return Err(PlannerError::new_err(format!(
                        "upper_layer: the argument ({upper_layer}) contradicts the settings ({})",
                        s.upper_layer
                    )));
                }
                s
            }
            None => ControllerSettings::default(),
        };
        settings.upper_layer = upper_layer;
        let set = ParamSet::load(params).map_err(|e| crate::param_err(&e))?;
        let dt = settings.mpc.dt;
        let mpc_model = self::target_model(py, target_model, &set, mu, dt)?;
        let planner_model = self::target_model(py, target_model, &set, mu, dt)?;
        let core = py
            .detach(move || CoreController::new(&set, mu, mpc_model, planner_model, settings))
            .map_err(plan_err)?;
        Ok(Self {
            core,
            params: params.to_owned(),
            scene: Scene::default(),
        })
    }

    /// The settings in use, as TOML (`ControllerSettings`).
    fn settings_toml(&self) -> String {
        self.core.settings().to_toml_string()
    }

    #[getter]
    fn target_model(&self) -> String {
        self.core.target_model_name().to_owned()
    }

    #[getter]
    fn upper_layer(&self) -> bool {
        self.core.settings().upper_layer
    }

    /// `chasing`, `pit`, `stabilising`, `done` or `aborted`.
    #[getter]
    fn phase(&self) -> &'static str {
        phase_str(self.core.phase())
    }

    /// Why the maneuver was aborted, or None (as `step()["abort"]`).
    #[getter]
    fn abort_reason(&self) -> Option<String> {
        self.core.abort_reason().map(abort_str)
    }

    /// The road, a TOML road specification (`dynamics::road::RoadSpec`).
    fn set_road(&mut self, road_toml: &str) -> PyResult<()> {
        self.scene.set_road(road_toml)
    }

    /// A straight road (as `Planner.set_straight_road`).
    #[pyo3(signature = (length = 2000.0, lanes = 3, lane_width = 3.5, shoulder = 1.0))]
    fn set_straight_road(
        &mut self,
        length: f64,
        lanes: i64,
        lane_width: f64,
        shoulder: f64,
    ) -> PyResult<()> {
        self.scene
            .set_straight_road(length, lanes, lane_width, shoulder)
    }

    /// Obstacles as an (n, 7) array (as `Planner.set_obstacles`).
    fn set_obstacles(&mut self, obstacles: &Bound<'_, PyAny>) -> PyResult<()> {
        self.scene.set_obstacles(obstacles)
    }

    /// One control step at `time` (s, on the obstacles' clock). The GIL is released
    /// meanwhile.
    #[pyo3(signature = (time, target, bullet, target_input = None))]
    fn step<'py>(
        &mut self,
        py: Python<'py>,
        time: f64,
        target: &Bound<'py, PyAny>,
        bullet: &Bound<'py, PyAny>,
        target_input: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let a = StateArgs::parse(time, target, bullet, target_input)?;
        let Self { core, scene, .. } = self;
        let road = scene.road()?;
        let obstacles = &scene.obstacles;
        let out = py
            .detach(|| {
                core.step(&ControllerInput {
                    time: a.time,
                    target: a.target,
                    bullet: a.bullet,
                    target_input: a.target_input,
                    road,
                    obstacles,
                })
            })
            .map_err(plan_err)?;
        let d = PyDict::new(py);
        d.set_item("command", PyArray1::from_slice(py, out.command.as_slice()))?;
        d.set_item("phase", phase_str(out.phase))?;
        d.set_item("mode", out.mode.map(mode_str))?;
        d.set_item("abort", out.abort.map(abort_str))?;
        d.set_item("mpc_status", out.mpc_status.map(|s| format!("{s:?}")))?;
        d.set_item("replanned", out.replanned)?;
        d.set_item("plan_time", out.plan_time)?;
        d.set_item("ctrl_time", out.ctrl_time)?;
        Ok(d)
    }

    /// The last decision package (as `Planner.plan`), or None without the upper layer.
    fn package<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyDict>>> {
        self.core.package().map(|p| package_dict(py, p)).transpose()
    }

    /// Start a new maneuver: phase chasing at the next step, no plan, MPC warm start dropped.
    fn reset(&mut self) {
        self.core.reset();
    }

    fn __repr__(&self) -> String {
        format!(
            "PitController(params={:?}, target_model={:?}, upper_layer={}, phase={:?})",
            self.params,
            self.core.target_model_name(),
            self.core.settings().upper_layer,
            phase_str(self.core.phase())
        )
    }
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("PlannerError", m.py().get_type::<PlannerError>())?;
    m.add_class::<PyPlanner>()?;
    m.add_class::<PyPitController>()
}
