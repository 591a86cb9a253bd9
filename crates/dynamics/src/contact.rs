//! Contact between oriented rectangles: separating-axis geometry, the contact frame, the
//! mapping of `f_c = [F_n, F_t]` into body frames, and the compliant contact law.
//!
//! Conventions (DESIGN.md): the normal `n` points from body A (the bullet, or the vehicle
//! in a vehicle–obstacle pair) into body B (the target, or the obstacle); `t` is `n` rotated
//! by +90°; `γ = atan2(n_y, n_x)`. B receives `+f_c`, A receives `−f_c`, both at the same
//! world point, so the pair is equal, opposite and collinear: linear and angular momentum
//! of the two bodies are conserved by construction.

use crate::geometry::{cross, rotate, Obb, Vec2};
use crate::params::ContactParams;

/// Where two rectangles touch.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ContactGeometry {
    /// Penetration depth δ ≥ 0 along the normal (m).
    pub depth: f64,
    /// Unit normal from A into B.
    pub normal: Vec2,
    /// Contact point in the world: the centroid of the penetrating features, halfway
    /// between the incident feature and the reference face.
    pub point: Vec2,
}

impl ContactGeometry {
    /// Heading γ of the normal in the world.
    #[inline]
    #[must_use]
    pub fn gamma(&self) -> f64 {
        self.normal.y.atan2(self.normal.x)
    }

    /// Unit tangent `t = n` rotated by +90°.
    #[inline]
    #[must_use]
    pub fn tangent(&self) -> Vec2 {
        Vec2::new(-self.normal.y, self.normal.x)
    }
}

/// Map a contact-frame force `f_c = [F_n, F_t]` into the world.
#[inline]
#[must_use]
pub fn contact_to_world(fc: Vec2, gamma: f64) -> Vec2 {
    rotate(gamma, fc)
}

/// Map a contact-frame force into the body frame of a vehicle with heading ψ:
/// `f_body = R(γ − ψ) f_c`.
#[inline]
#[must_use]
pub fn contact_to_body(fc: Vec2, gamma: f64, psi: f64) -> Vec2 {
    rotate(gamma - psi, fc)
}

/// Yaw moment of a force `f` acting at `p_c`, about `p_cg`: `(p_c − p_cg) × f`.
#[inline]
#[must_use]
pub fn yaw_moment(p_c: Vec2, p_cg: Vec2, f: Vec2) -> f64 {
    cross(p_c - p_cg, f)
}

#[inline]
fn projected_radius(b: &Obb, axis: Vec2) -> f64 {
    let (ax, ay) = b.axes();
    b.half.x * ax.dot(&axis).abs() + b.half.y * ay.dot(&axis).abs()
}

/// Separating-axis test between two oriented rectangles. Returns `None` when they do not
/// overlap (touching counts as no contact).
#[must_use]
pub fn obb_contact(a: &Obb, b: &Obb) -> Option<ContactGeometry> {
    let d = b.center - a.center;
    let (a_x, a_y) = a.axes();
    let (b_x, b_y) = b.axes();
    let axes = [a_x, a_y, b_x, b_y];
    let mut best_overlap = f64::INFINITY;
    let mut best = 0usize;
    for (i, axis) in axes.iter().enumerate() {
        let overlap = projected_radius(a, *axis) + projected_radius(b, *axis) - d.dot(axis).abs();
        if overlap <= 0.0 {
            return None;
        }
        // Prefer A's faces on near-ties so that the reference face does not flicker.
        let better = if i < 2 {
            overlap < best_overlap
        } else {
            overlap < best_overlap * (1.0 - 1e-9) - 1e-12
        };
        if better {
            best_overlap = overlap;
            best = i;
        }
    }
    let axis = axes[best];
    let normal = if d.dot(&axis) >= 0.0 { axis } else { -axis };
    // Reference face: on the body owning the axis, facing the other body.
    let (reference, incident, ref_normal) = if best < 2 {
        (a, b, normal)
    } else {
        (b, a, -normal)
    };
    Some(clip_contact(
        reference,
        incident,
        ref_normal,
        normal,
        best_overlap,
    ))
}

