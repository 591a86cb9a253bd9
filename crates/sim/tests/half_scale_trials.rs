//! The half-scale trial cases (`data/trials/half_scale.jsonl`, the paper's R1–R4) in process
//! with the half-scale controller settings (`configs/controller_half_scale.toml`): R1
//! succeeds on a fixed seed without sensing noise, and the measured impact (relative speed
//! of the two centres of gravity and heading difference at the first plant contact) is
//! sane. The clock is simulated, so the episodes are reproducible (the solvers' wall-clock
//! limits are lifted). What does not work yet (R2–R4, sensing noise) is in
//! `docs/planner.md`, "Half scale".

use sim::episode::{run_episode, ClockKind, EpisodeConfig};
use sim::Scenario;
use std::path::PathBuf;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..")
}

fn trials() -> Vec<Scenario> {
    sim::load_jsonl(root().join("data/trials/half_scale.jsonl")).expect("the trial file loads")
}

/// The preset as the benchmark runs it: its half-scale settings are the built-in file's.
fn config() -> EpisodeConfig {
    let mut c = EpisodeConfig::preset("picopinn").unwrap();
    c.models_dir = root().join("models");
    c.clock = ClockKind::Simulated;
    c
}

fn case(id: &str) -> Scenario {
    trials()
        .into_iter()
        .find(|s| s.id == id)
        .unwrap_or_else(|| panic!("case {id} in the trial file"))
}

#[test]
fn half_scale_scenes_run_with_the_half_scale_settings_file() {
    let text = std::fs::read_to_string(root().join("configs/controller_half_scale.toml"))
        .expect("the settings file exists");
    let file = planner::ControllerSettings::from_toml_str(&text).expect("valid settings");
    let c = config();
    assert_eq!(
        c.controller_for(sim::scenario::ParamSetName::HalfScale),
        &file
    );
    assert_eq!(
        c.controller_for(sim::scenario::ParamSetName::FullSize),
        &planner::ControllerSettings::default()
    );
    assert_ne!(file, planner::ControllerSettings::default());
    // The ablation switches the upper layer off for both.
    let no_upper = EpisodeConfig::preset("picopinn_no_upper").unwrap();
    assert!(!no_upper.controller_half_scale.upper_layer && !no_upper.controller.upper_layer);
    // A JSON override reaches the half-scale settings by their own key, and is validated.
    let j = EpisodeConfig::from_json(
        r#"{"preset": "picopinn", "controller_half_scale": {"planner": {"heading_tol": 0.2}}}"#,
    )
    .unwrap();
    assert!((j.controller_half_scale.planner.heading_tol - 0.2).abs() < 1e-12);
    assert_eq!(j.controller_half_scale.mpc, file.mpc);
    let bad = EpisodeConfig::from_json(
        r#"{"preset": "picopinn", "controller_half_scale": {"planner": {"heading_tol": -1.0}}}"#,
    )
    .unwrap_err();
    assert!(bad.to_string().contains("controller_half_scale"), "{bad}");
}

#[test]
fn the_trial_file_holds_r1_to_r4_at_half_scale_and_the_paper_speeds() {
    let t = trials();
    let ids: Vec<&str> = t.iter().map(|s| s.id.as_str()).collect();
    assert_eq!(ids, ["R1", "R2", "R3", "R4"]);
    for s in &t {
        assert_eq!(s.params, sim::scenario::ParamSetName::HalfScale);
        let kmh = s.target.vx * 3.6;
        assert!((7.5..=8.5).contains(&kmh), "{}: target {kmh} km/h", s.id);
        assert!(s.bullet.vx > s.target.vx, "{}: the bullet closes in", s.id);
    }
}

/// As in the paper's table, R1 and R3 succeed and R4 does not: the half-scale settings push
/// the slow target round (`push_round`). R4 and R2 (which the paper saves) end with the
/// target stopped part of the way round, held by its braking driver (docs/planner.md, "Half
/// scale").
#[test]
fn r1_and_r3_reverse_the_target_and_r4_does_not() {
    for (id, saved) in [("R1", true), ("R3", true), ("R4", false)] {
        let m = run_episode(&case(id), &config(), 0).unwrap().metrics;
        assert_eq!(m.success, saved, "{id}: {m:?}");
        assert!(
            !m.boundary_violation && !m.secondary_collision,
            "{id}: {m:?}"
        );
    }
}

#[test]
fn r1_turns_the_target_safely_with_a_sane_impact() {
    let r = run_episode(&case("R1"), &config(), 0).unwrap();
    let m = r.metrics;
    assert!(
        m.terminal_heading_error < std::f64::consts::PI - 30f64.to_radians(),
        "R1 barely turned the target: {m:?}"
    );
    assert!(!m.boundary_violation && !m.secondary_collision, "R1: {m:?}");
    let v = m.impact_speed.expect("R1 makes contact");
    let a = m.impact_angle.expect("R1 makes contact");
    // A contact from behind and beside: a relative speed of a few km/h and an angle well
    // short of a T-bone.
    assert!((0.1..3.0).contains(&v), "impact speed {v} m/s");
    assert!(
        (5f64.to_radians()..35f64.to_radians()).contains(&a),
        "impact angle {a} rad"
    );
    // The first touch lands on the target's rear half, on its side rather than its rear
    // face (at this scale it lands 0.18 m ahead of the rear axle, not behind it).
    let t = sim::scenario::ParamSetName::HalfScale
        .load()
        .unwrap()
        .target;
    let [x, y] = m.impact_point.expect("R1 makes contact");
    let rear = t.cg_to_front - t.length;
    assert!(
        rear - 0.02 < x && x < 0.0,
        "impact x {x} m (rear bumper {rear})"
    );
    assert!(
        y.abs() > 0.4 * t.width && y.abs() < 0.5 * t.width + 0.05,
        "impact y {y} m, width {}",
        t.width
    );
    // Reversed (within ε_ψ) at some point: the reversal time and the speed kept through the spin.
    if let (Some(tr), Some(vr)) = (m.reversed_at, m.reversed_speed) {
        let v0 = case("R1").target.vx;
        assert!(
            tr > 0.0 && tr <= m.decided_at.unwrap() + 1e-9,
            "reversed at {tr} s"
        );
        assert!(
            (0.0..v0).contains(&vr),
            "speed {vr} m/s at reversal from {v0} m/s"
        );
    }
}

#[test]
fn r4_the_weak_case_makes_contact_and_its_impact_is_measured() {
    let r = run_episode(&case("R4"), &config(), 0).unwrap();
    let m = r.metrics;
    assert!(m.contacts >= 1, "{m:?}");
    let v = m.impact_speed.expect("R4 makes contact");
    let a = m.impact_angle.expect("R4 makes contact");
    assert!(
        v.is_finite() && (0.0..3.0).contains(&v),
        "impact speed {v} m/s"
    );
    assert!(
        a.is_finite() && a < 45f64.to_radians(),
        "impact angle {a} rad"
    );
}

#[test]
fn no_contact_leaves_the_impact_unmeasured() {
    // One second is too short for the bullet to reach the target.
    let mut sc = case("R3");
    sc.t_max = 1.0;
    let r = run_episode(&sc, &config(), 0).unwrap();
    assert_eq!(r.metrics.contacts, 0);
    assert_eq!(r.metrics.impact_speed, None);
    assert_eq!(r.metrics.impact_angle, None);
    assert_eq!(r.metrics.impact_point, None);
    assert_eq!(r.metrics.reversed_at, None);
    assert_eq!(r.metrics.reversed_speed, None);
}
