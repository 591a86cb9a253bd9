//! Physics of the control-oriented models: the bullet single-track model's cornering,
//! drive and adhesion; the 4-DOF target's response to a push, roll, braking, coasting, its
//! driveline; momentum balance of a contact between the two.

use dynamics::bullet::{BulletInput, BulletModel, BulletState};
use dynamics::geometry::Vec2;
use dynamics::params::{ParamSet, VehicleParams};
use dynamics::target::idx;
use dynamics::target4dof::{FourDofTarget, V_BRAKE};
use dynamics::{ContactInput, TargetInput, TargetModel, TargetState, GRAVITY};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use std::f64::consts::PI;

mod common;
use common::*;

// ------------------------------------------------------------------------------------------
// Bullet physics.
// ------------------------------------------------------------------------------------------

/// Drive the bullet with constant steer `delta` and a speed-holding drive torque
/// (proportional feedback on v_x) until the motion is steady; returns the final state.
fn bullet_steady_turn(
    model: &BulletModel,
    p: &VehicleParams,
    speed: f64,
    delta: f64,
) -> BulletState {
    let mut x = BulletState::new(0.0, 0.0, 0.0, speed, 0.0, 0.0);
    let gain = p.drive_force_gain();
    let mut last_r = f64::NAN;
    for _ in 0..(120.0 / DT) as usize {
        // F_x,r = 2 m (v_ref − v_x): a 0.5 s speed loop.
        let tr = 2.0 * p.mass * (speed - x[3]) / gain;
        let u = BulletInput::new(delta, tr);
        last_r = x[5];
        x = model.step(&x, &u, &ContactInput::none());
    }
    assert!(
        (x[5] - last_r).abs() < 1e-12,
        "the turn did not settle: r {} → {}",
        last_r,
        x[5]
    );
    x
}

#[test]
fn bullet_steady_cornering_matches_understeer_gradient() {
    // Two speeds per parameter set (the half-scale ones Froude-scaled), a_y ≈ 1 m/s²: deep
    // in the linear tyre range, so the linear theory δ = L/R + K_us a_y must hold closely.
    for ((name, set), speeds) in sets().into_iter().zip([[15.0, 25.0], [10.0, 17.0]]) {
        let p = &set.bullet;
        let model = BulletModel::new(p, MU, DT);
        let k_us = model.understeer_gradient();
        let l = p.wheelbase();
        // The tyre's cornering stiffness is proportional to its load (CommonRoad's
        // K_y = p_Ky1 F_z), so the axles' stiffness ratio is their load ratio: neutral steer.
        assert!(
            k_us.abs() < 1e-12,
            "{name}: load-proportional cornering stiffness steers neutrally (K_us = {k_us:.3e})"
        );
        for speed in speeds {
            // Open-loop steer for a_y = 1 m/s² from the linear theory.
            let delta = l / (speed * speed) + k_us;
            let x = bullet_steady_turn(&model, p, speed, delta);
            let (vx, vy, r) = (x[3], x[4], x[5]);
            let v = vx.hypot(vy);
            let a_y = vx * r;
            let radius = v / r;
            let measured = delta - l / radius;
            let predicted = k_us * a_y;
            // Relative to the kinematic steer L/R (K_us a_y is zero here).
            let rel = (measured - predicted).abs() / (l / radius);
            eprintln!(
                "{name}: V = {v:.3} m/s, a_y = {a_y:.4} m/s², δ − L/R = {measured:.4e}, \
                 K_us a_y = {predicted:.4e}, error {rel:.2e} of L/R"
            );
            assert!(
                rel < 0.03,
                "{name}: δ − L/R = {measured:.4e} vs K_us a_y = {predicted:.4e} at {speed} m/s"
            );
        }
    }
}

