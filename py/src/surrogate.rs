//! Bindings for the learned target surrogates (`pico_nn::SurrogateModel`: teacher PINN and
//! PicoPINN files, `docs/model-format.md`), with the same `step`/`step_jac` conventions as
//! `FourDofTarget`.

use crate::models::{target_step, target_step_jac, StepJac};
use crate::vec_arg;
use dynamics::TargetModel;
use numpy::PyArray1;
use pico_nn::SurrogateModel as CoreSurrogate;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use std::collections::BTreeMap;
use std::path::PathBuf;

pyo3::create_exception!(
    picopit,
    ModelError,
    PyValueError,
    "A surrogate model file that cannot be used; the message names the metadata key or tensor."
);

/// A teacher PINN or PicoPINN loaded from a `picopit-mlp` v2 safetensors file: state
/// `[vx, vy, yaw, r, p, phi, X, Y]`, input `[delta, T_b]`, one step of the file's `dt`, on a
/// road of adhesion `mu` (default: the file's `mu_default`).
#[pyclass(module = "picopit._core", name = "SurrogateModel")]
pub struct SurrogateModel {
    inner: CoreSurrogate,
}

#[pymethods]
impl SurrogateModel {
    #[new]
    #[pyo3(signature = (path, mu = None))]
    fn new(py: Python<'_>, path: PathBuf, mu: Option<f64>) -> PyResult<Self> {
        let mut inner = py
            .detach(move || CoreSurrogate::from_path(&path))
            .map_err(|e| ModelError::new_err(e.to_string()))?;
        if let Some(mu) = mu {
            inner
                .set_mu(mu)
                .map_err(|e| ModelError::new_err(e.to_string()))?;
        }
        Ok(Self { inner })
    }

    /// Road adhesion μ, the network's last input; settable within `mu_range`.
    #[getter]
    fn mu(&self) -> f64 {
        self.inner.mu()
    }

    #[setter]
    fn set_mu(&mut self, mu: f64) -> PyResult<()> {
        self.inner
            .set_mu(mu)
            .map_err(|e| ModelError::new_err(e.to_string()))
    }

    /// `(lo, hi)`: the road adhesion the model was trained on (the file's `mu_range`).
    #[getter]
    fn mu_range(&self) -> (f64, f64) {
        self.inner.mu_range()
    }

    /// `pinn` or `picopinn` (the file's `kind`).
    #[getter]
    fn name(&self) -> String {
        self.inner.name().to_owned()
    }

    /// Step length (s), from the file.
    #[getter]
    fn dt(&self) -> f64 {
        self.inner.dt()
    }

    /// Free parameters, `len(theta)`.
    #[getter]
    fn param_count(&self) -> usize {
        self.inner.param_count()
    }

    /// Layer widths, input first.
    #[getter]
    fn layers(&self) -> Vec<usize> {
        self.inner.layers().to_vec()
    }

    /// The file's header metadata.
    #[getter]
    fn metadata(&self) -> BTreeMap<String, String> {
        self.inner.metadata().clone()
    }

    /// One step: the next state (8,).
    #[pyo3(signature = (x, u, fc = None, gamma = 0.0, point = None))]
    fn step<'py>(
        &mut self,
        py: Python<'py>,
        x: &Bound<'py, PyAny>,
        u: &Bound<'py, PyAny>,
        fc: Option<&Bound<'py, PyAny>>,
        gamma: f64,
        point: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<Bound<'py, PyArray1<f64>>> {
        target_step(py, &mut self.inner, x, u, fc, gamma, point)
    }

    /// One step with the exact Jacobians of the discrete map:
    /// `(x_next (8,), A (8, 8), B (8, 2), F (8, 2))`.
    #[pyo3(signature = (x, u, fc = None, gamma = 0.0, point = None))]
    fn step_jac<'py>(
        &mut self,
        py: Python<'py>,
        x: &Bound<'py, PyAny>,
        u: &Bound<'py, PyAny>,
        fc: Option<&Bound<'py, PyAny>>,
        gamma: f64,
        point: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<StepJac<'py>> {
        target_step_jac(py, &mut self.inner, x, u, fc, gamma, point)
    }

    /// The increments `o` (8,) (kinematic base included) for the features
    /// `[vx, vy, r, p, phi, delta, T_b, f_bx, f_by, M_z, mu]` (11,); μ is taken from the
    /// features (not range-checked) and the model's own `mu` is left unchanged.
    fn forward<'py>(
        &mut self,
        py: Python<'py>,
        features: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyArray1<f64>>> {
        let z = vec_arg::<11>(features, "features")?;
        let o = self.inner.forward_features(&z.into());
        Ok(PyArray1::from_slice(py, &o))
    }
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("ModelError", m.py().get_type::<ModelError>())?;
    m.add_class::<SurrogateModel>()?;
    Ok(())
}
