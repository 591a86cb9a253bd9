//! Bindings for the high-fidelity two-vehicle plant (`dynamics::plant`).

use crate::{corners_out, finite, param_err, vec_arg, vec_out};
use dynamics::params::ParamSet;
use dynamics::plant::{ContactReport, Gear, Plant as CorePlant, PlantConfig, VehicleInit, Which};
use numpy::{PyArray1, PyArray3};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;

/// Longest single `advance` call accepted (s of simulated time).
const MAX_ADVANCE: f64 = 1.0e5;

/// The two-vehicle truth simulator: bullet and target, contact, fixed-step integration.
#[pyclass(module = "picopit._core", name = "Plant")]
pub struct Plant {
    inner: CorePlant,
    params: String,
}

fn vehicle_init(x: &nalgebra::SVector<f64, 6>) -> VehicleInit {
    VehicleInit {
        x: x[0],
        y: x[1],
        yaw: x[2],
        vx: x[3],
        vy: x[4],
        r: x[5],
    }
}

#[pymethods]
impl Plant {
    /// `params`: a built-in set name or a TOML path; `mu`: road adhesion; `dt`: step (s,
    /// 1e-3 or finer); `tyre_forces=False` leaves only contact forces (diagnostics);
    /// `target_gear`: "forward" (its powertrain engaged: engine braking, a stall that holds
    /// the driven axle) or "neutral" (it rolls freely).
    #[new]
    #[pyo3(signature = (params = "full_size", mu = 0.9, dt = 1.0e-3, *, tyre_forces = true, target_gear = "forward"))]
    fn new(
        py: Python<'_>,
        params: &str,
        mu: f64,
        dt: f64,
        tyre_forces: bool,
        target_gear: &str,
    ) -> PyResult<Self> {
        let target_gear = gear_arg(target_gear)?;
        let name = params.to_owned();
        let inner = py
            .detach(move || {
                let set = ParamSet::load(&name)?;
                CorePlant::new(
                    &set,
                    PlantConfig {
                        dt,
                        mu,
                        tyre_forces,
                        target_gear,
                    },
                )
            })
            .map_err(|e| param_err(&e))?;
        Ok(Self {
            inner,
            params: params.to_owned(),
        })
    }

    /// Place both vehicles: `[X, Y, yaw, vx, vy, r]` each (c.g. position, body-frame
    /// velocities); time restarts at 0.
    fn reset(&mut self, bullet: &Bound<'_, PyAny>, target: &Bound<'_, PyAny>) -> PyResult<()> {
        let b = vec_arg::<6>(bullet, "bullet")?;
        let t = vec_arg::<6>(target, "target")?;
        self.inner.reset(&vehicle_init(&b), &vehicle_init(&t));
        Ok(())
    }

    /// Driver commands, held until changed: bullet front steer (rad) and rear drive torque
    /// T_r (N m, negative brakes through the drivetrain); target front steer (rad) and the
    /// target driver's longitudinal torque at the wheels `T_b` (N m: >= 0 service brakes,
    /// < 0 the throttle, drive torque -T_b at its driven axle); bullet service-brake torque
    /// (N m, >= 0). The plant applies the actuator limits, rate limits and lags.
    #[pyo3(signature = (bullet_steer, bullet_torque, target_steer = 0.0, target_brake = 0.0, bullet_brake = 0.0))]
    fn set_commands(
        &mut self,
        bullet_steer: f64,
        bullet_torque: f64,
        target_steer: f64,
        target_brake: f64,
        bullet_brake: f64,
    ) -> PyResult<()> {
        let bs = finite(bullet_steer, "bullet_steer")?;
        let bt = finite(bullet_torque, "bullet_torque")?;
        let ts = finite(target_steer, "target_steer")?;
        let tb = finite(target_brake, "target_brake")?;
        let bb = non_negative(bullet_brake, "bullet_brake")?;
        self.inner.set_bullet_command(bs, bt);
        self.inner.set_target_command(ts, tb);
        self.inner.set_brake(Which::Bullet, bb);
        Ok(())
    }

    /// The bullet command as the controllers plan it, `[δ_f, T_r]`: a positive T_r drives
    /// the rear axle, a negative one is blended into the service brakes of all four wheels
    /// with the same total force (what `CoupledMpc` and `PitController` commands mean).
    fn set_bullet_command_blended(&mut self, steer: f64, torque: f64) -> PyResult<()> {
        let s = finite(steer, "steer")?;
        let t = finite(torque, "torque")?;
        self.inner.set_bullet_command_blended(s, t);
        Ok(())
    }

    /// Simulate `duration` seconds (the GIL is released meanwhile).
    fn advance(&mut self, py: Python<'_>, duration: f64) -> PyResult<()> {
        if !(duration.is_finite() && (0.0..=MAX_ADVANCE).contains(&duration)) {
            return Err(PyValueError::new_err(format!(
                "duration = {duration}: must lie in [0, {MAX_ADVANCE}] s"
            )));
        }
        let inner = &mut self.inner;
        py.detach(move || inner.advance(duration));
        Ok(())
    }

    /// One integration step of `dt`.
    fn step(&mut self, py: Python<'_>) {
        let inner = &mut self.inner;
        py.detach(move || inner.step());
    }

    /// Simulated time (s).
    #[getter]
    fn time(&self) -> f64 {
        self.inner.time()
    }

