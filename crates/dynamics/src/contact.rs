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

/// The compliant contact law: a linear crush spring with a viscous damper whose damping
/// ratio gives a stated coefficient of restitution, and regularised Coulomb friction,
///
/// `F_n = max(0, k δ + c δ̇)`, `c = 2 ζ(e) sqrt(k m_eff)`, `F_t = −μ_c F_n tanh(v_t / v_s)`,
///
/// with δ the penetration, δ̇ its rate (positive while closing), `v_t` the tangential slip
/// velocity of B relative to A and `m_eff` the effective mass of the pair along the normal
/// at the contact point (impulse–momentum theory: `1/m_eff = nᵀ K (n + (F_t/F_n) t)`, `K`
/// the pair's inverse inertia at the point, see [`effective_inverse_mass`]). A body of mass
/// `m` meeting the law at any speed leaves it with the stated restitution `e`: the law is
/// linear, so the rebound scales with the approach speed, and scaling the damper with
/// `sqrt(k m_eff)` (the damping ratio ζ) makes `e` independent of the mass too. `ζ(e)` is
/// the exact inverse of the clipped oscillator's restitution ([`restitution_of_damping_ratio`]):
/// the force is clamped at zero, so the bodies part when `k δ + c δ̇` reaches zero, before
/// δ does. The law never pulls and the friction always opposes slip: over any closed
/// contact it dissipates energy, it never creates it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ContactLaw {
    /// k (N/m).
    pub stiffness: f64,
    /// The stated coefficient of restitution e.
    pub restitution: f64,
    /// ζ(e), the damping ratio that gives it.
    pub damping_ratio: f64,
    pub friction: f64,
    pub slip_speed: f64,
}

/// Restitution of a linear spring-damper that is clamped at zero force, for damping ratio
/// ζ ∈ [0, 1) (under-damped): with `x'' + 2ζ x' + x = 0`, `x(0) = 0`, `x'(0) = 1`, the force
/// `x + 2ζ x'` reaches zero at `ω_d t = π − atan(2ζ ω_d / (1 − 2ζ²))`, `ω_d = sqrt(1 − ζ²)`,
/// and the rebound speed there is `e = −x'` (the angle taken with `atan2`, so past
/// ζ = 1/√2 as well). (The unclamped oscillator's
/// `exp(−πζ/ω_d)` is lower: it counts the pull the clamp removes.)
#[must_use]
pub fn restitution_of_damping_ratio(zeta: f64) -> f64 {
    if zeta <= 0.0 {
        return 1.0;
    }
    let wd = (1.0 - zeta * zeta).sqrt();
    let theta = std::f64::consts::PI - (2.0 * zeta * wd).atan2(1.0 - 2.0 * zeta * zeta);
    let (s, c) = theta.sin_cos();
    -(-zeta * theta / wd).exp() * (c - zeta * s / wd)
}

