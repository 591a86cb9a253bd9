//! The target driver's lane-keeping law, shared by the scenario's driver (the truth,
//! `sim::TargetDriver`) and by a planner that models the driver in its rollout.
//!
//! Rolling forwards, `δ = L κ(s) + g (−k_d (d − offset) − k_ψ wrap(ψ − ψ_road) − k_r (r − v_x
//! κ))`, clamped to `±LANE_KEEP_MAX_STEER`: `L` the wheelbase, `(s, d, ψ_road, κ)` the
//! target's Frenet projection, `g` the driver's gain.
//!
//! The driver steers for the lane in the direction the car travels. Rolling backwards (a car
//! spun round by a PIT), the steer's effect on the yaw turns round with `v_x` (`r ≈ v_x δ / L`)
//! and the car's course is its heading turned by π, so the law is mirrored: the heading error
//! is taken against the reversed heading and the steer changes sign, blended over
//! `|v_x| < REVERSE_BLEND` (`σ = clamp(v_x / REVERSE_BLEND, −1, 1)`); its yaw-rate reference is
//! `|v_x| κ`. A car pointing across its direction of travel gives the law no meaning: the steer
//! is scaled by `c = clamp(2 cos e_ψ, 0, 1)`, whole up to 60° of heading error (in the frame
//! of travel) and faded out at 90°, where the driver has let go ([`lane_keep_fade`]):
//!
//! `δ = clamp(σ · c(e_ψ) · (L κ + g (−k_d (d − offset) − k_ψ e_ψ − k_r (r − |v_x| κ))), ±max)`
//! with `e_ψ = wrap(ψ − ψ_road)` rolling forwards and `wrap(ψ + π − ψ_road)` backwards.

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

/// Below this body-frame speed (m/s) a driver's steer fades out and turns round with the
/// direction of travel (the lane keeper here, the counter-steer of `sim::driver`).
pub const REVERSE_BLEND: f64 = 0.5;

