//! Roads: reference-line geometry (straights, arcs, clothoids), the Frenet frame, signed
//! distances to the road edges, and obstacles moving at constant velocity.
//!
//! # Conventions
//!
//! * SI units throughout (m, rad, 1/m for curvature, m/s for velocities).
//! * World frame as in `DESIGN.md`: X along the road's initial direction, Y to the left.
//!   The road starts at `origin = [x, y, heading]` (the pose of `s = 0`); the built-in
//!   constructors put it at the world origin heading along +X.
//! * The **reference line** is the centre of the carriageway. `s` is the arc length along
//!   it; `d` is the lateral offset, **positive to the left** of the direction of travel.
//!   Curvature is positive for a left turn (heading increasing with `s`).
//! * Cross-section: `lanes` lanes of `lane_width`, numbered from the right (lane 0 is the
//!   rightmost), then a paved `shoulder` on either side. The road edges are at
//!   `d = ±half_width` with `half_width = lanes · lane_width / 2 + shoulder`.
//! * Beyond its ends the road is extrapolated straight along the end tangents, so that
//!   [`Road::pose_at`], [`Road::to_world`] and [`Road::project`] are defined for every `s`
//!   and every point (with `s < 0` before the start and `s > length` after the end).
//! * Edge distances are signed margins, `half_width − |d|` minimised over a point or a
//!   footprint: positive inside the road, negative by how far something crosses an edge.
//! * Obstacles are rectangles centred at `(x, y)` at `t = 0`, moving at a constant
//!   world-frame velocity `(vx, vy)` with a constant heading.
//! * A road is a chain of segments, each starting at the end pose of the previous one, so
//!   the reference line is always continuous in position and heading (G1); it is also
//!   continuous in curvature (G2) where the segments' curvatures match, which is what
//!   clothoid transitions are for.
//!
//! # Numerics
//!
//! Straights and arcs are evaluated and projected in closed form (arcs through the
//! chord `σ · sinc(κσ/2)`, which stays exact as κ → 0). A clothoid's heading
//! `θ(σ) = θ₀ + κ₀σ + (κ₁ − κ₀)σ²/(2L)` is exact; its position is integrated with 10-point
//! Gauss–Legendre quadrature between knots precomputed at construction (knot spacing
//! ≤ 4 m and ≤ 0.5 rad of heading change), which is accurate to round-off. Projection onto
//! a clothoid brackets the foot point between knots and finishes with safeguarded Newton
//! iterations on `s` (short Newton steps advance the position with a 5-point rule).
//! Evaluation, projection and edge distances allocate nothing.

use crate::geometry::{cross, rotate, Obb, Pose2, Vec2};
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

fn check(field: impl FnOnce() -> String, value: f64, rule: Rule) -> Result<(), RoadError> {
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
fn no_fold(half_width: f64) -> Rule {
    Rule::AbsBelowInverse {
        scale: half_width,
        reason: "|curvature| × half_width must be below 1 (the inner road edge would fold)",
    }
}

/// A point of the reference line: position, heading and curvature.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RoadPose {
    /// Position of the reference line (m).
    pub point: Vec2,
    /// Heading of the reference line, counter-clockwise from world X (rad).
    pub heading: f64,
    /// Signed curvature (1/m, positive = turning left); 0 on the extrapolated ends.
    pub curvature: f64,
}

impl RoadPose {
    /// Unit tangent (direction of increasing `s`).
    #[inline]
    #[must_use]
    pub fn tangent(&self) -> Vec2 {
        unit(self.heading)
    }

    /// Unit normal, pointing left (direction of increasing `d`).
    #[inline]
    #[must_use]
    pub fn normal(&self) -> Vec2 {
        left_normal(self.heading)
    }

    /// The pose as a rigid transform (body x along the road, y to its left).
    #[inline]
    #[must_use]
    pub fn pose(&self) -> Pose2 {
        Pose2 {
            p_in_world: self.point,
            yaw: self.heading,
        }
    }
}

/// Frenet coordinates of a point, with the road's heading and curvature at its foot point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Frenet {
    /// Arc length of the foot point along the reference line (m); negative before the
    /// start, beyond [`Road::length`] after the end.
    pub s: f64,
    /// Signed lateral offset from the reference line (m), positive to the left.
    pub d: f64,
    /// Road heading at `s` (rad).
    pub heading: f64,
    /// Road curvature at `s` (1/m).
    pub curvature: f64,
}

