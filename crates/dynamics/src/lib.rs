//! Vehicle and contact dynamics for picopit.
//!
//! Everything here is SI (m, s, kg, N, N·m, rad) and follows the conventions of
//! `DESIGN.md`:
//!
//! * World frame: X along the road's initial direction, Y to the left, Z up; yaw ψ
//!   counter-clockwise from X. Body frame: x forward, y left.
//! * Target state (paper order) `x_T = [vx, vy, ψ, r, p, φ, X, Y]`, input `u_T = [δ, T_b]`.
//! * Bullet state `x_B = [X, Y, ψ, vx, vy, r]`, input `u_B = [δ_f, T_r]`,
//!   `F_x,r = η_d i_g T_r / R_w`.
//! * Contact frame: unit normal `n` from bullet into target, `t = n` rotated +90°, `γ` the
//!   world heading of `n`; `f_c = [F_n, F_t]`, the target receives `+f_c` and the bullet
//!   `−f_c`; in a body frame `f_body = R(γ − ψ) f_c`; every contact force carries its yaw
//!   moment `M_z = (p_c − p_cg) × f`.
//!
//! Modules:
//! * [`params`]: vehicle, tyre and contact parameter sets (TOML, validated).
//! * [`geometry`]: 2-D poses and oriented rectangles.
//! * [`tyre`]: the Magic Formula (pure and combined slip, CommonRoad's tyre form).
//! * [`contact`]: separating-axis contact geometry, contact frame, force mapping,
//!   compliant contact law.
//! * [`road`]: roads (straight, arc, clothoid), Frenet projection, edge distances, obstacles.
//! * `integrate` (internal): RK4 and RK4 with the exact Jacobian of the discrete step.
//! * [`bullet`]: the bullet's single-track control model with analytic Jacobians.
//! * [`target4dof`]: the 4-DOF analytic target model, first [`TargetModel`].
//! * [`plant`]: the high-fidelity two-vehicle plant (the truth).
//! * [`driver`]: the target driver's lane-keeping law (scenario driver and planner alike).

pub mod bullet;
pub mod compare;
pub mod contact;
pub mod driver;
pub mod error;
pub mod geometry;
mod integrate;
pub mod params;
pub mod plant;
pub mod road;
pub mod target;
pub mod target4dof;
pub mod tyre;

pub use error::ParamError;
pub use road::RoadError;
pub use target::{ContactInput, TargetInput, TargetJacobians, TargetModel, TargetState};

/// Standard gravity (m/s²).
pub const GRAVITY: f64 = 9.80665;

/// Wrap an angle to (−π, π].
#[inline]
#[must_use]
pub fn wrap_angle(a: f64) -> f64 {
    let two_pi = std::f64::consts::TAU;
    let mut w = a % two_pi;
    if w > std::f64::consts::PI {
        w -= two_pi;
    } else if w <= -std::f64::consts::PI {
        w += two_pi;
    }
    w
}

#[cfg(test)]
mod tests {
    use super::wrap_angle;
    use std::f64::consts::PI;

    #[test]
    fn wrap_angle_range_and_identity() {
        for k in -5..=5 {
            let a = 0.3 + f64::from(k) * 2.0 * PI;
            assert!((wrap_angle(a) - 0.3).abs() < 1e-12);
        }
        assert!((wrap_angle(PI) - PI).abs() < 1e-12);
        assert!((wrap_angle(-PI) - PI).abs() < 1e-12);
        assert!((wrap_angle(3.5 * PI) + 0.5 * PI).abs() < 1e-12);
    }
}