    /// Integration step (s).
    #[getter]
    fn dt(&self) -> f64 {
        self.inner.dt()
    }

    /// Road adhesion μ.
    #[getter]
    fn mu(&self) -> f64 {
        self.inner.config().mu
    }

    /// The parameter set this plant was built from (name or path).
    #[getter]
    fn params(&self) -> &str {
        &self.params
    }

    /// Bullet state `[X, Y, yaw, vx, vy, r]`.
    fn bullet_state<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        vec_out(py, &self.inner.bullet_state())
    }

    /// Target state `[vx, vy, yaw, r, p, phi, X, Y]` (the paper's order).
    fn target_state<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        vec_out(py, &self.inner.target_state())
    }

    /// The full state of one vehicle (`which`: "bullet" or "target"): `steer` (actual
    /// road-wheel steer, rad), `torque` (actual drive torque T_r, N m), `brake` (actual
    /// service-brake torque, N m), `omega` (wheel spin FL FR RL RR, rad/s), `fz` (wheel
    /// loads, N), `roll` / `pitch` (rad), `acc_body` (c.g. acceleration in the body frame,
    /// m/s²) of the last step, and `stalled` (the engine of a vehicle in gear has stalled).
    fn body<'py>(&self, py: Python<'py>, which: &str) -> PyResult<Bound<'py, PyDict>> {
        let b = self.inner.body(which_arg(which)?);
        let d = PyDict::new(py);
        d.set_item("steer", b.steer)?;
        d.set_item("torque", b.torque)?;
        d.set_item("brake", b.brake)?;
        d.set_item("omega", PyArray1::from_slice(py, &b.omega))?;
        d.set_item("fz", PyArray1::from_slice(py, &b.fz))?;
        d.set_item("roll", b.phi)?;
        d.set_item("pitch", b.theta)?;
        d.set_item("acc_body", PyArray1::from_slice(py, b.acc_body.as_slice()))?;
        d.set_item("stalled", b.stalled)?;
        Ok(d)
    }

    /// Drive-torque command T_r (N m, motor side, before the gear) of one vehicle
    /// (`which`: "bullet" or "target"); the actuator's limits and lag apply.
    fn set_drive(&mut self, which: &str, torque: f64) -> PyResult<()> {
        let torque = finite(torque, "torque")?;
        self.inner.set_drive(which_arg(which)?, torque);
        Ok(())
    }

    /// The current bullet-target contact, or None: `fc` = [F_n, F_t] on the target in the
    /// contact frame, `gamma`, contact points (world, target body, bullet body), `depth`.
    fn contact<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyDict>>> {
        self.inner
            .contact()
            .map(|c| contact_dict(py, &c))
            .transpose()
    }

    /// The contact averaged since the previous call (impulse over elapsed time; normal and
    /// points weighted by the normal impulse; `depth` the maximum), then averaging restarts.
    /// None if the vehicles did not touch in that interval. This is what a logger records.
    fn take_contact_average<'py>(
        &mut self,
        py: Python<'py>,
    ) -> PyResult<Option<Bound<'py, PyDict>>> {
        self.inner
            .take_contact_average()
            .map(|c| contact_dict(py, &c))
            .transpose()
    }

    /// Footprint corners, shape (2, 4, 2): [bullet, target] x 4 corners (counter-clockwise
    /// from front-left) x [X, Y].
    fn footprints<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray3<f64>> {
        corners_out(py, &self.inner.footprints())
    }

    fn __repr__(&self) -> String {
        format!(
            "Plant(params={:?}, time={:.3})",
            self.params,
            self.inner.time()
        )
    }
}

fn contact_dict<'py>(py: Python<'py>, c: &ContactReport) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("fc", PyArray1::from_slice(py, c.fc.as_slice()))?;
    d.set_item("gamma", c.gamma)?;
    d.set_item(
        "point_in_world",
        PyArray1::from_slice(py, c.point_in_world.as_slice()),
    )?;
    d.set_item(
        "point_in_target",
        PyArray1::from_slice(py, c.point_in_target.as_slice()),
    )?;
    d.set_item(
        "point_in_bullet",
        PyArray1::from_slice(py, c.point_in_bullet.as_slice()),
    )?;
    d.set_item("depth", c.depth)?;
    Ok(d)
}

/// A target gear by name ("forward" or "neutral").
pub(crate) fn gear_arg(gear: &str) -> PyResult<Gear> {
    match gear {
        "forward" => Ok(Gear::Forward),
        "neutral" => Ok(Gear::Neutral),
        other => Err(PyValueError::new_err(format!(
            "target_gear = {other:?}: must be \"forward\" or \"neutral\""
        ))),
    }
}

fn which_arg(which: &str) -> PyResult<Which> {
    match which {
        "bullet" => Ok(Which::Bullet),
        "target" => Ok(Which::Target),
        other => Err(PyValueError::new_err(format!(
            "which = {other:?}: must be \"bullet\" or \"target\""
        ))),
    }
}

fn non_negative(value: f64, name: &str) -> PyResult<f64> {
    if value.is_finite() && value >= 0.0 {
        Ok(value)
    } else {
        Err(PyValueError::new_err(format!(
            "{name} = {value}: must be finite and not negative"
        )))
    }
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<Plant>()
}