/// A road ready for evaluation: the validated specification plus every segment's start
/// pose, cumulative arc length and (for clothoids) precomputed quadrature knots.
#[derive(Clone, Debug)]
pub struct Road {
    spec: RoadSpec,
    segments: Vec<Segment>,
    length: f64,
    half_width: f64,
    /// Start of the reference line and its heading.
    start: Vec2,
    start_heading: f64,
    /// End of the reference line and its heading.
    end: Vec2,
    end_heading: f64,
}

impl TryFrom<RoadSpec> for Road {
    type Error = RoadError;

    fn try_from(spec: RoadSpec) -> Result<Self, RoadError> {
        Self::new(spec)
    }
}

impl Road {
    /// Validate `spec` and precompute the segments.
    ///
    /// # Errors
    /// As [`RoadSpec::validate`].
    pub fn new(spec: RoadSpec) -> Result<Self, RoadError> {
        spec.validate()?;
        let [x, y, heading] = spec.origin;
        let start = Vec2::new(x, y);
        let mut segments = Vec::with_capacity(spec.segments.len());
        let (mut s0, mut p, mut th) = (0.0, start, heading);
        for segment_spec in &spec.segments {
            let segment = Segment::new(segment_spec, s0, p, th);
            let end = segment.eval(segment.length);
            s0 += segment.length;
            p = end.point;
            th = end.heading;
            segments.push(segment);
        }
        Ok(Self {
            half_width: spec.half_width(),
            spec,
            segments,
            length: s0,
            start,
            start_heading: heading,
            end: p,
            end_heading: th,
        })
    }

    /// A straight road of `length` starting at the world origin along +X.
    ///
    /// # Panics
    /// If the arguments do not make a valid road (see [`RoadSpec::validate`]).
    #[must_use]
    pub fn straight(length: f64, lanes: u32, lane_width: f64, shoulder: f64) -> Self {
        let spec = RoadSpec {
            segments: vec![SegmentSpec::Straight { length }],
            lanes,
            lane_width,
            shoulder,
            origin: [0.0, 0.0, 0.0],
        };
        Self::new(spec).unwrap_or_else(|e| panic!("Road::straight: {e}"))
    }

    /// A curve starting at the world origin along +X: a straight entry of `entry`, a
    /// clothoid from curvature 0 to `1/radius` over `transition` (if `transition > 0`), an
    /// arc of `arc_length` at `1/radius`, the mirror clothoid back to 0, and a straight
    /// exit of `entry`. `radius` is signed: positive turns left. Zero `entry`,
    /// `transition` or `arc_length` leaves that piece out. The heading turns by
    /// `(arc_length + transition) / radius` in total.
    ///
    /// # Panics
    /// If `radius` is zero or not finite, a length is negative, every piece is empty, or the
    /// result is not a valid road (see [`RoadSpec::validate`]).
    #[must_use]
    pub fn curved(
        entry: f64,
        radius: f64,
        arc_length: f64,
        transition: f64,
        lanes: u32,
        lane_width: f64,
        shoulder: f64,
    ) -> Self {
        assert!(
            radius.is_finite() && radius != 0.0,
            "Road::curved: radius = {radius}: must be finite and non-zero"
        );
        for (name, v) in [
            ("entry", entry),
            ("arc_length", arc_length),
            ("transition", transition),
        ] {
            assert!(v >= 0.0, "Road::curved: {name} = {v}: must not be negative");
        }
        let k = radius.recip();
        let mut segments = Vec::with_capacity(5);
        if entry > 0.0 {
            segments.push(SegmentSpec::Straight { length: entry });
        }
        if transition > 0.0 {
            segments.push(SegmentSpec::Clothoid {
                length: transition,
                curvature_start: 0.0,
                curvature_end: k,
            });
        }
        if arc_length > 0.0 {
            segments.push(SegmentSpec::Arc {
                length: arc_length,
                curvature: k,
            });
        }
        if transition > 0.0 {
            segments.push(SegmentSpec::Clothoid {
                length: transition,
                curvature_start: k,
                curvature_end: 0.0,
            });
        }
        if entry > 0.0 {
            segments.push(SegmentSpec::Straight { length: entry });
        }
        let spec = RoadSpec {
            segments,
            lanes,
            lane_width,
            shoulder,
            origin: [0.0, 0.0, 0.0],
        };
        Self::new(spec).unwrap_or_else(|e| panic!("Road::curved: {e}"))
    }

    /// The specification this road was built from.
    #[must_use]
    pub fn spec(&self) -> &RoadSpec {
        &self.spec
    }

    /// Total arc length of the reference line (m).
    #[must_use]
    pub fn length(&self) -> f64 {
        self.length
    }

