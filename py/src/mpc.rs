//! Binding of the coupled collision MPC (`crates/mpc`): numpy in, numpy out, the GIL
//! released around every solve.

use crate::{finite, vec_arg, vec_out};
use dynamics::bullet::BulletInput;
use dynamics::geometry::Vec2;
use dynamics::params::ParamSet;
use dynamics::road::{Obstacle, Road, RoadSpec};
use dynamics::target4dof::FourDofTarget;
use dynamics::{TargetInput, TargetModel};
use mpc::reference::DefaultPit;
use mpc::{CoupledMpc as CoreMpc, MpcInput, MpcSettings, Reference, Side};
use numpy::{PyArray1, PyArray2};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::path::PathBuf;

pyo3::create_exception!(
    picopit,
    MpcError,
    PyValueError,
    "Bad MPC settings, construction input or control-step input; the message names the field."
);

fn mpc_err(e: impl std::fmt::Display) -> PyErr {
    MpcError::new_err(e.to_string())
}

/// The per-step arguments of `solve` and `evaluate`, checked and copied.
struct StepArgs {
    target: nalgebra::SVector<f64, 8>,
    bullet: nalgebra::SVector<f64, 6>,
    target_input: TargetInput,
    last_command: BulletInput,
    time: f64,
}

impl StepArgs {
    fn parse(
        target: &Bound<'_, PyAny>,
        bullet: &Bound<'_, PyAny>,
        target_input: Option<&Bound<'_, PyAny>>,
        last_command: Option<&Bound<'_, PyAny>>,
        time: f64,
    ) -> PyResult<Self> {
        Ok(Self {
            target: vec_arg::<8>(target, "target")?,
            bullet: vec_arg::<6>(bullet, "bullet")?,
            target_input: target_input
                .map(|a| vec_arg::<2>(a, "target_input"))
                .transpose()?
                .unwrap_or_else(TargetInput::zeros),
            last_command: last_command
                .map(|a| vec_arg::<2>(a, "last_command"))
                .transpose()?
                .unwrap_or_else(BulletInput::zeros),
            time: finite(time, "time")?,
        })
    }
}

impl PyCoupledMpc {
    /// Run `f` on the core with these arguments, the stored road, obstacles and reference,
    /// the GIL released.
    fn detached<R: Send>(
        &mut self,
        py: Python<'_>,
        a: &StepArgs,
        f: impl FnOnce(&mut CoreMpc, &MpcInput<'_>) -> R + Send,
    ) -> R {
        let Self {
            core,
            reference,
            road,
            obstacles,
            ..
        } = self;
        py.detach(|| {
            f(
                core,
                &MpcInput {
                    time: a.time,
                    target: a.target,
                    bullet: a.bullet,
                    target_input: a.target_input,
                    last_command: a.last_command,
                    road: road.as_ref(),
                    obstacles,
                    reference,
                },
            )
        })
    }
}

/// The coupled collision MPC.
#[pyclass(module = "picopit._core", name = "CoupledMpc")]
pub struct PyCoupledMpc {
    core: CoreMpc,
    params: ParamSet,
    reference: Reference,
    default_pit: DefaultPit,
    road: Option<Road>,
    obstacles: Vec<Obstacle>,
}

#[pymethods]
impl PyCoupledMpc {
    #[new]
    #[pyo3(signature = (params = "full_size", mu = 0.9, target_model = "4dof", settings = None, side = "left"))]
    fn new(
        py: Python<'_>,
        params: &str,
        mu: f64,
        target_model: &str,
        settings: Option<&str>,
        side: &str,
    ) -> PyResult<Self> {
        let side = match side {
            "left" => Side::Left,
            "right" => Side::Right,
            other => {
                return Err(MpcError::new_err(format!(
                    "side = {other:?}: must be \"left\" or \"right\""
                )))
            }
        };
        let settings = match settings {
            Some(text) => MpcSettings::from_toml_str(text).map_err(mpc_err)?,
            None => MpcSettings::default(),
        };
        let set = ParamSet::load(params).map_err(|e| crate::param_err(&e))?;
        let model = target_model.to_owned();
        let dt = settings.dt;
        let target: Box<dyn TargetModel + Send + Sync> = if model == "4dof" {
            Box::new(FourDofTarget::new(&set.target, mu.clamp(1e-3, 1.5), dt))
        } else {
            let path = PathBuf::from(&model);
            // The surrogate predicts at the road's μ, as the 4-DOF model does.
            let m = py
                .detach(move || {
                    pico_nn::SurrogateModel::from_path(path).and_then(|m| m.with_mu(mu))
                })
                .map_err(|e| crate::surrogate::ModelError::new_err(e.to_string()))?;
            Box::new(m)
        };
        let set2 = set.clone();
        let core = py
            .detach(move || CoreMpc::new(&set2, mu, target, settings))
            .map_err(mpc_err)?;
        let n = core.settings().horizon;
        Ok(Self {
            default_pit: DefaultPit::new(&set, side),
            reference: Reference::new(n),
            params: set,
            core,
            road: None,
            obstacles: Vec::new(),
        })
    }

