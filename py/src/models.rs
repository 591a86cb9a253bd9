//! Bindings for the control-oriented models: the bullet single-track model
//! (`dynamics::bullet`) and the 4-DOF analytic target model (`dynamics::target4dof`, the
//! first `TargetModel`).

use crate::{finite, mat_out, param_err, vec_arg, vec_out};
use dynamics::bullet::{BulletJacobians, BulletModel as CoreBullet};
use dynamics::geometry::Vec2;
use dynamics::params::{ParamSet, VehicleParams};
use dynamics::target4dof::FourDofTarget as CoreFourDof;
use dynamics::{ContactInput, TargetJacobians, TargetModel};
use nalgebra::{SMatrix, SVector};
use numpy::{PyArray1, PyArray2};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

/// `(x_next, A, B, F)` as numpy arrays.
pub(crate) type StepJac<'py> = (
    Bound<'py, PyArray1<f64>>,
    Bound<'py, PyArray2<f64>>,
    Bound<'py, PyArray2<f64>>,
    Bound<'py, PyArray2<f64>>,
);

/// Load a parameter set and pick one vehicle out of it.
fn vehicle_params(py: Python<'_>, params: &str, vehicle: &str) -> PyResult<VehicleParams> {
    if vehicle != "bullet" && vehicle != "target" {
        return Err(PyValueError::new_err(format!(
            "vehicle = {vehicle:?}: must be \"bullet\" or \"target\""
        )));
    }
    let name = params.to_owned();
    let set = py
        .detach(move || ParamSet::load(&name))
        .map_err(|e| param_err(&e))?;
    Ok(if vehicle == "bullet" {
        set.bullet
    } else {
        set.target
    })
}

/// Road adhesion, step length and sub-step count, checked.
fn settings(mu: f64, dt: f64, substeps: Option<usize>) -> PyResult<(f64, f64, Option<usize>)> {
    if !(mu.is_finite() && mu > 0.0 && mu <= 1.5) {
        return Err(PyValueError::new_err(format!(
            "mu = {mu}: must lie in (0, 1.5]"
        )));
    }
    if !(dt.is_finite() && dt > 0.0 && dt <= 1.0) {
        return Err(PyValueError::new_err(format!(
            "dt = {dt}: must lie in (0, 1] s"
        )));
    }
    if let Some(substeps) = substeps.filter(|n| !(1..=1000).contains(n)) {
        return Err(PyValueError::new_err(format!(
            "substeps = {substeps}: must lie in [1, 1000]"
        )));
    }
    Ok((mu, dt, substeps))
}

/// The contact arguments shared by every `step`: `fc = [F_n, F_t]` on the target in the
/// contact frame (the bullet receives `-fc`), `gamma` the world heading of the normal,
/// `point` the point of action in the receiving body's frame relative to its c.g. `None`
/// means zero.
fn contact_arg(
    fc: Option<&Bound<'_, PyAny>>,
    gamma: f64,
    point: Option<&Bound<'_, PyAny>>,
) -> PyResult<ContactInput> {
    let fc = fc
        .map(|a| vec_arg::<2>(a, "fc"))
        .transpose()?
        .unwrap_or_else(SVector::zeros);
    let p = point
        .map(|a| vec_arg::<2>(a, "point"))
        .transpose()?
        .unwrap_or_else(SVector::zeros);
    let gamma = finite(gamma, "gamma")?;
    Ok(ContactInput {
        fc: Vec2::new(fc[0], fc[1]),
        gamma,
        point_in_body: Vec2::new(p[0], p[1]),
    })
}

/// The arguments of every model `step`: state (N,), input (2,) and the contact.
pub(crate) fn step_args<const N: usize>(
    x: &Bound<'_, PyAny>,
    u: &Bound<'_, PyAny>,
    fc: Option<&Bound<'_, PyAny>>,
    gamma: f64,
    point: Option<&Bound<'_, PyAny>>,
) -> PyResult<(SVector<f64, N>, SVector<f64, 2>, ContactInput)> {
    Ok((
        vec_arg::<N>(x, "x")?,
        vec_arg::<2>(u, "u")?,
        contact_arg(fc, gamma, point)?,
    ))
}

/// `step` of any target model, GIL released: the shared body of the `FourDofTarget` and
/// `SurrogateModel` bindings.
pub(crate) fn target_step<'py>(
    py: Python<'py>,
    model: &mut (dyn TargetModel + Send),
    x: &Bound<'py, PyAny>,
    u: &Bound<'py, PyAny>,
    fc: Option<&Bound<'py, PyAny>>,
    gamma: f64,
    point: Option<&Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyArray1<f64>>> {
    let (x, u, c) = step_args::<8>(x, u, fc, gamma, point)?;
    let next = py.detach(move || model.step(&x, &u, &c));
    Ok(vec_out(py, &next))
}

/// `step_jac` of any target model, GIL released: `(x_next, A, B, F)`.
pub(crate) fn target_step_jac<'py>(
    py: Python<'py>,
    model: &mut (dyn TargetModel + Send),
    x: &Bound<'py, PyAny>,
    u: &Bound<'py, PyAny>,
    fc: Option<&Bound<'py, PyAny>>,
    gamma: f64,
    point: Option<&Bound<'py, PyAny>>,
) -> PyResult<StepJac<'py>> {
    let (x, u, c) = step_args::<8>(x, u, fc, gamma, point)?;
    let (next, jac) = py.detach(move || {
        let mut jac = TargetJacobians::default();
        let next = model.step_jac(&x, &u, &c, &mut jac);
        (next, jac)
    });
    Ok(jac_out(py, &next, &jac.a, &jac.b, &jac.f))
}

