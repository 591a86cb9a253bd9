//! The success test and the single first failure cause.

use dynamics::geometry::{Obb, Pose2};
use dynamics::road::{Obstacle, Road};
use dynamics::TargetState;
use sim::outcome::{FailureCause, JudgeSettings, Monitor, Observation, Outcome, Status};
use std::f64::consts::PI;

const DT: f64 = 0.05;

/// 3 lanes of 3.5 m + 1 m shoulders: edges at y = ±6.25.
fn road() -> Road {
    Road::straight(500.0, 3, 3.5, 1.0)
}

fn monitor(obstacles: Vec<Obstacle>) -> Monitor {
    Monitor::new(road(), obstacles, 0.35, 10.0, JudgeSettings::full_size()).unwrap()
}

fn fp(x: f64, y: f64, yaw: f64) -> Obb {
    Obb::vehicle_footprint(&Pose2::new(x, y, yaw), 4.5, 1.6, 2.1)
}

/// Target at (x, y, yaw) with speed v and yaw rate r; bullet parked well inside the road.
fn obs(t: f64, x: f64, y: f64, yaw: f64, v: f64, r: f64) -> Observation {
    Observation {
        time: t,
        target: TargetState::from([v, 0.0, yaw, r, 0.0, 0.0, x, y]),
        footprints: [fp(x - 20.0, 0.0, 0.0), fp(x, y, yaw)],
        vehicle_contact: false,
        closing_speed: 0.0,
        obstacle_contact: [false, false],
    }
}

fn run_until_done(m: &mut Monitor, mut f: impl FnMut(f64) -> Observation) -> Outcome {
    for k in 1..=400 {
        if let Status::Done(o) = m.observe(&f(k as f64 * DT)) {
            return o;
        }
    }
    panic!("never decided");
}

/// The episode ran to its end undecided.
#[track_caller]
fn assert_no_termination(o: &Outcome) {
    assert!(
        matches!(
            o,
            Outcome::Failure {
                cause: FailureCause::NoTermination,
                ..
            }
        ),
        "{o:?}"
    );
}

/// The episode failed on an unsafe rebound at `at` s.
#[track_caller]
fn assert_rebound_at(o: &Outcome, at: f64) {
    assert!(
        matches!(o, Outcome::Failure { cause: FailureCause::UnsafeRebound, time } if (time - at).abs() < 1e-9),
        "{o:?}"
    );
}

#[test]
fn a_target_reversed_and_at_rest_succeeds_after_the_dwell() {
    let mut m = monitor(vec![]);
    // Spinning down for 1 s, then at rest reversed (ψ = π + 0.2 within ε = 0.35).
    let o = run_until_done(&mut m, |t| {
        if t < 1.0 {
            obs(t, 50.0, 0.0, PI * t, 5.0, 2.0)
        } else {
            obs(t, 50.0, 0.0, PI + 0.2, 0.1, 0.02)
        }
    });
    match o {
        Outcome::Success { time } => assert!((time - 1.5).abs() < 1e-9, "{time}"),
        other => panic!("{other:?}"),
    }
    let me = m.metrics();
    assert!(me.success && me.at_rest && me.cause.is_none());
    assert!((me.terminal_heading_error - 0.2).abs() < 1e-9);
    assert!(me.min_margin > 0.0 && !me.boundary_violation && !me.secondary_collision);
    // First within ε_ψ of π while still spinning: ψ = 0.9 π at t = 0.9 s (error 0.31 rad),
    // at 5 m/s; the later observations do not overwrite it.
    assert!(
        (me.reversed_at.unwrap() - 0.9).abs() < 1e-9,
        "{:?}",
        me.reversed_at
    );
    assert!((me.reversed_speed.unwrap() - 5.0).abs() < 1e-12);
}

#[test]
fn either_direction_of_spin_counts_but_a_wrong_heading_does_not() {
    for yaw in [PI - 0.3, -PI + 0.3, 3.0 * PI + 0.1, -5.0 * PI] {
        let mut m = monitor(vec![]);
        let o = run_until_done(&mut m, |t| obs(t, 50.0, 0.0, yaw, 0.0, 0.0));
        assert!(matches!(o, Outcome::Success { .. }), "yaw {yaw}: {o:?}");
    }
    // At rest but only turned 90°: no success, and at T_max no termination.
    let mut m = monitor(vec![]);
    let o = run_until_done(&mut m, |t| obs(t, 50.0, 0.0, PI / 2.0, 0.0, 0.0));
    assert_eq!(
        o,
        Outcome::Failure {
            cause: FailureCause::NoTermination,
            time: 10.0
        }
    );
    assert!((m.metrics().terminal_heading_error - PI / 2.0).abs() < 1e-9);
}

