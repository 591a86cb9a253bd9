//! Physics tests of the high-fidelity plant.

use dynamics::params::ParamSet;
use dynamics::plant::{Gear, Plant, PlantConfig, VehicleInit, Which};
use dynamics::GRAVITY;

fn full() -> ParamSet {
    ParamSet::builtin("full_size").unwrap()
}

fn plant(config: PlantConfig) -> Plant {
    Plant::new(&full(), config).unwrap()
}

/// The bullet's front-left corner angled into the target's right rear quarter.
fn pit_start(p: &mut Plant, target_speed: f64, dv: f64) {
    let target = VehicleInit {
        x: 0.0,
        y: 0.0,
        yaw: 0.0,
        vx: target_speed,
        ..Default::default()
    };
    // Bullet behind and to the right, heading 20° towards the target; front-left corner just
    // short of the target's right rear quarter.
    let yaw = 20f64.to_radians();
    let bullet = VehicleInit {
        x: -3.9,
        y: -2.4,
        yaw,
        vx: target_speed + dv,
        ..Default::default()
    };
    p.reset(&bullet, &target);
}

#[test]
fn momentum_is_conserved_through_contact_with_tyres_off() {
    let mut p = plant(PlantConfig {
        tyre_forces: false,
        ..PlantConfig::default()
    });
    pit_start(&mut p, 15.0, 4.0);
    let m0 = p.total_momentum();
    let l0 = p.total_angular_momentum();
    let mut touched = 0;
    for _ in 0..2000 {
        p.step();
        if p.contact().is_some() {
            touched += 1;
        }
    }
    assert!(
        touched > 20,
        "the vehicles must actually touch ({touched} steps)"
    );
    let m1 = p.total_momentum();
    let rel = (m1 - m0).norm() / m0.norm();
    assert!(rel <= 1e-6, "linear momentum drift {rel:e}");
    let l1 = p.total_angular_momentum();
    // Angular momentum about the origin, relative to the scale m |r| |v|.
    let scale = p.mass(Which::Bullet) * 30.0 * 19.0;
    assert!(
        (l1 - l0).abs() / scale <= 1e-6,
        "angular momentum drift {}",
        (l1 - l0).abs() / scale
    );
}

#[test]
fn an_impulse_changes_momentum_by_j_and_angular_momentum_by_r_cross_j() {
    use dynamics::geometry::{cross, Vec2};
    let mut p = plant(PlantConfig::default());
    pit_start(&mut p, 15.0, 2.0);
    let (m0, l0, e0) = (
        p.total_momentum(),
        p.total_angular_momentum(),
        p.planar_kinetic_energy(),
    );
    // A lateral shove at the target's rear quarter, to its right.
    let at = p.body(Which::Target).pos + Vec2::new(-1.9, 0.9);
    let j = Vec2::new(0.0, -2500.0);
    p.apply_impulse(Which::Target, j, at);
    let dm = p.total_momentum() - m0;
    assert!((dm - j).norm() <= 1e-9 * j.norm(), "Δp = {dm:?}, J = {j:?}");
    let dl = p.total_angular_momentum() - l0;
    let expect = cross(at, j);
    assert!(
        (dl - expect).abs() <= 1e-9 * expect.abs().max(1.0),
        "ΔL = {dl}, r × J = {expect}"
    );
    // Pushed right behind the c.g., the target yaws to the left (r > 0) and gains energy.
    assert!(
        p.body(Which::Target).r > 0.5,
        "r = {}",
        p.body(Which::Target).r
    );
    assert!(p.planar_kinetic_energy() > e0);
    // A non-finite impulse is ignored.
    let before = *p.body(Which::Target);
    p.apply_impulse(Which::Target, Vec2::new(f64::NAN, 0.0), at);
    assert_eq!(*p.body(Which::Target), before);
}