    /// Distance from the reference line to either edge (m): the edges are at
    /// `d = ±half_width`.
    #[must_use]
    pub fn half_width(&self) -> f64 {
        self.half_width
    }

    /// Lateral offset `d` of the centre of `lane` (lane 0 is the rightmost).
    ///
    /// # Panics
    /// If `lane ≥ lanes`.
    #[must_use]
    pub fn lane_center_offset(&self, lane: u32) -> f64 {
        let lanes = self.spec.lanes;
        assert!(
            lane < lanes,
            "lane {lane} does not exist (the road has {lanes} lanes)"
        );
        (f64::from(lane) + 0.5 - 0.5 * f64::from(lanes)) * self.spec.lane_width
    }

    /// Position, heading and curvature of the reference line at `s`; beyond the ends the
    /// line continues straight along the end tangents (curvature 0 there).
    #[must_use]
    pub fn pose_at(&self, s: f64) -> RoadPose {
        if s < 0.0 {
            ray_pose(self.start, self.start_heading, s)
        } else if s > self.length {
            ray_pose(self.end, self.end_heading, s - self.length)
        } else {
            let segment = &self.segments[self.segment_index(s)];
            segment.eval(s - segment.s0)
        }
    }

    /// World point at Frenet coordinates `(s, d)`.
    #[must_use]
    pub fn to_world(&self, s: f64, d: f64) -> Vec2 {
        let pose = self.pose_at(s);
        pose.point + d * pose.normal()
    }

    /// Frenet coordinates of `p`: the foot point is the nearest point of the (extended)
    /// reference line, so `to_world(s, d) = p` and `p − pose_at(s).point` is normal to the
    /// road. Closed form on straights and arcs; Newton iterations on clothoids.
    #[must_use]
    pub fn project(&self, p: Vec2) -> Frenet {
        // The extrapolated ends.
        let mut best = {
            let t = unit(self.start_heading);
            let sigma = (p - self.start).dot(&t).min(0.0);
            let foot = ray_pose(self.start, self.start_heading, sigma);
            (sigma, foot, (p - foot.point).norm_squared())
        };
        {
            let t = unit(self.end_heading);
            let sigma = (p - self.end).dot(&t).max(0.0);
            let foot = ray_pose(self.end, self.end_heading, sigma);
            let dist2 = (p - foot.point).norm_squared();
            if dist2 < best.2 {
                best = (self.length + sigma, foot, dist2);
            }
        }
        for segment in &self.segments {
            // Every point of a segment is within length/2 of its middle.
            let lower = (p - segment.mid).norm() - 0.5 * segment.length;
            if lower > 0.0 && lower * lower >= best.2 {
                continue;
            }
            let foot = segment.closest(p, None);
            let dist2 = (p - foot.pose.point).norm_squared();
            if dist2 < best.2 {
                best = (segment.s0 + foot.sigma, foot.pose, dist2);
            }
        }
        frenet(p, best.0, &best.1)
    }

    /// Like [`Road::project`], starting the search at `s_hint` and walking along the road
    /// to the nearest local foot point, instead of searching every segment. Use it when
    /// the caller tracks `s` (a vehicle moving along the road): the result equals
    /// [`Road::project`] whenever the point is nearer to the road around the hint than to
    /// any other part of it.
    #[must_use]
    pub fn project_with_hint(&self, p: Vec2, s_hint: f64) -> Frenet {
        #[derive(Clone, Copy, PartialEq)]
        enum Dir {
            Back,
            Ahead,
        }
        #[derive(Clone, Copy)]
        enum Piece {
            Before,
            Segment(usize),
            After,
        }
        let last = self.segments.len() - 1;
        let mut piece = if s_hint < 0.0 {
            Piece::Before
        } else if s_hint > self.length {
            Piece::After
        } else {
            Piece::Segment(self.segment_index(s_hint))
        };
        let mut hint = s_hint;
        let mut moving: Option<Dir> = None;
        loop {
            match piece {
                Piece::Before => {
                    let sigma = (p - self.start).dot(&unit(self.start_heading));
                    if sigma <= 0.0 || moving == Some(Dir::Back) {
                        let foot = ray_pose(self.start, self.start_heading, sigma.min(0.0));
                        return frenet(p, sigma.min(0.0), &foot);
                    }
                    piece = Piece::Segment(0);
                    hint = 0.0;
                    moving = Some(Dir::Ahead);
                }
                Piece::After => {
                    let sigma = (p - self.end).dot(&unit(self.end_heading));
                    if sigma >= 0.0 || moving == Some(Dir::Ahead) {
                        let foot = ray_pose(self.end, self.end_heading, sigma.max(0.0));
                        return frenet(p, self.length + sigma.max(0.0), &foot);
                    }
                    piece = Piece::Segment(last);
                    hint = self.length;
                    moving = Some(Dir::Back);
                }
                Piece::Segment(i) => {
                    let segment = &self.segments[i];
                    let foot = segment.closest(p, Some(hint - segment.s0));
                    let done = |foot: &Foot| frenet(p, segment.s0 + foot.sigma, &foot.pose);
                    match foot.side {
                        Side::Interior => return done(&foot),
                        Side::Start => {
                            if moving == Some(Dir::Ahead) {
                                return done(&foot);
                            }
                            moving = Some(Dir::Back);
                            hint = segment.s0;
                            piece = if i == 0 {
                                Piece::Before
                            } else {
                                Piece::Segment(i - 1)
                            };
                        }
                        Side::End => {
                            if moving == Some(Dir::Back) {
                                return done(&foot);
                            }
                            moving = Some(Dir::Ahead);
                            hint = segment.s0 + segment.length;
                            piece = if i == last {
                                Piece::After
                            } else {
                                Piece::Segment(i + 1)
                            };
                        }
                    }
                }
            }
        }
    }

