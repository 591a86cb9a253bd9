//! `picopit._core`: thin pyo3 bindings to the picopit Rust core. No physics lives here.
//!
//! Rules at this boundary:
//! * every array argument is validated (shape, finiteness) and COPIED into owned nalgebra
//!   types before it reaches the core; no nalgebra view is ever built over numpy memory
//!   (nalgebra 0.35 mis-multiplies views with non-unit row stride);
//! * the GIL is released (`Python::detach`) around every simulation call;
//! * each Rust error type has its own Python exception (`ParamError` for
//!   `dynamics::ParamError`, a subclass of `ValueError`).

use dynamics::geometry::{Obb, Pose2};
use dynamics::params::ParamSet;
use nalgebra::{SMatrix, SVector};
use numpy::{AllowTypeChange, PyArray1, PyArray2, PyArray3, PyArrayLikeDyn, ToPyArray};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

mod bench;
mod models;
mod mpc;
mod oracle;
mod planner;
mod plant;
mod sim;
mod surrogate;

pyo3::create_exception!(
    picopit,
    ParamError,
    PyValueError,
    "A parameter set or parameter file that cannot be used; the message names the field."
);

/// An `(n, C)` float array, checked (shape, finiteness) and copied. Errors are messages that
/// name `name`; each binding raises them as its own exception.
pub(crate) fn table<const C: usize>(
    obj: &Bound<'_, PyAny>,
    name: &str,
) -> Result<Vec<[f64; C]>, String> {
    let arr = obj
        .extract::<PyArrayLikeDyn<'_, f64, AllowTypeChange>>()
        .map_err(|e| format!("{name}: expected a float array ({e})"))?;
    let view = arr.as_array();
    let shape = view.shape().to_vec();
    if shape.len() != 2 || shape[1] != C {
        return Err(format!("{name}: expected shape (n, {C}), got {shape:?}"));
    }
    let mut rows = vec![[0.0; C]; shape[0]];
    for (ix, v) in view.indexed_iter() {
        let (i, j) = (ix[0], ix[1]);
        if !v.is_finite() {
            return Err(format!("{name}[{i}, {j}] = {v}: must be finite"));
        }
        rows[i][j] = *v;
    }
    Ok(rows)
}

/// Obstacles from an `(n, 7)` array of `[x, y, heading, vx, vy, length, width]`, each
/// validated (the message names `obstacles[i].field`).
pub(crate) fn obstacles_arg(
    obj: &Bound<'_, PyAny>,
) -> Result<Vec<dynamics::road::Obstacle>, String> {
    table::<7>(obj, "obstacles")?
        .iter()
        .enumerate()
        .map(|(i, r)| {
            let o = dynamics::road::Obstacle {
                x: r[0],
                y: r[1],
                heading: r[2],
                vx: r[3],
                vy: r[4],
                length: r[5],
                width: r[6],
            };
            o.validate()
                .map(|()| o)
                .map_err(|e| e.within(&format!("obstacles[{i}]")).to_string())
        })
        .collect()
}

/// Map the core's parameter error onto the Python exception.
pub(crate) fn param_err(e: &dynamics::ParamError) -> PyErr {
    ParamError::new_err(e.to_string())
}

/// Copy a 1-D float array-like of length `N` into an owned vector, naming `name` in errors.
pub(crate) fn vec_arg<const N: usize>(
    obj: &Bound<'_, PyAny>,
    name: &str,
) -> PyResult<SVector<f64, N>> {
    let arr = obj
        .extract::<PyArrayLikeDyn<'_, f64, AllowTypeChange>>()
        .map_err(|e| {
            PyValueError::new_err(format!("{name}: expected an array of {N} floats ({e})"))
        })?;
    let view = arr.as_array();
    if view.shape() != [N] {
        return Err(PyValueError::new_err(format!(
            "{name}: expected shape ({N},), got {:?}",
            view.shape()
        )));
    }
    let mut out = SVector::<f64, N>::zeros();
    // ndarray iterates in logical order whatever the strides; the copy is element by element.
    for (i, v) in view.iter().enumerate() {
        if !v.is_finite() {
            return Err(PyValueError::new_err(format!(
                "{name}[{i}] = {v}: must be finite"
            )));
        }
        out[i] = *v;
    }
    Ok(out)
}

/// A finite float scalar, naming `name` in errors.
pub(crate) fn finite(value: f64, name: &str) -> PyResult<f64> {
    if value.is_finite() {
        Ok(value)
    } else {
        Err(PyValueError::new_err(format!(
            "{name} = {value}: must be finite"
        )))
    }
}

/// A finite, strictly positive float scalar.
pub(crate) fn positive(value: f64, name: &str) -> PyResult<f64> {
    if value.is_finite() && value > 0.0 {
        Ok(value)
    } else {
        Err(PyValueError::new_err(format!(
            "{name} = {value}: must be finite and positive"
        )))
    }
}

/// A new 1-D numpy array with a copy of `v`.
pub(crate) fn vec_out<'py, const N: usize>(
    py: Python<'py>,
    v: &SVector<f64, N>,
) -> Bound<'py, PyArray1<f64>> {
    PyArray1::from_slice(py, v.as_slice())
}

