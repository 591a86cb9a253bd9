//! Typed errors for bad input (parameter files, settings). Numerical trouble is never an
//! `Err`: the models return finite values or a status.

use thiserror::Error;

/// A parameter set or parameter file that cannot be used.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum ParamError {
    /// The TOML could not be parsed or did not match the schema (missing or unknown field,
    /// wrong type). The message from the parser names the field.
    #[error("{source_name}: {message}")]
    Parse {
        source_name: String,
        message: String,
    },
    /// A field has a value outside its admissible range.
    #[error("{field} = {value}: {reason}")]
    Invalid {
        field: String,
        value: f64,
        reason: &'static str,
    },
    /// A table a setting needs is absent (e.g. `target.powertrain` for a target in gear).
    #[error("{table}: missing, {reason}")]
    Missing { table: String, reason: &'static str },
    /// The file could not be read.
    #[error("cannot read {path}: {message}")]
    Io { path: String, message: String },
    /// A named built-in parameter set does not exist.
    #[error("unknown parameter set `{0}` (built in: full_size, half_scale)")]
    UnknownSet(String),
}