    /// Signed distance of a footprint to the nearer road edge: the minimum over the
    /// footprint of `half_width − |d|`. Positive: the footprint is inside the road with
    /// that margin; negative: it crosses an edge by that much.
    ///
    /// The minimum is taken over the four corners and, where a side of the rectangle runs
    /// parallel to a curved road, over the point of that side furthest from the reference
    /// line: on the inside of a curve a straight side bulges past the edge between two
    /// corners (by `l²/(8R)` for a side of length `l` on an edge of radius `R`).
    #[must_use]
    pub fn edge_distance(&self, footprint: &Obb) -> f64 {
        let corners = footprint.corners();
        let feet = corners.map(|c| self.project(c));
        let mut margin = feet
            .iter()
            .map(|f| self.half_width - f.d.abs())
            .fold(f64::INFINITY, f64::min);
        for i in 0..4 {
            let j = (i + 1) % 4;
            margin = margin.min(self.side_margin(corners[i], corners[j], &feet[i], &feet[j]));
        }
        margin
    }

    /// Signed distance of a point to the nearer road edge: `half_width − |d|`.
    #[must_use]
    pub fn edge_distance_point(&self, p: Vec2) -> f64 {
        self.half_width - self.project(p).d.abs()
    }

    /// Margin at the interior extremum of `d` along the side `a → b`, if `d` has one
    /// there (the side turns from moving away from the reference line to moving back);
    /// `+∞` otherwise, since `d` is then monotone along the side and the corners decide.
    fn side_margin(&self, a: Vec2, b: Vec2, fa: &Frenet, fb: &Frenet) -> f64 {
        let e = b - a;
        // d'(λ) along a + λ e is n(s)·e.
        let slope_a = left_normal(fa.heading).dot(&e);
        let slope_b = left_normal(fb.heading).dot(&e);
        if slope_a * slope_b >= 0.0 {
            return f64::INFINITY;
        }
        // Maximise sign·d: find the root of g = sign·d' with g(0) > 0 > g(1).
        let sign = slope_a.signum();
        let (mut lo, mut hi) = (0.0, 1.0);
        let (g_lo, g_hi) = (sign * slope_a, sign * slope_b);
        let mut lambda = g_lo / (g_lo - g_hi);
        let mut hint = fa.s + lambda * (fb.s - fa.s);
        let tol = 1e-9 / e.norm();
        let mut f = self.project_with_hint(a + lambda * e, hint);
        for _ in 0..30 {
            hint = f.s;
            let g = sign * left_normal(f.heading).dot(&e);
            if g > 0.0 {
                lo = lambda;
            } else {
                hi = lambda;
            }
            // d'' = −κ (t·e)² / (1 − κ d).
            let te = unit(f.heading).dot(&e);
            let dg = -sign * f.curvature * te * te / (1.0 - f.curvature * f.d);
            let mut next = lambda - g / dg;
            if !(next > lo && next < hi) {
                next = 0.5 * (lo + hi);
            }
            let step = (next - lambda).abs();
            lambda = next;
            f = self.project_with_hint(a + lambda * e, hint);
            if step < tol || hi - lo < tol {
                break;
            }
        }
        self.half_width - f.d.abs()
    }

    /// Index of the segment containing `s ∈ [0, length]` (the later one at a joint).
    fn segment_index(&self, s: f64) -> usize {
        self.segments
            .partition_point(|g| g.s0 <= s)
            .saturating_sub(1)
    }
}

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

