//! Plant versus the 4-DOF analytic model: how far the control-oriented target model is
//! from the truth, in a gentle manoeuvre and in a PIT push. The numbers are reported in
//! `docs/plant.md` (`cargo run --release -p picopit-dynamics --example plant_vs_4dof`) and
//! bounded in the test suite.

use crate::geometry::Vec2;
use crate::params::ParamSet;
use crate::plant::{Plant, PlantConfig, VehicleInit, Which};
use crate::target::{idx, ContactInput, TargetInput, TargetModel, TargetState};
use crate::target4dof::FourDofTarget;
use crate::wrap_angle;

/// Step of the comparison (the MPC step).
pub const DT: f64 = 0.05;

/// Open-loop agreement between the plant and the 4-DOF model over one manoeuvre.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Agreement {
    /// Largest position error over the run (m).
    pub max_position_error: f64,
    /// Largest wrapped heading error (rad).
    pub max_heading_error: f64,
    /// RMS yaw-rate error over the run (rad/s) and the plant's peak |r|.
    pub rms_yaw_rate_error: f64,
    pub peak_yaw_rate: f64,
    /// Mean one-step (0.05 s) prediction error of the state, teacher-forced from the plant:
    /// position (m), heading (rad) and velocity (m/s).
    pub one_step_position_error: f64,
    pub one_step_heading_error: f64,
    pub one_step_velocity_error: f64,
    /// Largest sideslip angle of the plant's target (rad), to say how nonlinear it was.
    pub peak_sideslip: f64,
}

struct Sample {
    x: TargetState,
    u: TargetInput,
    c: ContactInput,
}

fn agreement(model: &mut FourDofTarget, samples: &[Sample]) -> Agreement {
    let mut x = samples[0].x;
    let mut max_pos: f64 = 0.0;
    let mut max_head: f64 = 0.0;
    let mut sq = 0.0;
    let mut peak_r: f64 = 0.0;
    let mut peak_beta: f64 = 0.0;
    let (mut e_pos, mut e_head, mut e_vel) = (0.0, 0.0, 0.0);
    let n = samples.len() - 1;
    for k in 0..n {
        let s = &samples[k];
        let truth = &samples[k + 1].x;
        // Open loop.
        x = model.step(&x, &s.u, &s.c);
        max_pos = max_pos.max(pos_err(&x, truth));
        max_head = max_head.max(wrap_angle(x[idx::PSI] - truth[idx::PSI]).abs());
        sq += (x[idx::R] - truth[idx::R]).powi(2);
        peak_r = peak_r.max(truth[idx::R].abs());
        peak_beta = peak_beta.max(truth[idx::VY].atan2(truth[idx::VX].abs()).abs());
        // Teacher-forced one step.
        let y = model.step(&s.x, &s.u, &s.c);
        e_pos += pos_err(&y, truth);
        e_head += wrap_angle(y[idx::PSI] - truth[idx::PSI]).abs();
        e_vel +=
            ((y[idx::VX] - truth[idx::VX]).powi(2) + (y[idx::VY] - truth[idx::VY]).powi(2)).sqrt();
    }
    let nf = n as f64;
    Agreement {
        max_position_error: max_pos,
        max_heading_error: max_head,
        rms_yaw_rate_error: (sq / nf).sqrt(),
        peak_yaw_rate: peak_r,
        one_step_position_error: e_pos / nf,
        one_step_heading_error: e_head / nf,
        one_step_velocity_error: e_vel / nf,
        peak_sideslip: peak_beta,
    }
}

fn plant_on(params: &ParamSet, mu: f64) -> Plant {
    Plant::new(
        params,
        PlantConfig {
            mu,
            ..PlantConfig::default()
        },
    )
    .expect("valid parameters")
}

fn pos_err(a: &TargetState, b: &TargetState) -> f64 {
    ((a[idx::X] - b[idx::X]).powi(2) + (a[idx::Y] - b[idx::Y]).powi(2)).sqrt()
}

