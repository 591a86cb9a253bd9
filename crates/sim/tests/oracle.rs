//! The ideal-PIT bound (`sim::oracle`): a shove saves a scene only through the physics of the
//! spin, never by itself.

mod common;

use sim::oracle::{ideal_pit, shove_grid, DriverView, OracleSettings};
use sim::scenario::Scenario;

fn scenario(v: &serde_json::Value) -> Scenario {
    Scenario::from_json_line(&v.to_string(), 1).unwrap()
}

fn shoves(dv: &[f64]) -> OracleSettings {
    OracleSettings {
        shoves: dv.to_vec(),
        time_step: 0.5,
        ..OracleSettings::default()
    }
}

/// A lane-keeping target on a dry straight road at 15 m/s: a 2–3 m/s shove on the rear
/// quarter spins it round inside the road, but a shove of nothing leaves it driving on, and
/// the screening kept the scene because alone it never ends reversed.
#[test]
fn a_rear_quarter_shove_saves_a_dry_straight_scene_and_no_shove_does_not() {
    let sc = scenario(&common::straight());
    let none = ideal_pit(&sc, &shoves(&[0.0])).unwrap();
    assert!(none.feasible.is_none(), "{none:?}");
    assert!(none.tried > 10, "every candidate time is tried: {none:?}");
    assert!(none.alone_fails_at.is_none(), "{none:?}");

    let r = ideal_pit(&sc, &shoves(&[2.0, 2.5, 3.0])).unwrap();
    let s = r
        .feasible
        .unwrap_or_else(|| panic!("no shove worked: {r:?}"));
    assert!(
        s.time + 1e-9 >= r.t_reach,
        "shove before the bullet can be there: {r:?}"
    );
    assert!(s.decided_at > s.time + 1.0, "a spin takes time: {s:?}");
    assert!(s.side == 1.0 || s.side == -1.0);
}

/// Half scale at walking pace (the dataset's first half-scale scene: 100 kg target at
/// 1.9 m/s on μ 0.61): no single shove up to 2 m/s spins it round. Turning a car 180° about
/// its c.g. drags its axles π l_f and π l_r sideways against μ F_z, about
/// 0.61 · 981 N · π · 0.95 m ≈ 1.8 kJ, while the target and the largest shove bring
/// ½ · 100 kg · (1.9² + 2²) m²/s² ≈ 0.4 kJ.
#[test]
fn half_scale_at_walking_pace_cannot_be_spun_round_by_a_shove() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../data/scenarios.jsonl");
    let all = sim::load_jsonl(path).unwrap();
    let sc = all.iter().find(|s| s.id == "sc-00064").unwrap();
    assert_eq!(sc.params.name(), "half_scale");
    let r = ideal_pit(sc, &shoves(&[0.5, 1.0, 2.0])).unwrap();
    assert!(r.feasible.is_none(), "{r:?}");
    assert!(r.tried > 0, "{r:?}");
}

#[test]
fn bad_settings_are_refused_naming_the_field() {
    let sc = scenario(&common::straight());
    for (settings, field) in [
        (shoves(&[]), "oracle.shoves"),
        (shoves(&[f64::NAN]), "oracle.shoves"),
        (
            OracleSettings {
                time_step: 0.0,
                ..shoves(&[1.0])
            },
            "oracle.time_step",
        ),
        (
            OracleSettings {
                sides: vec![0.5],
                ..shoves(&[1.0])
            },
            "oracle.sides",
        ),
        (
            OracleSettings {
                window: Some([3.0, 1.0]),
                ..shoves(&[1.0])
            },
            "oracle.window",
        ),
    ] {
        let err = ideal_pit(&sc, &settings).unwrap_err().to_string();
        assert!(err.contains(field), "{err}");
    }
}

/// The grid holds exactly the shoves the search tries, and the search's first success is
/// the grid's earliest.
#[test]
fn the_shove_grid_agrees_with_the_search() {
    let sc = scenario(&common::straight());
    let settings = OracleSettings {
        exhaustive: true,
        ..shoves(&[1.5, 2.0, 2.5, 3.0])
    };
    let r = ideal_pit(&sc, &settings).unwrap();
    let g = shove_grid(&sc, &settings, DriverView::True).unwrap();
    assert_eq!(g.success.len(), r.tried);
    assert_eq!(g.success.len(), g.times.len() * 2 * 4);
    assert_eq!(g.success.iter().filter(|&&b| b).count(), r.successes);
    assert!(r.successes > 0, "{r:?}");
    assert!(
        g.times.windows(2).all(|w| (w[1] - w[0] - 0.5).abs() < 1e-9),
        "{:?}",
        g.times
    );
    let (f, c) = (r.feasible.unwrap(), g.earliest().unwrap());
    assert_eq!(
        (f.time, f.side, f.dv),
        (g.times[c.time], g.sides[c.side], g.shoves[c.shove])
    );
}

