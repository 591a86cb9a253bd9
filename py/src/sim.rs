//! Bindings of the scenario dataset (`crates/sim`): load and validate scenario files and
//! lines, screen a scenario on the plant, and the road geometry the generator needs. The
//! GIL is released around file reading, validation and simulation.

use ::sim::scenario::{RoadDef, Scenario, ScenarioError as CoreError};
use ::sim::screen::{screen, ScreenSettings};
use numpy::{AllowTypeChange, PyArray2, PyArrayLikeDyn};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;

pyo3::create_exception!(
    picopit,
    ScenarioError,
    PyValueError,
    "A scenario file or line that cannot be used; the message names the line and the field."
);

fn scenario_err(e: &CoreError) -> PyErr {
    ScenarioError::new_err(e.to_string())
}

/// A JSON text as Python objects (through the `json` module).
fn json_to_py<'py>(py: Python<'py>, text: &str) -> PyResult<Bound<'py, PyAny>> {
    py.import("json")?.call_method1("loads", (text,))
}

/// Read and validate a JSON-lines scenario file; returns the scenarios as dicts. A bad line
/// raises ScenarioError naming its line number and field.
#[pyfunction]
fn load_scenarios<'py>(py: Python<'py>, path: &str) -> PyResult<Vec<Bound<'py, PyAny>>> {
    let path = path.to_owned();
    let lines: Vec<String> = py
        .detach(move || {
            ::sim::load_jsonl(&path).map(|v| v.iter().map(Scenario::to_json_line).collect())
        })
        .map_err(|e| scenario_err(&e))?;
    lines.iter().map(|l| json_to_py(py, l)).collect()
}

/// Validate one scenario (a JSON object as text); errors name `line` and the field.
/// Returns the scenario as a dict (canonical: defaults filled in).
#[pyfunction]
#[pyo3(signature = (text, line = 1))]
fn validate_scenario_line<'py>(
    py: Python<'py>,
    text: &str,
    line: usize,
) -> PyResult<Bound<'py, PyAny>> {
    let owned = text.to_owned();
    let canonical = py
        .detach(move || Scenario::from_json_line(&owned, line).map(|s| s.to_json_line()))
        .map_err(|e| scenario_err(&e))?;
    json_to_py(py, &canonical)
}

/// Screen one scenario (JSON text): geometry rules, then the target alone on the plant
/// until T_max. Returns `verdict` (keep, trivial, impossible, rejected), `reason`,
/// `t_fail`, `t_stop` (None if not), `t_reach`, `simulated`, `min_margin`.
#[pyfunction]
fn screen_scenario<'py>(py: Python<'py>, text: &str) -> PyResult<Bound<'py, PyDict>> {
    let owned = text.to_owned();
    let report = py
        .detach(move || {
            let sc = Scenario::from_json_line(&owned, 1)?;
            screen(&sc, &ScreenSettings::default())
        })
        .map_err(|e| scenario_err(&e))?;
    let d = PyDict::new(py);
    d.set_item("verdict", report.verdict.name())?;
    d.set_item("reason", report.reason)?;
    d.set_item("t_fail", report.t_fail)?;
    d.set_item("t_stop", report.t_stop)?;
    d.set_item("t_reach", report.t_reach)?;
    d.set_item("simulated", report.simulated)?;
    d.set_item("min_margin", report.min_margin)?;
    Ok(d)
}

/// Initial states of a scenario (JSON text): `bullet` `[X, Y, yaw, vx, vy, r]` and
/// `target` `[vx, vy, yaw, r, p, phi, X, Y]`, world frame.
#[pyfunction]
fn scenario_initial_states<'py>(py: Python<'py>, text: &str) -> PyResult<Bound<'py, PyDict>> {
    let sc = Scenario::from_json_line(text, 1).map_err(|e| scenario_err(&e))?;
    let road = sc.build_road().map_err(|e| scenario_err(&e))?;
    let d = PyDict::new(py);
    d.set_item(
        "bullet",
        numpy::PyArray1::from_slice(py, &sc.bullet_state(&road)),
    )?;
    d.set_item(
        "target",
        numpy::PyArray1::from_slice(py, sc.target_state(&road).as_slice()),
    )?;
    Ok(d)
}

