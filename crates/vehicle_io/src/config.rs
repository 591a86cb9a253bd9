//! The two processes' settings: serde structs with defaults, loaded from TOML and validated
//! when built (a bad value is refused with its field named).

use planner::ControllerSettings;
use serde::{Deserialize, Serialize};
use sim::episode::{ModelKind, Uncertainty};
use std::path::PathBuf;

/// A setting that cannot be used, named by its TOML path.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ConfigError {
    #[error("{file}: {message}")]
    Parse { file: String, message: String },
    #[error("setting `{field}`: {problem}")]
    Invalid { field: String, problem: String },
}

fn invalid(field: &str, problem: impl Into<String>) -> ConfigError {
    ConfigError::Invalid {
        field: field.to_owned(),
        problem: problem.into(),
    }
}

/// Deserialize TOML (`file` names it in the error).
fn parse_toml<T: serde::de::DeserializeOwned>(text: &str, file: &str) -> Result<T, ConfigError> {
    toml::from_str(text).map_err(|e| ConfigError::Parse {
        file: file.to_owned(),
        message: e.to_string(),
    })
}

fn in_range(field: &str, v: f64, lo: f64, hi: f64) -> Result<(), ConfigError> {
    if v.is_finite() && v >= lo && v <= hi {
        Ok(())
    } else {
        Err(invalid(field, format!("{v}: must lie in [{lo}, {hi}]")))
    }
}

/// Whose clock the controller reads "now" from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum ControllerClock {
    /// Real time: the vehicle time of the newest state plus the wall time elapsed since it
    /// was sent (`CLOCK_MONOTONIC`, shared by the processes of one host).
    #[default]
    Wall,
    /// The vehicle's own (possibly simulated) clock: "now" is the newest state's `sent_ns`;
    /// wall time never enters the control law (a faster-than-real-time or lock-step run).
    Vehicle,
}

/// `pit-controller` settings (TOML; every field has a default).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ControllerIoSettings {
    /// Service-name prefix shared with the vehicle side.
    pub prefix: String,
    /// Control period (s); must equal the MPC step `controller.mpc.dt`.
    pub period: f64,
    /// A state older than `stale_periods` periods (at the command's time) is stale: the
    /// controller publishes its safe fallback instead of solving.
    pub stale_periods: f64,
    /// A control step (planning included) longer than this (s, wall time) is a missed
    /// deadline: its command is replaced by the safe fallback.
    pub deadline: f64,
    /// No vehicle heartbeat for this long (s, wall time): the peer is dead.
    pub peer_timeout: f64,
    /// Wait this long (s, wall time) for the first word from the vehicle (a heartbeat or a
    /// state); then give up and exit with `no_peer`.
    pub connect_timeout: f64,
    /// Nothing heard from the vehicle for this long (s, wall time) after it was heard:
    /// give up and exit with `peer_lost` (a restarted vehicle has this long to come back).
    pub peer_lost_timeout: f64,
    /// Delay compensation: the states are predicted forward by their age at the time of
    /// the command plus `actuation_delay` (s), at most `max_compensation` (s).
    pub compensate_delay: bool,
    pub actuation_delay: f64,
    pub max_compensation: f64,
    /// Fraction of μ g the fallback brakes with.
    pub fallback_brake: f64,
    /// Whose clock "now" comes from.
    pub clock: ControllerClock,
    /// The target surrogate (`4dof`, `pinn`, `picopinn`) and where the model files live.
    pub model: ModelKind,
    pub models_dir: PathBuf,
    /// Exit once the vehicle reports the run finished.
    pub exit_when_finished: bool,
    /// The hierarchical controller (planner, phases, MPC).
    pub controller: ControllerSettings,
}

impl Default for ControllerIoSettings {
    fn default() -> Self {
        Self {
            prefix: "picopit".to_owned(),
            period: 0.05,
            stale_periods: 2.0,
            deadline: 0.045,
            peer_timeout: 0.5,
            connect_timeout: 30.0,
            peer_lost_timeout: 10.0,
            compensate_delay: true,
            actuation_delay: 0.0,
            max_compensation: 0.25,
            fallback_brake: 0.6,
            clock: ControllerClock::Wall,
            model: ModelKind::PicoPinn,
            models_dir: PathBuf::from("models"),
            exit_when_finished: true,
            controller: ControllerSettings::default(),
        }
    }
}

impl ControllerIoSettings {
    /// Parse and validate TOML (missing fields take their defaults).
    ///
    /// # Errors
    /// [`ConfigError`] naming the file or the field.
    pub fn from_toml_str(text: &str, file: &str) -> Result<Self, ConfigError> {
        let s: Self = parse_toml(text, file)?;
        s.validate()?;
        Ok(s)
    }