#[test]
fn contact_dissipates_and_elastic_contact_nearly_conserves_energy() {
    for (restitution, friction, expect_loss) in [(0.3, 0.4, true), (1.0, 0.0, false)] {
        let mut set = full();
        set.contact.restitution = restitution;
        set.contact.friction = friction;
        // Bumper at the roll axis height and pitch centre so the contact does not pump
        // energy into the suspension (the test is about the contact law).
        let mut p = Plant::new(
            &set,
            PlantConfig {
                tyre_forces: false,
                ..PlantConfig::default()
            },
        )
        .unwrap();
        pit_start(&mut p, 15.0, 4.0);
        let e0 = p.planar_kinetic_energy();
        let mut touched = false;
        for _ in 0..2000 {
            p.step();
            touched |= p.contact().is_some();
        }
        assert!(touched);
        assert!(p.contact().is_none(), "the bodies separate again");
        let e1 = p.planar_kinetic_energy();
        let rel = (e1 - e0) / e0;
        if expect_loss {
            assert!(
                rel < -1e-4,
                "damped, frictional contact must dissipate: {rel:e}"
            );
        } else {
            // No damping and no friction: only the suspension (which is damped) takes energy.
            assert!(
                rel <= 1e-6,
                "elastic contact must not create energy: {rel:e}"
            );
            assert!(
                rel > -0.02,
                "elastic contact must nearly conserve energy: {rel:e}"
            );
        }
    }
}

#[test]
fn contact_forces_are_equal_and_opposite_and_push_apart() {
    let mut p = plant(PlantConfig::default());
    pit_start(&mut p, 15.0, 4.0);
    let mut max_fn: f64 = 0.0;
    let mut seen = None;
    for _ in 0..1500 {
        p.step();
        if let Some(c) = p.contact() {
            assert!(c.fc.x >= 0.0);
            assert!(c.fc.y.abs() <= full().contact.friction * c.fc.x + 1e-9);
            if c.fc.x > max_fn {
                max_fn = c.fc.x;
                seen = Some(c);
            }
        }
    }
    let c = seen.expect("contact");
    // The normal points from the bullet into the target: the target lies to the left of the
    // bullet here, so the normal has a positive Y component.
    assert!(c.gamma.sin() > 0.0, "gamma {}", c.gamma);
    // The contact point lies on the target's right rear quarter.
    assert!(
        c.point_in_target.x < 0.0 && c.point_in_target.y < 0.0,
        "{:?}",
        c.point_in_target
    );
    assert!(max_fn > 1e3, "a PIT push gives kN forces: {max_fn}");
}

#[test]
fn rear_quarter_push_spins_the_target() {
    let mut p = plant(PlantConfig {
        mu: 0.9,
        ..PlantConfig::default()
    });
    pit_start(&mut p, 15.0, 4.0);
    // Keep pushing: steer a little into the target and hold drive torque.
    for _ in 0..1500 {
        p.set_bullet_command(0.08, 400.0);
        p.step();
    }
    let t = p.target_state();
    // A push on the right rear quarter towards the left turns the target clockwise (r < 0).
    assert!(t[2] < -0.5, "target yaw after the push: {}", t[2]);
}

#[test]
fn at_rest_stays_at_rest() {
    let mut p = plant(PlantConfig::default());
    let init = VehicleInit::default();
    let far = VehicleInit {
        x: -50.0,
        ..Default::default()
    };
    p.reset(&far, &init);
    p.advance(5.0);
    for s in [p.bullet_state(), p.bullet_state()] {
        assert!(s.iter().all(|v| v.abs() < 1e-9 || v.abs() == 50.0), "{s:?}");
    }
    let t = p.target_state();
    assert!(t.iter().all(|v| v.abs() < 1e-6), "{t:?}");
}

