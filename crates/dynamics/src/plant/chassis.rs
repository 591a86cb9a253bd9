//! The constants of one plant vehicle, derived once from its parameters ([`Chassis`]), and
//! its powertrain in gear reduced to one driven wheel ([`Driveline`]).

use super::{VehicleBody, AIR_DENSITY};
use crate::geometry::Vec2;
use crate::params::{TyreParams, VehicleParams};

/// Constants of one vehicle, derived once from its parameters.
#[derive(Debug, Clone)]
pub(super) struct Chassis {
    pub(super) inv_m: f64,
    pub(super) m: f64,
    pub(super) ms: f64,
    pub(super) inv_iz: f64,
    pub(super) h_roll: f64,
    pub(super) h_pitch: f64,
    pub(super) roll_inertia: f64,
    pub(super) pitch_inertia: f64,
    pub(super) k_roll: [f64; 2],
    pub(super) c_roll: [f64; 2],
    pub(super) k_pitch: f64,
    pub(super) c_pitch: f64,
    pub(super) track: [f64; 2],
    pub(super) wheelbase: f64,
    /// Wheel positions relative to the chassis origin (static c.g.): FL, FR, RL, RR.
    pub(super) wheel_pos: [Vec2; 4],
    pub(super) fz_static: [f64; 4],
    /// Lateral load transfer per axle per unit a_y (unsprung + roll-centre terms), N/(m/s²).
    pub(super) lat_transfer: [f64; 2],
    /// Longitudinal load transfer of the unsprung masses per unit a_x, N/(m/s²).
    pub(super) long_transfer: f64,
    pub(super) h_bumper_roll: f64,
    pub(super) h_bumper: f64,
    pub(super) rw: f64,
    pub(super) iw: f64,
    pub(super) drive_gain: f64,
    pub(super) brake_share: [f64; 4],
    pub(super) steer_max: f64,
    pub(super) steer_rate_max: f64,
    /// Exact first-order-lag factors `1 − exp(−dt/τ)` for steer and torques.
    pub(super) steer_lag: f64,
    pub(super) torque_limits: (f64, f64),
    pub(super) torque_lag: f64,
    pub(super) brake_max: f64,
    /// [`VehicleParams::abs_slip`] (0: no ABS).
    pub(super) abs_slip: f64,
    pub(super) rolling_resistance: f64,
    pub(super) drag: f64,
    pub(super) length: f64,
    pub(super) width: f64,
    pub(super) cg_to_front: f64,
    pub(super) tyre: TyreParams,
    pub(super) mu_scale: f64,
    /// The engaged powertrain, per driven (rear) wheel; `None` for a by-wire vehicle or a
    /// target in neutral.
    pub(super) driveline: Option<Driveline>,
}

/// A powertrain in gear, reduced to one driven wheel (each rear wheel carries half the axle
/// torque).
#[derive(Debug, Clone, Copy)]
pub(super) struct Driveline {
    /// Closed-throttle engine braking per driven wheel, `½ i_g T_drag` (N m).
    pub(super) drag: f64,
    /// Holding torque of the stalled engine per driven wheel, `½ i_g T_stall` (N m).
    pub(super) hold: f64,
    /// Axle speed at the engine's stall speed, `ω_stall / i_g` (rad/s).
    pub(super) stall_axle_speed: f64,
}

impl Driveline {
    pub(super) fn new(p: &VehicleParams) -> Option<Self> {
        p.powertrain.as_ref().map(|pt| Self {
            drag: 0.5 * p.gear_ratio * pt.engine_drag_torque,
            hold: 0.5 * p.gear_ratio * pt.stall_torque,
            stall_axle_speed: pt.stall_speed / p.gear_ratio,
        })
    }
}

impl Chassis {
    /// Offset of the total c.g. from the chassis origin (body frame).
    #[inline]
    pub(super) fn cg_offset(&self, b: &VehicleBody) -> Vec2 {
        Vec2::new(self.h_pitch * b.theta, self.h_roll * b.phi) * (self.ms * self.inv_m)
    }

    #[inline]
    pub(super) fn cg_rate(&self, b: &VehicleBody) -> Vec2 {
        Vec2::new(self.h_pitch * b.q, self.h_roll * b.p) * (self.ms * self.inv_m)
    }

