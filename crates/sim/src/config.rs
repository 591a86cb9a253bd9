//! The episode's configuration and its errors: which surrogate the controller uses, its
//! settings, the sensing and actuation uncertainty, the clock, the presets the benchmark
//! runs and the JSON form (a preset with overrides) the command line and Python pass.
//!
//! A module of its own so that the simulated vehicle ([`crate::vehicle`]) and the episode
//! runner ([`crate::episode`]) both depend on it and not on each other.

use crate::scenario::{ParamSetName, ScenarioError};
use dynamics::plant::Gear;
use planner::ControllerSettings;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use thiserror::Error;

/// Why an episode could not be run (bad configuration, scenario or model file). A
/// controller or plant that merely performs badly is an outcome, never an error.
#[derive(Debug, Error)]
pub enum EpisodeError {
    /// A configuration value or document that cannot be used; names the field.
    #[error("episode config: `{field}`: {message}")]
    Config { field: String, message: String },
    #[error(transparent)]
    Scenario(#[from] ScenarioError),
    /// A target-model file that cannot be loaded (or does not cover the scenario's μ).
    #[error("model {path}: {message}")]
    Model { path: PathBuf, message: String },
    /// The plant refused the parameter set.
    #[error("plant: {0}")]
    Plant(String),
    /// The controller could not be built from the settings and the model.
    #[error("controller: {0}")]
    Controller(String),
    /// The controller refused its input (a non-finite state, too many obstacles).
    #[error("controller step at t = {time:.3} s: {message}")]
    Step { time: f64, message: String },
}

fn config_err(field: &str, message: impl Into<String>) -> EpisodeError {
    EpisodeError::Config {
        field: field.to_owned(),
        message: message.into(),
    }
}

/// The controller's target surrogate.
#[derive(Serialize, Deserialize, Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum ModelKind {
    /// The 4-DOF analytic model (`dynamics::target4dof`).
    #[serde(rename = "4dof")]
    FourDof,
    /// The teacher PINN (`models/<params>/pinn.safetensors`).
    #[serde(rename = "pinn")]
    Pinn,
    /// PicoPINN (`models/<params>/picopinn.safetensors`).
    #[serde(rename = "picopinn")]
    PicoPinn,
}

impl ModelKind {
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            Self::FourDof => "4dof",
            Self::Pinn => "pinn",
            Self::PicoPinn => "picopinn",
        }
    }

    /// The model file of a learned surrogate under `models_dir`; `None` for the 4-DOF model.
    #[must_use]
    pub fn file(self, models_dir: &Path, params: ParamSetName) -> Option<PathBuf> {
        let stem = match self {
            Self::FourDof => return None,
            Self::Pinn => "pinn",
            Self::PicoPinn => "picopinn",
        };
        Some(
            models_dir
                .join(params.name())
                .join(format!("{stem}.safetensors")),
        )
    }
}

/// Which clock the controller measures its planning and control times (and the MPC its
/// time budget) with.
#[derive(Serialize, Deserialize, Clone, Copy, Debug, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum ClockKind {
    /// Wall-clock time (`std::time::Instant`): real runtimes; the MPC's time budget is real.
    Wall,
    /// A clock that advances by `clock_tick` per reading: times count readings, the episode
    /// is reproducible bit for bit, and the solvers' own wall-clock limits are lifted.
    Simulated,
}

/// Sensing noise, sensing latency and actuator uncertainty. All zero by default (a perfect
/// vehicle interface). Noise is zero-mean Gaussian with the given standard deviations, drawn
/// per control step and state component; actuator errors are uniform in `±value`, drawn once
/// per episode.
#[derive(Serialize, Deserialize, Clone, Copy, Debug, PartialEq, Default)]
#[serde(default, deny_unknown_fields)]
pub struct Uncertainty {
    /// Position noise on X and Y of both vehicles (m).
    pub position_std: f64,
    /// Heading noise on ψ of both vehicles (rad).
    pub heading_std: f64,
    /// Velocity noise on vx and vy of both vehicles (m/s).
    pub speed_std: f64,
    /// Yaw-rate noise on r of both vehicles (and roll rate p of the target) (rad/s).
    pub yaw_rate_std: f64,
    /// Age of the state the controller sees (s), rounded to plant steps; ≤ 1 s.
    pub latency: f64,
    /// Relative steer gain error: applied δ = (1 + e) δ_cmd, e uniform in ±value (≤ 0.5).
    pub steer_gain: f64,
    /// Steer bias (rad): applied δ = … + b, b uniform in ±value (≤ 0.1).
    pub steer_bias: f64,
    /// Relative torque gain error: applied T_r = (1 + e) T_cmd, e uniform in ±value (≤ 0.5).
    pub torque_gain: f64,
}