#[test]
fn bullet_drive_torque_accelerates_straight() {
    // F_x,r = η_d i_g T_r / R_w and nothing else acts in straight running.
    for (name, set) in sets() {
        let p = &set.bullet;
        let model = BulletModel::new(p, MU, DT);
        let x = BulletState::new(3.0, -1.0, 0.4, 12.0, 0.0, 0.0);
        let u = BulletInput::new(0.0, 0.5 * p.drive_torque_max);
        let xn = model.step(&x, &u, &ContactInput::none());
        let expected = p.drive_efficiency * p.gear_ratio * u[1] / p.wheel_radius / p.mass;
        let measured = (xn[3] - x[3]) / DT;
        assert!(
            (measured - expected).abs() < 1e-9 * expected,
            "{name}: {measured} vs {expected}"
        );
        assert!(
            xn[4].abs() < 1e-12 && xn[5].abs() < 1e-12,
            "{name}: straight run turned"
        );
        // The heading is kept and the path follows it.
        let moved = (xn[1] - x[1]).atan2(xn[0] - x[0]);
        assert!((moved - 0.4).abs() < 1e-12, "{name}: moved along {moved}");
    }
}

#[test]
fn lower_adhesion_caps_the_lateral_force() {
    // A hard slide: |ΣF_y| can never exceed μ m g (the axle peaks are μ_y F_z,axle with a
    // μ_y that only falls with load), and set_mu is the same as building with that μ.
    let set = ParamSet::builtin("full_size").unwrap();
    let p = &set.bullet;
    let mut model = BulletModel::new(p, 1.0, DT);
    let x = BulletState::new(0.0, 0.0, 0.0, 10.0, 4.0, 0.5);
    let u = BulletInput::new(0.1, 0.0);
    let lateral = |m: &BulletModel| {
        let d = m.derivative(&x, &u, &ContactInput::none());
        (d[4] + x[5] * x[3]) * p.mass
    };
    let high = lateral(&model);
    for mu in [0.7, 0.3] {
        model.set_mu(mu);
        let f = lateral(&model);
        let fresh = lateral(&BulletModel::new(p, mu, DT));
        assert_eq!(f, fresh, "set_mu({mu}) differs from new(.., {mu}, ..)");
        assert!(
            f.abs() < high.abs(),
            "μ = {mu}: |F_y| = {f} not below the μ = 1 value {high}"
        );
        assert!(
            f.abs() <= mu * p.mass * GRAVITY,
            "μ = {mu}: |F_y| = {f} beyond μ m g"
        );
    }
}

// ------------------------------------------------------------------------------------------
// 4-DOF target physics.
// ------------------------------------------------------------------------------------------

#[test]
fn target_model_identity() {
    let set = ParamSet::builtin("half_scale").unwrap();
    let model = FourDofTarget::new(&set.target, MU, DT);
    assert_eq!(model.name(), "4dof");
    assert_eq!(model.param_count(), 0);
    assert_eq!(model.dt(), DT);
}

#[test]
fn rear_quarter_push_yaws_the_target_with_the_moment() {
    // Push the target's rear quarter sideways at speed (the PIT): the yaw rate must follow
    // the sign of the contact moment, and the initial yaw acceleration must be M_z / I_z.
    for (name, set) in sets() {
        let p = &set.target;
        let mut model = FourDofTarget::new(p, MU, DT);
        let rear = p.length - p.cg_to_front;
        let psi = 0.3;
        let x0 = target_state(20.0, 0.0, psi, 0.0);
        let u = TargetInput::zeros();
        let f_n = 0.5 * p.mass * GRAVITY;
        for side in [1.0, -1.0] {
            // Contact on the side facing the bullet; the normal points into the target.
            let point = Vec2::new(-rear + 0.2, -side * 0.5 * p.width);
            let gamma = psi + side * 0.5 * PI;
            let c = ContactInput {
                fc: Vec2::new(f_n, 0.0),
                gamma,
                point_in_body: point,
            };
            let moment = point.x * side * f_n; // (p × f)_z with f = (0, side·F_n)
            assert!(moment * side < 0.0);
            let d_c = model.derivative(&x0, &u, &c);
            let d_0 = model.derivative(&x0, &u, &ContactInput::none());
            let yaw_acc = d_c[idx::R] - d_0[idx::R];
            assert!(
                (yaw_acc - moment / p.iz).abs() < 1e-9 * (moment / p.iz).abs(),
                "{name}: ṙ from contact {yaw_acc} vs M/I_z {}",
                moment / p.iz
            );
            let (mut xc, mut xf) = (x0, x0);
            for _ in 0..4 {
                xc = model.step(&xc, &u, &c);
                xf = model.step(&xf, &u, &ContactInput::none());
            }
            let dr = xc[idx::R] - xf[idx::R];
            assert!(
                dr * moment > 0.0 && dr.abs() > 0.05,
                "{name}: yaw rate change {dr} after 0.2 s does not follow M_z = {moment}"
            );
            // The push also moves the c.g. toward the side it comes from.
            assert!(
                (xc[idx::VY] - xf[idx::VY]) * side > 0.0,
                "{name}: lateral velocity sign"
            );
        }
    }
}

