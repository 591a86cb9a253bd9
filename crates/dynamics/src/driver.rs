//! The target driver's lane-keeping law, shared by the scenario's driver (the truth,
//! `sim::TargetDriver`) and by a planner that models the driver in its rollout.
//!
//! `δ = L κ(s) + g (−k_d (d − offset) − k_ψ wrap(ψ − ψ_road) − k_r (r − v_x κ))`, clamped to
//! `±LANE_KEEP_MAX_STEER`: `L` the wheelbase, `(s, d, ψ_road, κ)` the target's Frenet
//! projection, `g` the driver's gain.

use crate::road::Frenet;
use crate::target::{idx, TargetState};
use nalgebra::SVector;

/// Lateral-offset gain (rad/m).
pub const LANE_KEEP_KD: f64 = 0.05;
/// Heading-error gain (rad/rad).
pub const LANE_KEEP_KPSI: f64 = 0.6;
/// Yaw-rate gain (s).
pub const LANE_KEEP_KR: f64 = 0.1;
/// Largest steer (rad): a driver's corrections, not a spin recovery.
pub const LANE_KEEP_MAX_STEER: f64 = 0.15;

/// A lane keeper following the line `d = offset` with gain `gain`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LaneKeeper {
    pub offset: f64,
    pub gain: f64,
    pub wheelbase: f64,
}

impl LaneKeeper {
    /// The steer (rad) at state `x` whose Frenet projection is `f`.
    #[must_use]
    pub fn steer(&self, x: &TargetState, f: &Frenet) -> f64 {
        self.unclamped(x, f)
            .clamp(-LANE_KEEP_MAX_STEER, LANE_KEEP_MAX_STEER)
    }

    /// The steer and its gradient with respect to the state (zero where the steer is
    /// clamped). The road heading turns with the position (∂ψ_road/∂s = κ); the change of
    /// the curvature itself along a clothoid is not differentiated.
    #[must_use]
    pub fn steer_and_gradient(&self, x: &TargetState, f: &Frenet) -> (f64, SVector<f64, 8>) {
        let raw = self.unclamped(x, f);
        let steer = raw.clamp(-LANE_KEEP_MAX_STEER, LANE_KEEP_MAX_STEER);
        let mut g = SVector::<f64, 8>::zeros();
        if raw.abs() < LANE_KEEP_MAX_STEER {
            let (sin, cos) = f.heading.sin_cos();
            // d grows to the left of the road heading: ∂d/∂(X, Y) = (−sin, cos); the foot
            // point moves by ∂s/∂(X, Y) = (cos, sin)/(1 − κ d), turning the road heading.
            let turn = f.curvature / (1.0 - f.curvature * f.d);
            g[idx::VX] = self.gain * LANE_KEEP_KR * f.curvature;
            g[idx::PSI] = -self.gain * LANE_KEEP_KPSI;
            g[idx::R] = -self.gain * LANE_KEEP_KR;
            g[idx::X] = self.gain * (LANE_KEEP_KD * sin + LANE_KEEP_KPSI * turn * cos);
            g[idx::Y] = self.gain * (-LANE_KEEP_KD * cos + LANE_KEEP_KPSI * turn * sin);
        }
        (steer, g)
    }

    fn unclamped(&self, x: &TargetState, f: &Frenet) -> f64 {
        let e_d = f.d - self.offset;
        let e_psi = crate::wrap_angle(x[idx::PSI] - f.heading);
        let r_ref = x[idx::VX] * f.curvature;
        let fb = -LANE_KEEP_KD * e_d - LANE_KEEP_KPSI * e_psi - LANE_KEEP_KR * (x[idx::R] - r_ref);
        self.wheelbase * f.curvature + self.gain * fb
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::Vec2;
    use crate::road::{Road, RoadSpec, SegmentSpec};

    /// The gradient matches central differences of the steer on a curve, with the road
    /// re-projected at every perturbed state.
    #[test]
    fn the_gradient_matches_finite_differences() {
        let road = Road::new(RoadSpec {
            segments: vec![
                SegmentSpec::Straight { length: 30.0 },
                SegmentSpec::Arc {
                    length: 200.0,
                    curvature: 0.004,
                },
            ],
            lanes: 2,
            lane_width: 3.5,
            shoulder: 0.5,
            origin: [0.0, 0.0, 0.0],
        })
        .unwrap();
        let lk = LaneKeeper {
            offset: 1.75,
            gain: 1.2,
            wheelbase: 2.7,
        };
        let mut x = TargetState::zeros();
        x.copy_from_slice(&[20.0, 0.3, 0.12, 0.05, 0.0, 0.01, 60.0, 2.0]);
        let f = road.project(Vec2::new(x[idx::X], x[idx::Y]));
        let (s, g) = lk.steer_and_gradient(&x, &f);
        assert!(s.abs() < LANE_KEEP_MAX_STEER, "not clamped: {s}");
        assert_eq!(s, lk.steer(&x, &f));
        for i in 0..8 {
            let h = 1e-5;
            let (mut p, mut m) = (x, x);
            p[i] += h;
            m[i] -= h;
            let fp = road.project(Vec2::new(p[idx::X], p[idx::Y]));
            let fm = road.project(Vec2::new(m[idx::X], m[idx::Y]));
            let fd = (lk.steer(&p, &fp) - lk.steer(&m, &fm)) / (2.0 * h);
            assert!((fd - g[i]).abs() < 1e-7, "∂δ/∂x[{i}]: {} vs {fd}", g[i]);
        }
        // Clamped: no gradient.
        x[idx::PSI] = 1.0;
        let (s, g) = lk.steer_and_gradient(&x, &f);
        assert_eq!(s, -LANE_KEEP_MAX_STEER);
        assert_eq!(g, SVector::<f64, 8>::zeros());
    }
}