/// The damping ratio ζ whose clamped spring-damper has restitution `e` ∈ (0, 1] (the
/// inverse of [`restitution_of_damping_ratio`], by bisection over ζ ∈ [0, 0.999]; `e`
/// below the law's floor there, ≈ 0.137, gives that limit).
#[must_use]
pub fn damping_ratio_for_restitution(e: f64) -> f64 {
    let (mut lo, mut hi) = (0.0, 0.999);
    if e >= 1.0 {
        return 0.0;
    }
    for _ in 0..100 {
        let mid = 0.5 * (lo + hi);
        if restitution_of_damping_ratio(mid) > e {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}

/// `nᵀ K d` for the pair's inverse-inertia matrix at a contact point, `K = (1/m_A + 1/m_B) I
/// + Σ (ẑ × r_i)(ẑ × r_i)ᵀ / I_z,i`, with `r_i` the arms from each c.g. to the point
/// (impulse–momentum theory, Brach 1983). A body of infinite mass (an obstacle) is left
/// out by passing `inv_m = inv_iz = 0`. The normal velocity responds to a force
/// `F_n (n + (F_t/F_n) t)` as `d(v_n)/dt = −nᵀ K (n + (F_t/F_n) t) F_n`, so with
/// `d = n + (F_t/F_n) t` this is the inverse of the effective mass the damper sees.
#[inline]
#[must_use]
pub fn effective_inverse_mass(normal: Vec2, direction: Vec2, bodies: [(f64, f64, Vec2); 2]) -> f64 {
    let mut k = 0.0;
    for (inv_m, inv_iz, arm) in bodies {
        k += inv_m * normal.dot(&direction) + inv_iz * cross(arm, normal) * cross(arm, direction);
    }
    k
}

impl ContactLaw {
    #[must_use]
    pub fn from_params(p: &ContactParams) -> Self {
        Self {
            stiffness: p.stiffness,
            restitution: p.restitution,
            damping_ratio: damping_ratio_for_restitution(p.restitution),
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

    /// Damping coefficient c (N s/m) for a pair of effective mass `1 / inv_mass`.
    #[inline]
    #[must_use]
    pub fn damping(&self, inv_mass: f64) -> f64 {
        2.0 * self.damping_ratio * (self.stiffness / inv_mass).sqrt()
    }

    /// Normal force for penetration `depth` ≥ 0, penetration rate `depth_rate` and damping
    /// coefficient `damping` ([`ContactLaw::damping`]).
    #[inline]
    #[must_use]
    pub fn normal_force(&self, depth: f64, depth_rate: f64, damping: f64) -> f64 {
        if depth <= 0.0 {
            return 0.0;
        }
        (self.stiffness * depth + damping * depth_rate).max(0.0)
    }

    /// Tangential (friction) force on B for normal force `fn_` and slip velocity `vt`.
    #[inline]
    #[must_use]
    pub fn tangential_force(&self, fn_: f64, vt: f64) -> f64 {
        -self.friction * fn_ * (vt / self.slip_speed).tanh()
    }

    /// `f_c = [F_n, F_t]` on B from the geometry, the velocity of B's material point
    /// relative to A's at the contact point, and the bodies as `(1/m, 1/I_z, arm from the
    /// c.g. to the contact point)` (zeros for an immovable obstacle).
    #[inline]
    #[must_use]
    pub fn force(
        &self,
        geom: &ContactGeometry,
        v_rel: Vec2,
        bodies: [(f64, f64, Vec2); 2],
    ) -> Vec2 {
        let n = geom.normal;
        let t = geom.tangent();
        let depth_rate = -v_rel.dot(&n);
        let slip = -self.friction * (v_rel.dot(&t) / self.slip_speed).tanh();
        // The friction ratio F_t/F_n is known before F_n, so the damper sees the pair's
        // effective mass along the direction the contact force actually acts in. With
        // body-panel friction it cannot vanish (|F_t/F_n| ≤ μ_c < 1 and K is positive
        // definite), but keep it away from zero for degenerate arms.
        let plain = effective_inverse_mass(n, n, bodies);
        let inv_mass = effective_inverse_mass(n, n + t * slip, bodies).max(0.25 * plain);
        let fn_ = self.normal_force(geom.depth, depth_rate, self.damping(inv_mass));
        Vec2::new(fn_, slip * fn_)
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

    fn law(restitution: f64) -> ContactLaw {
        ContactLaw::from_params(&ContactParams {
            stiffness: 4e5,
            restitution,
            friction: 0.4,
            slip_speed: 0.1,
            obstacle_stiffness_factor: 2.0,
        })
    }

    #[test]
    fn law_clamps_and_opposes_slip() {
        let law = law(0.3);
        let c = law.damping(1.0 / 500.0);
        assert_eq!(law.normal_force(0.0, 5.0, c), 0.0);
        assert_eq!(law.normal_force(0.01, -10.0, c), 0.0, "never pulls");
        assert!((law.normal_force(0.01, 0.0, c) - 4000.0).abs() < 1e-9);
        assert!(
            law.tangential_force(1000.0, 2.0) < 0.0 && law.tangential_force(1000.0, -2.0) > 0.0
        );
        assert!(
            (law.tangential_force(1000.0, 100.0) + 400.0).abs() < 1e-6,
            "saturates at μ F_n"
        );
    }

    #[test]
    fn damping_ratio_inverts_the_clamped_restitution() {
        assert_eq!(restitution_of_damping_ratio(0.0), 1.0);
        let mut last = 1.0;
        for i in 1..96 {
            let zeta = f64::from(i) * 0.01;
            let e = restitution_of_damping_ratio(zeta);
            assert!(e < last && e > 0.0, "monotone in ζ: {zeta} → {e}");
            last = e;
            assert!((damping_ratio_for_restitution(e) - zeta).abs() < 1e-9);
        }
        // Above the unclamped oscillator's restitution exp(−πζ/ω_d): the clamp takes away
        // the pull that would have slowed the rebound.
        let zeta: f64 = 0.36;
        let unclamped = (-std::f64::consts::PI * zeta / (1.0 - zeta * zeta).sqrt()).exp();
        assert!(restitution_of_damping_ratio(zeta) > unclamped);
    }

    /// One body of mass `m` driven into the law at `v0` (fine explicit steps); the rebound
    /// speed over the approach speed.
    fn one_body_restitution(law: &ContactLaw, m: f64, v0: f64) -> f64 {
        let c = law.damping(1.0 / m);
        let (mut x, mut v) = (0.0, v0);
        let h = 1e-6;
        loop {
            let f = law.normal_force(x, v, c);
            if v < 0.0 && (f == 0.0 || x <= 0.0) {
                return -v / v0;
            }
            v -= f / m * h;
            x += v * h;
        }
    }

    #[test]
    fn one_body_restitution_is_the_stated_value_at_any_speed_and_mass() {
        for e in [0.2, 0.3, 0.45] {
            let law = law(e);
            for m in [150.0, 600.0, 2000.0] {
                for v0 in [0.5, 1.0, 3.0, 6.0] {
                    let got = one_body_restitution(&law, m, v0);
                    assert!(
                        (got - e).abs() < 2e-3,
                        "e {e}, m {m}, v0 {v0}: measured {got}"
                    );
                }
            }
        }
    }

    #[test]
    fn effective_mass_of_a_central_hit_is_the_reduced_mass() {
        let n = Vec2::new(1.0, 0.0);
        let k = effective_inverse_mass(
            n,
            n,
            [
                (1.0 / 1000.0, 1e-3, Vec2::zeros()),
                (1.0 / 500.0, 1e-3, Vec2::zeros()),
            ],
        );
        assert!((1.0 / k - 1000.0 * 500.0 / 1500.0).abs() < 1e-9);
        // An off-centre hit is lighter: the arm adds (r × n)² / I_z.
        let off = effective_inverse_mass(
            n,
            n,
            [
                (1.0 / 1000.0, 1e-3, Vec2::new(0.0, 2.0)),
                (1.0 / 500.0, 1e-3, Vec2::zeros()),
            ],
        );
        assert!((off - k - 4e-3).abs() < 1e-12);
    }

    #[test]
    fn law_never_creates_energy_over_closed_cycles() {
        // Prescribe closed penetration histories δ(t) ≥ 0 (in and out again) and integrate
        // the work the normal force does on the bodies, W = −∫ F_n dδ: it must be ≤ 0,
        // and = 0 without damping.
        for e in [0.3, 1.0] {
            let law = law(e);
            let c = law.damping(1.0 / 400.0);
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
                    work -= law.normal_force(depth_at(t), ddepth, c) * ddepth * dt;
                }
                let scale = law.stiffness * amp * amp;
                if e == 1.0 {
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