/// Clip the incident edge against the reference face and average the penetrating points.
fn clip_contact(
    reference: &Obb,
    incident: &Obb,
    ref_normal: Vec2,
    normal: Vec2,
    overlap: f64,
) -> ContactGeometry {
    let (rx, ry) = reference.axes();
    // Reference face: centre, tangent direction and half length.
    let (face_half_extent, face_tangent, face_offset) =
        if ref_normal.dot(&rx).abs() > ref_normal.dot(&ry).abs() {
            (reference.half.y, ry, reference.half.x)
        } else {
            (reference.half.x, rx, reference.half.y)
        };
    let face_center = reference.center + ref_normal * face_offset;
    // Incident edge: the incident body's edge whose outward normal is most anti-parallel to
    // the reference normal.
    let (ix, iy) = incident.axes();
    let candidates = [
        (ix, incident.half.x, iy, incident.half.y),
        (iy, incident.half.y, ix, incident.half.x),
    ];
    let mut edge = (Vec2::zeros(), Vec2::zeros());
    let mut most_anti = f64::INFINITY;
    for (axis, offset, along, half_len) in candidates {
        for sign in [1.0, -1.0] {
            let n_out = axis * sign;
            let dot = n_out.dot(&ref_normal);
            if dot < most_anti {
                most_anti = dot;
                let c = incident.center + n_out * offset;
                edge = (c - along * half_len, c + along * half_len);
            }
        }
    }
    // Clip the edge to the reference face's side planes.
    let (mut p0, mut p1) = edge;
    let s0 = (p0 - face_center).dot(&face_tangent);
    let s1 = (p1 - face_center).dot(&face_tangent);
    let clip = |s_from: f64, s_to: f64, a: Vec2, b: Vec2, limit: f64| -> Vec2 {
        let t = (limit - s_from) / (s_to - s_from);
        a + (b - a) * t
    };
    let (lo, hi) = (-face_half_extent, face_half_extent);
    let (q0, q1) = (p0, p1);
    if s0 < lo && s1 > lo {
        p0 = clip(s0, s1, q0, q1, lo);
    } else if s0 > hi && s1 < hi {
        p0 = clip(s0, s1, q0, q1, hi);
    }
    if s1 < lo && s0 > lo {
        p1 = clip(s1, s0, q1, q0, lo);
    } else if s1 > hi && s0 < hi {
        p1 = clip(s1, s0, q1, q0, hi);
    }
    // Penetrating points lie behind the reference face.
    let mut sum = Vec2::zeros();
    let mut count = 0.0;
    let mut max_depth: f64 = 0.0;
    for p in [p0, p1] {
        let sep = (p - face_center).dot(&ref_normal);
        let s = (p - face_center).dot(&face_tangent);
        if sep < 0.0 && s >= lo - 1e-12 && s <= hi + 1e-12 {
            sum += p - ref_normal * (0.5 * sep);
            count += 1.0;
            max_depth = max_depth.max(-sep);
        }
    }
    if count == 0.0 {
        // Degenerate (deep or grazing) configuration: fall back to the midpoint between the
        // two centres projected on the reference face.
        let mid = 0.5 * (reference.center + incident.center);
        let on_face =
            face_center + face_tangent * (mid - face_center).dot(&face_tangent).clamp(lo, hi);
        return ContactGeometry {
            depth: overlap,
            normal,
            point: on_face - ref_normal * (0.5 * overlap),
        };
    }
    ContactGeometry {
        depth: max_depth.min(overlap).max(0.0),
        normal,
        point: sum / count,
    }
}

/// Signed distance between two rectangles: the gap when apart (exact Euclidean distance
/// between the polygons), minus the penetration depth when they overlap.
#[must_use]
pub fn obb_signed_distance(a: &Obb, b: &Obb) -> f64 {
    if let Some(c) = obb_contact(a, b) {
        return -c.depth;
    }
    let ca = a.corners();
    let cb = b.corners();
    let mut best = f64::INFINITY;
    for (poly_p, poly_e) in [(&ca, &cb), (&cb, &ca)] {
        for p in poly_p.iter() {
            for i in 0..4 {
                let (s0, s1) = (poly_e[i], poly_e[(i + 1) % 4]);
                best = best.min(point_segment_distance(*p, s0, s1));
            }
        }
    }
    best
}

#[inline]
fn point_segment_distance(p: Vec2, a: Vec2, b: Vec2) -> f64 {
    let ab = b - a;
    let t = ((p - a).dot(&ab) / ab.norm_squared()).clamp(0.0, 1.0);
    (p - (a + ab * t)).norm()
}

/// The compliant contact law: Hunt–Crossley normal force and regularised Coulomb friction,
///
/// `F_n = max(0, k δⁿ (1 + c δ̇))`, `F_t = −μ_c F_n tanh(v_t / v_s)`,
///
/// with δ the penetration, δ̇ its rate (positive while closing) and `v_t` the tangential
/// slip velocity of B relative to A. The damping term is proportional to `δⁿ`, so the force
/// is continuous at first touch and never pulls (the clamp), and the friction always
/// opposes slip: over any closed contact the law dissipates energy, it never creates it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ContactLaw {
    pub stiffness: f64,
    pub exponent: f64,
    pub damping: f64,
    pub friction: f64,
    pub slip_speed: f64,
}

