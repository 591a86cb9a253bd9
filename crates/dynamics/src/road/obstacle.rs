//! Obstacles: rectangles moving at constant velocity.

use super::spec::check;
use super::RoadError;
use crate::geometry::{Obb, Vec2};
use crate::params::Rule;
use serde::{Deserialize, Serialize};

/// An obstacle: a rectangle moving at constant world-frame velocity (zero for a static
/// one). `(x, y)` is the rectangle's centre at `t = 0`.
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Obstacle {
    /// Centre at `t = 0` (m).
    pub x: f64,
    /// Centre at `t = 0` (m).
    pub y: f64,
    /// Heading of the rectangle's length axis (rad); constant.
    pub heading: f64,
    /// World-frame velocity (m/s).
    pub vx: f64,
    /// World-frame velocity (m/s).
    pub vy: f64,
    /// Extent along the heading (m).
    pub length: f64,
    /// Extent across the heading (m).
    pub width: f64,
}

impl Obstacle {
    /// Check every field (finite; positive length and width). Field names are relative to
    /// the obstacle; use [`RoadError::within`] to add the path of the enclosing list.
    ///
    /// # Errors
    /// [`RoadError::Invalid`] naming the first bad field.
    pub fn validate(&self) -> Result<(), RoadError> {
        for (name, value) in [
            ("x", self.x),
            ("y", self.y),
            ("heading", self.heading),
            ("vx", self.vx),
            ("vy", self.vy),
        ] {
            check(|| name.to_owned(), value, Rule::Finite)?;
        }
        check(|| "length".to_owned(), self.length, Rule::Positive)?;
        check(|| "width".to_owned(), self.width, Rule::Positive)
    }

    /// Centre at time `t` (s).
    #[must_use]
    pub fn position_at(&self, t: f64) -> Vec2 {
        Vec2::new(self.x + self.vx * t, self.y + self.vy * t)
    }

    /// Footprint at time `t` (s).
    #[must_use]
    pub fn footprint_at(&self, t: f64) -> Obb {
        Obb::new(self.position_at(t), self.heading, self.length, self.width)
    }

    /// Whether the obstacle does not move.
    #[must_use]
    pub fn is_static(&self) -> bool {
        self.vx == 0.0 && self.vy == 0.0
    }
}