#[test]
fn steady_turn_roll_matches_the_roll_gradient() {
    // Per the model's sign convention (φ > 0 leans toward +y) a steady left turn gives
    // φ = −m_s h a_y / (K_φ − m_s g h).
    for (name, set) in sets() {
        let p = &neutral(&set.target);
        let mut model = FourDofTarget::new(p, MU, DT);
        let h = p.roll_arm();
        let k_phi = p.roll_stiffness_front + p.roll_stiffness_rear;
        let gradient = -p.sprung_mass * h / (k_phi - p.sprung_mass * GRAVITY * h);
        assert!((model.roll_gradient() - gradient).abs() < 1e-12 * gradient.abs());
        let u = TargetInput::new(0.03, 0.0);
        let mut x = target_state(15.0, 0.0, 0.0, 0.0);
        for _ in 0..(8.0 / DT) as usize {
            x = model.step(&x, &u, &ContactInput::none());
        }
        let d = model.derivative(&x, &u, &ContactInput::none());
        let a_y = d[idx::VY] + x[idx::VX] * x[idx::R];
        let expected = gradient * a_y;
        eprintln!(
            "{name}: a_y = {a_y:.3} m/s², φ = {:.5} rad, expected {expected:.5}",
            x[idx::PHI]
        );
        assert!(a_y > 2.0, "{name}: not a real turn (a_y = {a_y})");
        assert!(
            x[idx::PHI] < 0.0,
            "{name}: the body must lean out of a left turn"
        );
        assert!(
            (x[idx::PHI] - expected).abs() < 0.01 * expected.abs(),
            "{name}: φ = {} vs m_s h a_y / (K_φ − m_s g h) = {expected}",
            x[idx::PHI]
        );
    }
}

#[test]
fn braking_decelerates_at_brake_torque_over_mass_and_radius() {
    for (name, set) in sets() {
        let p = &frictionless(&neutral(&set.target));
        let mut model = FourDofTarget::new(p, MU, DT);
        let tb = 0.5 * p.brake_torque_max;
        let u = TargetInput::new(0.0, tb);
        let expected = tb / (p.mass * p.wheel_radius);
        let mut x = target_state(20.0, 0.0, 1.0, 0.0);
        let steps = (1.0 / DT) as usize;
        for _ in 0..steps {
            x = model.step(&x, &u, &ContactInput::none());
        }
        let decel = (20.0 - x[idx::VX]) / (steps as f64 * DT);
        assert!(
            (decel - expected).abs() < 1e-3 * expected,
            "{name}: {decel} vs {expected}"
        );
        // Keep braking: the car comes to rest and does not reverse; it stays on its line.
        for _ in 0..(20.0 / DT) as usize {
            x = model.step(&x, &u, &ContactInput::none());
            assert!(
                x[idx::VX] >= 0.0,
                "{name}: braking reversed the car: vx = {}",
                x[idx::VX]
            );
        }
        assert!(
            x[idx::VX] < 0.05,
            "{name}: still moving at {} m/s",
            x[idx::VX]
        );
        assert!(x[idx::VY].abs() < 1e-12 && x[idx::R].abs() < 1e-12 && x[idx::PSI] == 1.0);
        assert!(((x[idx::Y]).atan2(x[idx::X]) - 1.0).abs() < 1e-12);
    }
}

#[test]
fn target_at_rest_stays_at_rest_even_when_braked() {
    // In gear too: the stalled engine's hold, like the brake, opposes motion only.
    for (name, set) in sets() {
        let mut model = FourDofTarget::new(&set.target, MU, DT);
        let x = TargetState::from([0.0, 0.0, -2.5, 0.0, 0.0, 0.0, 12.0, -3.0]);
        for tb in [0.0, set.target.brake_torque_max] {
            let u = TargetInput::new(0.0, tb);
            let mut xs = x;
            for _ in 0..100 {
                xs = model.step(&xs, &u, &ContactInput::none());
            }
            assert_eq!(xs, x, "{name}: T_b = {tb} moved a car at rest");
        }
    }
}

