//! Time stepping: advancing the plant, and the semi-implicit Euler step of one vehicle
//! (wheel loads, tyre forces and drag, planar motion, roll and pitch, the implicit
//! wheel-spin update with brakes and driveline, actuator lags).

use super::chassis::Chassis;
use super::contact::External;
use super::{Plant, VehicleBody, ABS_MIN_SPEED};
use crate::geometry::{cross, Vec2};
use crate::tyre::{combined_slip4, tan_slip, V_LOW};
use crate::GRAVITY;

impl Plant {
    /// Advance by `duration` (rounded to whole steps).
    pub fn advance(&mut self, duration: f64) {
        if !(duration.is_finite() && duration > 0.0) {
            return;
        }
        let n = (duration / self.config.dt).round() as u64;
        for _ in 0..n {
            self.step();
        }
    }

    /// One integration step.
    pub fn step(&mut self) {
        let dt = self.config.dt;
        let ext = self.contact_forces(dt);
        let tyres = self.config.tyre_forces;
        for ((chassis, body), ext) in self.chassis.iter().zip(self.bodies.iter_mut()).zip(&ext) {
            integrate_vehicle(chassis, body, ext, dt, tyres);
        }
        self.steps += 1;
        self.time = self.steps as f64 * dt;
        self.accum.since += dt;
    }
}

/// Velocities of the four wheel centres (FL, FR, RL, RR) in their wheel frames (the front
/// wheels steered by δ, given as `sin δ`, `cos δ`).
#[inline]
fn wheel_velocities(c: &Chassis, b: &VehicleBody, sd: f64, cd: f64) -> [Vec2; 4] {
    let e = c.cg_offset(b);
    let e_dot = c.cg_rate(b);
    // Velocity of the chassis origin in the body frame.
    let v_o = b.vel_body() - e_dot - Vec2::new(-b.r * e.y, b.r * e.x);
    std::array::from_fn(|w| {
        let pos = c.wheel_pos[w];
        let v = Vec2::new(v_o.x - b.r * pos.y, v_o.y + b.r * pos.x);
        if w < 2 {
            Vec2::new(cd * v.x + sd * v.y, -sd * v.x + cd * v.y)
        } else {
            v
        }
    })
}