#[test]
fn coasting_decelerates_by_rolling_resistance_and_drag() {
    // In neutral: the wheels roll freely.
    let set = full();
    let mut p = plant(PlantConfig {
        target_gear: Gear::Neutral,
        ..PlantConfig::default()
    });
    let v0 = 20.0;
    p.reset(
        &VehicleInit {
            x: -100.0,
            vx: v0,
            ..Default::default()
        },
        &VehicleInit {
            x: 100.0,
            vx: v0,
            ..Default::default()
        },
    );
    p.advance(2.0);
    let v = p.target_state()[0];
    let veh = &set.target;
    let f = veh.rolling_resistance * veh.mass * GRAVITY + 0.5 * 1.204 * veh.drag_area * v0 * v0;
    let expect = f / veh.mass * 2.0;
    let got = v0 - v;
    assert!(
        (got - expect).abs() < 0.25 * expect,
        "speed loss {got} vs {expect}"
    );
    // Straight: no lateral drift, no yaw.
    let t = p.target_state();
    assert!(t[1].abs() < 1e-9 && t[2].abs() < 1e-9 && t[7].abs() < 1e-9);
}

#[test]
fn full_braking_stops_the_car_and_holds_it() {
    for mu in [0.9, 0.3] {
        let mut p = plant(PlantConfig {
            mu,
            ..PlantConfig::default()
        });
        let v0 = 20.0;
        p.reset(
            &VehicleInit {
                x: -100.0,
                ..Default::default()
            },
            &VehicleInit {
                x: 0.0,
                vx: v0,
                ..Default::default()
            },
        );
        p.set_target_command(0.0, 1e5);
        p.advance(15.0);
        let t = p.target_state();
        assert!(t[0].abs() < 1e-3, "mu {mu}: stopped, vx {}", t[0]);
        let dist = t[6];
        let ideal = v0 * v0 / (2.0 * mu * GRAVITY);
        // Locked wheels slide with less than peak friction; load sensitivity helps a bit.
        assert!(
            dist > 0.9 * ideal && dist < 1.8 * ideal,
            "mu {mu}: {dist} m vs ideal {ideal} m"
        );
        let x = t[6];
        p.advance(2.0);
        assert!((p.target_state()[6] - x).abs() < 1e-3, "holds still");
    }
}

#[test]
fn steady_left_turn_rolls_outward_and_loads_the_outer_wheels() {
    let mut p = plant(PlantConfig::default());
    p.reset(
        &VehicleInit {
            x: -100.0,
            y: -100.0,
            ..Default::default()
        },
        &VehicleInit {
            vx: 15.0,
            ..Default::default()
        },
    );
    p.set_target_command(0.03, 0.0);
    p.advance(6.0);
    let b = p.body(Which::Target);
    let ay = b.acc_body.y;
    assert!(ay > 1.0, "left turn: lateral acceleration {ay}");
    assert!(
        b.phi < 0.0,
        "rolls outward (c.g. to the right): φ = {}",
        b.phi
    );
    assert!(
        b.fz[1] > b.fz[0] && b.fz[3] > b.fz[2],
        "outer (right) wheels carry more: {:?}",
        b.fz
    );
    // Roll gradient: steady roll = −m_s h a_y / (K_φ − m_s g h).
    let v = &full().target;
    let h = v.roll_arm();
    let k = v.roll_stiffness_front + v.roll_stiffness_rear;
    let phi = -v.sprung_mass * h * ay / (k - v.sprung_mass * GRAVITY * h);
    assert!(
        (b.phi - phi).abs() < 0.05 * phi.abs(),
        "roll {} vs {}",
        b.phi,
        phi
    );
    let total: f64 = b.fz.iter().sum();
    assert!(
        (total - v.mass * GRAVITY).abs() < 1e-6 * total,
        "vertical equilibrium"
    );
}

#[test]
fn plant_is_deterministic() {
    let run = || {
        let mut p = plant(PlantConfig::default());
        pit_start(&mut p, 15.0, 4.0);
        for k in 0..3000 {
            p.set_bullet_command(0.1 * (f64::from(k) * 0.01).sin(), 300.0);
            p.step();
        }
        (p.bullet_state(), p.target_state())
    };
    let (a, b) = run();
    let (c, d) = run();
    assert_eq!(a, c);
    assert_eq!(b, d);
}

