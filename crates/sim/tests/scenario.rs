//! The scenario schema: round trip, typed errors naming line and field, helpers.

mod common;

use serde_json::json;
use sim::scenario::{parse_jsonl, Scenario, ScenarioError};

#[test]
fn a_scenario_round_trips() {
    for v in [common::curved(), common::straight()] {
        let sc = Scenario::from_json_line(&v.to_string(), 1).unwrap();
        let line = sc.to_json_line();
        let back = Scenario::from_json_line(&line, 1).unwrap();
        assert_eq!(sc, back);
        assert_eq!(line, back.to_json_line());
    }
}

#[test]
fn a_file_with_a_bad_line_names_the_line_and_the_field() {
    let good = common::curved();
    let mut second = common::straight();
    second["mu"] = json!(3.0);
    let text = format!("{good}\n\n{second}\n");
    let err = parse_jsonl(&text).unwrap_err();
    let msg = err.to_string();
    assert!(
        matches!(err, ScenarioError::Field { line: 3, ref field, .. } if field == "mu"),
        "{msg}"
    );
    assert!(msg.starts_with("line 3: mu:"), "{msg}");
}

#[test]
fn missing_unknown_and_mistyped_fields_are_named() {
    let mut v = common::curved();
    v.as_object_mut().unwrap().remove("eps_psi");
    let (line, field, msg) = common::field_error(&v.to_string(), 5);
    assert_eq!((line, field.as_str()), (5, "eps_psi"), "{msg}");

    let mut v = common::curved();
    v["road"].as_object_mut().unwrap().remove("lanes");
    assert_eq!(common::field_error(&v.to_string(), 1).1, "road.lanes");

    let mut v = common::curved();
    v["target"]["spin"] = json!(1.0);
    assert_eq!(common::field_error(&v.to_string(), 1).1, "target.spin");

    let mut v = common::curved();
    v["obstacles"][0]["body"]["width"] = json!("wide");
    let (_, field, msg) = common::field_error(&v.to_string(), 1);
    assert_eq!(field, "obstacles[0].body.width", "{msg}");

    let mut v = common::curved();
    v["obstacles"][0]["body"]["width"] = json!(-1.0);
    assert_eq!(
        common::field_error(&v.to_string(), 1).1,
        "obstacles[0].body.width"
    );

    let mut v = common::curved();
    v["driver"]["kind"] = json!("swerve");
    assert_eq!(common::field_error(&v.to_string(), 1).1, "driver.kind");

    let mut v = common::curved();
    v["category"] = json!("roundabout");
    assert_eq!(common::field_error(&v.to_string(), 1).1, "category");
}

#[test]
fn ranges_and_consistency_are_checked() {
    type Edit = Box<dyn Fn(&mut serde_json::Value)>;
    let cases: Vec<(&str, Edit)> = vec![
        ("mu", Box::new(|v| v["mu"] = json!(0.0))),
        ("adhesion", Box::new(|v| v["adhesion"] = json!("low"))),
        (
            "road.radius",
            Box::new(|v| v["category"] = json!("straight_highway")),
        ),
        ("target.d", Box::new(|v| v["target"]["d"] = json!(9.0))),
        ("bullet.vx", Box::new(|v| v["bullet"]["vx"] = json!(-2.0))),
        ("t_max", Box::new(|v| v["t_max"] = json!(0.0))),
        ("eps_psi", Box::new(|v| v["eps_psi"] = json!(2.0))),
        (
            "road.radius",
            Box::new(|v| v["road"]["radius"] = json!(3.0)),
        ),
        (
            "road.length",
            Box::new(|v| v["road"]["length"] = json!(150.0)),
        ),
        (
            "driver.gain",
            Box::new(|v| v["driver"]["gain"] = json!(0.0)),
        ),
        ("id", Box::new(|v| v["id"] = json!(""))),
    ];
    for (field, edit) in cases {
        let mut v = common::curved();
        edit(&mut v);
        let (_, got, msg) = common::field_error(&v.to_string(), 2);
        assert_eq!(got, field, "{msg}");
    }
}

#[test]
fn not_json_is_a_syntax_error_with_the_line() {
    let err = Scenario::from_json_line("{\"id\": ", 9).unwrap_err();
    assert!(
        matches!(err, ScenarioError::Syntax { line: 9, .. }),
        "{err}"
    );
    let text = format!("{}\n{{oops\n", common::curved());
    assert!(matches!(
        parse_jsonl(&text),
        Err(ScenarioError::Syntax { line: 2, .. })
    ));
}

#[test]
fn duplicate_ids_are_refused() {
    let v = common::curved();
    let text = format!("{v}\n{v}\n");
    assert!(matches!(
        parse_jsonl(&text),
        Err(ScenarioError::DuplicateId {
            line: 2,
            first: 1,
            ..
        })
    ));
}