impl ContactLaw {
    #[must_use]
    pub fn from_params(p: &ContactParams) -> Self {
        Self {
            stiffness: p.stiffness,
            exponent: p.exponent,
            damping: p.damping,
            friction: p.friction,
            slip_speed: p.slip_speed,
        }
    }

    /// The same law with the stiffness scaled (e.g. for rigid obstacles).
    #[must_use]
    pub fn stiffer(mut self, factor: f64) -> Self {
        self.stiffness *= factor;
        self
    }

    /// Normal force for penetration `depth` ≥ 0 and penetration rate `depth_rate`.
    #[inline]
    #[must_use]
    pub fn normal_force(&self, depth: f64, depth_rate: f64) -> f64 {
        if depth <= 0.0 {
            return 0.0;
        }
        let spring = if self.exponent == 1.0 {
            self.stiffness * depth
        } else {
            self.stiffness * depth.powf(self.exponent)
        };
        (spring * (1.0 + self.damping * depth_rate)).max(0.0)
    }

    /// Tangential (friction) force on B for normal force `fn_` and slip velocity `vt`.
    #[inline]
    #[must_use]
    pub fn tangential_force(&self, fn_: f64, vt: f64) -> f64 {
        -self.friction * fn_ * (vt / self.slip_speed).tanh()
    }

