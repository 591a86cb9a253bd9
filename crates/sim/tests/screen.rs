//! Screening: rules, trivial and impossible scenarios on the plant.

mod common;

use serde_json::json;
use sim::scenario::Scenario;
use sim::screen::{screen, ScreenSettings, Verdict};

fn verdict(v: &serde_json::Value) -> sim::ScreenReport {
    let sc = Scenario::from_json_line(&v.to_string(), 1).unwrap();
    screen(&sc, &ScreenSettings::default()).unwrap()
}

#[test]
fn a_lane_keeping_target_within_reach_is_kept() {
    for v in [common::curved(), common::straight()] {
        let r = verdict(&v);
        assert_eq!(r.verdict, Verdict::Keep, "{r:?}");
        assert!(r.t_fail.is_none() && r.t_stop.is_none());
        assert!(r.t_reach > 0.0 && r.t_reach < 5.0, "{r:?}");
    }
}

#[test]
fn a_target_that_brakes_to_rest_by_itself_is_trivial() {
    let mut v = common::straight();
    v["driver"] = json!({"kind": "brake", "offset": 0.0, "gain": 1.0, "trigger": "start",
                         "delay": 0.5, "fraction": 0.6});
    let r = verdict(&v);
    assert_eq!(r.verdict, Verdict::Trivial, "{r:?}");
    assert!(r.t_stop.unwrap() < 6.0);
    // Braking only after a contact never happens alone: kept.
    v["driver"]["trigger"] = json!("contact");
    assert_eq!(verdict(&v).verdict, Verdict::Keep);
}

#[test]
fn a_target_leaving_the_road_before_the_bullet_arrives_is_impossible() {
    // Hard drift steer on a 1-lane road, bullet 40 m back at the same speed.
    let mut v = common::straight();
    v["road"] = json!({"lanes": 1, "lane_width": 3.5, "shoulder": 0.5, "length": 500.0});
    v["target"]["d"] = json!(0.0);
    v["bullet"]["d"] = json!(0.0);
    v["bullet"]["s"] = json!(20.0);
    v["bullet"]["vx"] = json!(15.0);
    v["driver"] = json!({"kind": "none", "steer": 0.05});
    let lead = ScreenSettings::default().pit_lead;
    let r = verdict(&v);
    assert_eq!(r.verdict, Verdict::Impossible, "{r:?}");
    assert!(r.t_fail.unwrap() < r.t_reach + lead);
    // A slower drift with the bullet right behind and a little faster: it leaves the road
    // only after the bullet could have turned it round (`pit_lead`): kept.
    v["bullet"]["s"] = json!(53.0);
    v["bullet"]["vx"] = json!(16.0);
    v["driver"]["steer"] = json!(0.001);
    let r = verdict(&v);
    assert_eq!(r.verdict, Verdict::Keep, "{r:?}");
    assert!(r.t_fail.unwrap() >= r.t_reach + lead, "{r:?}");
    // Faster, it goes before: the race is lost.
    v["driver"]["steer"] = json!(0.005);
    let r = verdict(&v);
    assert_eq!(r.verdict, Verdict::Impossible, "{r:?}");
}

#[test]
fn the_reach_bound_is_the_controllers_approach_model_where_that_is_slower() {
    // 25 m behind at the target's speed: full acceleration would close in ~3.2 s; the
    // controller's approach (accelerating and braking at 0.25 μ g to arrive at rest beside
    // the target: 2 √(gap / a), plus 0.3 s to settle) takes longer.
    let mut v = common::straight();
    v["bullet"]["s"] = json!(30.0);
    v["bullet"]["vx"] = v["target"]["vx"].clone();
    v["bullet"]["d"] = v["target"]["d"].clone();
    let r = verdict(&v);
    let sc = Scenario::from_json_line(&v.to_string(), 1).unwrap();
    let params = sc.params.load().unwrap();
    let gap = sc.target.s - (params.target.lr + params.bullet.cg_to_front) - sc.bullet.s;
    let a = 0.25 * sc.mu * dynamics::GRAVITY;
    let model = 0.3 + 2.0 * (gap / a).sqrt();
    assert!((r.t_reach - model).abs() < 1e-9, "{} vs {model}", r.t_reach);
}

#[test]
fn a_target_hitting_forward_traffic_first_is_impossible() {
    let mut v = common::straight();
    v["obstacles"] = json!([{"role": "forward_traffic",
        "body": {"x": 75.0, "y": 0.0, "heading": 0.0, "vx": 0.0, "vy": 0.0, "length": 4.5, "width": 1.8}}]);
    v["bullet"]["s"] = json!(20.0);
    let r = verdict(&v);
    assert_eq!(r.verdict, Verdict::Impossible, "{r:?}");
}

#[test]
fn geometry_rules_reject() {
    type Edit = Box<dyn Fn(&mut serde_json::Value)>;
    let cases: Vec<(&str, Edit)> = vec![
        (
            "bullet_not_behind",
            Box::new(|v| v["bullet"]["s"] = json!(70.0)),
        ),
        (
            "target_off_road",
            Box::new(|v| v["target"]["d"] = json!(5.9)),
        ),
        (
            "vehicles_overlap",
            Box::new(|v| {
                v["bullet"]["s"] = json!(58.0);
                v["bullet"]["d"] = json!(0.5);
            }),
        ),
        (
            "target_near_obstacle",
            Box::new(|v| {
                v["obstacles"] = json!([{"role": "roadside",
            "body": {"x": 60.0, "y": 2.0, "heading": 0.0, "vx": 0.0, "vy": 0.0, "length": 1.0, "width": 1.0}}])
            }),
        ),
        (
            "target_too_fast_for_curve",
            Box::new(|v| {
                v["category"] = json!("curved");
                v["road"] = json!({"lanes": 3, "lane_width": 3.5, "shoulder": 1.0, "length": 200.0,
                               "radius": 60.0, "entry": 50.0, "transition": 20.0});
                v["mu"] = json!(0.3);
                v["adhesion"] = json!("low");
            }),
        ),
    ];
    for (rule, edit) in cases {
        let mut v = common::straight();
        edit(&mut v);
        let r = verdict(&v);
        assert_eq!(r.verdict, Verdict::Rejected, "{rule}: {r:?}");
        assert!(r.reason.starts_with(rule), "{rule}: {}", r.reason);
    }
}