#[test]
fn load_jsonl_reports_io_and_empty_files() {
    let dir = std::env::temp_dir().join(format!("picopit-sim-test-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let empty = dir.join("empty.jsonl");
    std::fs::write(&empty, "\n\n").unwrap();
    assert!(matches!(
        sim::load_jsonl(&empty),
        Err(ScenarioError::Empty { .. })
    ));
    assert!(matches!(
        sim::load_jsonl(dir.join("missing.jsonl")),
        Err(ScenarioError::Io { .. })
    ));
    let ok = dir.join("ok.jsonl");
    std::fs::write(
        &ok,
        format!("{}\n{}\n", common::curved(), common::straight()),
    )
    .unwrap();
    assert_eq!(sim::load_jsonl(&ok).unwrap().len(), 2);
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn initial_states_follow_the_road() {
    let sc = Scenario::from_json_line(&common::curved().to_string(), 1).unwrap();
    let road = sc.build_road().unwrap();
    let x = sc.target_state(&road);
    // s = 60 m is 10 m into the clothoid: heading κ'σ²/2 = (1/200)/30 · 100 / 2.
    let heading = 1.0 / 200.0 / 30.0 * 100.0 / 2.0;
    assert!((x[2] - heading).abs() < 1e-9, "{}", x[2]);
    let p = road.project(dynamics::geometry::Vec2::new(x[6], x[7]));
    assert!((p.s - 60.0).abs() < 1e-6 && (p.d + 1.75).abs() < 1e-6);
    let b = sc.bullet_state(&road);
    assert!((b[3] - 18.0).abs() < 1e-12);
}

#[test]
fn a_lane_keeping_target_stays_in_its_lane_on_the_curve() {
    let sc = Scenario::from_json_line(&common::curved().to_string(), 1).unwrap();
    let params = sc.params.load().unwrap();
    let road = sc.build_road().unwrap();
    let (_, ti) = sc.initial_states(&road);
    let mut plant = common::target_alone(&sc, &params, &ti);
    let mut driver = sc.target_driver(&params);
    let mut worst: f64 = 0.0;
    for k in 0..200 {
        let x = plant.target_state();
        let (d, b) = driver.command(k as f64 * 0.05, None, &x, &road);
        plant.set_target_command(d, b);
        plant.advance(0.05);
        let x = plant.target_state();
        let f = road.project(dynamics::geometry::Vec2::new(x[6], x[7]));
        worst = worst.max((f.d + 1.75).abs());
    }
    // 10 s, through the clothoid into the arc: within 0.5 m of the lane centre.
    assert!(worst < 0.5, "lane error {worst}");
}

/// Every kind of driver holds the target's initial speed with the throttle until the first
/// contact (in gear, against engine braking, rolling resistance and drag; on the curve and
/// on the straight road), within ±0.5 m/s over 5 s, and lets go of it after the contact.
#[test]
fn before_the_contact_every_driver_holds_its_speed() {
    for (road_kind, base) in [
        ("curved", common::curved()),
        ("straight", common::straight()),
    ] {
        for driver in [
            json!({"kind": "none", "steer": 0.0}),
            json!({"kind": "lane_keep", "offset": -1.75, "gain": 1.0}),
            json!({"kind": "brake", "offset": -1.75, "gain": 1.0, "trigger": "contact", "delay": 0.3, "fraction": 0.4}),
            json!({"kind": "counter_steer", "offset": -1.75, "gain": 1.0, "delay": 0.3, "steer_gain": 0.25, "max_steer": 0.25}),
        ] {
            let mut v = base.clone();
            v["driver"] = driver.clone();
            let sc = Scenario::from_json_line(&v.to_string(), 1).unwrap();
            let params = sc.params.load().unwrap();
            let road = sc.build_road().unwrap();
            let (_, ti) = sc.initial_states(&road);
            let mut plant = common::target_alone(&sc, &params, &ti);
            let mut d = sc.target_driver(&params);
            let mut worst: f64 = 0.0;
            for k in 0..100 {
                let x = plant.target_state();
                let (steer, tb) = d.command(k as f64 * 0.05, None, &x, &road);
                assert!(
                    tb < 0.0,
                    "{road_kind} {driver}: on the throttle before the contact"
                );
                plant.set_target_command(steer, tb);
                plant.advance(0.05);
                worst = worst.max((plant.target_state()[0] - ti.vx).abs());
            }
            assert!(
                worst < 0.5,
                "{road_kind} {driver}: speed off by {worst:.2} m/s"
            );
            let x = plant.target_state();
            let (_, tb) = d.command(5.0, Some(4.9), &x, &road);
            assert!(
                tb >= 0.0,
                "{road_kind} {driver}: off the throttle after the contact"
            );
        }
    }
}

/// The counter-steering driver slows the yaw whichever way the car rolls: over 1.5 s from a
/// yaw rate of 0.4 rad/s at 8 m/s it turns the car less than a driver off the controls, rolling
/// forwards and rolling backwards (after a spin). The bare law `δ = −gain · r`, without the
/// turn with the direction of travel, steers a car rolling backwards into its spin.
#[test]
fn a_counter_steering_driver_slows_the_yaw_rolling_forwards_and_backwards() {
    use dynamics::plant::VehicleInit;
    let mut v = common::straight();
    v["driver"] = json!({"kind": "counter_steer", "offset": 0.0, "gain": 1.0, "delay": 0.3,
                         "steer_gain": 0.4, "max_steer": 0.3});
    let sc = Scenario::from_json_line(&v.to_string(), 1).unwrap();
    let params = sc.params.load().unwrap();
    let road = sc.build_road().unwrap();
    let (_, ti) = sc.initial_states(&road);
    // The yaw turned in 1.5 s from `vx`, r = 0.4 rad/s, with the steer law `law` (None: the
    // driver's own) and no pedals.
    let turned = |vx: f64, law: Option<fn(f64) -> f64>| -> f64 {
        let mut plant = common::target_alone(&sc, &params, &VehicleInit { vx, r: 0.4, ..ti });
        let mut driver = sc.target_driver(&params);
        let psi0 = plant.target_state()[2];
        for k in 0..30 {
            let x = plant.target_state();
            let (own, tb) = driver.command(1.0 + k as f64 * 0.05, Some(0.0), &x, &road);
            assert!(
                tb.abs() < 1e-12,
                "a counter-steering driver leaves the pedals"
            );
            let steer = law.map_or(own, |f| f(x[3]));
            plant.set_target_command(steer, 0.0);
            plant.advance(0.05);
        }
        (plant.target_state()[2] - psi0).abs()
    };
    let hands_off: fn(f64) -> f64 = |_| 0.0;
    let bare: fn(f64) -> f64 = |r| (-0.4 * r).clamp(-0.3, 0.3);
    for vx in [8.0, -8.0] {
        let (cs, off) = (turned(vx, None), turned(vx, Some(hands_off)));
        assert!(
            cs < 0.9 * off,
            "vx {vx}: counter-steer turned {cs:.3} rad, hands off {off:.3} rad"
        );
    }
    let (bare_back, off_back) = (turned(-8.0, Some(bare)), turned(-8.0, Some(hands_off)));
    assert!(
        bare_back > off_back,
        "rolling backwards the bare law turned {bare_back:.3} rad, hands off {off_back:.3} rad"
    );
}

/// A lane-keeping target spun round by a push, rolling backwards at 8 m/s with its heading
/// 7° off the reversed one (its course drifting towards the right edge), keeps steering for
/// its lane in the direction it travels: over 3 s it strays less far from its lane than a
/// driver off the controls, who lets the car roll on along its course towards the edge.
#[test]
fn a_lane_keeping_driver_steers_a_car_rolling_backwards_by_its_course() {
    use dynamics::plant::VehicleInit;
    let v = common::straight();
    let sc = Scenario::from_json_line(&v.to_string(), 1).unwrap();
    let params = sc.params.load().unwrap();
    let road = sc.build_road().unwrap();
    let (_, ti) = sc.initial_states(&road);
    let heading = ti.yaw + std::f64::consts::PI - 0.12;
    // The lateral offset from the lane (d, offset 0) after 3 s from the spun state, with the
    // driver's own steer or none; the pedals left alone, the engine stalled in gear.
    let drift = |hands_off: bool| -> f64 {
        let init = VehicleInit {
            yaw: heading,
            vx: -8.0,
            r: 0.0,
            ..ti
        };
        let mut plant = common::target_alone(&sc, &params, &init);
        let mut driver = sc.target_driver(&params);
        let mut worst: f64 = 0.0;
        for k in 0..60 {
            let x = plant.target_state();
            let (own, tb) = driver.command(5.0 + k as f64 * 0.05, Some(1.0), &x, &road);
            assert!(tb.abs() < 1e-12, "off the throttle after the contact");
            plant.set_target_command(if hands_off { 0.0 } else { own }, 0.0);
            plant.advance(0.05);
            let x = plant.target_state();
            let f = road.project(dynamics::geometry::Vec2::new(x[6], x[7]));
            worst = worst.max(f.d.abs());
        }
        worst
    };
    let (kept, off) = (drift(false), drift(true));
    assert!(
        kept < 0.7 * off && off > 1.0,
        "lane keeping drifted {kept:.2} m, hands off {off:.2} m"
    );
}