#[test]
fn straight_coasting_is_preserved() {
    // No input, no contact, no slip: nothing dissipates or injects energy in neutral; in
    // gear, a throttle that balances the engine braking holds the speed as well.
    for (name, set) in sets() {
        let ideal = frictionless(&set.target);
        for (mut model, tb) in [
            (FourDofTarget::new(&neutral(&ideal), MU, DT), 0.0),
            (
                FourDofTarget::new(&ideal, MU, DT),
                // The engine braking at 25 m/s, i_g T_drag s(25 m/s), balanced.
                -set.target.gear_ratio
                    * set.target.powertrain.as_ref().unwrap().engine_drag_torque
                    * 25.0
                    / (25.0f64.powi(2) + V_BRAKE * V_BRAKE).sqrt(),
            ),
        ] {
            let (v, psi) = (25.0, 0.7);
            let mut x = TargetState::from([v, 0.0, psi, 0.0, 0.0, 0.0, 5.0, 6.0]);
            let steps = 200;
            for _ in 0..steps {
                x = model.step(&x, &TargetInput::new(0.0, tb), &ContactInput::none());
            }
            let t = steps as f64 * DT;
            assert!(
                (x[idx::VX] - v).abs() < 1e-12,
                "{name}: speed drifted to {}",
                x[idx::VX]
            );
            for i in [idx::VY, idx::R, idx::P, idx::PHI] {
                assert!(x[i].abs() < 1e-12, "{name}: state {i} = {}", x[i]);
            }
            assert!((x[idx::PSI] - psi).abs() < 1e-12);
            assert!(
                (x[idx::X] - (5.0 + v * psi.cos() * t)).abs() < 1e-9,
                "{name}: X = {}",
                x[idx::X]
            );
            assert!(
                (x[idx::Y] - (6.0 + v * psi.sin() * t)).abs() < 1e-9,
                "{name}: Y = {}",
                x[idx::Y]
            );
        }
    }
}

#[test]
fn in_gear_the_engine_brakes_and_a_stalled_engine_holds() {
    // Above the stall speed the closed-throttle engine decelerates the car by
    // i_g T_drag / (R_w m); far below it (or rolling backwards) the stalled engine holds the
    // driven axle with i_g T_stall / R_w, and the car comes to rest and stays there.
    for (name, set) in sets() {
        let p = &frictionless(&set.target);
        let pt = p.powertrain.clone().unwrap();
        let mut model = FourDofTarget::new(p, MU, DT);
        let per_nm = p.gear_ratio / (p.wheel_radius * p.mass);
        let v_stall = pt.stall_speed * p.wheel_radius / p.gear_ratio;
        let v0 = v_stall + 8.0;
        let mut x = target_state(v0, 0.0, 0.0, 0.0);
        let steps = (1.0 / DT) as usize;
        for _ in 0..steps {
            x = model.step(&x, &TargetInput::zeros(), &ContactInput::none());
        }
        let decel = (v0 - x[idx::VX]) / (steps as f64 * DT);
        let expect = pt.engine_drag_torque * per_nm;
        assert!(
            (decel - expect).abs() < 5e-3 * expect,
            "{name}: engine braking {decel} vs {expect}"
        );
        // Rolling backwards at 3 m/s: held.
        let mut x = target_state(-3.0, 0.0, 0.0, 0.0);
        model.step(&x, &TargetInput::zeros(), &ContactInput::none());
        let d = model.derivative(&x, &TargetInput::zeros(), &ContactInput::none());
        let expect = pt.stall_torque * per_nm * 3.0 / (9.0f64 + 0.25).sqrt();
        assert!(
            (d[idx::VX] - expect).abs() < 1e-3 * expect,
            "{name}: backwards {} vs {expect}",
            d[idx::VX]
        );
        for _ in 0..(10.0 / DT) as usize {
            x = model.step(&x, &TargetInput::zeros(), &ContactInput::none());
            assert!(
                x[idx::VX] <= 1e-9,
                "{name}: the hold drove the car forwards"
            );
        }
        assert!(
            x[idx::VX].abs() < 0.05,
            "{name}: still rolling at {}",
            x[idx::VX]
        );
    }
}

