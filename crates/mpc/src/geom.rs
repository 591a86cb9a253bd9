//! Geometry the MPC linearises: the bullet–target gap and contact frame, road edges and
//! obstacle clearances, each as a value and its gradient with respect to the poses.

use dynamics::contact::{obb_contact, obb_signed_distance};
use dynamics::geometry::{Obb, Vec2};
use dynamics::road::Road;

/// `ẑ × v`: `v` rotated by +90°.
#[inline]
fn perp(v: Vec2) -> Vec2 {
    Vec2::new(-v.y, v.x)
}

/// Signed distance between two rectangles with its witness: unit normal from A into B and
/// the witness points on each. Penetrating: `d = −depth`, both witnesses at the contact
/// point. Separated: the closest points (exact for convex polygons).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PairGeometry {
    pub gap: f64,
    pub normal: Vec2,
    pub point_a: Vec2,
    pub point_b: Vec2,
}

impl PairGeometry {
    /// Heading γ of the normal in the world.
    #[must_use]
    pub fn gamma(&self) -> f64 {
        self.normal.y.atan2(self.normal.x)
    }

    /// Gradient of the gap with respect to A's pose `[X, Y, ψ]` (centre of rotation
    /// `center_a`) and B's pose (about `center_b`), witness features held fixed: exact
    /// while the rectangles are apart (the closest points move rigidly with their bodies).
    /// While they overlap, use [`gap_gradient`], which differentiates the depth itself.
    #[must_use]
    pub fn gradient(&self, center_a: Vec2, center_b: Vec2) -> ([f64; 3], [f64; 3]) {
        let n = self.normal;
        let ga = [-n.x, -n.y, -n.dot(&perp(self.point_a - center_a))];
        let gb = [n.x, n.y, n.dot(&perp(self.point_b - center_b))];
        (ga, gb)
    }
}

/// `obb` moved by `[dx, dy, dψ]`, the rotation about `pivot`.
fn displaced(obb: &Obb, pivot: Vec2, d: [f64; 3]) -> Obb {
    let rel = obb.center - pivot;
    let (s, c) = d[2].sin_cos();
    let rot = Vec2::new(c * rel.x - s * rel.y, s * rel.x + c * rel.y);
    Obb {
        center: pivot + rot + Vec2::new(d[0], d[1]),
        yaw: obb.yaw + d[2],
        half: obb.half,
    }
}

/// Gradient of the signed distance with respect to both poses (A about `center_a`, B about
/// `center_b`): analytic while apart, central differences of the penetration depth while
/// overlapping (the depth's dependence on rotation runs through the deepest corner and,
/// for a face of B, the rotating normal; differencing the separating-axis depth is exact to
/// O(h²) and costs 12 evaluations).
#[must_use]
pub fn gap_gradient(
    a: &Obb,
    b: &Obb,
    center_a: Vec2,
    center_b: Vec2,
    g: &PairGeometry,
) -> ([f64; 3], [f64; 3]) {
    if g.gap > 0.0 {
        return g.gradient(center_a, center_b);
    }
    const H: f64 = 1e-6;
    let mut ga = [0.0; 3];
    let mut gb = [0.0; 3];
    for i in 0..3 {
        let mut d = [0.0; 3];
        d[i] = H;
        let plus = obb_signed_distance(&displaced(a, center_a, d), b);
        d[i] = -H;
        let minus = obb_signed_distance(&displaced(a, center_a, d), b);
        ga[i] = (plus - minus) / (2.0 * H);
        d[i] = H;
        let plus = obb_signed_distance(a, &displaced(b, center_b, d));
        d[i] = -H;
        let minus = obb_signed_distance(a, &displaced(b, center_b, d));
        gb[i] = (plus - minus) / (2.0 * H);
    }
    (ga, gb)
}

fn closest_on_segment(p: Vec2, a: Vec2, b: Vec2) -> Vec2 {
    let ab = b - a;
    let t = ((p - a).dot(&ab) / ab.norm_squared()).clamp(0.0, 1.0);
    a + ab * t
}