    /// `f_c = [F_n, F_t]` on B from the geometry and the velocity of B's material point
    /// relative to A's at the contact point.
    #[inline]
    #[must_use]
    pub fn force(&self, geom: &ContactGeometry, v_rel: Vec2) -> Vec2 {
        let depth_rate = -v_rel.dot(&geom.normal);
        let fn_ = self.normal_force(geom.depth, depth_rate);
        let ft = self.tangential_force(fn_, v_rel.dot(&geom.tangent()));
        Vec2::new(fn_, ft)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::FRAC_PI_4;

    fn close(a: Vec2, b: Vec2, tol: f64) -> bool {
        (a - b).norm() < tol
    }

    #[test]
    fn separated_and_touching_give_none() {
        let a = Obb::new(Vec2::new(0.0, 0.0), 0.0, 4.0, 2.0);
        let b = Obb::new(Vec2::new(5.0, 0.0), 0.0, 4.0, 2.0);
        assert!(obb_contact(&a, &b).is_none());
        assert!((obb_signed_distance(&a, &b) - 1.0).abs() < 1e-12);
        let touching = Obb::new(Vec2::new(4.0, 0.0), 0.0, 4.0, 2.0);
        assert!(obb_contact(&a, &touching).is_none());
        assert!(obb_signed_distance(&a, &touching).abs() < 1e-12);
        // Rotated square beyond the corner: gap measured corner to corner.
        let c = Obb::new(
            Vec2::new(2.0 + 1.0 + 2f64.sqrt(), 1.0 + 1.0 + 2f64.sqrt()),
            FRAC_PI_4,
            2.0,
            2.0,
        );
        let gap = obb_signed_distance(&a, &c);
        assert!(gap > 0.0 && obb_contact(&a, &c).is_none(), "gap {gap}");
    }

    #[test]
    fn corner_to_edge() {
        // A: 4 x 2 at the origin. B: a 2 x 2 square turned 45°, its lowest corner 0.1 m
        // below A's top face at x = 0.5.
        let a = Obb::new(Vec2::new(0.0, 0.0), 0.0, 4.0, 2.0);
        let half_diag = 2f64.sqrt();
        let b = Obb::new(Vec2::new(0.5, 0.9 + half_diag), FRAC_PI_4, 2.0, 2.0);
        let c = obb_contact(&a, &b).expect("overlap");
        assert!((c.depth - 0.1).abs() < 1e-9, "depth {}", c.depth);
        assert!(close(c.normal, Vec2::new(0.0, 1.0), 1e-12));
        assert!(
            close(c.point, Vec2::new(0.5, 0.95), 1e-9),
            "point {:?}",
            c.point
        );
        assert!((c.gamma() - std::f64::consts::FRAC_PI_2).abs() < 1e-12);
        // Swapping the bodies flips the normal and keeps the point.
        let s = obb_contact(&b, &a).unwrap();
        assert!(close(s.normal, Vec2::new(0.0, -1.0), 1e-12));
        assert!(close(s.point, c.point, 1e-9));
        assert!((s.depth - c.depth).abs() < 1e-12);
    }

    #[test]
    fn edge_to_edge() {
        let a = Obb::new(Vec2::new(0.0, 0.0), 0.0, 4.0, 2.0);
        let b = Obb::new(Vec2::new(3.0, 1.9), 0.0, 4.0, 2.0);
        let c = obb_contact(&a, &b).unwrap();
        assert!((c.depth - 0.1).abs() < 1e-12);
        assert!(close(c.normal, Vec2::new(0.0, 1.0), 1e-12));
        // Overlap of the faces spans x in [1, 2]: midpoint, halfway into the overlap.
        assert!(
            close(c.point, Vec2::new(1.5, 0.95), 1e-12),
            "point {:?}",
            c.point
        );
        // A side-by-side push along x (rear bumper into front bumper).
        let d = Obb::new(Vec2::new(3.95, 0.5), 0.0, 4.0, 2.0);
        let e = obb_contact(&a, &d).unwrap();
        assert!((e.depth - 0.05).abs() < 1e-12);
        assert!(close(e.normal, Vec2::new(1.0, 0.0), 1e-12));
        assert!(
            close(e.point, Vec2::new(1.975, 0.25), 1e-12),
            "point {:?}",
            e.point
        );
    }

    #[test]
    fn rotated_frames_are_consistent() {
        // The same configuration as edge_to_edge, rotated and translated as a whole.
        let rot = 0.7;
        let shift = Vec2::new(10.0, -3.0);
        let map = |p: Vec2| rotate(rot, p) + shift;
        let a = Obb::new(map(Vec2::new(0.0, 0.0)), rot, 4.0, 2.0);
        let b = Obb::new(map(Vec2::new(3.0, 1.9)), rot, 4.0, 2.0);
        let c = obb_contact(&a, &b).unwrap();
        assert!((c.depth - 0.1).abs() < 1e-9);
        assert!(close(c.normal, rotate(rot, Vec2::new(0.0, 1.0)), 1e-9));
        assert!(close(c.point, map(Vec2::new(1.5, 0.95)), 1e-9));
    }

    #[test]
    fn body_mapping_round_trip() {
        let fc = Vec2::new(1000.0, -300.0);
        let gamma = 1.2;
        let psi = -0.4;
        let world = contact_to_world(fc, gamma);
        let body = contact_to_body(fc, gamma, psi);
        assert!(close(rotate(psi, body), world, 1e-9));
        // F_n along n, F_t along t.
        let n = Vec2::new(gamma.cos(), gamma.sin());
        assert!((world.dot(&n) - 1000.0).abs() < 1e-9);
    }

    #[test]
    fn law_clamps_and_opposes_slip() {
        let law = ContactLaw {
            stiffness: 4e5,
            exponent: 1.0,
            damping: 0.35,
            friction: 0.4,
            slip_speed: 0.1,
        };
        assert_eq!(law.normal_force(0.0, 5.0), 0.0);
        assert_eq!(law.normal_force(0.01, -10.0), 0.0, "never pulls");
        assert!((law.normal_force(0.01, 0.0) - 4000.0).abs() < 1e-9);
        assert!(
            law.tangential_force(1000.0, 2.0) < 0.0 && law.tangential_force(1000.0, -2.0) > 0.0
        );
        assert!(
            (law.tangential_force(1000.0, 100.0) + 400.0).abs() < 1e-6,
            "saturates at μ F_n"
        );
    }

    #[test]
    fn law_never_creates_energy_over_closed_cycles() {
        // Prescribe closed penetration histories δ(t) ≥ 0 (in and out again) and integrate
        // the work the normal force does on the bodies, W = −∫ F_n dδ: it must be ≤ 0,
        // and = 0 without damping.
        for (k, n, c) in [
            (4e5, 1.0, 0.35),
            (1e5, 1.5, 1.0),
            (7e5, 1.0, 0.0),
            (2e5, 1.3, 0.0),
        ] {
            let law = ContactLaw {
                stiffness: k,
                exponent: n,
                damping: c,
                friction: 0.4,
                slip_speed: 0.1,
            };
            for (amp, period, shape) in [(0.05, 0.15, 1.0), (0.1, 0.3, 3.0), (0.02, 0.05, 0.5)] {
                let steps = 200_000;
                let dt = period / f64::from(steps);
                let mut work = 0.0;
                // Asymmetric closed history (skewed by `shape`), zero at both ends.
                let depth_at = |tt: f64| {
                    let p = std::f64::consts::PI * tt / period;
                    amp * p.sin() * (1.0 + 0.3 * shape * p.cos()).max(0.1)
                };
                for i in 0..steps {
                    let t = (f64::from(i) + 0.5) * dt;
                    let h = 1e-9;
                    let ddepth = (depth_at(t + h) - depth_at(t - h)) / (2.0 * h);
                    work -= law.normal_force(depth_at(t), ddepth) * ddepth * dt;
                }
                let scale = k * amp.powf(n) * amp;
                if c == 0.0 {
                    assert!(
                        work.abs() < 1e-6 * scale,
                        "elastic cycle must be lossless: {work}"
                    );
                } else {
                    assert!(work < -1e-6 * scale, "damped cycle must dissipate: {work}");
                }
            }
        }
    }
}