/// `(x_next, A, B, F)` as fresh numpy arrays.
pub(crate) fn jac_out<'py, const N: usize>(
    py: Python<'py>,
    next: &SVector<f64, N>,
    a: &SMatrix<f64, N, N>,
    b: &SMatrix<f64, N, 2>,
    f: &SMatrix<f64, N, 2>,
) -> StepJac<'py> {
    (
        vec_out(py, next),
        mat_out(py, a),
        mat_out(py, b),
        mat_out(py, f),
    )
}

/// The bullet's front-steer / rear-drive single-track model: state `[X, Y, yaw, vx, vy, r]`,
/// input `[delta_f, T_r]`, one RK4 step of `dt` per call (in `substeps` sub-steps).
#[pyclass(module = "picopit._core", name = "BulletModel")]
pub struct BulletModel {
    inner: CoreBullet,
}

#[pymethods]
impl BulletModel {
    #[new]
    #[pyo3(signature = (params = "full_size", mu = 0.9, dt = 0.05, vehicle = "bullet", *, substeps = None))]
    fn new(
        py: Python<'_>,
        params: &str,
        mu: f64,
        dt: f64,
        vehicle: &str,
        substeps: Option<usize>,
    ) -> PyResult<Self> {
        let (mu, dt, substeps) = settings(mu, dt, substeps)?;
        let v = vehicle_params(py, params, vehicle)?;
        Ok(Self {
            inner: match substeps {
                Some(n) => CoreBullet::new(&v, mu, dt).with_substeps(n),
                None => CoreBullet::new(&v, mu, dt),
            },
        })
    }

    /// Step length (s).
    #[getter]
    fn dt(&self) -> f64 {
        self.inner.dt()
    }

    /// RK4 sub-steps per step.
    #[getter]
    fn substeps(&self) -> usize {
        self.inner.substeps()
    }

    /// Understeer gradient of the model (rad s²/m), from its axle curves.
    #[getter]
    fn understeer_gradient(&self) -> f64 {
        self.inner.understeer_gradient()
    }

    /// One step: the next state (6,).
    #[pyo3(signature = (x, u, fc = None, gamma = 0.0, point = None))]
    fn step<'py>(
        &self,
        py: Python<'py>,
        x: &Bound<'py, PyAny>,
        u: &Bound<'py, PyAny>,
        fc: Option<&Bound<'py, PyAny>>,
        gamma: f64,
        point: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<Bound<'py, PyArray1<f64>>> {
        let (x, u, c) = step_args::<6>(x, u, fc, gamma, point)?;
        let inner = &self.inner;
        let next = py.detach(move || inner.step(&x, &u, &c));
        Ok(vec_out(py, &next))
    }

    /// One step with the exact Jacobians of the discrete map:
    /// `(x_next (6,), A = dx+/dx (6, 6), B = dx+/du (6, 2), F = dx+/dfc (6, 2))`.
    #[pyo3(signature = (x, u, fc = None, gamma = 0.0, point = None))]
    fn step_jac<'py>(
        &self,
        py: Python<'py>,
        x: &Bound<'py, PyAny>,
        u: &Bound<'py, PyAny>,
        fc: Option<&Bound<'py, PyAny>>,
        gamma: f64,
        point: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<StepJac<'py>> {
        let (x, u, c) = step_args::<6>(x, u, fc, gamma, point)?;
        let inner = &self.inner;
        let (next, jac) = py.detach(move || {
            let mut jac = BulletJacobians::default();
            let next = inner.step_jac(&x, &u, &c, &mut jac);
            (next, jac)
        });
        Ok(jac_out(py, &next, &jac.a, &jac.b, &jac.f))
    }
}

/// The 4-DOF analytic target model (longitudinal, lateral, yaw, roll with kinematics):
/// state `[vx, vy, yaw, r, p, phi, X, Y]`, input `[delta, T_b]`, one RK4 step of `dt`.
#[pyclass(module = "picopit._core", name = "FourDofTarget")]
pub struct FourDofTarget {
    inner: CoreFourDof,
}

#[pymethods]
impl FourDofTarget {
    #[new]
    #[pyo3(signature = (params = "full_size", mu = 0.9, dt = 0.05, vehicle = "target", *, substeps = None))]
    fn new(
        py: Python<'_>,
        params: &str,
        mu: f64,
        dt: f64,
        vehicle: &str,
        substeps: Option<usize>,
    ) -> PyResult<Self> {
        let (mu, dt, substeps) = settings(mu, dt, substeps)?;
        let v = vehicle_params(py, params, vehicle)?;
        Ok(Self {
            inner: match substeps {
                Some(n) => CoreFourDof::new(&v, mu, dt).with_substeps(n),
                None => CoreFourDof::new(&v, mu, dt),
            },
        })
    }

    /// Step length (s).
    #[getter]
    fn dt(&self) -> f64 {
        self.inner.dt()
    }

    /// RK4 sub-steps per step.
    #[getter]
    fn substeps(&self) -> usize {
        self.inner.substeps()
    }

    /// Trainable parameters (0: the model is analytic).
    #[getter]
    fn param_count(&self) -> usize {
        self.inner.param_count()
    }

    /// Short name for reports (`4dof`).
    #[getter]
    fn name(&self) -> String {
        self.inner.name().to_owned()
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
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<BulletModel>()?;
    m.add_class::<FourDofTarget>()?;
    Ok(())
}