// ---------------------------------------------------------------------------------------
// Segments

/// Positive nodes of the 10-point Gauss–Legendre rule on [−1, 1] (the others are their
/// negatives) and their weights.
const GL_NODES: [f64; 5] = [
    0.148_874_338_981_631_22,
    0.433_395_394_129_247_2,
    0.679_409_568_299_024_4,
    0.865_063_366_688_984_5,
    0.973_906_528_517_171_7,
];
const GL_WEIGHTS: [f64; 5] = [
    0.295_524_224_714_752_87,
    0.269_266_719_309_996_35,
    0.219_086_362_515_982_04,
    0.149_451_349_150_580_6,
    0.066_671_344_308_688_14,
];

/// `∫_a^b f(u) du` by 10-point Gauss–Legendre.
#[inline]
fn gauss_legendre(a: f64, b: f64, f: impl Fn(f64) -> Vec2) -> Vec2 {
    let half = 0.5 * (b - a);
    let mid = 0.5 * (a + b);
    let mut sum = Vec2::zeros();
    for (x, w) in GL_NODES.iter().zip(GL_WEIGHTS) {
        sum += w * (f(mid - half * x) + f(mid + half * x));
    }
    half * sum
}

/// `∫_a^b f(u) du` by 5-point Gauss–Legendre (for short steps).
#[inline]
fn gauss_legendre_5(a: f64, b: f64, f: impl Fn(f64) -> Vec2) -> Vec2 {
    const NODES: [f64; 2] = [0.538_469_310_105_683_1, 0.906_179_845_938_664];
    const WEIGHTS: [f64; 2] = [0.478_628_670_499_366_47, 0.236_926_885_056_189_08];
    const CENTRE_WEIGHT: f64 = 128.0 / 225.0;
    let half = 0.5 * (b - a);
    let mid = 0.5 * (a + b);
    let mut sum = CENTRE_WEIGHT * f(mid);
    for (x, w) in NODES.iter().zip(WEIGHTS) {
        sum += w * (f(mid - half * x) + f(mid + half * x));
    }
    half * sum
}

/// Longest knot interval of a clothoid (m) and largest heading change across one (rad).
const KNOT_MAX_STEP: f64 = 4.0;
const KNOT_MAX_TURN: f64 = 0.5;
/// Longest step (m) and heading change (rad) taken with the 5-point rule.
const SHORT_STEP: f64 = 0.25;
const SHORT_TURN: f64 = 0.05;

#[inline]
fn unit(heading: f64) -> Vec2 {
    let (s, c) = heading.sin_cos();
    Vec2::new(c, s)
}

#[inline]
fn left_normal(heading: f64) -> Vec2 {
    rotate(heading, Vec2::new(0.0, 1.0))
}

/// `sin(x)/x`, exact near 0.
#[inline]
fn sinc(x: f64) -> f64 {
    if x.abs() < 1e-4 {
        let x2 = x * x;
        1.0 - x2 / 6.0 * (1.0 - x2 / 20.0)
    } else {
        x.sin() / x
    }
}

/// The straight extrapolation at `sigma` from `(start, heading)`.
#[inline]
fn ray_pose(start: Vec2, heading: f64, sigma: f64) -> RoadPose {
    RoadPose {
        point: start + sigma * unit(heading),
        heading,
        curvature: 0.0,
    }
}

/// Frenet coordinates of `p` given its foot point `foot` at arc length `s`.
#[inline]
fn frenet(p: Vec2, s: f64, foot: &RoadPose) -> Frenet {
    Frenet {
        s,
        d: cross(foot.tangent(), p - foot.point),
        heading: foot.heading,
        curvature: foot.curvature,
    }
}

#[derive(Clone, Debug)]
struct Segment {
    /// Arc length at the segment's start.
    s0: f64,
    length: f64,
    /// Start pose.
    p0: Vec2,
    heading0: f64,
    /// The point at half the length (for pruning in [`Road::project`]).
    mid: Vec2,
    shape: Shape,
}

#[derive(Clone, Debug)]
enum Shape {
    Line,
    Arc { curvature: f64 },
    Clothoid(Clothoid),
}

#[derive(Clone, Debug)]
struct Clothoid {
    /// Start heading.
    heading0: f64,
    /// Curvature at the start.
    k0: f64,
    /// Rate of change of curvature (1/m²).
    dk: f64,
    /// Largest |curvature| on the segment.
    k_max: f64,
    length: f64,
    /// Knot spacing; the last knot is at `length`.
    step: f64,
    /// Number of knot intervals (knots: `intervals + 1`).
    intervals: usize,
    /// Positions at the knots `σ_j = j · step`.
    knots: Vec<Vec2>,
    /// Unit tangents at the knots.
    tangents: Vec<Vec2>,
}

