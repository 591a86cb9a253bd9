//! The 4-DOF analytic model agrees with the plant in gentle driving and departs from it in a
//! PIT push (the model mismatch the learned surrogates are meant to close). Numbers:
//! `cargo run --release -p picopit-dynamics --example plant_vs_4dof`, recorded in docs/plant.md.

use dynamics::compare::{lane_change, pit_push};
use dynamics::params::ParamSet;

#[test]
fn close_in_a_gentle_lane_change() {
    let set = ParamSet::builtin("full_size").unwrap();
    let a = lane_change(&set, 0.9, 20.0, 0.02);
    assert!(
        a.peak_yaw_rate > 0.05,
        "the manoeuvre must actually turn: {a:?}"
    );
    assert!(a.max_position_error < 0.5, "{a:?}");
    assert!(a.max_heading_error < 0.01, "{a:?}");
    assert!(a.rms_yaw_rate_error < 0.05 * a.peak_yaw_rate, "{a:?}");
}

#[test]
fn clearly_apart_in_a_pit_push() {
    let set = ParamSet::builtin("full_size").unwrap();
    let gentle = lane_change(&set, 0.9, 20.0, 0.02);
    let push = pit_push(&set, 0.9, 15.0, 4.0);
    assert!(push.peak_sideslip > 0.5, "high slip: {push:?}");
    assert!(
        push.max_position_error > 0.75 || push.max_heading_error > 0.1,
        "{push:?}"
    );
    assert!(
        push.max_position_error > 3.0 * gentle.max_position_error,
        "{push:?} vs {gentle:?}"
    );
    assert!(
        push.one_step_velocity_error > 5.0 * gentle.one_step_velocity_error,
        "{push:?} vs {gentle:?}"
    );
}