#[test]
fn reversed_but_still_rolling_succeeds_only_at_t_max_and_not_at_rest() {
    // Rolling backwards at 1 m/s, reversed throughout: not at rest, so nothing is decided
    // before T_max; at T_max it has been reversed for longer than the dwell: settled.
    let mut m = monitor(vec![]);
    let o = run_until_done(&mut m, |t| obs(t, 50.0 - 1.0 * t, 0.0, PI, 1.0, 0.0));
    match o {
        Outcome::Success { time } => assert!((time - 10.0).abs() < 1e-9, "{time}"),
        other => panic!("{other:?}"),
    }
    assert!(m.metrics().success && !m.metrics().at_rest);

    // Reversed only for the last 0.3 s (< dwell 0.5 s): a target spinning into the band
    // as time runs out has not settled.
    let mut m = monitor(vec![]);
    let o = run_until_done(&mut m, |t| {
        let yaw = if t < 9.7 - 1e-9 { PI / 2.0 } else { PI };
        obs(t, 50.0 - 1.0 * t, 0.0, yaw, 1.0, 0.0)
    });
    assert_no_termination(&o);

    // Spinning through the reversed heading at 1 rad/s: in the band (±0.35 rad) for 0.7 s
    // around t = 9.5 s but out of it at T_max.
    let mut m = monitor(vec![]);
    let o = run_until_done(&mut m, |t| obs(t, 50.0, 0.0, PI + (t - 9.5), 3.0, 1.0));
    assert_no_termination(&o);

    // Reversed and rolling, but it rolls over the road edge before T_max.
    let mut m = monitor(vec![]);
    let o = run_until_done(&mut m, |t| obs(t, 50.0, 1.0 * t, PI, 1.0, 0.0));
    assert!(
        matches!(
            o,
            Outcome::Failure {
                cause: FailureCause::BoundaryViolation,
                ..
            }
        ),
        "{o:?}"
    );

    // Coming to rest reversed is decided at once and flagged at rest.
    let mut m = monitor(vec![]);
    let o = run_until_done(&mut m, |t| obs(t, 50.0, 0.0, PI, (2.0 - t).max(0.0), 0.0));
    match o {
        Outcome::Success { time } => assert!(time < 3.0, "{time}"),
        other => panic!("{other:?}"),
    }
    assert!(m.metrics().at_rest);
}

#[test]
fn a_footprint_over_the_edge_is_a_boundary_violation() {
    let mut m = monitor(vec![]);
    // The target drifts left at 1 m/s from y = 3: its left corners (half width 0.8) reach
    // the edge at y = 6.25 when the c.g. is at 5.45, i.e. after 2.45 s.
    let o = run_until_done(&mut m, |t| obs(t, 50.0, 3.0 + t, 0.0, 10.0, 0.0));
    match o {
        Outcome::Failure { cause, time } => {
            assert_eq!(cause, FailureCause::BoundaryViolation);
            assert!((time - 2.5).abs() < 1e-9, "{time}");
        }
        other => panic!("{other:?}"),
    }
    let me = m.metrics();
    assert!(me.boundary_violation && !me.success && me.min_margin < 0.0);
    assert_eq!(me.failed_vehicle, Some(sim::outcome::Party::Target));
    // Frozen after the decision.
    let after = m.observe(&obs(3.0, 50.0, 0.0, PI, 0.0, 0.0));
    assert_eq!(after, Status::Done(o));
    assert_eq!(m.metrics(), me);
}

#[test]
fn a_rotated_footprint_crossing_the_edge_is_caught_by_its_corner() {
    let mut m = monitor(vec![]);
    // c.g. at y = 5.0 (1.25 m inside), yawed 60°: the front corner reaches past y = 6.25.
    let st = m.observe(&obs(DT, 50.0, 5.0, PI / 3.0, 5.0, 0.0));
    assert!(matches!(
        st,
        Status::Done(Outcome::Failure {
            cause: FailureCause::BoundaryViolation,
            ..
        })
    ));
}