    /// The settings in use, as TOML.
    #[getter]
    fn settings(&self) -> String {
        self.core.settings().to_toml_string()
    }

    #[getter]
    fn horizon(&self) -> usize {
        self.core.settings().horizon
    }

    #[getter]
    fn target_model(&self) -> String {
        self.core.target_model_name().to_owned()
    }

    #[getter]
    fn param_count(&self) -> usize {
        self.core.target_param_count()
    }

    /// ((columns, rows) of the coupled QP, (columns, rows) of the bullet-only QP).
    #[getter]
    fn qp_sizes(&self) -> ((usize, usize), (usize, usize)) {
        self.core.qp_sizes()
    }

    /// The road (a TOML road specification, as `dynamics::road::RoadSpec`), or None.
    fn set_road(&mut self, road_toml: Option<&str>) -> PyResult<()> {
        self.road = match road_toml {
            None => None,
            Some(text) => {
                let spec = RoadSpec::from_toml_str(text, "road").map_err(mpc_err)?;
                Some(Road::new(spec).map_err(mpc_err)?)
            }
        };
        Ok(())
    }

    /// A straight road of `length` m, `lanes` lanes of `lane_width` m and `shoulder` m on
    /// each side, starting at the origin along +X.
    #[pyo3(signature = (length = 2000.0, lanes = 3, lane_width = 3.5, shoulder = 1.0))]
    fn set_straight_road(
        &mut self,
        length: f64,
        lanes: u32,
        lane_width: f64,
        shoulder: f64,
    ) -> PyResult<()> {
        let ok = length.is_finite()
            && length > 0.0
            && lanes > 0
            && lane_width.is_finite()
            && lane_width > 0.0
            && shoulder.is_finite()
            && shoulder >= 0.0;
        if !ok {
            return Err(MpcError::new_err(
                "set_straight_road: length, lanes and lane_width must be positive, shoulder >= 0",
            ));
        }
        self.road = Some(Road::straight(length, lanes, lane_width, shoulder));
        Ok(())
    }

    /// Obstacles as an (n, 7) array of `[x, y, heading, vx, vy, length, width]` (the centre
    /// at time 0 and a constant world velocity).
    fn set_obstacles(&mut self, obstacles: &Bound<'_, PyAny>) -> PyResult<()> {
        let out = crate::obstacles_arg(obstacles).map_err(MpcError::new_err)?;
        self.obstacles = out;
        Ok(())
    }

    /// Fill the reference with the default PIT h_ref (no upper layer) for these states.
    #[pyo3(signature = (target, bullet, lane_heading = 0.0))]
    fn default_reference(
        &mut self,
        target: &Bound<'_, PyAny>,
        bullet: &Bound<'_, PyAny>,
        lane_heading: f64,
    ) -> PyResult<()> {
        let xt = vec_arg::<8>(target, "target")?;
        let xb = vec_arg::<6>(bullet, "bullet")?;
        let lane_heading = finite(lane_heading, "lane_heading")?;
        let dt = self.core.settings().dt;
        self.default_pit.fill(
            &mut self.reference,
            xt.as_slice(),
            xb.as_slice(),
            dt,
            lane_heading,
        );
        Ok(())
    }