#[test]
fn contact_average_matches_impulse() {
    let mut p = plant(PlantConfig::default());
    pit_start(&mut p, 15.0, 4.0);
    let _ = p.take_contact_average();
    let mut impulse = 0.0;
    for _ in 0..50 {
        p.step();
        if let Some(c) = p.contact() {
            impulse += c.fc.x * p.dt();
        }
    }
    // The first 50 ms: may or may not touch; run until they do.
    let mut guard = 0;
    while impulse == 0.0 && guard < 40 {
        let _ = p.take_contact_average();
        for _ in 0..50 {
            p.step();
            if let Some(c) = p.contact() {
                impulse += c.fc.x * p.dt();
            }
        }
        guard += 1;
    }
    let avg = p.take_contact_average().expect("contact in the window");
    assert!(
        (avg.fc.x * 0.05 - impulse).abs() < 1e-9 * impulse.max(1.0),
        "{} vs {}",
        avg.fc.x * 0.05,
        impulse
    );
    assert!(avg.point_in_target.x < 0.0);
}

#[test]
fn bad_config_is_refused() {
    for cfg in [
        PlantConfig {
            dt: 0.01,
            ..PlantConfig::default()
        },
        PlantConfig {
            dt: f64::NAN,
            ..PlantConfig::default()
        },
        PlantConfig {
            mu: -0.1,
            ..PlantConfig::default()
        },
    ] {
        let err = Plant::new(&full(), cfg).unwrap_err().to_string();
        assert!(err.contains("plant."), "{err}");
    }
}

#[test]
fn a_car_driving_into_a_parked_car_is_stopped_by_it() {
    let mut p = plant(PlantConfig::default());
    let obstacle = dynamics::road::Obstacle {
        x: 20.0,
        y: 0.0,
        heading: 0.0,
        vx: 0.0,
        vy: 0.0,
        length: 4.5,
        width: 1.8,
    };
    let rear_of_obstacle = obstacle.x - 0.5 * obstacle.length;
    p.set_obstacles(vec![obstacle]);
    p.reset(
        &VehicleInit {
            x: -60.0,
            y: 20.0,
            ..Default::default()
        },
        &VehicleInit {
            vx: 10.0,
            ..Default::default()
        },
    );
    let front = full().target.cg_to_front;
    let mut hit = false;
    let mut max_depth: f64 = 0.0;
    for _ in 0..4000 {
        p.step();
        if let Some(c) = p.obstacle_contacts()[Which::Target as usize] {
            hit = true;
            assert_eq!(c.obstacle, 0);
            assert!(c.normal_force >= 0.0);
        }
        max_depth = max_depth.max(p.target_state()[6] + front - rear_of_obstacle);
    }
    assert!(hit, "the obstacle contact is reported");
    // A 10 m/s impact into a stiff barrier crushes a few tens of centimetres at most.
    assert!(
        max_depth > 0.0 && max_depth < 0.5,
        "penetration {max_depth} m"
    );
    assert!(
        p.target_state()[0] < 1.0,
        "it does not drive through: vx {}",
        p.target_state()[0]
    );
    assert!(p.obstacle_contacts()[Which::Bullet as usize].is_none());
}

/// Straight braking from 20 m/s with total brake torque `torque` at step `dt`: the times at
/// which the target's speed crosses each of `edges` (falling).
fn braking_crossings(dt: f64, torque: f64, edges: &[f64]) -> Vec<f64> {
    let mut p = plant(PlantConfig {
        dt,
        ..PlantConfig::default()
    });
    p.reset(
        &VehicleInit {
            x: -100.0,
            ..Default::default()
        },
        &VehicleInit {
            vx: 20.0,
            ..Default::default()
        },
    );
    p.set_target_command(0.0, torque);
    let mut times = Vec::new();
    let mut last = (0.0, 20.0);
    while times.len() < edges.len() && p.time() < 20.0 {
        p.step();
        let now = (p.time(), p.target_state()[0]);
        while let Some(&v) = edges.get(times.len()) {
            if now.1 > v {
                break;
            }
            // Linear interpolation between the steps.
            times.push(last.0 + (now.0 - last.0) * (last.1 - v) / (last.1 - now.1));
        }
        last = now;
    }
    assert_eq!(times.len(), edges.len(), "dt {dt}: never slowed to 0.5 m/s");
    times
}