#[test]
fn touching_an_obstacle_is_a_secondary_collision() {
    let parked = Obstacle {
        x: 60.0,
        y: 0.0,
        heading: 0.0,
        vx: 0.0,
        vy: 0.0,
        length: 4.5,
        width: 1.8,
    };
    let mut m = monitor(vec![parked]);
    // The target rolls toward the parked car at 5 m/s from x = 40.
    let o = run_until_done(&mut m, |t| obs(t, 40.0 + 5.0 * t, 0.0, 0.0, 5.0, 0.0));
    assert!(
        matches!(
            o,
            Outcome::Failure {
                cause: FailureCause::SecondaryCollision,
                ..
            }
        ),
        "{o:?}"
    );
    assert!(m.metrics().secondary_collision);
    // A reported obstacle contact of the bullet counts too.
    let mut m = monitor(vec![]);
    let mut ob = obs(DT, 50.0, 0.0, 0.0, 5.0, 0.0);
    ob.obstacle_contact = [true, false];
    assert!(matches!(
        m.observe(&ob),
        Status::Done(Outcome::Failure {
            cause: FailureCause::SecondaryCollision,
            ..
        })
    ));
    assert_eq!(
        m.metrics().failed_vehicle,
        Some(sim::outcome::Party::Bullet)
    );
}

#[test]
fn the_first_cause_wins() {
    let parked = Obstacle {
        x: 60.0,
        y: 5.5,
        heading: 0.0,
        vx: 0.0,
        vy: 0.0,
        length: 4.5,
        width: 1.0,
    };
    // The same observation crosses the edge and hits the obstacle: boundary first (order).
    let mut m = monitor(vec![parked.clone()]);
    let st = m.observe(&obs(DT, 60.0, 5.8, 0.0, 5.0, 0.0));
    assert!(matches!(
        st,
        Status::Done(Outcome::Failure {
            cause: FailureCause::BoundaryViolation,
            ..
        })
    ));
    assert!(m.metrics().boundary_violation && m.metrics().secondary_collision);

    // Infeasible decision first, then a boundary violation: the decision stays.
    let mut m = monitor(vec![]);
    m.observe(&obs(DT, 50.0, 0.0, 0.0, 10.0, 0.0));
    assert!(matches!(
        m.decision_infeasible(0.1),
        Status::Done(Outcome::Failure {
            cause: FailureCause::DecisionInfeasible,
            ..
        })
    ));
    let st = m.observe(&obs(0.15, 50.0, 6.0, 0.0, 10.0, 0.0));
    assert!(matches!(
        st,
        Status::Done(Outcome::Failure {
            cause: FailureCause::DecisionInfeasible,
            ..
        })
    ));
    assert!(!m.metrics().boundary_violation);

    // An obstacle hit at 1 s, a boundary crossing later: secondary collision.
    let mut m = monitor(vec![parked]);
    let o = run_until_done(&mut m, |t| {
        if t < 1.0 {
            obs(t, 40.0, 0.0, 0.0, 5.0, 0.0)
        } else {
            obs(t, 60.0, 4.9, 0.0, 5.0, 0.0)
        }
    });
    assert!(
        matches!(o, Outcome::Failure { cause: FailureCause::SecondaryCollision, time } if (time - 1.0).abs() < 1e-9),
        "{o:?}"
    );
}

fn contact_obs(t: f64, touching: bool, closing: f64) -> Observation {
    let mut o = obs(t, 50.0, 0.0, 0.5 * t, 8.0, 0.5);
    o.vehicle_contact = touching;
    o.closing_speed = closing;
    o
}

#[test]
fn a_hard_recontact_in_stabilisation_is_an_unsafe_rebound() {
    // Push 1.0–1.2 s; apart; touch again at 2.0 s at 3 m/s closing.
    let mut m = monitor(vec![]);
    let o = run_until_done(&mut m, |t| {
        let touching = (1.0..1.25).contains(&t) || (2.0..2.1).contains(&t);
        contact_obs(t, touching, if t > 1.9 { 3.0 } else { 4.0 })
    });
    assert_rebound_at(&o, 2.0);
    assert_eq!(m.metrics().contacts, 2);

    // The same with a gentle re-contact (0.5 m/s): no rebound.
    let mut m = monitor(vec![]);
    let o = run_until_done(&mut m, |t| {
        let touching = (1.0..1.25).contains(&t) || (2.0..2.1).contains(&t);
        contact_obs(t, touching, if t > 1.9 { 0.5 } else { 4.0 })
    });
    assert_no_termination(&o);
    assert_eq!(m.metrics().contacts, 2);

    // Chatter within 0.3 s is one episode (a push), never a rebound.
    let mut m = monitor(vec![]);
    let o = run_until_done(&mut m, |t| {
        let touching = (1.0..1.1).contains(&t) || (1.25..1.4).contains(&t);
        contact_obs(t, touching, 4.0)
    });
    assert_no_termination(&o);
    assert_eq!(m.metrics().contacts, 1);

    // A second push before the controller enters stabilisation is allowed; one after is not.
    let mut m = monitor(vec![]);
    m.enter_stabilisation(3.0);
    let o = run_until_done(&mut m, |t| {
        let touching =
            (1.0..1.25).contains(&t) || (2.0..2.1).contains(&t) || (3.5..3.6).contains(&t);
        contact_obs(t, touching, 3.0)
    });
    assert_rebound_at(&o, 3.5);
    assert_eq!(m.metrics().contacts, 3);
}