    /// Set the reference stage by stage: `stages` is an (N, 8) array of
    /// `[rel_x, rel_y, rel_heading, rel_speed, track, fn_lo, fn_hi, envelope_lat]` (the
    /// bullet's c.g. in the target frame, ψ_B − ψ_T, v_B − v_T, the tracking scale, the
    /// normal-force corridor in N and the envelope's half width in m).
    fn set_reference(
        &mut self,
        stages: &Bound<'_, PyAny>,
        target_heading: f64,
        target_weight: f64,
    ) -> PyResult<()> {
        let rows = crate::table::<8>(stages, "stages").map_err(PyValueError::new_err)?;
        let n = self.core.settings().horizon;
        if rows.len() != n {
            return Err(MpcError::new_err(format!(
                "stages: expected {n} rows (the horizon), got {}",
                rows.len()
            )));
        }
        for (i, r) in rows.iter().enumerate() {
            if r[4] < 0.0 || r[5] > r[6] || r[7] < 0.0 {
                return Err(MpcError::new_err(format!(
                    "stages[{i}]: need track >= 0, fn_lo <= fn_hi, envelope_lat >= 0"
                )));
            }
        }
        for (st, r) in self.reference.stages.iter_mut().zip(&rows) {
            st.rel_pos = Vec2::new(r[0], r[1]);
            st.rel_heading = r[2];
            st.rel_speed = r[3];
            st.track = r[4];
            st.fn_lo = r[5];
            st.fn_hi = r[6];
            st.envelope_lat = r[7];
        }
        self.reference.target_heading = finite(target_heading, "target_heading")?;
        self.reference.target_weight = finite(target_weight, "target_weight")?;
        Ok(())
    }

    /// The target objective of the current reference: (target_heading, target_weight).
    #[getter]
    fn reference_target(&self) -> (f64, f64) {
        (self.reference.target_heading, self.reference.target_weight)
    }

    /// The current reference as an (N, 8) array (same columns as `set_reference`).
    fn reference<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        let rows: Vec<Vec<f64>> = self
            .reference
            .stages
            .iter()
            .map(|s| {
                vec![
                    s.rel_pos.x,
                    s.rel_pos.y,
                    s.rel_heading,
                    s.rel_speed,
                    s.track,
                    s.fn_lo,
                    s.fn_hi,
                    s.envelope_lat,
                ]
            })
            .collect();
        PyArray2::from_vec2(py, &rows).expect("rows have equal length")
    }

