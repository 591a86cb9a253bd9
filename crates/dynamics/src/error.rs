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
    #[error("{field} = {}: {reason}", Shown(*.value))]
    Invalid {
        field: String,
        value: f64,
        reason: &'static str,
    },
    /// A finite value far outside what any road vehicle (1:5 scale model to heavy truck) or
    /// its contact could have: the plant would run but its numbers would mean nothing.
    #[error(
        "{field} = {}: outside the physical range [{}, {}]{}{unit}",
        Shown(*.value), Shown(*.lo), Shown(*.hi), if unit.is_empty() { "" } else { " " }
    )]
    OutOfRange {
        field: String,
        value: f64,
        lo: f64,
        hi: f64,
        unit: &'static str,
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

/// A number as a person writes it: plain in [1e-3, 1e6), otherwise in scientific notation
/// (`1e308`, not three hundred digits).
#[derive(Debug, Clone, Copy)]
pub struct Shown(pub f64);

impl std::fmt::Display for Shown {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let a = self.0.abs();
        if a == 0.0 || !a.is_finite() || (1e-3..1e6).contains(&a) {
            write!(f, "{}", self.0)
        } else {
            write!(f, "{:e}", self.0)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::Shown;

    #[test]
    fn numbers_are_shown_as_written() {
        let shown = |v: f64| Shown(v).to_string();
        assert_eq!(shown(1e308), "1e308");
        assert_eq!(shown(-1e-9), "-1e-9");
        assert_eq!(shown(1e15), "1e15");
        assert_eq!(shown(1093.2952), "1093.2952");
        assert_eq!(shown(0.0), "0");
        assert_eq!(shown(f64::NAN), "NaN");
    }
}
