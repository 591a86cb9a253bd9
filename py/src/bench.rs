//! Bindings of the closed-loop episode runner (`sim::episode`): one episode per call, the
//! GIL released while it runs, results as a flat dict of Python scalars plus numpy arrays.

use ::sim::episode::{
    phase_name, run_episode as core_run, EpisodeConfig, EpisodeError as CoreError, Sample,
};
use ::sim::scenario::Scenario;
use numpy::{PyArray1, ToPyArray};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;

pyo3::create_exception!(
    picopit,
    EpisodeError,
    PyValueError,
    "An episode that cannot be run: a bad configuration (the message names the field), a model \
     file that cannot be loaded, or settings the controller refuses."
);

fn episode_err(e: &CoreError) -> PyErr {
    match e {
        CoreError::Scenario(s) => crate::sim::ScenarioError::new_err(s.to_string()),
        other => EpisodeError::new_err(other.to_string()),
    }
}

/// Parse and validate a configuration: a preset name (`4dof`, `pinn`, `picopinn`,
/// `picopinn_no_upper`) or a JSON object (optionally `{"preset": NAME, …overrides}`).
fn parse_config(config: &str, models_dir: Option<&str>) -> Result<EpisodeConfig, CoreError> {
    let mut cfg = EpisodeConfig::parse(config)?;
    if let Some(dir) = models_dir {
        cfg.models_dir = dir.into();
    }
    Ok(cfg)
}

/// The benchmark's preset configuration names.
#[pyfunction]
fn episode_presets() -> Vec<String> {
    EpisodeConfig::PRESETS
        .iter()
        .map(|s| (*s).to_owned())
        .collect()
}

/// The resolved configuration (preset name or JSON) as a dict; raises EpisodeError naming
/// the field at fault.
#[pyfunction]
fn episode_config<'py>(py: Python<'py>, config: &str) -> PyResult<Bound<'py, PyAny>> {
    let cfg = parse_config(config, None).map_err(|e| episode_err(&e))?;
    let text = serde_json::to_string(&cfg).map_err(|e| EpisodeError::new_err(e.to_string()))?;
    py.import("json")?.call_method1("loads", (text,))
}

/// Column names of the recorded trajectory array.
#[pyfunction]
fn trajectory_columns() -> Vec<String> {
    Sample::COLUMNS.iter().map(|s| (*s).to_owned()).collect()
}