/// Where the nearest point of a segment lies: inside it, or clamped to an end because the
/// unconstrained foot point is before the start or after the end.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Side {
    Interior,
    Start,
    End,
}

/// The nearest point of one segment: local arc length, pose there, and where it lies.
#[derive(Clone, Copy, Debug)]
struct Foot {
    sigma: f64,
    pose: RoadPose,
    side: Side,
}

impl Segment {
    fn new(spec: &SegmentSpec, s0: f64, p0: Vec2, heading0: f64) -> Self {
        let length = spec.length();
        let shape = match *spec {
            SegmentSpec::Straight { .. } => Shape::Line,
            SegmentSpec::Arc { curvature, .. } => Shape::Arc { curvature },
            SegmentSpec::Clothoid {
                curvature_start: k0,
                curvature_end: k1,
                ..
            } => Shape::Clothoid(Clothoid::new(length, heading0, p0, k0, k1)),
        };
        let mut segment = Self {
            s0,
            length,
            p0,
            heading0,
            mid: p0,
            shape,
        };
        segment.mid = segment.eval(0.5 * length).point;
        segment
    }

    /// Pose at local arc length `sigma ∈ [0, length]`.
    fn eval(&self, sigma: f64) -> RoadPose {
        match &self.shape {
            Shape::Line => ray_pose(self.p0, self.heading0, sigma),
            &Shape::Arc { curvature } => {
                let half_turn = 0.5 * curvature * sigma;
                let chord = sigma * sinc(half_turn);
                RoadPose {
                    point: self.p0 + chord * unit(self.heading0 + half_turn),
                    heading: self.heading0 + 2.0 * half_turn,
                    curvature,
                }
            }
            Shape::Clothoid(c) => c.eval(sigma),
        }
    }

    fn foot(&self, sigma: f64, side: Side) -> Foot {
        Foot {
            sigma,
            pose: self.eval(sigma),
            side,
        }
    }

    /// The segment point nearest to `p` (locally, near `hint` if given).
    fn closest(&self, p: Vec2, hint: Option<f64>) -> Foot {
        match &self.shape {
            Shape::Line => {
                let sigma = (p - self.p0).dot(&unit(self.heading0));
                self.clamped(sigma)
            }
            &Shape::Arc { curvature } => self.closest_on_arc(p, curvature, hint.unwrap_or(0.0)),
            Shape::Clothoid(c) => self.closest_on_clothoid(c, p, hint),
        }
    }

    /// The foot at `sigma`, clamped to the segment.
    fn clamped(&self, sigma: f64) -> Foot {
        if sigma < 0.0 {
            self.foot(0.0, Side::Start)
        } else if sigma > self.length {
            self.foot(self.length, Side::End)
        } else {
            self.foot(sigma, Side::Interior)
        }
    }

    /// Closed form: in the start frame the arc is centred at `(0, 1/κ)` and the foot of
    /// `(u, v)` has local heading `α = atan2(κu, 1 − κv)`, so `σ = α/κ` modulo a full turn.
    fn closest_on_arc(&self, p: Vec2, k: f64, hint: f64) -> Foot {
        let q = rotate(-self.heading0, p - self.p0);
        if k == 0.0 {
            return self.clamped(q.x);
        }
        let base = (k * q.x).atan2(1.0 - k * q.y) / k;
        let period = std::f64::consts::TAU / k.abs();
        // The equivalents base + n·period that lie on the arc, if any.
        let n_lo = (-base / period).ceil();
        let n_hi = ((self.length - base) / period).floor();
        if n_lo <= n_hi {
            let n = ((hint - base) / period).round().clamp(n_lo, n_hi);
            let sigma = (base + n * period).clamp(0.0, self.length);
            return self.foot(sigma, Side::Interior);
        }
        // Off the arc: the nearer end is the nearest point.
        let start = self.foot(0.0, Side::Start);
        let end = self.foot(self.length, Side::End);
        if (p - start.pose.point).norm_squared() <= (p - end.pose.point).norm_squared() {
            start
        } else {
            end
        }
    }

