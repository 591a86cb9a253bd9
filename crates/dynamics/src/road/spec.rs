//! The road's and obstacles' specification (segments, cross-section) and its validation.

use crate::params::Rule;
use serde::{Deserialize, Serialize};
use thiserror::Error;

/// A road (or obstacle) description that cannot be used.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum RoadError {
    /// A field has a value outside its admissible range; `field` is its path in the
    /// specification (e.g. `segments[2].length`).
    #[error("{field} = {value}: {reason}")]
    Invalid {
        field: String,
        value: f64,
        reason: &'static str,
    },
    /// The road has no segments.
    #[error("segments: a road needs at least one segment")]
    NoSegments,
    /// The text could not be parsed or did not match the schema (missing or unknown field,
    /// unknown segment kind, wrong type); the parser's message names the field.
    #[error("{source_name}: {message}")]
    Parse {
        source_name: String,
        message: String,
    },
}

impl RoadError {
    /// Prefix the field path with the path of the enclosing object, e.g.
    /// `obstacle.validate().map_err(|e| e.within("obstacles[3]"))` reports
    /// `obstacles[3].length`.
    #[must_use]
    pub fn within(self, parent: &str) -> Self {
        match self {
            Self::Invalid {
                field,
                value,
                reason,
            } => Self::Invalid {
                field: format!("{parent}.{field}"),
                value,
                reason,
            },
            Self::NoSegments => Self::Invalid {
                field: format!("{parent}.segments"),
                value: 0.0,
                reason: "a road needs at least one segment",
            },
            parse @ Self::Parse { .. } => parse,
        }
    }
}

/// One piece of the reference line. In TOML:
/// `segments = [{ kind = "straight", length = 50.0 }, { kind = "arc", length = 30.0, curvature = 0.02 }]`.
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum SegmentSpec {
    /// A straight line of `length` (m).
    Straight { length: f64 },
    /// A circular arc of `length` (m) and constant signed `curvature` (1/m, positive = left).
    Arc { length: f64, curvature: f64 },
    /// A clothoid (Euler spiral): curvature varies linearly with `s` from
    /// `curvature_start` to `curvature_end` over `length`.
    Clothoid {
        length: f64,
        curvature_start: f64,
        curvature_end: f64,
    },
}

impl SegmentSpec {
    /// The segment's arc length (m).
    #[must_use]
    pub fn length(&self) -> f64 {
        match *self {
            Self::Straight { length }
            | Self::Arc { length, .. }
            | Self::Clothoid { length, .. } => length,
        }
    }
}

/// A road as it appears in a scenario or settings file.
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct RoadSpec {
    /// The reference line, from `s = 0` on.
    pub segments: Vec<SegmentSpec>,
    /// Number of lanes (≥ 1).
    pub lanes: u32,
    /// Width of one lane (m).
    pub lane_width: f64,
    /// Paved shoulder beyond the outer lanes on each side, inside the edge (m).
    pub shoulder: f64,
    /// Pose of `s = 0`: `[x, y, heading]` (m, m, rad).
    pub origin: [f64; 3],
}

impl RoadSpec {
    /// Distance from the reference line to either edge:
    /// `lanes · lane_width / 2 + shoulder`.
    #[must_use]
    pub fn half_width(&self) -> f64 {
        0.5 * f64::from(self.lanes) * self.lane_width + self.shoulder
    }

    /// Check every field; the error names the first offending one.
    ///
    /// Rules: at least one segment; every value finite; lengths positive; `lanes ≥ 1`;
    /// `lane_width > 0`; `shoulder ≥ 0`; and `|curvature| · half_width < 1` everywhere,
    /// so that the edge on the inside of a curve does not fold over itself.
    ///
    /// # Errors
    /// [`RoadError::Invalid`] naming the first bad field, or [`RoadError::NoSegments`].
    pub fn validate(&self) -> Result<(), RoadError> {
        for (i, &v) in self.origin.iter().enumerate() {
            check(|| format!("origin[{i}]"), v, Rule::Finite)?;
        }
        if self.lanes == 0 {
            return Err(RoadError::Invalid {
                field: "lanes".to_owned(),
                value: 0.0,
                reason: "must be at least 1",
            });
        }
        check(|| "lane_width".to_owned(), self.lane_width, Rule::Positive)?;
        check(|| "shoulder".to_owned(), self.shoulder, Rule::NonNegative)?;
        if self.segments.is_empty() {
            return Err(RoadError::NoSegments);
        }
        let half_width = self.half_width();
        let fold = no_fold(half_width);
        for (i, segment) in self.segments.iter().enumerate() {
            let field = |name: &str| format!("segments[{i}].{name}");
            check(|| field("length"), segment.length(), Rule::Positive)?;
            match *segment {
                SegmentSpec::Straight { .. } => {}
                SegmentSpec::Arc { curvature, .. } => {
                    check(|| field("curvature"), curvature, fold)?;
                }
                SegmentSpec::Clothoid {
                    curvature_start,
                    curvature_end,
                    ..
                } => {
                    check(|| field("curvature_start"), curvature_start, fold)?;
                    check(|| field("curvature_end"), curvature_end, fold)?;
                }
            }
        }
        let total: f64 = self.segments.iter().map(SegmentSpec::length).sum();
        check(|| "segments".to_owned(), total, Rule::Finite)
    }

    /// Parse TOML text and validate it; `source_name` (a file name, say) prefixes parse
    /// errors.
    ///
    /// # Errors
    /// [`RoadError::Parse`] if the text is not TOML or does not match the schema (the
    /// message names the field); otherwise as [`RoadSpec::validate`].
    pub fn from_toml_str(text: &str, source_name: &str) -> Result<Self, RoadError> {
        let spec: Self = toml::from_str(text).map_err(|e| RoadError::Parse {
            source_name: source_name.to_owned(),
            message: e.to_string().trim_end().to_owned(),
        })?;
        spec.validate()?;
        Ok(spec)
    }

    /// Serialise to TOML (round-trips through [`RoadSpec::from_toml_str`]).
    ///
    /// # Panics
    /// Never in practice: every field of a specification has a TOML representation.
    #[must_use]
    pub fn to_toml_string(&self) -> String {
        toml::to_string(self).expect("a road specification always serialises")
    }
}

pub(super) fn check(
    field: impl FnOnce() -> String,
    value: f64,
    rule: Rule,
) -> Result<(), RoadError> {
    match rule.violation(value) {
        Some(reason) => Err(RoadError::Invalid {
            field: field(),
            value,
            reason,
        }),
        None => Ok(()),
    }
}

/// The road-specific rule: the inner edge must not fold over the reference line.
pub(super) fn no_fold(half_width: f64) -> Rule {
    Rule::AbsBelowInverse {
        scale: half_width,
        reason: "|curvature| × half_width must be below 1 (the inner road edge would fold)",
    }
}