/// The lane keeper's share of its law at heading error `e_psi` (rad, wrapped) and its
/// derivative: `c = clamp(2 cos e_ψ, 0, 1)`, 1 up to 60°, 0 from 90° on.
#[must_use]
pub fn lane_keep_fade(e_psi: f64) -> (f64, f64) {
    let (sin, cos) = e_psi.sin_cos();
    let c = 2.0 * cos;
    if c >= 1.0 {
        (1.0, 0.0)
    } else if c <= 0.0 {
        (0.0, 0.0)
    } else {
        (c, -2.0 * sin)
    }
}

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
        let (law, e_psi) = self.law(x, f);
        let sigma = (x[idx::VX] / REVERSE_BLEND).clamp(-1.0, 1.0);
        (sigma * lane_keep_fade(e_psi).0 * law).clamp(-LANE_KEEP_MAX_STEER, LANE_KEEP_MAX_STEER)
    }

    /// The steer and its gradient with respect to the state (zero where the steer is
    /// clamped). The road heading turns with the position (∂ψ_road/∂s = κ); the change of
    /// the curvature itself along a clothoid is not differentiated.
    #[must_use]
    pub fn steer_and_gradient(&self, x: &TargetState, f: &Frenet) -> (f64, SVector<f64, 8>) {
        let (law, e_psi) = self.law(x, f);
        let (fade, dfade) = lane_keep_fade(e_psi);
        let vx = x[idx::VX];
        let sigma = (vx / REVERSE_BLEND).clamp(-1.0, 1.0);
        let raw = sigma * fade * law;
        let steer = raw.clamp(-LANE_KEEP_MAX_STEER, LANE_KEEP_MAX_STEER);
        let mut g = SVector::<f64, 8>::zeros();
        if raw.abs() < LANE_KEEP_MAX_STEER {
            let (sin, cos) = f.heading.sin_cos();
            // d grows to the left of the road heading: ∂d/∂(X, Y) = (−sin, cos); the foot
            // point moves by ∂s/∂(X, Y) = (cos, sin)/(1 − κ d), turning the road heading.
            let turn = f.curvature / (1.0 - f.curvature * f.d);
            // The law: its yaw-rate reference |v_x| κ.
            g[idx::VX] = self.gain * LANE_KEEP_KR * f.curvature * vx.signum();
            g[idx::PSI] = -self.gain * LANE_KEEP_KPSI;
            g[idx::R] = -self.gain * LANE_KEEP_KR;
            g[idx::X] = self.gain * (LANE_KEEP_KD * sin + LANE_KEEP_KPSI * turn * cos);
            g[idx::Y] = self.gain * (-LANE_KEEP_KD * cos + LANE_KEEP_KPSI * turn * sin);
            // The fade: ∂c/∂x = c'(e_ψ) ∂e_ψ/∂x with ∂e_ψ/∂(ψ, X, Y) = (1, −turn cos, −turn sin).
            g *= fade;
            g[idx::PSI] += law * dfade;
            g[idx::X] -= law * dfade * turn * cos;
            g[idx::Y] -= law * dfade * turn * sin;
            g *= sigma;
            // The direction of travel's blend.
            if vx.abs() < REVERSE_BLEND {
                g[idx::VX] += fade * law / REVERSE_BLEND;
            }
        }
        (steer, g)
    }

    /// The unblended, unfaded, unclamped law in the frame of travel and its heading error.
    fn law(&self, x: &TargetState, f: &Frenet) -> (f64, f64) {
        let vx = x[idx::VX];
        let course = if vx < 0.0 { std::f64::consts::PI } else { 0.0 };
        let e_d = f.d - self.offset;
        let e_psi = crate::wrap_angle(x[idx::PSI] + course - f.heading);
        let r_ref = vx.abs() * f.curvature;
        let fb = -LANE_KEEP_KD * e_d - LANE_KEEP_KPSI * e_psi - LANE_KEEP_KR * (x[idx::R] - r_ref);
        (self.wheelbase * f.curvature + self.gain * fb, e_psi)
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
        assert_gradient(&lk, &road, &x, &g, 1e-5, 1e-7, "");
        // Clamped: no gradient.
        x[idx::PSI] = 1.0;
        let (s, g) = lk.steer_and_gradient(&x, &f);
        assert_eq!(s, -LANE_KEEP_MAX_STEER);
        assert_eq!(g, SVector::<f64, 8>::zeros());
        // In the fade (between 60° and 90° of heading error), rolling forwards and rolling
        // backwards, and in the blend of the direction of travel: unclamped, the fade's and
        // the blend's derivatives are part of the gradient.
        for (psi, vx) in [
            (1.53, 20.0),
            (std::f64::consts::PI + 0.1, -8.0),
            (0.05, 0.3),
        ] {
            x[idx::PSI] = f.heading + psi;
            x[idx::VX] = vx;
            let (s, g) = lk.steer_and_gradient(&x, &f);
            assert!(
                s.abs() < LANE_KEEP_MAX_STEER && s != 0.0,
                "ψ {psi}, v_x {vx}: {s}"
            );
            assert_gradient(
                &lk,
                &road,
                &x,
                &g,
                1e-6,
                1e-6,
                &format!("ψ {psi}, v_x {vx}"),
            );
        }
    }

    /// `g` against central differences (step `h`, tolerance `tol`) of the steer, with the
    /// road re-projected at every perturbed state.
    fn assert_gradient(
        lk: &LaneKeeper,
        road: &Road,
        x: &TargetState,
        g: &SVector<f64, 8>,
        h: f64,
        tol: f64,
        label: &str,
    ) {
        for i in 0..8 {
            let (mut p, mut m) = (*x, *x);
            p[i] += h;
            m[i] -= h;
            let fp = road.project(Vec2::new(p[idx::X], p[idx::Y]));
            let fm = road.project(Vec2::new(m[idx::X], m[idx::Y]));
            let fd = (lk.steer(&p, &fp) - lk.steer(&m, &fm)) / (2.0 * h);
            assert!(
                (fd - g[i]).abs() < tol,
                "{label} ∂δ/∂x[{i}]: {} vs {fd}",
                g[i]
            );
        }
    }

    /// The steer of a lane keeper of the line d = 1.75 m (gain 1, wheelbase 2.7 m) on
    /// [`straight`] at station 100 m, lateral offset `y`, heading `psi`, speed `vx`, yaw rate `r`.
    fn steer_on_straight(psi: f64, vx: f64, r: f64, y: f64) -> f64 {
        let lk = LaneKeeper {
            offset: 1.75,
            gain: 1.0,
            wheelbase: 2.7,
        };
        let mut x = TargetState::zeros();
        x.copy_from_slice(&[vx, 0.0, psi, r, 0.0, 0.0, 100.0, y]);
        lk.steer(&x, &straight().project(Vec2::new(100.0, y)))
    }

    fn straight() -> Road {
        Road::new(RoadSpec {
            segments: vec![SegmentSpec::Straight { length: 300.0 }],
            lanes: 2,
            lane_width: 3.5,
            shoulder: 0.5,
            origin: [0.0, 0.0, 0.0],
        })
        .unwrap()
    }

    /// Rolling forwards: the whole law up to 60° of heading error; nothing from 90° on
    /// (either way round), where the car travels across the road or back along it; a
    /// continuous steer in between.
    #[test]
    fn the_lane_keeper_lets_go_once_the_car_travels_across_the_road() {
        let steer_at = |psi: f64, vx: f64| steer_on_straight(psi, vx, 0.0, 1.0);
        // Up to 60° the law is whole: −k_d (1 − 1.75) − k_ψ ψ, clamped.
        for psi in [-1.0, -0.3, 0.0, 0.3, 1.0] {
            let law = -LANE_KEEP_KD * (1.0 - 1.75) - LANE_KEEP_KPSI * psi;
            let want = law.clamp(-LANE_KEEP_MAX_STEER, LANE_KEEP_MAX_STEER);
            assert!((steer_at(psi, 15.0) - want).abs() < 1e-12, "ψ {psi}");
        }
        // From 90° on, hands off; rolling backwards the same holds about the reversed heading.
        for psi in [1.58, 2.5, 3.1, 3.2, -3.1, -2.0, -1.58] {
            assert_eq!(steer_at(psi, 8.0), 0.0, "ψ {psi}");
            assert_eq!(steer_at(psi + std::f64::consts::PI, -8.0), 0.0, "ψ {psi}");
        }
        // Continuous through the fade.
        let mut last = steer_at(1.0, 15.0);
        for k in 1..=200 {
            let psi = 1.0 + 0.6 * f64::from(k) / 200.0;
            let s = steer_at(psi, 15.0);
            assert!((s - last).abs() < 0.01, "jump at ψ {psi}: {last} → {s}");
            last = s;
        }
        assert_eq!(lane_keep_fade(0.5), (1.0, 0.0));
        assert_eq!(lane_keep_fade(std::f64::consts::PI), (0.0, 0.0));
    }

    /// Rolling backwards, the law is mirrored: at the reversed heading turned by `a` the
    /// steer is the opposite of the forward steer at `a` (a steered front axle yaws a car
    /// rolling backwards the other way), and it continues through a standstill.
    #[test]
    fn rolling_backwards_the_lane_keeper_steers_the_mirrored_law() {
        let steer_at = steer_on_straight;
        for (a, r, y) in [(0.1, 0.0, 1.0), (-0.12, 0.05, 2.5), (0.03, -0.1, -1.0)] {
            let fwd = steer_at(a, 8.0, r, y);
            let back = steer_at(std::f64::consts::PI + a, -8.0, r, y);
            assert!(
                fwd != 0.0 && (back + fwd).abs() < 1e-12,
                "{a}: {fwd} vs {back}"
            );
        }
        // A car rolling backwards 7° off the reversed heading, its course drifting to the
        // right (−d): the steer turns its heading towards the reversed one, r = v_x δ / L > 0.
        let psi = std::f64::consts::PI - 0.126;
        let delta = steer_at(psi, -9.0, 0.0, 1.75);
        assert!(-9.0 * delta / 2.7 > 0.0, "δ {delta}");
        // Through a standstill the steer goes through zero.
        for vx in [-0.01, 0.0, 0.01] {
            assert!(steer_at(psi, vx, 0.0, 1.75).abs() < 0.01, "v_x {vx}");
        }
    }
}