#[test]
fn braking_does_not_depend_on_the_time_step() {
    // Wheel spin and tyre force are solved together: the deceleration in every speed window
    // down to 0.5 m/s at the plant's 1 kHz matches a ten times finer step.
    let edges = [18.0, 15.0, 10.0, 5.0, 2.0, 1.0, 0.5];
    for torque in [1500.0, 3000.0] {
        let coarse = braking_crossings(1e-3, torque, &edges);
        let fine = braking_crossings(1e-4, torque, &edges);
        for i in 0..edges.len() - 1 {
            let dv = edges[i] - edges[i + 1];
            let (a, b) = (
                dv / (coarse[i + 1] - coarse[i]),
                dv / (fine[i + 1] - fine[i]),
            );
            assert!(
                (a - b).abs() <= 0.03 * b,
                "{torque} N m, {}–{} m/s: {a:.3} m/s² at 1 ms vs {b:.3} at 0.1 ms",
                edges[i],
                edges[i + 1]
            );
        }
    }
}

#[test]
fn a_braked_vehicle_at_rest_stays_at_rest() {
    for dt in [1e-3, 1e-4] {
        let mut p = plant(PlantConfig {
            dt,
            ..PlantConfig::default()
        });
        p.reset(
            &VehicleInit {
                x: -100.0,
                ..Default::default()
            },
            &VehicleInit::default(),
        );
        p.set_target_command(0.0, 3000.0);
        p.advance(3.0);
        let t = p.target_state();
        assert!(
            t[0].abs() < 1e-9 && t[1].abs() < 1e-9 && t[6].abs() < 1e-9,
            "dt {dt}: crept {t:?}"
        );
        let body = p.body(Which::Target);
        assert!(
            body.omega.iter().all(|w| *w == 0.0),
            "wheels {:?}",
            body.omega
        );
    }
}

/// The target straight ahead at `v0`, driver off the controls, after `seconds`: its speed.
fn coast(gear: Gear, v0: f64, seconds: f64) -> (f64, bool) {
    let mut p = plant(PlantConfig {
        target_gear: gear,
        ..PlantConfig::default()
    });
    p.reset(
        &VehicleInit {
            x: -100.0,
            ..Default::default()
        },
        &VehicleInit {
            vx: v0,
            ..Default::default()
        },
    );
    p.advance(seconds);
    (p.target_state()[0], p.body(Which::Target).stalled)
}

#[test]
fn closed_throttle_engine_braking_lies_in_the_published_range() {
    // Fuel cut-off motoring mep of a petrol engine is 2–3 bar (friction and pumping;
    // Heywood 1988, ch. 13): for the 1.99 L engine 32–48 N m, through the engaged gear
    // i_g / (R_w m_eff) of deceleration. In gear the target slows by that much more than in
    // neutral, and it equals the file's T_drag within the rounding of the wheel dynamics.
    let veh = full().target;
    let pt = veh.powertrain.clone().unwrap();
    // The mass the axle torque accelerates includes the four wheels' spin inertia.
    let m_eff = veh.mass + 4.0 * veh.wheel_inertia / (veh.wheel_radius * veh.wheel_radius);
    let per_nm = veh.gear_ratio / (veh.wheel_radius * m_eff);
    let (band_lo, band_hi) = (32.0 * per_nm, 48.0 * per_nm);
    let seconds = 3.0;
    let (v_gear, stalled) = coast(Gear::Forward, 20.0, seconds);
    let (v_neutral, _) = coast(Gear::Neutral, 20.0, seconds);
    assert!(!stalled, "the engine runs at 20 m/s");
    let extra = (v_neutral - v_gear) / seconds;
    assert!(
        (band_lo..=band_hi).contains(&extra),
        "engine braking {extra:.3} m/s² outside [{band_lo:.3}, {band_hi:.3}]"
    );
    let expect = pt.engine_drag_torque * per_nm;
    assert!(
        (extra - expect).abs() < 0.05 * expect,
        "{extra:.4} vs {expect:.4} m/s²"
    );
}