/// Reference-line poses `[x, y, heading]` (n, 3) of a scenario road (the `road` object as
/// JSON text) at stations `s` (m); with `d` (same length) the points are offset laterally.
#[pyfunction]
#[pyo3(signature = (road, s, d = None))]
fn road_poses<'py>(
    py: Python<'py>,
    road: &str,
    s: &Bound<'py, PyAny>,
    d: Option<&Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let def: RoadDef =
        serde_json::from_str(road).map_err(|e| ScenarioError::new_err(format!("road: {e}")))?;
    let built = def.build().map_err(|e| scenario_err(&e))?;
    let floats = |obj: &Bound<'py, PyAny>, name: &str| -> PyResult<Vec<f64>> {
        let arr = obj
            .extract::<PyArrayLikeDyn<'_, f64, AllowTypeChange>>()
            .map_err(|e| PyValueError::new_err(format!("{name}: expected a float array ({e})")))?;
        let v: Vec<f64> = arr.as_array().iter().copied().collect();
        if let Some((i, x)) = v.iter().enumerate().find(|(_, x)| !x.is_finite()) {
            return Err(PyValueError::new_err(format!(
                "{name}[{i}] = {x}: must be finite"
            )));
        }
        Ok(v)
    };
    let s = floats(s, "s")?;
    let d = match d {
        Some(obj) => {
            let d = floats(obj, "d")?;
            if d.len() != s.len() {
                return Err(PyValueError::new_err(format!(
                    "d: {} values for {} stations",
                    d.len(),
                    s.len()
                )));
            }
            d
        }
        None => vec![0.0; s.len()],
    };
    let rows: Vec<Vec<f64>> = s
        .iter()
        .zip(&d)
        .map(|(&si, &di)| {
            let pose = built.pose_at(si);
            let p = built.to_world(si, di);
            vec![p.x, p.y, pose.heading]
        })
        .collect();
    if rows.is_empty() {
        return Ok(PyArray2::zeros(py, [0, 3], false));
    }
    Ok(PyArray2::from_vec2(py, &rows).expect("rows have equal length"))
}

/// Frenet coordinates `[s, d, heading]` (n, 3) of world points `(x[i], y[i])` on a scenario
/// road (the `road` object as JSON text): the station and lateral offset of the nearest
/// point of the reference line (m, `d` positive to the left) and the road's heading there.
#[pyfunction]
fn road_project<'py>(
    py: Python<'py>,
    road: &str,
    x: Vec<f64>,
    y: Vec<f64>,
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let def: RoadDef =
        serde_json::from_str(road).map_err(|e| ScenarioError::new_err(format!("road: {e}")))?;
    let built = def.build().map_err(|e| scenario_err(&e))?;
    if x.len() != y.len() {
        return Err(PyValueError::new_err(format!(
            "y: {} values for {} x values",
            y.len(),
            x.len()
        )));
    }
    let rows: Vec<Vec<f64>> = x
        .iter()
        .zip(&y)
        .map(|(&xi, &yi)| {
            if xi.is_finite() && yi.is_finite() {
                let f = built.project(dynamics::geometry::Vec2::new(xi, yi));
                vec![f.s, f.d, f.heading]
            } else {
                vec![f64::NAN; 3]
            }
        })
        .collect();
    if rows.is_empty() {
        return Ok(PyArray2::zeros(py, [0, 3], false));
    }
    Ok(PyArray2::from_vec2(py, &rows).expect("rows have equal length"))
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("ScenarioError", m.py().get_type::<ScenarioError>())?;
    m.add_function(wrap_pyfunction!(load_scenarios, m)?)?;
    m.add_function(wrap_pyfunction!(validate_scenario_line, m)?)?;
    m.add_function(wrap_pyfunction!(screen_scenario, m)?)?;
    m.add_function(wrap_pyfunction!(scenario_initial_states, m)?)?;
    m.add_function(wrap_pyfunction!(road_poses, m)?)?;
    m.add_function(wrap_pyfunction!(road_project, m)?)
}