/// A gentle single lane change of the target alone: full-sine steer of `amplitude` rad over
/// 2.5 s at `speed` m/s, speed held by a throttle loop in the plant (in gear), 5 s in all.
pub fn lane_change(params: &ParamSet, mu: f64, speed: f64, amplitude: f64) -> Agreement {
    let mut plant = plant_on(params, mu);
    plant.reset(
        &VehicleInit {
            x: -1000.0,
            y: -50.0,
            ..VehicleInit::default()
        },
        &VehicleInit {
            vx: speed,
            ..VehicleInit::default()
        },
    );
    let per_sample = (DT / plant.dt()).round() as usize;
    let mut samples = Vec::new();
    let period = 2.5;
    let drive_gain = params.target.drive_efficiency * params.target.gear_ratio;
    for _ in 0..=100 {
        let body = plant.body(Which::Target);
        // The model is fed the plant's actual (lagged, rate-limited) steer angle, and its
        // drive torque at the axle as the throttle (T_b < 0).
        let u = TargetInput::new(body.steer, -drive_gain * body.torque);
        samples.push(Sample {
            x: plant.target_state(),
            u,
            c: ContactInput::none(),
        });
        for _ in 0..per_sample {
            let t_now = plant.time();
            let steer = if (0.5..0.5 + period).contains(&t_now) {
                amplitude * (std::f64::consts::TAU * (t_now - 0.5) / period).sin()
            } else {
                0.0
            };
            let vx = plant.target_state()[idx::VX];
            plant.set_target_command(steer, 0.0);
            plant.set_drive(Which::Target, 300.0 * (speed - vx));
            plant.step();
        }
    }
    // Use the inputs at the middle of each interval (the plant's actuators move within it).
    for k in 0..samples.len() - 1 {
        samples[k].u = 0.5 * (samples[k].u + samples[k + 1].u);
    }
    let mut model = FourDofTarget::new(&params.target, mu, DT);
    agreement(&mut model, &samples)
}

/// A PIT-like rear-quarter push: the bullet, 20° into the target's right rear quarter with
/// `dv` m/s more speed, keeps steering in and driving for 0.6 s; the target's driver does
/// nothing. The 4-DOF model is fed the plant's contact force averaged over each 0.05 s
/// (impulse-preserving) with its direction and point of action; 3 s in all.
pub fn pit_push(params: &ParamSet, mu: f64, target_speed: f64, dv: f64) -> Agreement {
    let mut plant = plant_on(params, mu);
    let t = &params.target;
    let b = &params.bullet;
    let yaw = 20f64.to_radians();
    // Bullet front-left corner 0.1 m outside the target's right side, 0.3 m ahead of its
    // rear bumper.
    let corner = Vec2::new(-(t.length - t.cg_to_front) + 0.3, -0.5 * t.width - 0.1);
    let to_cg = crate::geometry::rotate(yaw, Vec2::new(-b.cg_to_front, -0.5 * b.width));
    let cg = corner + to_cg;
    plant.reset(
        &VehicleInit {
            x: cg.x,
            y: cg.y,
            yaw,
            vx: target_speed + dv,
            ..VehicleInit::default()
        },
        &VehicleInit {
            vx: target_speed,
            ..VehicleInit::default()
        },
    );
    let per_sample = (DT / plant.dt()).round() as usize;
    let mut samples: Vec<Sample> = Vec::new();
    let _ = plant.take_contact_average();
    for _ in 0..=60 {
        let x = plant.target_state();
        for _ in 0..per_sample {
            if plant.time() < 0.6 {
                plant.set_bullet_command(0.08, b.drive_torque_max);
            } else {
                plant.set_bullet_command(-0.05, 0.0);
                plant.set_brake(Which::Bullet, 0.5 * b.brake_torque_max);
            }
            plant.step();
        }
        let c = plant
            .take_contact_average()
            .map_or_else(ContactInput::none, |r| ContactInput {
                fc: r.fc,
                gamma: r.gamma,
                point_in_body: r.point_in_target,
            });
        samples.push(Sample {
            x,
            u: TargetInput::zeros(),
            c,
        });
    }
    let mut model = FourDofTarget::new(&params.target, mu, DT);
    agreement(&mut model, &samples)
}