/// Holding the driver's command at the shove is not knowing its law: a driver who brakes
/// hard once hit stops the spun target where a held command (the throttle it had before the
/// contact) keeps driving it.
#[test]
fn holding_the_command_is_not_knowing_the_drivers_law() {
    let settings = shoves(&[1.5, 2.0, 2.5, 3.0]);
    let mut v = common::straight();
    v["driver"] = serde_json::json!({"kind": "brake", "offset": -1.75, "gain": 1.0,
        "trigger": "contact", "delay": 0.0, "fraction": 1.0});
    let sc = scenario(&v);
    let truth = shove_grid(&sc, &settings, DriverView::True).unwrap();
    let held = shove_grid(&sc, &settings, DriverView::Held).unwrap();
    assert_eq!(truth.times, held.times);
    assert_ne!(
        truth.success, held.success,
        "the driver's braking matters after a shove"
    );
}

/// The dataset's sc-00184 (straight urban road, the target in the left lane 2.0 m from the
/// edge, braking after the contact): a shove on its left side spins it round inside the
/// road, but no bullet fits beside it there, so with the bullet's room checked that side
/// saves nothing; on its right side, where a bullet fits, the check changes nothing.
#[test]
fn a_shove_counts_only_from_a_side_where_a_bullet_fits_inside_the_road() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../data/scenarios.jsonl");
    let all = sim::load_jsonl(path).unwrap();
    let sc = all.iter().find(|s| s.id == "sc-00184").unwrap();
    assert_left_blocked_right_unchanged(sc, [3.0, 4.5]);
}

/// With shoves of 1–3 m/s over `window`: the left side saves the scene when the bullet's
/// room is not checked and nothing when it is (the same candidates tried); the right side
/// is tried and the check changes nothing there.
fn assert_left_blocked_right_unchanged(sc: &Scenario, window: [f64; 2]) {
    let side = |sides: &[f64], beside: bool| OracleSettings {
        sides: sides.to_vec(),
        bullet_beside: beside,
        exhaustive: true,
        time_step: 0.25,
        window: Some(window),
        ..shoves(&[1.0, 1.5, 2.0, 2.5, 3.0])
    };
    let left_free = ideal_pit(sc, &side(&[1.0], false)).unwrap();
    assert!(left_free.successes > 0, "{left_free:?}");
    let left = ideal_pit(sc, &side(&[1.0], true)).unwrap();
    assert_eq!(left.tried, left_free.tried, "{left:?}");
    assert_eq!(left.successes, 0, "{left:?}");
    assert!(left.feasible.is_none());
    let right_free = ideal_pit(sc, &side(&[-1.0], false)).unwrap();
    let right = ideal_pit(sc, &side(&[-1.0], true)).unwrap();
    assert!(right.tried > 0, "{right:?}");
    assert_eq!(right, right_free);
}

/// A post in the lane to the target's left, level with its rear quarter at the moment of
/// the shove, leaves no room for a bullet on that side then: with the bullet's room checked
/// the left side saves nothing, although its shoves alone (no bullet in the way; the target
/// spins away ahead of the post) save the scene; on the right side, where a bullet fits,
/// the check changes nothing.
#[test]
fn a_shove_counts_only_from_a_side_clear_of_obstacles() {
    let mut v = common::straight();
    // The target in the middle lane (d = 0) holds 15 m/s: at 3.5 s its c.g. is at x = 112.5
    // m, and a bullet flush against its left side, front at the contact point, covers
    // x ≈ 106–111 m, d ≈ 0.85–2.55 m.
    v["obstacles"] = serde_json::json!([
        {"role": "roadside", "body": {"x": 108.5, "y": 1.7, "heading": 0.0, "vx": 0.0,
                                       "vy": 0.0, "length": 0.4, "width": 0.4}}
    ]);
    assert_left_blocked_right_unchanged(&scenario(&v), [3.45, 3.55]);
}