    /// Bracket the foot point between knots (walking from the knot interval of the hint,
    /// or from the nearest knot), then solve `g(σ) = (p − c(σ))·t(σ) = 0` there.
    fn closest_on_clothoid(&self, c: &Clothoid, p: Vec2, hint: Option<f64>) -> Foot {
        let intervals = c.intervals;
        let solved = |j: usize, ga: f64, gb: f64| {
            let (sigma, pose) = c.solve(p, j, ga, gb);
            Foot {
                sigma,
                pose,
                side: Side::Interior,
            }
        };
        // g at knot j; g decreases through zero at a foot point.
        let g = |j: usize| (p - c.knots[j]).dot(&c.tangents[j]);
        let j = match hint {
            Some(h) => c.knot_below(h.clamp(0.0, self.length)),
            None => {
                let nearest = c
                    .knots
                    .iter()
                    .map(|k| (p - k).norm_squared())
                    .enumerate()
                    .fold(
                        (0, f64::INFINITY),
                        |best, (j, d2)| if d2 < best.1 { (j, d2) } else { best },
                    );
                let k = nearest.0;
                if k == intervals || (k > 0 && g(k) < 0.0) {
                    k - 1
                } else {
                    k
                }
            }
        };
        let (ga, gb) = (g(j), g(j + 1));
        let walk_back = |mut j: usize, mut gb: f64| loop {
            if j == 0 {
                break self.foot(0.0, Side::Start);
            }
            j -= 1;
            let ga = g(j);
            if ga >= 0.0 {
                break solved(j, ga, gb);
            }
            gb = ga;
        };
        let walk_ahead = |mut j: usize, mut ga: f64| loop {
            if j + 1 == intervals {
                break self.foot(self.length, Side::End);
            }
            j += 1;
            let gb = g(j + 1);
            if gb <= 0.0 {
                break solved(j, ga, gb);
            }
            ga = gb;
        };
        match (ga >= 0.0, gb <= 0.0) {
            (true, true) => solved(j, ga, gb),
            (false, true) => walk_back(j, ga),
            (true, false) => walk_ahead(j, gb),
            // A local maximum of the distance inside (p is beyond the centre of
            // curvature): look both ways.
            (false, false) => {
                let back = walk_back(j, ga);
                let ahead = walk_ahead(j, gb);
                if (p - back.pose.point).norm_squared() <= (p - ahead.pose.point).norm_squared() {
                    back
                } else {
                    ahead
                }
            }
        }
    }
}

impl Clothoid {
    /// Precompute the knots of a clothoid of `length` from `(p0, heading0)` with curvature
    /// going linearly from `k0` to `k1`.
    fn new(length: f64, heading0: f64, p0: Vec2, k0: f64, k1: f64) -> Self {
        let k_max = k0.abs().max(k1.abs());
        // Both ratios are finite and non-negative (validated) and the count is small.
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        let n = (length / KNOT_MAX_STEP)
            .max(k_max * length / KNOT_MAX_TURN)
            .ceil()
            .max(1.0) as usize;
        let mut c = Self {
            heading0,
            k0,
            dk: (k1 - k0) / length,
            k_max,
            length,
            step: length / n as f64,
            intervals: n,
            knots: Vec::with_capacity(n + 1),
            tangents: Vec::with_capacity(n + 1),
        };
        let mut p = p0;
        for j in 0..=n {
            if j > 0 {
                let (a, b) = (c.sigma(j - 1), c.sigma(j));
                p += gauss_legendre(a, b, |u| unit(c.heading(u)));
            }
            c.knots.push(p);
            c.tangents.push(unit(c.heading(c.sigma(j))));
        }
        c
    }

    /// Heading at `sigma` (exact).
    #[inline]
    fn heading(&self, sigma: f64) -> f64 {
        self.heading0 + sigma * (self.k0 + 0.5 * self.dk * sigma)
    }

    /// Pose at `sigma ∈ [0, length]`: the knot below plus the quadrature from it.
    fn eval(&self, sigma: f64) -> RoadPose {
        let j = self.knot_below(sigma);
        let point = self.knots[j] + gauss_legendre(self.sigma(j), sigma, |u| unit(self.heading(u)));
        RoadPose {
            point,
            heading: self.heading(sigma),
            curvature: self.k0 + self.dk * sigma,
        }
    }

    /// Pose at `b` from the pose `from` at `a`, for short steps (see [`Clothoid::is_short`]).
    fn advance(&self, from: &RoadPose, a: f64, b: f64) -> RoadPose {
        let point = from.point + gauss_legendre_5(a, b, |u| unit(self.heading(u)));
        RoadPose {
            point,
            heading: self.heading(b),
            curvature: self.k0 + self.dk * b,
        }
    }

