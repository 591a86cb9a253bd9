//! Scenarios that parse but must not run: a key named twice (JSON keeps the last silently)
//! and an obstacle that overlaps a vehicle at t = 0.

mod common;

use serde_json::json;
use sim::scenario::Scenario;

#[test]
fn a_key_named_twice_is_refused_with_its_path() {
    let good = common::curved().to_string();
    assert!(Scenario::from_json_line(&good, 1).is_ok());
    // At the top level (serde_json would have run on the second μ).
    let twice = good.replacen('{', r#"{"mu": 0.2, "#, 1);
    let (line, field, message) = common::field_error(&twice, 4);
    assert_eq!((line, field.as_str()), (4, "mu"), "{message}");
    assert!(message.contains("twice"), "{message}");
    // Deeper down.
    let twice = good.replacen(r#""lanes":"#, r#""lanes": 2, "lanes":"#, 1);
    let (_, field, _) = common::field_error(&twice, 1);
    assert_eq!(field, "road.lanes");
}

#[test]
fn an_obstacle_on_a_vehicle_at_the_start_is_refused() {
    let mut v = common::curved();
    let sc = Scenario::from_json_line(&v.to_string(), 1).unwrap();
    let road = sc.build_road().unwrap();
    let (bullet, target) = sc.initial_states(&road);
    for (who, at) in [("target", target), ("bullet", bullet)] {
        v["obstacles"] = json!([
            {"role": "roadside", "body": {"x": at.x + 200.0, "y": at.y, "heading": 0.0,
             "vx": 0.0, "vy": 0.0, "length": 0.4, "width": 0.4}},
            {"role": "roadside", "body": {"x": at.x + 0.5, "y": at.y, "heading": 0.3,
             "vx": 0.0, "vy": 0.0, "length": 0.4, "width": 0.4}},
        ]);
        let (_, field, message) = common::field_error(&v.to_string(), 2);
        assert_eq!(field, "obstacles[1].body", "{message}");
        assert_eq!(message, format!("overlaps the {who} at t = 0"));
    }
    // Beside the target, clear of it, is fine.
    v["obstacles"] = json!([
        {"role": "roadside", "body": {"x": target.x, "y": target.y + 3.0, "heading": 0.0,
         "vx": 0.0, "vy": 0.0, "length": 0.4, "width": 0.4}},
    ]);
    assert!(Scenario::from_json_line(&v.to_string(), 1).is_ok());
}