#[test]
fn rolling_below_the_stall_speed_stalls_the_engine_and_holds_the_car() {
    // 3 m/s in the engaged gear turns the engine at 3/R_w·i_g ≈ 35 rad/s, below its stall
    // speed: it stalls, and the held axle stops the car where a car in neutral rolls on.
    let (v_gear, stalled) = coast(Gear::Forward, 3.0, 3.0);
    assert!(stalled);
    assert!(v_gear.abs() < 1e-3, "still rolling at {v_gear}");
    let (v_neutral, stalled) = coast(Gear::Neutral, 3.0, 3.0);
    assert!(!stalled && v_neutral > 2.0, "neutral: {v_neutral}");
}

/// A rear-quarter push at `speed` + `dv` for `push` s, then the bullet steers away and
/// brakes; returns (time and speed when the target first reached a reversed heading, time it
/// came to rest, its speed at `probe` s, stalled at the end).
fn spin(
    gear: Gear,
    speed: f64,
    dv: f64,
    push: f64,
    probe: f64,
) -> (f64, f64, Option<f64>, f64, bool) {
    let mut p = plant(PlantConfig {
        target_gear: gear,
        ..PlantConfig::default()
    });
    pit_start(&mut p, speed, dv);
    let (mut reversed, mut rest, mut probed) = (None, None, f64::NAN);
    while p.time() < 15.0 {
        if p.time() < push {
            p.set_bullet_command(0.08, 400.0);
        } else {
            p.set_bullet_command(-0.1, 0.0);
            p.set_brake(Which::Bullet, 3000.0);
        }
        p.step();
        let t = p.target_state();
        let v = t[0].hypot(t[1]);
        if reversed.is_none() && t[2].abs() > 2.6 {
            reversed = Some((p.time(), v));
        }
        if rest.is_none() && reversed.is_some() && v < 0.05 {
            rest = Some(p.time());
        }
        if (p.time() - probe).abs() < 0.5e-3 {
            probed = v;
        }
    }
    let (t_rev, v_rev) = reversed.expect("the push reverses the target");
    (t_rev, v_rev, rest, probed, p.body(Which::Target).stalled)
}

#[test]
fn a_target_spun_round_in_gear_stalls_and_comes_to_rest_within_the_bound() {
    // Bound: once reversed, the target rolls backwards on a stalled engine, which holds its
    // driven axle with i_g T_stall; with rolling resistance that alone decelerates it at
    //   a_min = i_g T_stall / (R_w m) + f_r g   (≈ 1.72 m/s² for full_size),
    // and the tyres scrubbing sideways in the spin only add to it. So it is at rest within
    // v_rev / a_min of reversing (7 s at 12 m/s). In neutral nothing holds it: it still
    // rolls at that time.
    let veh = full().target;
    let pt = veh.powertrain.clone().unwrap();
    let a_min = veh.gear_ratio * pt.stall_torque / (veh.wheel_radius * veh.mass)
        + veh.rolling_resistance * GRAVITY;
    for (speed, dv, push) in [(15.0, 3.0, 0.8), (17.0, 3.0, 1.0), (20.0, 3.0, 1.0)] {
        let (t_rev, v_rev, rest, _, stalled) = spin(Gear::Forward, speed, dv, push, 0.0);
        let bound = v_rev / a_min;
        let rest = rest.expect("in gear the target comes to rest");
        assert!(stalled, "{speed} m/s: the engine stalls");
        assert!(
            rest - t_rev <= bound,
            "{speed} m/s: at rest {:.2} s after reversing at {v_rev:.1} m/s, bound {bound:.2} s",
            rest - t_rev
        );
        let (_, _, _, rolling, stalled) = spin(Gear::Neutral, speed, dv, push, t_rev + bound);
        assert!(!stalled);
        assert!(
            rolling > 0.5,
            "{speed} m/s: neutral rolls on ({rolling:.2} m/s)"
        );
    }
}