    /// One control step. Returns a dict: `status`, `command` [δ_f, T_r], `fallback`
    /// (None, "shifted_plan" or "brake"), `coupled` (whether the QP carried the target),
    /// `scp_iterations`, `qp_iterations`, `merit`, `max_violation`, `times` (seconds:
    /// linearise, assemble, qp, total).
    #[pyo3(signature = (target, bullet, target_input = None, last_command = None, time = 0.0))]
    fn solve<'py>(
        &mut self,
        py: Python<'py>,
        target: &Bound<'py, PyAny>,
        bullet: &Bound<'py, PyAny>,
        target_input: Option<&Bound<'py, PyAny>>,
        last_command: Option<&Bound<'py, PyAny>>,
        time: f64,
    ) -> PyResult<Bound<'py, PyDict>> {
        let args = StepArgs::parse(target, bullet, target_input, last_command, time)?;
        let out = self
            .detached(py, &args, |core, input| core.solve(input))
            .map_err(mpc_err)?;
        let d = PyDict::new(py);
        d.set_item("status", format!("{:?}", out.status))?;
        d.set_item("command", vec_out(py, &out.command))?;
        d.set_item(
            "fallback",
            out.fallback.map(|f| match f {
                mpc::Fallback::ShiftedPlan => "shifted_plan",
                mpc::Fallback::Brake => "brake",
            }),
        )?;
        d.set_item("coupled", self.core.last_qp_coupled())?;
        d.set_item("scp_iterations", out.scp_iterations)?;
        d.set_item("qp_iterations", out.qp_iterations)?;
        d.set_item("merit", out.merit)?;
        d.set_item("max_violation", out.max_violation)?;
        let t = PyDict::new(py);
        t.set_item("linearise", out.times.linearise)?;
        t.set_item("assemble", out.times.assemble)?;
        t.set_item("qp", out.times.qp)?;
        t.set_item("total", out.times.total)?;
        d.set_item("times", t)?;
        Ok(d)
    }

    /// The plan of the last control step: `u` (N, 2), `f` (N, 2) contact forces on the target
    /// [F_n, F_t], `target` (N+1, 8), `bullet` (N+1, 6), `gap` (N+1,).
    fn plan<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let p = self.core.plan();
        let d = PyDict::new(py);
        let rows2 = |v: &[nalgebra::SVector<f64, 2>]| -> Vec<Vec<f64>> {
            v.iter().map(|x| x.as_slice().to_vec()).collect()
        };
        d.set_item("u", PyArray2::from_vec2(py, &rows2(&p.u)).expect("rows"))?;
        d.set_item("f", PyArray2::from_vec2(py, &rows2(&p.f)).expect("rows"))?;
        let xt: Vec<Vec<f64>> = p.xt.iter().map(|x| x.as_slice().to_vec()).collect();
        let xb: Vec<Vec<f64>> = p.xb.iter().map(|x| x.as_slice().to_vec()).collect();
        d.set_item("target", PyArray2::from_vec2(py, &xt).expect("rows"))?;
        d.set_item("bullet", PyArray2::from_vec2(py, &xb).expect("rows"))?;
        let gaps: Vec<f64> = p.pair.iter().map(|g| g.gap).collect();
        d.set_item("gap", PyArray1::from_vec(py, gaps))?;
        Ok(d)
    }

    /// The linearisation the last QP used, per stage (arrays of length N): `gamma`,
    /// `point_target` (N, 2), `point_bullet` (N, 2), `gap` (at x_{k+1}), `gap_grad_bullet`
    /// (N, 3) and `gap_grad_target` (N, 3) on [X, Y, ψ], `fn_max`, `band` (bool), and the
    /// soft rows `road_bullet`, `road_target`, `obstacle_bullet`, `obstacle_target` as
    /// (N, 4) `[gX, gY, gψ, rhs]` meaning `g · δpose − s ≤ rhs`; and the linearisation point
    /// itself: `u_lin` (N, 2), `f_lin` (N, 2), `target_lin` (N+1, 8), `bullet_lin` (N+1, 6).
    fn linearisation<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let n = self.core.settings().horizon;
        let st: Vec<mpc::StageLinearisation> =
            (0..n).map(|k| self.core.stage_linearisation(k)).collect();
        let d = PyDict::new(py);
        let col = |f: &dyn Fn(&mpc::StageLinearisation) -> f64| -> Vec<f64> {
            st.iter().map(f).collect()
        };
        let mat = |f: &dyn Fn(&mpc::StageLinearisation) -> Vec<f64>| -> Vec<Vec<f64>> {
            st.iter().map(f).collect()
        };
        d.set_item("gamma", PyArray1::from_vec(py, col(&|s| s.gamma)))?;
        d.set_item("gap", PyArray1::from_vec(py, col(&|s| s.gap)))?;
        d.set_item("fn_max", PyArray1::from_vec(py, col(&|s| s.fn_max)))?;
        d.set_item("band", st.iter().map(|s| s.band).collect::<Vec<bool>>())?;
        let two = |v: Vec2| vec![v.x, v.y];
        for (name, rows) in [
            ("point_target", mat(&|s| two(s.point_target))),
            ("point_bullet", mat(&|s| two(s.point_bullet))),
            ("gap_grad_bullet", mat(&|s| s.gap_grad_bullet.to_vec())),
            ("gap_grad_target", mat(&|s| s.gap_grad_target.to_vec())),
        ] {
            d.set_item(name, PyArray2::from_vec2(py, &rows).expect("rows"))?;
        }
        let lp = self.core.linearisation_point();
        let rows_of = |v: &[nalgebra::SVector<f64, 2>]| -> Vec<Vec<f64>> {
            v.iter().map(|x| x.as_slice().to_vec()).collect()
        };
        d.set_item(
            "u_lin",
            PyArray2::from_vec2(py, &rows_of(&lp.u)).expect("rows"),
        )?;
        d.set_item(
            "f_lin",
            PyArray2::from_vec2(py, &rows_of(&lp.f)).expect("rows"),
        )?;
        let xt: Vec<Vec<f64>> = lp.xt.iter().map(|x| x.as_slice().to_vec()).collect();
        let xb: Vec<Vec<f64>> = lp.xb.iter().map(|x| x.as_slice().to_vec()).collect();
        d.set_item("target_lin", PyArray2::from_vec2(py, &xt).expect("rows"))?;
        d.set_item("bullet_lin", PyArray2::from_vec2(py, &xb).expect("rows"))?;
        let row4 = |(g, r): ([f64; 3], f64)| vec![g[0], g[1], g[2], r];
        for (name, rows) in [
            ("road_bullet", mat(&|s| row4(s.road_bullet))),
            ("road_target", mat(&|s| row4(s.road_target))),
            ("obstacle_bullet", mat(&|s| row4(s.obstacle_bullet))),
            ("obstacle_target", mat(&|s| row4(s.obstacle_target))),
        ] {
            d.set_item(name, PyArray2::from_vec2(py, &rows).expect("rows"))?;
        }
        Ok(d)
    }

    /// Merit (cost + penalty · violations on the nonlinear models and geometry) and the
    /// largest violation of the plan that inputs `u` (N, 2) and forces `f` (N, 2) produce
    /// from these states, with the current road, obstacles and reference: the yardstick for
    /// comparing plans from different solvers.
    #[pyo3(signature = (target, bullet, u, f, target_input = None, last_command = None, time = 0.0))]
    #[allow(clippy::too_many_arguments)]
    fn evaluate(
        &mut self,
        py: Python<'_>,
        target: &Bound<'_, PyAny>,
        bullet: &Bound<'_, PyAny>,
        u: &Bound<'_, PyAny>,
        f: &Bound<'_, PyAny>,
        target_input: Option<&Bound<'_, PyAny>>,
        last_command: Option<&Bound<'_, PyAny>>,
        time: f64,
    ) -> PyResult<(f64, f64)> {
        let args = StepArgs::parse(target, bullet, target_input, last_command, time)?;
        let n = self.core.settings().horizon;
        let u_rows = crate::table::<2>(u, "u").map_err(PyValueError::new_err)?;
        let f_rows = crate::table::<2>(f, "f").map_err(PyValueError::new_err)?;
        if u_rows.len() != n || f_rows.len() != n {
            return Err(MpcError::new_err(format!(
                "u, f: expected {n} rows (the horizon), got {} and {}",
                u_rows.len(),
                f_rows.len()
            )));
        }
        let u: Vec<BulletInput> = u_rows
            .iter()
            .map(|r| BulletInput::new(r[0], r[1]))
            .collect();
        let f: Vec<Vec2> = f_rows.iter().map(|r| Vec2::new(r[0], r[1])).collect();
        self.detached(py, &args, |core, input| core.evaluate(input, &u, &f))
            .map_err(mpc_err)
    }

    /// The largest |x_QP − x_rollout| of the last QP's step (the linearisation error).
    #[getter]
    fn linearisation_error(&self) -> f64 {
        self.core.linearisation_error()
    }

    /// Forget the previous plan.
    fn reset(&mut self) {
        self.core.reset();
    }

    fn __repr__(&self) -> String {
        format!(
            "CoupledMpc(target_model={:?}, horizon={}, params={:?})",
            self.core.target_model_name(),
            self.core.settings().horizon,
            self.params.bullet.name
        )
    }
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("MpcError", m.py().get_type::<MpcError>())?;
    m.add_class::<PyCoupledMpc>()
}