    /// Whether a step is short enough for [`Clothoid::advance`] to stay at round-off (the
    /// 5-point rule's error is below `(κ h)¹⁰ h · 10⁻¹²`).
    #[inline]
    fn is_short(&self, step: f64) -> bool {
        step.abs() <= SHORT_STEP && step.abs() * self.k_max <= SHORT_TURN
    }

    /// Safeguarded Newton on `g(σ) = (p − c)·t` in knot interval `j`, where
    /// `g(σ_j) = ga ≥ 0 ≥ gb = g(σ_{j+1})`; `g' = −(1 − κd)`. Falls back to bisection when a
    /// Newton step leaves the bracket.
    fn solve(&self, p: Vec2, j: usize, ga: f64, gb: f64) -> (f64, RoadPose) {
        let (mut lo, mut hi) = (self.sigma(j), self.sigma(j + 1));
        // Start from the linear interpolation of g between the knots.
        let mut sigma = if ga - gb > 0.0 {
            lo + (hi - lo) * ga / (ga - gb)
        } else {
            lo
        };
        let mut pose = self.eval(sigma);
        for _ in 0..100 {
            let r = p - pose.point;
            let g = r.dot(&pose.tangent());
            if g > 0.0 {
                lo = sigma;
            } else {
                hi = sigma;
            }
            let slope = 1.0 - pose.curvature * r.dot(&pose.normal());
            let mut next = sigma + g / slope;
            let newton = slope > 0.0 && next >= lo && next <= hi;
            if !newton {
                next = 0.5 * (lo + hi);
            }
            let step = next - sigma;
            if step == 0.0 {
                break;
            }
            pose = if self.is_short(step) {
                self.advance(&pose, sigma, next)
            } else {
                self.eval(next)
            };
            sigma = next;
            // After a Newton step of δ the error is O(δ²): below 1e-8 m, it is round-off.
            if (newton && step.abs() < 1e-8) || hi - lo < 1e-13 {
                break;
            }
        }
        (sigma, pose)
    }

    /// Arc length of knot `j` (the last knot sits exactly at `length`).
    #[inline]
    fn sigma(&self, j: usize) -> f64 {
        if j == self.intervals {
            self.length
        } else {
            j as f64 * self.step
        }
    }

    /// Index of the knot interval containing `sigma` (clamped to the segment).
    #[inline]
    fn knot_below(&self, sigma: f64) -> usize {
        // Non-negative, and bounded after the clamp.
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        let j = (sigma / self.step).floor().max(0.0) as usize;
        j.min(self.intervals - 1)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gauss_legendre_is_exact_to_degree_19() {
        for n in 0..20 {
            let exact = if n % 2 == 0 {
                2.0 / f64::from(n + 1)
            } else {
                0.0
            };
            let got = gauss_legendre(-1.0, 1.0, |u| Vec2::new(u.powi(n), 0.0)).x;
            assert!((got - exact).abs() < 1e-14, "degree {n}: {got} vs {exact}");
        }
    }

    #[test]
    fn gauss_legendre_5_is_exact_to_degree_9() {
        for n in 0..10 {
            let exact = if n % 2 == 0 {
                2.0 / f64::from(n + 1)
            } else {
                0.0
            };
            let got = gauss_legendre_5(-1.0, 1.0, |u| Vec2::new(u.powi(n), 0.0)).x;
            assert!((got - exact).abs() < 1e-15, "degree {n}: {got} vs {exact}");
        }
    }

    #[test]
    fn sinc_is_continuous_at_the_switch() {
        let x = 1e-4;
        // Series just below the switch, sin(x)/x at it: equal to round-off.
        assert!((sinc(x * (1.0 - 1e-12)) - sinc(x)).abs() < 4e-16);
        assert_eq!(sinc(0.0), 1.0);
    }

    #[test]
    fn clothoid_knots_respect_spacing() {
        let road = Road::new(RoadSpec {
            segments: vec![SegmentSpec::Clothoid {
                length: 90.0,
                curvature_start: 0.0,
                curvature_end: 0.1,
            }],
            lanes: 2,
            lane_width: 3.5,
            shoulder: 0.5,
            origin: [0.0, 0.0, 0.0],
        })
        .unwrap();
        let Shape::Clothoid(c) = &road.segments[0].shape else {
            panic!("not a clothoid")
        };
        // Turn 0.1 · 90 = 9 rad at most / 0.5 → 18 intervals; length 90 / 4 → 23.
        assert_eq!(c.knots.len(), 24);
        assert!((c.sigma(23) - 90.0).abs() < 1e-15);
        assert_eq!(c.knot_below(90.0), 22);
        assert_eq!(c.knot_below(0.0), 0);
    }
}