/// One semi-implicit Euler step of one vehicle.
#[allow(clippy::too_many_lines)]
fn integrate_vehicle(c: &Chassis, b: &mut VehicleBody, ext: &External, dt: f64, tyres: bool) {
    let (s, co) = b.yaw.sin_cos();
    let to_body = |v: Vec2| Vec2::new(co * v.x + s * v.y, -s * v.x + co * v.y);
    let to_world = |v: Vec2| Vec2::new(co * v.x - s * v.y, s * v.x + co * v.y);
    let e = c.cg_offset(b);
    let v_cg = to_body(b.vel);
    let (sd, cd) = b.steer.sin_cos();
    let v_wheel = wheel_velocities(c, b, sd, cd);

    // Wheel loads: static + pitch/roll suspension moments + unsprung / roll-centre terms
    // (with the last step's c.g. acceleration).
    let m_pitch = c.k_pitch * b.theta + c.c_pitch * b.q;
    let d_front = (m_pitch - c.long_transfer * b.acc_body.x) / c.wheelbase;
    let d_left: [f64; 2] = std::array::from_fn(|axle| {
        let m_roll = c.k_roll[axle] * b.phi + c.c_roll[axle] * b.p;
        m_roll / c.track[axle] - c.lat_transfer[axle] * b.acc_body.y
    });
    let fz = [
        (c.fz_static[0] + 0.5 * d_front + d_left[0]).max(0.0),
        (c.fz_static[1] + 0.5 * d_front - d_left[0]).max(0.0),
        (c.fz_static[2] - 0.5 * d_front + d_left[1]).max(0.0),
        (c.fz_static[3] - 0.5 * d_front - d_left[1]).max(0.0),
    ];

    // Tyre forces.
    let mut f_body = Vec2::zeros();
    let mut m_z = 0.0;
    let mut fx_wheel = [0.0; 4];
    let mut kx_over_v = [0.0; 4];
    if tyres {
        // Wheel-frame velocities (front wheels steered by δ), slips, then all four tyres.
        let mut kappa = [0.0; 4];
        let mut alpha = [0.0; 4];
        let mut denom = [0.0; 4];
        for w in 0..4 {
            let vw = v_wheel[w];
            denom[w] = vw.x.abs().max(V_LOW);
            kappa[w] = (b.omega[w] * c.rw - vw.x) / denom[w];
            alpha[w] = tan_slip(vw.x, vw.y);
        }
        let forces = combined_slip4(&c.tyre, c.mu_scale, &fz, &kappa, &alpha);
        for (w, f) in forces.iter().enumerate() {
            fx_wheel[w] = f.fx;
            kx_over_v[w] = f.kx / denom[w];
            let fb = if w < 2 {
                Vec2::new(cd * f.fx - sd * f.fy, sd * f.fx + cd * f.fy)
            } else {
                Vec2::new(f.fx, f.fy)
            };
            f_body += fb;
            m_z += cross(c.wheel_pos[w] - e, fb);
        }
    }
    // Aerodynamic drag at the c.g.
    if tyres {
        f_body -= v_cg * (c.drag * v_cg.norm());
    }

    // Planar motion of the c.g.
    let f_world = to_world(f_body) + ext.force;
    let acc_world = f_world * c.inv_m;
    let acc_body = to_body(acc_world);
    b.vel += acc_world * dt;
    b.r += (m_z + ext.moment) * c.inv_iz * dt;

    // Roll and pitch of the sprung mass, driven by the c.g. acceleration and by contact
    // forces acting at bumper height.
    let fc_body = to_body(ext.contact_force);
    let g = GRAVITY;
    let p_dot = (-c.ms * c.h_roll * acc_body.y + c.ms * g * c.h_roll * b.phi
        - (c.k_roll[0] + c.k_roll[1]) * b.phi
        - (c.c_roll[0] + c.c_roll[1]) * b.p
        + fc_body.y * c.h_bumper_roll)
        / c.roll_inertia;
    let q_dot = (-c.ms * c.h_pitch * acc_body.x + c.ms * g * c.h_pitch * b.theta
        - c.k_pitch * b.theta
        - c.c_pitch * b.q
        + fc_body.x * c.h_bumper)
        / c.pitch_inertia;
    b.p += p_dot * dt;
    b.q += q_dot * dt;
    b.phi += b.p * dt;
    b.theta += b.q * dt;
    b.yaw += b.r * dt;
    b.pos += b.vel * dt;

    // Wheel spin, implicit in the tyre's slip stiffness and solved together with the
    // chassis: the longitudinal force is linearised in the slip velocity ω R_w − v_x,
    // `F_x(t + dt) ≈ F_x + K (R_w Δω − Δv_x)` with `K = K_x / max(|v_x|, V_LOW)`, and the
    // wheel's ground speed change Δv_x over this step (the chassis has just been updated)
    // enters the balance. Without that term the wheel lags the decelerating chassis by
    // one step, which at low speed (large K) under-brakes by a time-step-dependent amount.
    // Then the Coulomb brake and rolling-resistance torque (stable to standstill).
    let v_wheel_new = if tyres {
        wheel_velocities(c, b, sd, cd)
    } else {
        v_wheel
    };
    // The powertrain on the driven wheels: the throttle's drive torque and closed-throttle
    // engine braking while the engine runs; once the axle has dragged it below its stall
    // speed, the stalled engine's hold, a Coulomb torque like a brake's.
    let (drive_wheel, hold_wheel) = match &c.driveline {
        Some(d) => {
            if !b.stalled && 0.5 * (b.omega[2] + b.omega[3]) < d.stall_axle_speed {
                b.stalled = true;
            }
            if b.stalled {
                (0.0, d.hold)
            } else {
                (0.5 * c.drive_gain * b.torque - d.drag, 0.0)
            }
        }
        None => (0.5 * c.drive_gain * b.torque, 0.0),
    };
    for w in 0..4 {
        let (drive, hold) = if w >= 2 {
            (drive_wheel, hold_wheel)
        } else {
            (0.0, 0.0)
        };
        let i_eff = c.iw + dt * c.rw * c.rw * kx_over_v[w];
        let ground = c.rw * kx_over_v[w] * (v_wheel_new[w].x - v_wheel[w].x);
        let omega_free = b.omega[w] + dt * (drive - c.rw * fx_wheel[w] + ground) / i_eff;
        let coulomb = c.brake_share[w] * b.brake + c.rolling_resistance * fz[w] * c.rw + hold;
        let cap = dt * coulomb / i_eff;
        let braked = if omega_free.abs() <= cap {
            0.0
        } else {
            omega_free - cap.copysign(omega_free)
        };
        // ABS: the brake may slow the wheel to the slip it holds, not below (it releases
        // the pressure there), while the wheel rolls fast enough for the system to act.
        let v_x = v_wheel_new[w].x;
        b.omega[w] = if c.abs_slip > 0.0 && b.brake > 0.0 && v_x.abs() > ABS_MIN_SPEED {
            let floor = (1.0 - c.abs_slip) * v_x / c.rw;
            if v_x > 0.0 {
                braked.max(omega_free.min(floor))
            } else {
                braked.min(omega_free.max(floor))
            }
        } else {
            braked
        };
    }

    // Actuators.
    let steer_target = b.cmd_steer.clamp(-c.steer_max, c.steer_max);
    let step_max = c.steer_rate_max * dt;
    b.steer += ((steer_target - b.steer) * c.steer_lag).clamp(-step_max, step_max);
    b.torque +=
        (b.cmd_torque.clamp(c.torque_limits.0, c.torque_limits.1) - b.torque) * c.torque_lag;
    b.brake += (b.cmd_brake.clamp(0.0, c.brake_max) - b.brake) * c.torque_lag;

    b.fz = fz;
    b.acc_body = acc_body;
    flush_tiny(b);
}

/// Values that decay exponentially at rest (damped suspension, creeping velocity) would
/// reach subnormal numbers after minutes of simulated time, where arithmetic is ~100× slower.
/// Anything below 1e-150 is physically zero.
#[inline]
fn flush_tiny(b: &mut VehicleBody) {
    const TINY: f64 = 1e-150;
    let flush = |v: &mut f64| {
        if v.abs() < TINY {
            *v = 0.0;
        }
    };
    flush(&mut b.vel.x);
    flush(&mut b.vel.y);
    for v in [&mut b.r, &mut b.phi, &mut b.p, &mut b.theta, &mut b.q] {
        flush(v);
    }
}
