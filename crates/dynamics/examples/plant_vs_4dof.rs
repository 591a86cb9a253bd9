//! Prints how far the 4-DOF analytic target model is from the plant, in a gentle lane change
//! and in PIT pushes. `cargo run --release -p picopit-dynamics --example plant_vs_4dof`
use dynamics::compare::{lane_change, pit_push, Agreement};
use dynamics::params::ParamSet;

fn row(name: &str, a: &Agreement) {
    println!(
        "| {name} | {:.3} | {:.3} | {:.3} / {:.3} | {:.3} | {:.4} | {:.4} | {:.3} |",
        a.max_position_error,
        a.max_heading_error,
        a.rms_yaw_rate_error,
        a.peak_yaw_rate,
        a.peak_sideslip,
        a.one_step_position_error,
        a.one_step_heading_error,
        a.one_step_velocity_error
    );
}

fn main() {
    let set = ParamSet::builtin("full_size").expect("built-in set");
    println!("| manoeuvre (full_size) | max pos err (m) | max heading err (rad) | RMS r err / peak r (rad/s) | peak sideslip (rad) | 1-step pos err (m) | 1-step heading err (rad) | 1-step vel err (m/s) |");
    println!("|---|---|---|---|---|---|---|---|");
    row(
        "lane change 20 m/s, 0.02 rad, mu 0.9",
        &lane_change(&set, 0.9, 20.0, 0.02),
    );
    row(
        "lane change 15 m/s, 0.03 rad, mu 0.5",
        &lane_change(&set, 0.5, 15.0, 0.03),
    );
    row(
        "PIT push 15 m/s + 4 m/s, mu 0.9",
        &pit_push(&set, 0.9, 15.0, 4.0),
    );
    row(
        "PIT push 20 m/s + 3 m/s, mu 0.5",
        &pit_push(&set, 0.5, 20.0, 3.0),
    );
}
