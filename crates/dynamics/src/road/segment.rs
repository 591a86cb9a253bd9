//! The reference line's segments (straights, arcs, clothoids): evaluation and projection
//! in closed form or by quadrature between precomputed knots (the road module's "Numerics").

use super::spec::SegmentSpec;
use super::{Frenet, RoadPose};
use crate::geometry::{cross, rotate, Vec2};

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
pub(super) fn unit(heading: f64) -> Vec2 {
    let (s, c) = heading.sin_cos();
    Vec2::new(c, s)
}

#[inline]
pub(super) fn left_normal(heading: f64) -> Vec2 {
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
pub(super) fn ray_pose(start: Vec2, heading: f64, sigma: f64) -> RoadPose {
    RoadPose {
        point: start + sigma * unit(heading),
        heading,
        curvature: 0.0,
    }
}

/// Frenet coordinates of `p` given its foot point `foot` at arc length `s`.
#[inline]
pub(super) fn frenet(p: Vec2, s: f64, foot: &RoadPose) -> Frenet {
    Frenet {
        s,
        d: cross(foot.tangent(), p - foot.point),
        heading: foot.heading,
        curvature: foot.curvature,
    }
}

#[derive(Clone, Debug)]
pub(super) struct Segment {
    /// Arc length at the segment's start.
    pub(super) s0: f64,
    pub(super) length: f64,
    /// Start pose.
    p0: Vec2,
    heading0: f64,
    /// The point at half the length (for pruning in [`Road::project`]).
    pub(super) mid: Vec2,
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
    pub(super) length: f64,
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
pub(super) enum Side {
    Interior,
    Start,
    End,
}

/// The nearest point of one segment: local arc length, pose there, and where it lies.
#[derive(Clone, Copy, Debug)]
pub(super) struct Foot {
    pub(super) sigma: f64,
    pub(super) pose: RoadPose,
    pub(super) side: Side,
}

impl Segment {
    pub(super) fn new(spec: &SegmentSpec, s0: f64, p0: Vec2, heading0: f64) -> Self {
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
    pub(super) fn eval(&self, sigma: f64) -> RoadPose {
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
    pub(super) fn closest(&self, p: Vec2, hint: Option<f64>) -> Foot {
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
    pub(super) fn new(length: f64, heading0: f64, p0: Vec2, k0: f64, k1: f64) -> Self {
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
    pub(super) fn eval(&self, sigma: f64) -> RoadPose {
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
    pub(super) fn sigma(&self, j: usize) -> f64 {
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
    use super::super::{Road, RoadSpec};
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
