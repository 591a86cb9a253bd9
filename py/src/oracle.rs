//! Bindings of the ideal-PIT bound (`sim::oracle`): one scenario per call, the GIL released
//! while its shoves are simulated (a caller's threads then run scenes in parallel).

use ::sim::oracle::{
    ideal_pit as core_ideal_pit, oracle_tiers as core_tiers, shove_grid as core_grid, DriverView,
    OracleSettings, ShoveGrid, TIERS,
};
use ::sim::scenario::{Scenario, ScenarioError as CoreError};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::sim::ScenarioError;

/// The settings from JSON text (`None`: the defaults), validated; errors name the field.
fn settings(text: Option<&str>) -> PyResult<OracleSettings> {
    let s: OracleSettings = match text {
        None => OracleSettings::default(),
        Some(t) => {
            let mut de = serde_json::Deserializer::from_str(t);
            serde_path_to_error::deserialize(&mut de).map_err(|e| {
                ScenarioError::new_err(format!("oracle settings: {}: {}", e.path(), e.inner()))
            })?
        }
    };
    s.validate()
        .map_err(|e: CoreError| ScenarioError::new_err(e.to_string()))?;
    Ok(s)
}

/// The oracle's settings (JSON text over the defaults, `None`: the defaults) as a dict,
/// validated: `shoves` (Δv of the target's c.g., m/s), `time_step` (s), `contact_back`,
/// `min_remaining`, `exhaustive`, `sides`, `window`, `screen`. Raises ScenarioError naming
/// the field.
#[pyfunction]
#[pyo3(signature = (settings_json = None))]
fn oracle_settings<'py>(
    py: Python<'py>,
    settings_json: Option<&str>,
) -> PyResult<Bound<'py, PyAny>> {
    let s = settings(settings_json)?;
    let text = serde_json::to_string(&s).map_err(|e| ScenarioError::new_err(e.to_string()))?;
    py.import("json")?.call_method1("loads", (text,))
}

/// Parses `scenario` (JSON text) and runs `f` on it with the oracle settings, the GIL
/// released; a bad scenario, bad settings or a failed run is a `ScenarioError`.
fn on_scenario<T: Send, E: Send + std::fmt::Display + From<CoreError>>(
    py: Python<'_>,
    scenario: &str,
    settings_json: Option<&str>,
    f: fn(&Scenario, &OracleSettings) -> Result<T, E>,
) -> PyResult<T> {
    let s = settings(settings_json)?;
    let text = scenario.to_owned();
    py.detach(move || {
        let sc = Scenario::from_json_line(&text, 1)?;
        f(&sc, &s)
    })
    .map_err(|e| ScenarioError::new_err(e.to_string()))
}

/// The ideal-PIT bound on one scenario (JSON text): could one rear-quarter shove of the
/// settings' grid (`settings_json`, see `oracle_settings`) at a time the bullet could be
/// there end in success by the benchmark's test? Returns `feasible` (bool), `shove` (the
/// earliest that worked: `time`, `side`, `dv`, `decided_at`, `at_rest`; None), `t_reach`,
/// `tried`, `successes`, `alone_fails_at` (None if the target alone never fails). The GIL
/// is released while it runs.
#[pyfunction]
#[pyo3(signature = (scenario, settings_json = None))]
fn ideal_pit<'py>(
    py: Python<'py>,
    scenario: &str,
    settings_json: Option<&str>,
) -> PyResult<Bound<'py, PyDict>> {
    let r = on_scenario(py, scenario, settings_json, core_ideal_pit)?;
    let d = PyDict::new(py);
    d.set_item("feasible", r.feasible.is_some())?;
    match r.feasible {
        Some(f) => {
            let shove = PyDict::new(py);
            shove.set_item("time", f.time)?;
            shove.set_item("side", f.side)?;
            shove.set_item("dv", f.dv)?;
            shove.set_item("decided_at", f.decided_at)?;
            shove.set_item("at_rest", f.at_rest)?;
            d.set_item("shove", shove)?;
        }
        None => d.set_item("shove", py.None())?,
    }
    d.set_item("t_reach", r.t_reach)?;
    d.set_item("tried", r.tried)?;
    d.set_item("successes", r.successes)?;
    d.set_item("alone_fails_at", r.alone_fails_at)?;
    Ok(d)
}