impl Uncertainty {
    /// # Errors
    /// [`EpisodeError::Config`] naming the field (`uncertainty.latency`, …) out of range.
    pub fn validate(&self) -> Result<(), EpisodeError> {
        for (field, value, max) in [
            ("uncertainty.position_std", self.position_std, 10.0),
            ("uncertainty.heading_std", self.heading_std, 1.0),
            ("uncertainty.speed_std", self.speed_std, 10.0),
            ("uncertainty.yaw_rate_std", self.yaw_rate_std, 2.0),
            ("uncertainty.latency", self.latency, 1.0),
            ("uncertainty.steer_gain", self.steer_gain, 0.5),
            ("uncertainty.steer_bias", self.steer_bias, 0.1),
            ("uncertainty.torque_gain", self.torque_gain, 0.5),
        ] {
            if !(value.is_finite() && (0.0..=max).contains(&value)) {
                return Err(config_err(
                    field,
                    format!("{value}: must lie in [0, {max}]"),
                ));
            }
        }
        Ok(())
    }

    pub(crate) fn has_noise(&self) -> bool {
        self.position_std > 0.0
            || self.heading_std > 0.0
            || self.speed_std > 0.0
            || self.yaw_rate_std > 0.0
    }
}

/// One benchmark configuration: the target surrogate, the controller settings (the upper
/// layer on or off is `controller.upper_layer`), the uncertainty and the clock.
///
/// As JSON (serde, unknown fields refused) it may start from a preset:
/// `{"preset": "picopinn", "uncertainty": {"latency": 0.02}}` takes the preset and
/// overrides the fields given (objects are merged key by key).
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct EpisodeConfig {
    /// Name in reports (`4dof`, `pinn`, `picopinn`, `picopinn_no_upper`, …).
    pub name: String,
    /// The controller's target surrogate (planner and MPC alike, unless `planner_model`).
    pub model: ModelKind,
    /// The upper layer's surrogate when it differs from `model`, which then serves the MPC
    /// only: a diagnostic of which layer a surrogate's accuracy matters in (JSON key
    /// `planner_model`, e.g. `picopit trace SCENE --config '{"preset": "picopinn",
    /// "planner_model": "4dof"}'`). `None` (the default): `model`.
    pub planner_model: Option<ModelKind>,
    /// Folder of the model files: `<models_dir>/<params>/{pinn,picopinn}.safetensors`.
    pub models_dir: PathBuf,
    /// A model file to use instead (for every parameter set).
    pub model_path: Option<PathBuf>,
    /// The controller's settings on full-size scenes.
    pub controller: ControllerSettings,
    /// The controller's settings on half-scale scenes (default: the built-in
    /// `configs/controller_half_scale.toml`, tuned for the 100 kg target of the paper's
    /// platform; the full-size settings push it with forces meant for a 1093 kg car).
    pub controller_half_scale: ControllerSettings,
    pub uncertainty: Uncertainty,
    pub clock: ClockKind,
    /// Seconds per reading of the simulated clock.
    pub clock_tick: f64,
    /// Keep the trajectory (one sample per control step) in the result.
    pub record: bool,
    /// The target's gear: `forward` (its powertrain engaged, the default) or `neutral` (it
    /// rolls freely once its driver lets go: for comparison).
    pub target_gear: Gear,
}

impl Default for EpisodeConfig {
    fn default() -> Self {
        Self {
            name: "picopinn".to_owned(),
            model: ModelKind::PicoPinn,
            planner_model: None,
            models_dir: PathBuf::from("models"),
            model_path: None,
            controller: ControllerSettings::default(),
            controller_half_scale: half_scale_controller(),
            uncertainty: Uncertainty::default(),
            clock: ClockKind::Wall,
            clock_tick: 1.0e-5,
            record: false,
            target_gear: Gear::Forward,
        }
    }
}