#[test]
fn a_contact_the_step_cannot_resolve_is_refused_and_the_stiffest_accepted_one_is_sound() {
    let mut set = full();
    set.contact.stiffness = 1e8;
    let err = Plant::new(&set, PlantConfig::default())
        .unwrap_err()
        .to_string();
    assert!(
        err.starts_with("contact.stiffness") && err.contains("plant step"),
        "{err}"
    );
    // The stiffest accepted contact (within 10 %), elastic and frictionless with tyres off:
    // it neither creates energy nor loses momentum.
    set.contact.restitution = 1.0;
    set.contact.friction = 0.0;
    let config = PlantConfig {
        tyre_forces: false,
        ..PlantConfig::default()
    };
    set.contact.stiffness = 4e5;
    while Plant::new(&set, config).is_ok() {
        set.contact.stiffness *= 1.1;
    }
    set.contact.stiffness /= 1.1;
    assert!(set.contact.stiffness > 4e6, "{}", set.contact.stiffness);
    let mut p = Plant::new(&set, config).unwrap();
    pit_start(&mut p, 15.0, 4.0);
    let (e0, m0) = (p.planar_kinetic_energy(), p.total_momentum());
    let mut touched = false;
    for _ in 0..2000 {
        p.step();
        touched |= p.contact().is_some();
    }
    assert!(touched && p.contact().is_none());
    let rel = (p.planar_kinetic_energy() - e0) / e0;
    assert!(
        (-0.02..=1e-6).contains(&rel),
        "stiffest contact: energy change {rel:e}"
    );
    assert!((p.total_momentum() - m0).norm() / m0.norm() <= 1e-6);
}

/// The bullet's ABS (`abs_slip`, full size 0.15): braking at its full service-brake torque
/// from 20 m/s on dry asphalt, no wheel locks while the car rolls
/// faster than `ABS_MIN_SPEED`, the car keeps its heading (a yaw disturbance of 0.05 rad/s
/// dies out) and slows at more than 0.85 μ g once the brakes are on.
/// The same car without ABS locks its rear wheels (its brake bias, 0.66 front, over-brakes the
/// unloaded rear axle above ~0.8 μ g) and turns away.
#[test]
fn the_bullets_abs_keeps_its_wheels_turning_and_its_heading_under_full_braking() {
    let mu = 0.9;
    let run = |abs_slip: f64| -> (f64, bool, f64) {
        let mut params = full();
        params.bullet.abs_slip = abs_slip;
        let mut p = Plant::new(
            &params,
            PlantConfig {
                mu,
                ..PlantConfig::default()
            },
        )
        .unwrap();
        p.reset(
            &VehicleInit {
                vx: 20.0,
                r: 0.05,
                ..Default::default()
            },
            &VehicleInit {
                x: 1e4,
                ..Default::default()
            },
        );
        p.set_bullet_command(0.0, 0.0);
        p.set_brake(Which::Bullet, params.bullet.brake_torque_max);
        let mut locked = false;
        // The mean deceleration from 0.3 s (the brake's lag) to 1.5 s.
        p.advance(0.3);
        let v0 = p.bullet_state()[3];
        for _ in 0..12 {
            p.advance(0.1);
            locked |= p.body(Which::Bullet).omega.contains(&0.0);
        }
        let decel = (v0 - p.bullet_state()[3]) / 1.2;
        assert!(p.bullet_state()[3] > dynamics::plant::ABS_MIN_SPEED + 1.0);
        (p.bullet_state()[2].abs(), locked, decel)
    };
    let (yaw, locked, decel) = run(0.15);
    assert!(!locked, "with ABS no wheel locks");
    assert!(
        yaw < 3f64.to_radians(),
        "with ABS it keeps its heading: {yaw} rad"
    );
    assert!(
        decel > 0.85 * mu * GRAVITY,
        "with ABS it slows at {decel} m/s²"
    );
    let (yaw_off, locked_off, _) = run(0.0);
    assert!(locked_off, "without ABS a wheel locks");
    assert!(
        yaw_off > 3.0 * yaw,
        "without ABS it turns away: {yaw_off} against {yaw} rad"
    );
}