/// Run one closed-loop episode: `scenario` is one scenario as JSON text, `config` a preset
/// name or a JSON configuration, `seed` seeds the sensing noise and actuator errors. With
/// `record` the result holds the trajectory (one row per control step) and the upper
/// layer's plans (`plans`: `time`, `mode`, `reason` (why an abort: the race lost or the
/// infeasibility, else None), `side`, `hold_back` (the bullet held back behind the target for an obstacle), `push_from`, `push_to`, `push_peak`, `push_impulse` (∫F_n dt, N s),
/// `predicted_heading_error`, `predicted_time` and `predicted_target` (the plan's step times
/// and predicted target states); empty without `record`). The GIL is
/// released while the episode runs.
#[pyfunction]
#[pyo3(signature = (scenario, config, seed = 0, record = false, models_dir = None))]
fn run_episode<'py>(
    py: Python<'py>,
    scenario: &str,
    config: &str,
    seed: u64,
    record: bool,
    models_dir: Option<&str>,
) -> PyResult<Bound<'py, PyDict>> {
    let text = scenario.to_owned();
    let mut cfg = parse_config(config, models_dir).map_err(|e| episode_err(&e))?;
    cfg.record |= record;
    let r = py
        .detach(move || {
            let sc = Scenario::from_json_line(&text, 1)?;
            core_run(&sc, &cfg, seed)
        })
        .map_err(|e| episode_err(&e))?;
    let d = PyDict::new(py);
    let m = &r.metrics;
    d.set_item("scenario", &r.scenario)?;
    d.set_item("config", &r.config)?;
    d.set_item("seed", r.seed)?;
    d.set_item("model", &r.model)?;
    d.set_item("param_count", r.param_count)?;
    d.set_item("upper_layer", r.upper_layer)?;
    d.set_item("success", m.success)?;
    d.set_item("at_rest", m.at_rest)?;
    d.set_item("cause", m.cause.map(|c| c.name()))?;
    d.set_item("decided_at", m.decided_at)?;
    d.set_item("terminal_heading_error", m.terminal_heading_error)?;
    d.set_item("min_margin", m.min_margin)?;
    d.set_item("boundary_violation", m.boundary_violation)?;
    d.set_item("secondary_collision", m.secondary_collision)?;
    d.set_item("contacts", m.contacts)?;
    d.set_item("contact_at", m.contact_at)?;
    d.set_item("impact_speed", m.impact_speed)?;
    d.set_item("impact_angle", m.impact_angle)?;
    d.set_item("impact_x", m.impact_point.map(|p| p[0]))?;
    d.set_item("impact_y", m.impact_point.map(|p| p[1]))?;
    d.set_item("reversed_at", m.reversed_at)?;
    d.set_item("reversed_speed", m.reversed_speed)?;
    d.set_item(
        "failed_vehicle",
        m.failed_vehicle.map(|p| match p {
            ::sim::outcome::Party::Bullet => "bullet",
            ::sim::outcome::Party::Target => "target",
            ::sim::outcome::Party::Both => "both",
        }),
    )?;
    d.set_item("sim_time", r.sim_time)?;
    d.set_item("control_steps", r.control_steps)?;
    for (prefix, s) in [("plan", &r.plan), ("ctrl", &r.ctrl)] {
        d.set_item(format!("{prefix}_count"), s.count)?;
        d.set_item(format!("{prefix}_ms_median"), s.median_ms)?;
        d.set_item(format!("{prefix}_ms_p99"), s.p99_ms)?;
        d.set_item(format!("{prefix}_ms_max"), s.max_ms)?;
    }
    d.set_item("final_phase", phase_name(r.final_phase))?;
    d.set_item("abort", r.abort.as_deref())?;
    d.set_item("mpc_failures", r.mpc_failures)?;
    d.set_item("mpc_time_budget", r.mpc_time_budget)?;
    d.set_item("held_back_until", r.held_back_until)?;
    d.set_item("wall_time", r.wall_time)?;
    d.set_item("plan_times_ms", PyArray1::from_slice(py, &r.plan_times_ms))?;
    d.set_item("ctrl_times_ms", PyArray1::from_slice(py, &r.ctrl_times_ms))?;
    // The upper layer's plans (recorded with the trajectory): when, the mode, the span of
    // plan steps with a planned push and its peak normal force, the predicted heading error.
    let plans = pyo3::types::PyList::empty(py);
    for p in &r.plans {
        let dt = p.predicted.get(1).map_or(0.0, |b| b.0 - p.predicted[0].0);
        let pushed: Vec<_> = p.predicted.iter().filter(|s| s.2[0] > 0.0).collect();
        let plan = PyDict::new(py);
        plan.set_item("time", p.time)?;
        plan.set_item(
            "mode",
            serde_json::to_value(p.mode)
                .ok()
                .and_then(|v| v.as_str().map(str::to_owned)),
        )?;
        plan.set_item(
            "reason",
            if p.race_lost {
                Some("race lost".to_owned())
            } else {
                p.infeasible.map(|i| i.describe().to_owned())
            },
        )?;
        plan.set_item("side", if p.side_sign > 0.0 { "left" } else { "right" })?;
        plan.set_item("hold_back", p.hold_back)?;
        plan.set_item("push_from", pushed.first().map(|s| s.0))?;
        plan.set_item("push_to", pushed.last().map(|s| s.0 + dt))?;
        plan.set_item(
            "push_peak",
            pushed.iter().map(|s| s.2[0]).fold(0.0, f64::max),
        )?;
        plan.set_item(
            "push_impulse",
            pushed.iter().map(|s| s.2[0] * dt).sum::<f64>(),
        )?;
        plan.set_item("predicted_heading_error", p.predicted_heading_error)?;
        // The whole prediction: step start times and the predicted target states.
        let times: Vec<f64> = p.predicted.iter().map(|s| s.0).collect();
        let states: Vec<f64> = p.predicted.iter().flat_map(|s| s.1).collect();
        plan.set_item("predicted_time", PyArray1::from_vec(py, times))?;
        plan.set_item("predicted_target", crate::planner::rows_out(py, states, 8)?)?;
        plans.append(plan)?;
    }
    d.set_item("plans", plans)?;
    if r.trajectory.is_empty() {
        d.set_item("trajectory", py.None())?;
    } else {
        let n = r.trajectory.len();
        let last = n - 1;
        let mut flat = Vec::with_capacity(n * Sample::COLUMNS.len());
        for (i, s) in r.trajectory.iter().enumerate() {
            flat.extend_from_slice(&s.row(i == last && m.decided_at.is_some()));
        }
        let arr = numpy::ndarray::Array2::from_shape_vec((n, Sample::COLUMNS.len()), flat)
            .map_err(|e| EpisodeError::new_err(e.to_string()))?;
        d.set_item("trajectory", arr.to_pyarray(py))?;
    }
    Ok(d)
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("EpisodeError", m.py().get_type::<EpisodeError>())?;
    m.add_function(wrap_pyfunction!(episode_presets, m)?)?;
    m.add_function(wrap_pyfunction!(episode_config, m)?)?;
    m.add_function(wrap_pyfunction!(trajectory_columns, m)?)?;
    m.add_function(wrap_pyfunction!(run_episode, m)?)
}