    /// Displacement of the sprung body at bumper height from the chassis origin.
    #[inline]
    pub(super) fn bumper_offset(&self, b: &VehicleBody) -> Vec2 {
        Vec2::new(self.h_bumper * b.theta, self.h_bumper_roll * b.phi)
    }

    #[inline]
    pub(super) fn bumper_rate(&self, b: &VehicleBody) -> Vec2 {
        Vec2::new(self.h_bumper * b.q, self.h_bumper_roll * b.p)
    }

    pub(super) fn new(p: &VehicleParams, mu: f64, dt: f64, driveline: Option<Driveline>) -> Self {
        let l = p.wheelbase();
        let (fz_f, fz_r) = p.static_axle_loads();
        let mus = p.mass - p.sprung_mass;
        let h_roll = p.roll_arm();
        let h_pitch = p.h_sprung;
        let ms2 = p.sprung_mass * p.sprung_mass;
        let ms_axle = [p.sprung_mass * p.lr / l, p.sprung_mass * p.lf / l];
        let lat_transfer = [
            (ms_axle[0] * p.h_roll_axis + 0.5 * mus * p.wheel_radius) / p.track_front,
            (ms_axle[1] * p.h_roll_axis + 0.5 * mus * p.wheel_radius) / p.track_rear,
        ];
        let bf = p.brake_bias_front;
        Self {
            inv_m: 1.0 / p.mass,
            m: p.mass,
            ms: p.sprung_mass,
            inv_iz: 1.0 / p.iz,
            h_roll,
            h_pitch,
            // Inertias about the roll / pitch axes, reduced by the coupling to the c.g.
            // motion (the c.g. acceleration is the state's, not the axis').
            roll_inertia: p.ix_sprung + p.sprung_mass * h_roll * h_roll
                - ms2 * h_roll * h_roll / p.mass,
            pitch_inertia: p.iy_sprung + p.sprung_mass * h_pitch * h_pitch
                - ms2 * h_pitch * h_pitch / p.mass,
            k_roll: [p.roll_stiffness_front, p.roll_stiffness_rear],
            c_roll: [p.roll_damping_front, p.roll_damping_rear],
            k_pitch: p.pitch_stiffness,
            c_pitch: p.pitch_damping,
            track: [p.track_front, p.track_rear],
            wheelbase: l,
            wheel_pos: [
                Vec2::new(p.lf, 0.5 * p.track_front),
                Vec2::new(p.lf, -0.5 * p.track_front),
                Vec2::new(-p.lr, 0.5 * p.track_rear),
                Vec2::new(-p.lr, -0.5 * p.track_rear),
            ],
            fz_static: [0.5 * fz_f, 0.5 * fz_f, 0.5 * fz_r, 0.5 * fz_r],
            lat_transfer,
            long_transfer: mus * p.wheel_radius / l,
            h_bumper_roll: p.bumper_height - p.h_roll_axis,
            h_bumper: p.bumper_height,
            rw: p.wheel_radius,
            iw: p.wheel_inertia,
            drive_gain: p.drive_efficiency * p.gear_ratio,
            brake_share: [0.5 * bf, 0.5 * bf, 0.5 * (1.0 - bf), 0.5 * (1.0 - bf)],
            steer_max: p.steer_max,
            steer_rate_max: p.steer_rate_max,
            steer_lag: lag_factor(dt, p.steer_time_constant),
            torque_limits: (p.drive_torque_min, p.drive_torque_max),
            torque_lag: lag_factor(dt, p.torque_time_constant),
            brake_max: p.brake_torque_max,
            abs_slip: p.abs_slip,
            rolling_resistance: p.rolling_resistance,
            drag: 0.5 * AIR_DENSITY * p.drag_area,
            length: p.length,
            width: p.width,
            cg_to_front: p.cg_to_front,
            tyre: p.tyre.clone(),
            mu_scale: p.tyre.mu_scale(mu),
            driveline,
        }
    }
}

/// Exact discretisation factor of a first-order lag: `1 − exp(−dt/τ)` (1 for τ = 0).
fn lag_factor(dt: f64, tau: f64) -> f64 {
    if tau <= 0.0 {
        1.0
    } else {
        1.0 - (-dt / tau).exp()
    }
}