    /// # Errors
    /// [`ConfigError::Invalid`] naming the first bad field.
    pub fn validate(&self) -> Result<(), ConfigError> {
        crate::ports::ServiceNames::new(&self.prefix)
            .map_err(|e| invalid("prefix", e.to_string()))?;
        in_range("period", self.period, 1e-3, 1.0)?;
        in_range("stale_periods", self.stale_periods, 1.0, 100.0)?;
        in_range("deadline", self.deadline, 1e-4, 60.0)?;
        in_range("peer_timeout", self.peer_timeout, 1e-3, 600.0)?;
        in_range("connect_timeout", self.connect_timeout, 0.0, 3600.0)?;
        in_range(
            "peer_lost_timeout",
            self.peer_lost_timeout,
            self.peer_timeout,
            3600.0,
        )?;
        in_range("actuation_delay", self.actuation_delay, 0.0, 1.0)?;
        in_range("max_compensation", self.max_compensation, 0.0, 1.0)?;
        in_range("fallback_brake", self.fallback_brake, 0.0, 1.0)?;
        self.controller
            .validate()
            .map_err(|e| invalid("controller", e.to_string()))?;
        if (self.controller.mpc.dt - self.period).abs() > 1e-9 {
            return Err(invalid(
                "period",
                format!(
                    "{} s: must equal controller.mpc.dt ({} s)",
                    self.period, self.controller.mpc.dt
                ),
            ));
        }
        Ok(())
    }

    /// The stale limit (ns).
    #[must_use]
    pub fn stale_ns(&self) -> u64 {
        secs_to_ns(self.stale_periods * self.period)
    }
}

/// How the vehicle side paces the run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum VehicleClock {
    /// Real time: the plant advances with the wall clock; commands apply on arrival.
    #[default]
    Wall,
    /// Lock step on a simulated clock: after each state the vehicle waits (at most
    /// `lockstep_timeout` of wall time) for the answering command, then advances one
    /// period. Runs as fast as the controller answers.
    Simulated,
}

/// Faults injected on the vehicle side (for tests and robustness runs).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, Default)]
#[serde(default, deny_unknown_fields)]
pub struct Faults {
    /// Probability that a state estimate is not published (dropped).
    pub drop_states: f64,
    /// From `stall_at` (s, vehicle time) on, for `stall_for` (s), no state is published.
    pub stall_at: f64,
    pub stall_for: f64,
}

/// `pit-vehicle` settings (TOML; every field has a default).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct VehicleIoSettings {
    pub prefix: String,
    /// State publication period (s).
    pub period: f64,
    pub clock: VehicleClock,
    /// Simulated clock: wall time to wait for the command answering a state (s); a longer
    /// wait is a missed deadline.
    pub lockstep_timeout: f64,
    /// No valid command for this long (s, vehicle time): the vehicle's own safe stop
    /// (latched).
    pub command_timeout: f64,
    /// A safe stop latched on the command timeout is released by this many consecutive
    /// fresh commands: valid, in track or fallback mode, answering states published after
    /// the latch (0: it stays latched until the run ends). A safe stop the controller asked
    /// for is never released.
    pub resume_after: u32,
    /// Wait this long (s, wall time) for the controller's first heartbeat before starting.
    pub connect_timeout: f64,
    /// Fraction of μ g of the vehicle's own safe stop.
    pub safe_stop_brake: f64,
    /// Sensing noise, latency and actuator errors of the simulated vehicles.
    pub uncertainty: Uncertainty,
    pub faults: Faults,
    /// Seed of the noise and actuator errors.
    pub seed: u64,
    /// Soak: restart the scenario whenever a run is over until this many periods have
    /// passed (0: one run).
    pub soak_periods: u64,
}

impl Default for VehicleIoSettings {
    fn default() -> Self {
        Self {
            prefix: "picopit".to_owned(),
            period: 0.05,
            clock: VehicleClock::Wall,
            lockstep_timeout: 1.0,
            command_timeout: 0.15,
            resume_after: 3,
            connect_timeout: 30.0,
            safe_stop_brake: 0.6,
            uncertainty: Uncertainty::default(),
            faults: Faults::default(),
            seed: 0,
            soak_periods: 0,
        }
    }
}

impl VehicleIoSettings {
    /// Parse and validate TOML (missing fields take their defaults).
    ///
    /// # Errors
    /// [`ConfigError`] naming the file or the field.
    pub fn from_toml_str(text: &str, file: &str) -> Result<Self, ConfigError> {
        let s: Self = parse_toml(text, file)?;
        s.validate()?;
        Ok(s)
    }

    /// # Errors
    /// [`ConfigError::Invalid`] naming the first bad field.
    pub fn validate(&self) -> Result<(), ConfigError> {
        crate::ports::ServiceNames::new(&self.prefix)
            .map_err(|e| invalid("prefix", e.to_string()))?;
        in_range("period", self.period, 1e-3, 1.0)?;
        in_range("lockstep_timeout", self.lockstep_timeout, 1e-3, 600.0)?;
        in_range("command_timeout", self.command_timeout, self.period, 60.0)?;
        if self.resume_after > 1000 {
            return Err(invalid(
                "resume_after",
                format!("{}: must lie in [0, 1000] commands", self.resume_after),
            ));
        }
        in_range("connect_timeout", self.connect_timeout, 0.0, 3600.0)?;
        in_range("safe_stop_brake", self.safe_stop_brake, 0.0, 1.0)?;
        in_range("faults.drop_states", self.faults.drop_states, 0.0, 1.0)?;
        in_range("faults.stall_at", self.faults.stall_at, 0.0, 1e6)?;
        in_range("faults.stall_for", self.faults.stall_for, 0.0, 1e6)?;
        self.uncertainty
            .validate()
            .map_err(|e| invalid("uncertainty", e.to_string()))?;
        Ok(())
    }
}

/// Seconds to nanoseconds (rounded; negative and NaN give 0).
#[must_use]
pub fn secs_to_ns(s: f64) -> u64 {
    if s.is_finite() && s > 0.0 {
        (s * 1e9).round() as u64
    } else {
        0
    }
}
