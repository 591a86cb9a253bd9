//! A valid scenario to start tests from.
#![allow(dead_code)]

use dynamics::params::ParamSet;
use dynamics::plant::{Plant, PlantConfig, VehicleInit};
use serde_json::{json, Value};
use sim::scenario::{Scenario, ScenarioError};

/// The `(line, field, message)` of the field error `text` must give at `line`.
pub fn field_error(text: &str, line: usize) -> (usize, String, String) {
    match Scenario::from_json_line(text, line) {
        Err(ScenarioError::Field {
            line,
            field,
            message,
        }) => (line, field, message),
        other => panic!("expected a field error, got {other:?}"),
    }
}

/// A curved full-size scenario: 2 lanes of 3.5 m, R = 200 m left, target in the right
/// lane at 15 m/s keeping its lane, the bullet 8 m behind in the left lane at 18 m/s.
pub fn curved() -> Value {
    json!({
        "id": "test-0001",
        "category": "curved",
        "params": "full_size",
        "prior": "P-test",
        "seed": 7,
        "road": {"lanes": 2, "lane_width": 3.5, "shoulder": 1.0, "length": 600.0,
                 "radius": 200.0, "entry": 50.0, "transition": 30.0},
        "mu": 0.85,
        "adhesion": "high",
        "obstacles": [
            {"role": "roadside", "body": {"x": 30.0, "y": -4.2, "heading": 0.0, "vx": 0.0,
                                           "vy": 0.0, "length": 4.5, "width": 0.5}}
        ],
        "target": {"s": 60.0, "d": -1.75, "heading": 0.0, "vx": 15.0, "vy": 0.0, "r": 0.0},
        "bullet": {"s": 48.0, "d": 1.75, "heading": 0.0, "vx": 18.0, "vy": 0.0, "r": 0.0},
        "driver": {"kind": "lane_keep", "offset": -1.75, "gain": 1.0},
        "t_max": 12.0,
        "eps_psi": 0.35
    })
}

/// A straight 3-lane road scenario with no obstacles.
pub fn straight() -> Value {
    let mut v = curved();
    v["id"] = json!("test-0002");
    v["category"] = json!("straight_urban");
    v["road"] = json!({"lanes": 3, "lane_width": 3.5, "shoulder": 1.0, "length": 500.0});
    v["obstacles"] = json!([]);
    v["target"]["d"] = json!(0.0);
    v["bullet"]["d"] = json!(3.5);
    v["driver"] = json!({"kind": "lane_keep", "offset": 0.0, "gain": 1.0});
    v
}

/// A plant on the scenario's μ with the target at `target` and the bullet parked far away:
/// the target alone, as its driver tests drive it.
pub fn target_alone(sc: &Scenario, params: &ParamSet, target: &VehicleInit) -> Plant {
    let mut plant = Plant::new(
        params,
        PlantConfig {
            mu: sc.mu,
            ..PlantConfig::default()
        },
    )
    .unwrap();
    plant.reset(
        &VehicleInit {
            x: -1e5,
            ..VehicleInit::default()
        },
        target,
    );
    plant
}
