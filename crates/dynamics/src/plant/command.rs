//! What goes into the plant from outside: the drivers' commands (sanitised to finite
//! values) and idealised impulses.

use super::{Plant, Which};
use crate::geometry::{cross, Vec2};

impl Plant {
    /// Bullet commands: road-wheel steer δ_f (rad) and drive torque T_r (N m).
    pub fn set_bullet_command(&mut self, delta: f64, t_r: f64) {
        let b = &mut self.bodies[Which::Bullet as usize];
        b.cmd_steer = finite_or_zero(delta);
        b.cmd_torque = finite_or_zero(t_r);
    }

    /// Bullet commands as the MPC plans them, `u_B = [δ_f, T_r]` with the rear-axle force
    /// `F_x,r = η_d i_g T_r / R_w`, realised the way a vehicle interface would: a positive
    /// T_r drives the rear axle, a negative one is blended into the service brakes (all four
    /// wheels, the vehicle's brake bias) with the same total force `−η_d i_g T_r / R_w`, so
    /// that braking while steering does not lock the driven axle alone.
    pub fn set_bullet_command_blended(&mut self, delta: f64, t_r: f64) {
        let gain = self.chassis[Which::Bullet as usize].drive_gain;
        let t_r = finite_or_zero(t_r);
        let (drive, brake) = if t_r >= 0.0 {
            (t_r, 0.0)
        } else {
            (0.0, -gain * t_r)
        };
        let b = &mut self.bodies[Which::Bullet as usize];
        b.cmd_steer = finite_or_zero(delta);
        b.cmd_torque = drive;
        b.cmd_brake = brake;
    }

    /// Target driver commands as the target models take them, `u_T = [δ, T_b]`: steer δ
    /// (rad) and the driver's longitudinal torque at the wheels (N m): `T_b ≥ 0` the total
    /// service-brake torque, `T_b < 0` the throttle, a drive torque `−T_b` at the driven
    /// axle (motor side `T_r = −T_b / (η_d i_g)`).
    pub fn set_target_command(&mut self, delta: f64, t_b: f64) {
        let gain = self.chassis[Which::Target as usize].drive_gain;
        let t_b = finite_or_zero(t_b);
        let b = &mut self.bodies[Which::Target as usize];
        b.cmd_steer = finite_or_zero(delta);
        b.cmd_brake = t_b.max(0.0);
        b.cmd_torque = (-t_b).max(0.0) / gain;
    }

    /// Drive-torque command T_r of either vehicle (N m, motor side; the target's driver is
    /// normally off the throttle, but tests and scripted drivers may hold its speed).
    pub fn set_drive(&mut self, which: Which, t_r: f64) {
        self.bodies[which as usize].cmd_torque = finite_or_zero(t_r);
    }

    /// Service-brake command of either vehicle (N m total at the wheels).
    pub fn set_brake(&mut self, which: Which, t_b: f64) {
        self.bodies[which as usize].cmd_brake = finite_or_zero(t_b);
    }

    /// Apply an instantaneous planar impulse `impulse` (N s, world frame) at the world point
    /// `at` to one vehicle: its c.g. velocity changes by `J / m` and its yaw rate by
    /// `(at − c.g.) × J / I_z` (a rigid-body impulse; wheel spin, roll and pitch are left as
    /// they are). For idealised studies (`sim::oracle`); the plant's own contact never
    /// calls it. A non-finite impulse or point is ignored.
    pub fn apply_impulse(&mut self, which: Which, impulse: Vec2, at: Vec2) {
        if !(impulse.x.is_finite() && impulse.y.is_finite() && at.x.is_finite() && at.y.is_finite())
        {
            return;
        }
        let i = which as usize;
        let c = &self.chassis[i];
        let b = &mut self.bodies[i];
        b.vel += impulse * c.inv_m;
        b.r += cross(at - b.pos, impulse) * c.inv_iz;
    }
}

#[inline]
fn finite_or_zero(x: f64) -> f64 {
    if x.is_finite() {
        x
    } else {
        0.0
    }
}