/// A new C-order 2-D numpy array with a copy of `m` (nalgebra stores column-major).
pub(crate) fn mat_out<'py, const R: usize, const C: usize>(
    py: Python<'py>,
    m: &SMatrix<f64, R, C>,
) -> Bound<'py, PyArray2<f64>> {
    let rows: Vec<Vec<f64>> = (0..R)
        .map(|i| (0..C).map(|j| m[(i, j)]).collect())
        .collect();
    PyArray2::from_vec2(py, &rows).expect("rows have equal length")
}

/// Corners of oriented rectangles as an (n, 4, 2) array, counter-clockwise from front-left.
pub(crate) fn corners_out<'py>(py: Python<'py>, boxes: &[Obb]) -> Bound<'py, PyArray3<f64>> {
    let mut flat = Vec::with_capacity(boxes.len() * 8);
    for b in boxes {
        for c in b.corners() {
            flat.push(c.x);
            flat.push(c.y);
        }
    }
    numpy::ndarray::Array3::from_shape_vec((boxes.len(), 4, 2), flat)
        .expect("8 values per box")
        .to_pyarray(py)
}

/// Load and validate a parameter set (a built-in name or a TOML path); returns it as TOML.
#[pyfunction]
fn load_params(py: Python<'_>, name_or_path: &str) -> PyResult<String> {
    let name = name_or_path.to_owned();
    py.detach(move || ParamSet::load(&name).map(|p| p.to_toml_string()))
        .map_err(|e| param_err(&e))
}

/// Names of the built-in parameter sets.
#[pyfunction]
fn builtin_param_sets() -> Vec<String> {
    ParamSet::BUILTIN.iter().map(|s| (*s).to_owned()).collect()
}

/// Corners (4, 2) of a vehicle footprint whose c.g. is at `pose = [X, Y, yaw]`.
#[pyfunction]
fn footprint<'py>(
    py: Python<'py>,
    pose: &Bound<'py, PyAny>,
    length: f64,
    width: f64,
    cg_to_front: f64,
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let p = vec_arg::<3>(pose, "pose")?;
    let length = positive(length, "length")?;
    let width = positive(width, "width")?;
    let cg_to_front = finite(cg_to_front, "cg_to_front")?;
    let obb = Obb::vehicle_footprint(&Pose2::new(p[0], p[1], p[2]), length, width, cg_to_front);
    let rows: Vec<Vec<f64>> = obb.corners().iter().map(|c| vec![c.x, c.y]).collect();
    Ok(PyArray2::from_vec2(py, &rows).expect("rows have equal length"))
}

/// Where two vehicle footprints overlap (the plant's separating-axis test): a dict with the
/// world heading `gamma` of the contact normal (from the first vehicle into the second), the
/// contact `point` `[X, Y]` and the penetration `depth` (m), or `None` when they do not overlap.
/// Each vehicle is `pose = [X, Y, yaw]` of its c.g. and `size = [length, width, cg_to_front]`.
#[pyfunction]
fn footprint_contact<'py>(
    py: Python<'py>,
    pose_a: &Bound<'py, PyAny>,
    size_a: &Bound<'py, PyAny>,
    pose_b: &Bound<'py, PyAny>,
    size_b: &Bound<'py, PyAny>,
) -> PyResult<Option<Bound<'py, pyo3::types::PyDict>>> {
    let obb = |pose: &Bound<'py, PyAny>, size: &Bound<'py, PyAny>, who: &str| -> PyResult<Obb> {
        let p = vec_arg::<3>(pose, &format!("pose_{who}"))?;
        let s = vec_arg::<3>(size, &format!("size_{who}"))?;
        let length = positive(s[0], &format!("size_{who}[0] (length)"))?;
        let width = positive(s[1], &format!("size_{who}[1] (width)"))?;
        Ok(Obb::vehicle_footprint(
            &Pose2::new(p[0], p[1], p[2]),
            length,
            width,
            s[2],
        ))
    };
    let (a, b) = (obb(pose_a, size_a, "a")?, obb(pose_b, size_b, "b")?);
    let Some(c) = dynamics::contact::obb_contact(&a, &b) else {
        return Ok(None);
    };
    let d = pyo3::types::PyDict::new(py);
    d.set_item("gamma", c.gamma())?;
    d.set_item("point", vec![c.point.x, c.point.y])?;
    d.set_item("depth", c.depth)?;
    Ok(Some(d))
}

/// Wrap an angle to (−π, π].
#[pyfunction]
fn wrap_angle(a: f64) -> f64 {
    dynamics::wrap_angle(a)
}

#[pymodule]
fn _core(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("ParamError", m.py().get_type::<ParamError>())?;
    m.add_function(wrap_pyfunction!(load_params, m)?)?;
    m.add_function(wrap_pyfunction!(builtin_param_sets, m)?)?;
    m.add_function(wrap_pyfunction!(footprint, m)?)?;
    m.add_function(wrap_pyfunction!(footprint_contact, m)?)?;
    m.add_function(wrap_pyfunction!(wrap_angle, m)?)?;
    m.add("GRAVITY", dynamics::GRAVITY)?;
    plant::register(m)?;
    models::register(m)?;
    surrogate::register(m)?;
    mpc::register(m)?;
    sim::register(m)?;
    oracle::register(m)?;
    planner::register(m)?;
    bench::register(m)?;
    Ok(())
}