/// A target going straight at 8 m/s, not turning; the bullet touching it as given.
fn unspun(t: f64, touching: bool, closing: f64) -> Observation {
    let mut o = obs(t, 50.0 + 8.0 * t, 0.0, 0.0, 8.0, 0.0);
    o.vehicle_contact = touching;
    o.closing_speed = closing;
    o
}

/// Observe `f` from step 1 to step `to` (inclusive), expecting no decision.
fn run_to(m: &mut Monitor, from: usize, to: usize, f: impl Fn(f64) -> Observation) {
    for k in from..=to {
        assert!(
            matches!(m.observe(&f(k as f64 * DT)), Status::Running),
            "decided at {} s",
            k as f64 * DT
        );
    }
}

#[test]
fn a_push_tried_again_on_an_unspun_target_is_a_first_contact() {
    // A brush at 1.0–1.1 s that does not turn the target; a second push at 2.5 s at 3 m/s.
    let touching = |t: f64| (1.0..1.1).contains(&t) || (2.5..2.9).contains(&t);
    let f = |t: f64| unspun(t, touching(t), 3.0);
    // Without a word from the controller the second push is a rebound (the first contact
    // episode has ended).
    let mut m = monitor(vec![]);
    let o = run_until_done(&mut m, f);
    assert_rebound_at(&o, 2.5);
    // The controller went back to chasing at 1.5 s: the second push is a first contact.
    let mut m = monitor(vec![]);
    run_to(&mut m, 1, 30, f);
    assert!(m.push_retried());
    let o = run_until_done(&mut m, |t| f(t + 1.5));
    assert_no_termination(&o);
    assert_eq!(m.metrics().contacts, 2);
    // A third hard contact after the second push has ended is a rebound again.
    let mut m = monitor(vec![]);
    run_to(&mut m, 1, 30, f);
    assert!(m.push_retried());
    let third = |t: f64| {
        let on = touching(t) || (3.5..3.6).contains(&t);
        unspun(t, on, 3.0)
    };
    let o = run_until_done(&mut m, |t| third(t + 1.5));
    assert_rebound_at(&o, 3.5);
}

#[test]
fn a_push_tried_again_is_refused_once_the_target_spins_or_stabilisation_began() {
    // The first contact set the target yawing at 0.6 rad/s: a retry would hide a rebound.
    let mut m = monitor(vec![]);
    run_to(&mut m, 1, 30, |t| {
        let mut o = unspun(t, (1.0..1.1).contains(&t), 3.0);
        if t >= 1.1 {
            o.target[3] = 0.6;
            o.target[2] = 0.6 * (t - 1.1);
        }
        o
    });
    assert!(!m.push_retried());
    // Turned 0.4 rad (past `retry_turn`) though no longer yawing.
    let mut m = monitor(vec![]);
    run_to(&mut m, 1, 30, |t| {
        let mut o = unspun(t, (1.0..1.1).contains(&t), 3.0);
        if t >= 1.2 {
            o.target[2] = 0.4;
        }
        o
    });
    assert!(!m.push_retried());
    // No contact yet: nothing to try again.
    let mut m = monitor(vec![]);
    run_to(&mut m, 1, 30, |t| unspun(t, false, 0.0));
    assert!(!m.push_retried());
    // In stabilisation.
    let mut m = monitor(vec![]);
    run_to(&mut m, 1, 30, |t| unspun(t, (1.0..1.1).contains(&t), 3.0));
    m.enter_stabilisation(1.4);
    assert!(!m.push_retried());
}

#[test]
fn bad_settings_are_refused() {
    let mut s = JudgeSettings::full_size();
    s.dwell = -1.0;
    let e = Monitor::new(road(), vec![], 0.35, 10.0, s).unwrap_err();
    assert_eq!(e.field, "dwell");
    assert!(Monitor::new(road(), vec![], f64::NAN, 10.0, JudgeSettings::full_size()).is_err());
}