// ------------------------------------------------------------------------------------------
// Action and reaction.
// ------------------------------------------------------------------------------------------

#[test]
fn contact_momentum_balances_between_bullet_and_target() {
    // The same f_c enters the target as +f_c and the bullet as −f_c, each rotated into its
    // own body frame. The contact's share of the world-frame momentum rates must cancel:
    // m_B R(ψ_B) Δv̇_B + R(ψ_T) (m_T Δv̇x_T, m_T Δv̇y_T + m_s h Δṗ_T) = 0, whatever the
    // headings, speeds and tyre states (the tyre terms do not depend on f_c).
    let mut rng = ChaCha8Rng::seed_from_u64(SEED + 2);
    for (name, set) in sets() {
        let (pb, pt) = (&set.bullet, &set.target);
        let bullet = BulletModel::new(pb, MU, DT);
        let target = FourDofTarget::new(pt, MU, DT);
        let ms_h = pt.sprung_mass * pt.roll_arm();
        for k in 0..50 {
            let (vx, vy, psi, r, x, y) = random_planar(&mut rng);
            let xb = BulletState::new(x, y, psi, vx, vy, r);
            let ub = BulletInput::new(
                uniform(&mut rng, -0.3, 0.3),
                uniform(&mut rng, -100.0, 300.0),
            );
            let (vx, vy, psi, r, x, y) = random_planar(&mut rng);
            let xt = TargetState::from([vx, vy, psi, r, 0.1, -0.02, x, y]);
            let ut = TargetInput::new(uniform(&mut rng, -0.3, 0.3), uniform(&mut rng, 0.0, 500.0));
            let fc = Vec2::new(uniform(&mut rng, 0.0, 2e4), uniform(&mut rng, -8e3, 8e3));
            let gamma = uniform(&mut rng, -PI, PI);
            let cb = ContactInput {
                fc,
                gamma,
                point_in_body: Vec2::new(2.0, 0.3),
            };
            let ct = ContactInput {
                fc,
                gamma,
                point_in_body: Vec2::new(-1.8, -0.7),
            };
            let db = bullet.derivative(&xb, &ub, &cb)
                - bullet.derivative(&xb, &ub, &ContactInput::none());
            let dt = target.derivative(&xt, &ut, &ct)
                - target.derivative(&xt, &ut, &ContactInput::none());
            let rot = |a: f64, v: Vec2| dynamics::geometry::rotate(a, v);
            let pb_rate = rot(xb[2], Vec2::new(db[3], db[4]) * pb.mass);
            let pt_rate = rot(
                xt[idx::PSI],
                Vec2::new(
                    dt[idx::VX] * pt.mass,
                    dt[idx::VY] * pt.mass + ms_h * dt[idx::P],
                ),
            );
            // Each model applies exactly ContactInput::body_force with its sign.
            let (fb, mb) = cb.body_force(xb[2], -1.0);
            let (ft, mt) = ct.body_force(xt[idx::PSI], 1.0);
            let tol = 1e-9 * fc.norm();
            assert!(
                (Vec2::new(db[3], db[4]) * pb.mass - fb).norm() <= tol,
                "{name} #{k}: bullet force"
            );
            assert!(
                (db[5] * pb.iz - mb).abs() <= tol * 3.0,
                "{name} #{k}: bullet moment"
            );
            assert!(
                (dt[idx::R] * pt.iz - mt).abs() <= tol * 3.0,
                "{name} #{k}: target moment"
            );
            assert!(
                (dt[idx::VX] * pt.mass - ft.x).abs() <= tol,
                "{name} #{k}: target F_x"
            );
            let sum = pb_rate + pt_rate;
            assert!(
                sum.norm() <= 1e-9 * fc.norm(),
                "{name} #{k}: momentum rates {pb_rate} + {pt_rate} do not cancel"
            );
            // Each side gets |f_c|, the target along γ's frame.
            assert!((pt_rate - dynamics::geometry::rotate(gamma, fc)).norm() <= 1e-9 * fc.norm());
        }
    }
}
