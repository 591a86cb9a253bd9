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

mod obstacle;
mod segment;
mod spec;

pub use obstacle::Obstacle;
pub use spec::{RoadError, RoadSpec, SegmentSpec};

use crate::geometry::{Obb, Pose2, Vec2};
use segment::{frenet, left_normal, ray_pose, unit, Foot, Segment, Side};

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

    /// The sharpest curvature (signed; the first of equal magnitude) of the reference line
    /// at the stations `s + k · step`, `k` over `stations` in order; 0 when `stations` is
    /// empty. Beyond the ends the line is straight (see [`Self::pose_at`]). A sampled
    /// look over a stretch of road, e.g. "does the road the target reaches in 4 s bend?".
    #[must_use]
    pub fn sharpest_curvature(
        &self,
        s: f64,
        step: f64,
        stations: std::ops::RangeInclusive<i64>,
    ) -> f64 {
        stations
            .map(|k| self.pose_at(s + k as f64 * step).curvature)
            .fold(0.0, |sharpest, k| {
                if k.abs() > sharpest.abs() {
                    k
                } else {
                    sharpest
                }
            })
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