/// The signed distance of two rectangles and its witness.
#[must_use]
pub fn pair_geometry(a: &Obb, b: &Obb) -> PairGeometry {
    if let Some(c) = obb_contact(a, b) {
        return PairGeometry {
            gap: -c.depth,
            normal: c.normal,
            point_a: c.point,
            point_b: c.point,
        };
    }
    let ca = a.corners();
    let cb = b.corners();
    let mut best = f64::INFINITY;
    let mut pa = a.center;
    let mut pb = b.center;
    for i in 0..4 {
        let (a0, a1) = (ca[i], ca[(i + 1) % 4]);
        let (b0, b1) = (cb[i], cb[(i + 1) % 4]);
        for j in 0..4 {
            // Corner of A against an edge of B.
            let q = closest_on_segment(ca[j], b0, b1);
            let d = (q - ca[j]).norm();
            if d < best {
                best = d;
                pa = ca[j];
                pb = q;
            }
            // Corner of B against an edge of A.
            let q = closest_on_segment(cb[j], a0, a1);
            let d = (cb[j] - q).norm();
            if d < best {
                best = d;
                pa = q;
                pb = cb[j];
            }
        }
    }
    let diff = pb - pa;
    let normal = if best > 1e-12 {
        diff / best
    } else {
        let d = b.center - a.center;
        d / d.norm().max(1e-12)
    };
    PairGeometry {
        gap: best,
        normal,
        point_a: pa,
        point_b: pb,
    }
}

/// The road constraint of one footprint, linearised at its worst corner:
/// `side · (d + n·Δp + (n·ẑ×r) Δψ) ≤ half_width − margin` with `side = sign(d)` of that
/// corner, `n` the road's left normal at its foot point and `r` the corner relative to the
/// c.g.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EdgeRow {
    /// Coefficients on `[X, Y, ψ]`.
    pub grad: [f64; 3],
    /// Right-hand side: `half_width − margin − side·d`.
    pub rhs: f64,
}

/// Linearise the road-edge constraint of `footprint` (c.g. at `cg`).
#[must_use]
pub fn edge_row(road: &Road, footprint: &Obb, cg: Vec2, margin: f64) -> EdgeRow {
    let mut worst = f64::INFINITY;
    let mut row = EdgeRow {
        grad: [0.0; 3],
        rhs: f64::INFINITY,
    };
    for c in footprint.corners() {
        let f = road.project(c);
        let m = road.half_width() - f.d.abs();
        if m < worst {
            worst = m;
            let side = if f.d >= 0.0 { 1.0 } else { -1.0 };
            let n = Vec2::new(-f.heading.sin(), f.heading.cos()) * side;
            row = EdgeRow {
                grad: [n.x, n.y, n.dot(&perp(c - cg))],
                rhs: road.half_width() - margin - f.d.abs(),
            };
        }
    }
    row
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gap_matches_signed_distance_and_its_gradient_matches_finite_differences() {
        let a = Obb::new(Vec2::new(0.0, 0.0), 0.1, 4.5, 1.8);
        for (bx, by, yaw) in [
            (1.0, 2.2, 0.3),
            (5.0, 0.5, -0.2),
            (2.0, 1.5, 0.05),
            (0.5, 1.6, 1.2),
        ] {
            let b = Obb::new(Vec2::new(bx, by), yaw, 4.5, 1.8);
            let g = pair_geometry(&a, &b);
            assert!((g.gap - obb_signed_distance(&a, &b)).abs() < 1e-12);
            let (_, gb) = gap_gradient(&a, &b, a.center, b.center, &g);
            let h = 1e-6;
            for (i, gi) in gb.iter().enumerate() {
                let mut db = [bx, by, yaw];
                db[i] += h;
                let bp = Obb::new(Vec2::new(db[0], db[1]), db[2], 4.5, 1.8);
                db[i] -= 2.0 * h;
                let bm = Obb::new(Vec2::new(db[0], db[1]), db[2], 4.5, 1.8);
                let fd = (obb_signed_distance(&a, &bp) - obb_signed_distance(&a, &bm)) / (2.0 * h);
                assert!(
                    (fd - gi).abs() < 2e-4,
                    "case ({bx},{by},{yaw}) d/d{i}: {fd} vs {gi}"
                );
            }
        }
    }
}
