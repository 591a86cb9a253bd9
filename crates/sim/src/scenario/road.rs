//! The scenario's road: its cross-section and reference line, validated and built into a
//! [`Road`].

use super::{finite, range, ScenarioError};
use dynamics::road::{Road, RoadSpec, SegmentSpec};
use serde::{Deserialize, Serialize};

/// The road: a cross-section and a reference line, either straight (`radius` absent) or a
/// curve: straight `entry`, clothoid `transition` from 0 to `1/radius`, arc, the mirror
/// clothoid, straight `entry` again; `length` is the total (m).
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct RoadDef {
    /// Number of lanes (1–8), numbered from the right.
    pub lanes: u32,
    /// Lane width (m).
    pub lane_width: f64,
    /// Paved shoulder beyond the outer lanes, each side (m).
    pub shoulder: f64,
    /// Total length of the reference line (m).
    pub length: f64,
    /// Signed radius of the arc (m, positive turns left); absent for a straight road.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub radius: Option<f64>,
    /// Straight before and after the curve (m); curved roads only.
    #[serde(default)]
    pub entry: f64,
    /// Clothoid length into and out of the arc (m); curved roads only.
    #[serde(default)]
    pub transition: f64,
}

impl RoadDef {
    /// Half width of the carriageway including shoulders (m).
    #[must_use]
    pub fn half_width(&self) -> f64 {
        0.5 * f64::from(self.lanes) * self.lane_width + self.shoulder
    }

    /// The arc's length (m) of a curved road.
    #[must_use]
    pub fn arc_length(&self) -> f64 {
        self.length - 2.0 * self.entry - 2.0 * self.transition
    }

    /// The reference line as a [`RoadSpec`] (not validated).
    #[must_use]
    pub fn spec(&self) -> RoadSpec {
        let mut segments = Vec::with_capacity(5);
        match self.radius {
            None => segments.push(SegmentSpec::Straight {
                length: self.length,
            }),
            Some(radius) => {
                let k = 1.0 / radius;
                if self.entry > 0.0 {
                    segments.push(SegmentSpec::Straight { length: self.entry });
                }
                if self.transition > 0.0 {
                    segments.push(SegmentSpec::Clothoid {
                        length: self.transition,
                        curvature_start: 0.0,
                        curvature_end: k,
                    });
                }
                segments.push(SegmentSpec::Arc {
                    length: self.arc_length(),
                    curvature: k,
                });
                if self.transition > 0.0 {
                    segments.push(SegmentSpec::Clothoid {
                        length: self.transition,
                        curvature_start: k,
                        curvature_end: 0.0,
                    });
                }
                if self.entry > 0.0 {
                    segments.push(SegmentSpec::Straight { length: self.entry });
                }
            }
        }
        RoadSpec {
            segments,
            lanes: self.lanes,
            lane_width: self.lane_width,
            shoulder: self.shoulder,
            origin: [0.0, 0.0, 0.0],
        }
    }

    /// Build the road.
    ///
    /// # Errors
    /// [`ScenarioError::Field`] (on line 0: use [`ScenarioError::at_line`]) naming the bad
    /// road field.
    pub fn build(&self) -> Result<Road, ScenarioError> {
        self.check(0)?;
        Road::new(self.spec()).map_err(|e| ScenarioError::field(0, "road", e.to_string()))
    }

    pub(super) fn check(&self, line: usize) -> Result<(), ScenarioError> {
        let f = |name: &str| format!("road.{name}");
        if !(1..=8).contains(&self.lanes) {
            return Err(ScenarioError::field(
                line,
                f("lanes"),
                format!("{}: must lie in 1..=8", self.lanes),
            ));
        }
        range(line, &f("lane_width"), self.lane_width, 0.5, 6.0)?;
        range(line, &f("shoulder"), self.shoulder, 0.0, 10.0)?;
        range(line, &f("length"), self.length, 10.0, 20_000.0)?;
        range(line, &f("entry"), self.entry, 0.0, 20_000.0)?;
        range(line, &f("transition"), self.transition, 0.0, 20_000.0)?;
        match self.radius {
            None => {
                if self.entry != 0.0 || self.transition != 0.0 {
                    return Err(ScenarioError::field(
                        line,
                        f("entry"),
                        "entry and transition belong to a curve: give a radius or set them to 0",
                    ));
                }
            }
            Some(r) => {
                finite(line, &f("radius"), r)?;
                let hw = self.half_width();
                if r.abs() < (2.0 * hw).max(10.0) {
                    return Err(ScenarioError::field(
                        line,
                        f("radius"),
                        format!(
                            "{r}: |radius| must be at least max(10 m, the road's width {:.2} m)",
                            2.0 * hw
                        ),
                    ));
                }
                let arc = self.arc_length();
                if arc <= 0.0 {
                    return Err(ScenarioError::field(
                        line,
                        f("length"),
                        format!(
                            "{}: must exceed 2·entry + 2·transition (the arc would be {arc} m)",
                            self.length
                        ),
                    ));
                }
                let turn = (arc + self.transition) / r.abs();
                if turn > std::f64::consts::PI + 1e-9 {
                    return Err(ScenarioError::field(
                        line,
                        f("(length, entry, transition, radius)"),
                        format!(
                            "({}, {}, {}, {r}): the curve turns {turn:.3} rad; at most π",
                            self.length, self.entry, self.transition
                        ),
                    ));
                }
            }
        }
        Ok(())
    }
}