impl EpisodeConfig {
    /// The benchmark's configurations: the three surrogates with the upper layer, and
    /// PicoPINN without it (the planning-structure ablation).
    pub const PRESETS: [&'static str; 4] = ["4dof", "pinn", "picopinn", "picopinn_no_upper"];

    /// A preset by name.
    ///
    /// # Errors
    /// [`EpisodeError::Config`] (field `preset`) for an unknown name, listing the known ones.
    pub fn preset(name: &str) -> Result<Self, EpisodeError> {
        let (model, upper) = match name {
            "4dof" => (ModelKind::FourDof, true),
            "pinn" => (ModelKind::Pinn, true),
            "picopinn" => (ModelKind::PicoPinn, true),
            "picopinn_no_upper" => (ModelKind::PicoPinn, false),
            _ => {
                return Err(config_err(
                    "preset",
                    format!(
                        "unknown configuration {name:?}; known: {}",
                        Self::PRESETS.join(", ")
                    ),
                ))
            }
        };
        let mut c = Self {
            name: name.to_owned(),
            model,
            ..Self::default()
        };
        c.controller.upper_layer = upper;
        c.controller_half_scale.upper_layer = upper;
        Ok(c)
    }

    /// A preset name, or a JSON object (see [`EpisodeConfig`]); validated.
    ///
    /// # Errors
    /// [`EpisodeError::Config`] naming the field at fault.
    pub fn parse(text: &str) -> Result<Self, EpisodeError> {
        let t = text.trim();
        if t.starts_with('{') {
            Self::from_json(t)
        } else {
            let c = Self::preset(t)?;
            c.validate()?;
            Ok(c)
        }
    }

    /// Parse and validate a JSON configuration.
    ///
    /// # Errors
    /// [`EpisodeError::Config`] naming the field (e.g. `uncertainty.latency`) at fault.
    pub fn from_json(text: &str) -> Result<Self, EpisodeError> {
        let mut value: serde_json::Value =
            serde_json::from_str(text).map_err(|e| config_err("(document)", e.to_string()))?;
        let obj = value
            .as_object_mut()
            .ok_or_else(|| config_err("(document)", "expected a JSON object"))?;
        if let Some(p) = obj.remove("preset") {
            let name = p
                .as_str()
                .ok_or_else(|| config_err("preset", format!("{p}: expected a string")))?;
            let mut base = serde_json::to_value(Self::preset(name)?)
                .map_err(|e| config_err("preset", e.to_string()))?;
            merge(&mut base, serde_json::Value::Object(std::mem::take(obj)));
            value = base;
        }
        let c: Self = serde_path_to_error::deserialize(value).map_err(|e| {
            let path = e.path().to_string();
            config_err(&path, e.into_inner().to_string())
        })?;
        c.validate()?;
        Ok(c)
    }

    /// # Errors
    /// [`EpisodeError::Config`] naming the first bad field.
    pub fn validate(&self) -> Result<(), EpisodeError> {
        if self.name.is_empty() || self.name.len() > 64 {
            return Err(config_err("name", "must have 1 to 64 characters"));
        }
        if !(self.clock_tick.is_finite() && self.clock_tick > 0.0 && self.clock_tick <= 1.0) {
            return Err(config_err(
                "clock_tick",
                format!("{}: must lie in (0, 1] s", self.clock_tick),
            ));
        }
        self.uncertainty.validate()?;
        self.controller
            .validate()
            .map_err(|e| config_err("controller", e.to_string()))?;
        self.controller_half_scale
            .validate()
            .map_err(|e| config_err("controller_half_scale", e.to_string()))
    }

    /// The controller settings for a scene of parameter set `params`.
    #[must_use]
    pub fn controller_for(&self, params: ParamSetName) -> &ControllerSettings {
        match params {
            ParamSetName::FullSize => &self.controller,
            ParamSetName::HalfScale => &self.controller_half_scale,
        }
    }
}

fn half_scale_controller() -> ControllerSettings {
    ControllerSettings::builtin(ParamSetName::HalfScale.name()).expect("a built-in parameter set")
}

/// Merge `over` into `base`: objects key by key (recursively), anything else replaced.
fn merge(base: &mut serde_json::Value, over: serde_json::Value) {
    match (base, over) {
        (serde_json::Value::Object(b), serde_json::Value::Object(o)) => {
            for (k, v) in o {
                match b.get_mut(&k) {
                    Some(slot) => merge(slot, v),
                    None => {
                        b.insert(k, v);
                    }
                }
            }
        }
        (b, o) => *b = o,
    }
}