/// The tiers' names, in the order of `oracle_tiers(...)["tiers"]`.
#[pyfunction]
fn oracle_tier_names() -> Vec<String> {
    TIERS.iter().map(|s| (*s).to_owned()).collect()
}

/// The tiers of the ideal-PIT bound on one scenario (JSON text): the whole grid of shoves
/// simulated with the driver's true law and with its command held, each tier's choice
/// judged in the truth (`sim::oracle::tiers`). Returns `tiers` (a dict name -> chance of
/// success in [0, 1]), `true_share`, `held_share`, `t_reach`, `shoves` (per grid). The GIL
/// is released while it runs.
#[pyfunction]
#[pyo3(signature = (scenario, settings_json = None))]
fn oracle_tiers<'py>(
    py: Python<'py>,
    scenario: &str,
    settings_json: Option<&str>,
) -> PyResult<Bound<'py, PyDict>> {
    let r = on_scenario(py, scenario, settings_json, core_tiers)?;
    let d = PyDict::new(py);
    let tiers = PyDict::new(py);
    for (name, v) in TIERS.iter().zip(r.tiers) {
        tiers.set_item(*name, v)?;
    }
    d.set_item("tiers", tiers)?;
    d.set_item("true_share", r.true_share)?;
    d.set_item("held_share", r.held_share)?;
    d.set_item("t_reach", r.t_reach)?;
    d.set_item("shoves", r.shoves)?;
    Ok(d)
}

fn grid_true(sc: &Scenario, s: &OracleSettings) -> Result<ShoveGrid, CoreError> {
    core_grid(sc, s, DriverView::True)
}

fn grid_held(sc: &Scenario, s: &OracleSettings) -> Result<ShoveGrid, CoreError> {
    core_grid(sc, s, DriverView::Held)
}

/// The whole grid of single shoves on one scenario (JSON text): every candidate time (from
/// the bullet's earliest arrival, every `time_step`) × side × size of the settings,
/// simulated to the benchmark's verdict with the driver's true law (`held`: its command at
/// the shove held). Returns `times` (s), `sides`, `shoves` (m/s), `success` (nested lists
/// `[time][side][shove]` of bool) and `t_reach`. The GIL is released while it runs.
#[pyfunction]
#[pyo3(signature = (scenario, settings_json = None, held = false))]
fn shove_grid<'py>(
    py: Python<'py>,
    scenario: &str,
    settings_json: Option<&str>,
    held: bool,
) -> PyResult<Bound<'py, PyDict>> {
    let g = on_scenario(
        py,
        scenario,
        settings_json,
        if held { grid_held } else { grid_true },
    )?;
    let (ns, nv) = (g.sides.len(), g.shoves.len());
    let success: Vec<Vec<Vec<bool>>> = (0..g.times.len())
        .map(|it| {
            (0..ns)
                .map(|is| g.success[(it * ns + is) * nv..(it * ns + is + 1) * nv].to_vec())
                .collect()
        })
        .collect();
    let d = PyDict::new(py);
    d.set_item("times", g.times)?;
    d.set_item("sides", g.sides)?;
    d.set_item("shoves", g.shoves)?;
    d.set_item("success", success)?;
    d.set_item("t_reach", g.t_reach)?;
    Ok(d)
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(shove_grid, m)?)?;
    m.add_function(wrap_pyfunction!(oracle_settings, m)?)?;
    m.add_function(wrap_pyfunction!(ideal_pit, m)?)?;
    m.add_function(wrap_pyfunction!(oracle_tier_names, m)?)?;
    m.add_function(wrap_pyfunction!(oracle_tiers, m)?)
}
