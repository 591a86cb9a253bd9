//! The decision layer on scripted situations: the package is consistent, obstacles change
//! the decision, no feasible decision is reported with its reason, and the search is
//! deterministic; judging a push, and the closed loop's test that a push has done its work
//! (the chase's situations are in `chase.rs`).

use dynamics::bullet::BulletState;
use dynamics::geometry::{rotate, Vec2};
use dynamics::road::{Obstacle, Road};
use dynamics::{TargetInput, TargetState};
use planner::decision::wrap;
mod common;

use common::{input, params, planner, road, states};
use planner::{DecisionPackage, Infeasible, Mode, PhaseSettings, PlannerSettings, Release};

fn check_consistent(p: &DecisionPackage, s: &PlannerSettings, force_max: f64) {
    let n = s.steps();
    assert_eq!(p.steps.len(), n + 1);
    for w in p.steps.windows(2) {
        assert!((w[1].time - w[0].time - s.dt).abs() < 1e-9);
    }
    assert!((p.steps[0].time - p.time).abs() < 1e-12);
    // The terminal set contains the reversed heading of the lane (heading 0 here).
    assert!(
        (wrap(p.terminal.heading - std::f64::consts::PI)).abs() < 1e-9,
        "{:?}",
        p.terminal
    );
    for st in &p.steps {
        let f = st.force;
        assert!(
            f.x >= -1e-6 && f.x <= force_max + 1e-6,
            "F_n {} outside [0, {force_max}]",
            f.x
        );
        assert!(f.y.abs() <= s.friction * f.x + 1e-6, "friction cone: {f:?}");
        assert!(st.corridor.0 <= st.corridor.1 + 1e-9);
        assert!(st.corridor.1 <= force_max + 1e-6);
        let inside = p.has_window() && st.time >= p.window.0 - 1e-9 && st.time < p.window.1 - 1e-9;
        if !inside {
            assert_eq!(f.x, 0.0, "a force outside the window at t={}", st.time);
            assert_eq!(st.corridor, (0.0, 0.0));
        }
    }
    if p.mode == Mode::Pit {
        // The contact point is one of those tried along the rear quarter.
        let rq = mpc::reference::rear_quarter_x(&params());
        assert!(
            s.contact_offsets
                .iter()
                .any(|o| (p.contact_point.x - (rq + o)).abs() < 1e-9),
            "contact point {:?}",
            p.contact_point
        );
        assert!((p.contact_point.y.abs() - 0.5 * params().target.width).abs() < 1e-9);
        assert!(p.has_window());
        // The contact window lies inside the look-ahead.
        assert!(
            p.window.0 >= p.time - 1e-9 && p.window.1 <= p.time + s.horizon + 1e-9,
            "{:?}",
            p.window
        );
        assert!(p.predicted_heading_error <= s.heading_tol + 1e-9);
        assert!(p.predicted_road_margin >= -s.violation_tol);
        assert!(p.predicted_stop_margin >= -s.violation_tol);
        // The safety set keeps clear of the obstacles.
        assert!(p.predicted_clearance >= s.obstacle_clearance - s.violation_tol);
        assert!(p.infeasible.is_none());
        assert!(
            p.steps.iter().any(|st| st.force.x > 0.0),
            "a PIT with no force"
        );
    }
}

#[test]
fn the_package_is_consistent_on_scripted_situations() {
    let s = PlannerSettings::default();
    let force_max = s.force_max_g * params().target.mass * 9.81;
    let road = road();
    let cases = [
        // (rel x, rel y, v target, v bullet, expected mode). The contact window (0.8 s) must
        // fit the 2 s look-ahead after the bullet's earliest arrival (the approach profile,
        // at rest beside the contact pose, plus 0.3 s to settle), so the bullet commits once
        // it is within about half a metre of its contact station; 6 m or 30 m back it chases.
        (-4.3, 2.2, 15.0, 16.0, Mode::Pit),
        (-6.0, 2.5, 15.0, 17.0, Mode::Chase),
        (-4.3, -2.2, 15.0, 16.0, Mode::Pit),
        (-30.0, 3.0, 15.0, 17.0, Mode::Chase),
        (-3.7, 2.0, 15.0, 16.0, Mode::Pit),
    ];
    let mut p = planner(s.clone());
    for (rx, ry, vt, vb, mode) in cases {
        let (xt, xb) = states(&road, rx, ry, vt, vb);
        let pkg = p.plan(&input(&road, &[], xt, xb)).unwrap().clone();
        assert_eq!(
            pkg.mode, mode,
            "case ({rx}, {ry}): {:?} {:?}",
            pkg.mode, pkg.infeasible
        );
        check_consistent(&pkg, &s, force_max);
        if mode == Mode::Pit {
            // The side the bullet is on, the target spun towards its reversal.
            assert_eq!(pkg.side.sign(), ry.signum(), "case ({rx}, {ry})");
            let last = pkg.steps.last().unwrap().target;
            assert!(
                last[2] * ry.signum() > 1.0,
                "the target should be spinning: ψ_N {}",
                last[2]
            );
        }
    }
}

#[test]
fn an_obstacle_where_the_target_would_spin_changes_the_decision_or_aborts() {
    let s = PlannerSettings::default();
    let road = road();
    let (xt, xb) = states(&road, -4.3, 2.2, 15.0, 16.0);
    let mut p = planner(s.clone());
    let free = p.plan(&input(&road, &[], xt, xb)).unwrap().clone();
    assert_eq!(free.mode, Mode::Pit);
    // A parked car right where the unobstructed plan leaves the target.
    let end = free.steps.last().unwrap().target;
    let obstacle = Obstacle {
        x: end[6] + 1.0,
        y: end[7],
        heading: 0.0,
        vx: 0.0,
        vy: 0.0,
        length: 4.5,
        width: 1.8,
    };
    let obstacles = [obstacle];
    let with = p.plan(&input(&road, &obstacles, xt, xb)).unwrap().clone();
    let force_max = s.force_max_g * params().target.mass * 9.81;
    check_consistent(&with, &s, force_max);
    match with.mode {
        Mode::Pit => {
            assert!(
                with.side != free.side || with.window != free.window || with.steps != free.steps,
                "the same decision with an obstacle in the way"
            );
            assert!(with.predicted_clearance >= s.obstacle_clearance - s.violation_tol);
        }
        Mode::Abort => assert_eq!(with.infeasible, Some(Infeasible::ObstacleClearance)),
        m => panic!("unexpected mode {m:?}"),
    }
    assert!(
        free.predicted_clearance > 100.0,
        "no obstacle, no clearance limit"
    );
}

#[test]
fn no_feasible_decision_is_reported_with_its_reason() {
    // One narrow lane without shoulders: no room for the bullet beside the target, and every
    // push that spins the target round would take it over an edge.
    let s = PlannerSettings::default();
    let road = Road::straight(3000.0, 1, 3.0, 0.0);
    let lane = road.lane_center_offset(0);
    let mut xt = TargetState::zeros();
    xt[0] = 25.0;
    xt[6] = 100.0;
    xt[7] = lane;
    let xb = BulletState::from_column_slice(&[94.0, lane + 1.9, 0.0, 27.0, 0.0, 0.0]);
    let mut p = planner(s);
    let pkg = p.plan(&input(&road, &[], xt, xb)).unwrap();
    assert_eq!(pkg.mode, Mode::Abort, "{:?}", pkg.infeasible);
    assert_eq!(pkg.infeasible, Some(Infeasible::RoadBoundary));
    assert_eq!(pkg.feasible_candidates, 0);
    assert!(!pkg.has_window());
    assert!(!pkg.infeasible.unwrap().describe().is_empty());
}

#[test]
fn the_same_inputs_give_the_same_package() {
    let road = road();
    let (xt, xb) = states(&road, -4.3, 2.2, 15.0, 16.0);
    let obstacles = [Obstacle {
        x: 150.0,
        y: -3.5,
        heading: 0.0,
        vx: 8.0,
        vy: 0.0,
        length: 4.5,
        width: 1.8,
    }];
    let mut a = planner(PlannerSettings::default());
    let mut b = planner(PlannerSettings::default());
    let pa = a.plan(&input(&road, &obstacles, xt, xb)).unwrap().clone();
    // b plans something else first: no state may leak between plans.
    let (xt2, xb2) = states(&road, -4.3, -2.2, 15.0, 16.0);
    b.plan(&input(&road, &[], xt2, xb2)).unwrap();
    let pb = b.plan(&input(&road, &obstacles, xt, xb)).unwrap().clone();
    assert_eq!(pa, pb);
    let pa2 = a.plan(&input(&road, &obstacles, xt, xb)).unwrap().clone();
    assert_eq!(pa, pa2);
}

#[test]
fn bad_input_is_an_error_not_a_panic() {
    let road = road();
    let (mut xt, xb) = states(&road, -6.0, 2.5, 15.0, 17.0);
    let mut p = planner(PlannerSettings::default());
    xt[2] = f64::NAN;
    assert_eq!(
        p.plan(&input(&road, &[], xt, xb)).unwrap_err(),
        planner::PlanError::NonFiniteState
    );
    let many = vec![
        Obstacle {
            x: 0.0,
            y: 50.0,
            heading: 0.0,
            vx: 0.0,
            vy: 0.0,
            length: 1.0,
            width: 1.0
        };
        planner::MAX_OBSTACLES + 1
    ];
    let (xt, xb) = states(&road, -4.3, 2.2, 15.0, 16.0);
    assert_eq!(
        p.plan(&input(&road, &many, xt, xb)).unwrap_err(),
        planner::PlanError::TooManyObstacles
    );
}

/// A plan made while the bullet touches the target puts its force at the rear-quarter
/// point, wherever the bullet touches (here its inner front corner, 0.9 m ahead of it).
#[test]
fn a_plan_in_contact_pushes_at_the_rear_quarter_point() {
    let p = params();
    let road = road();
    let (mut xt, _) = states(&road, -6.0, 3.0, 20.0, 21.0);
    xt[0] = 20.0;
    let x_rq = mpc::reference::rear_quarter_x(&p);
    let x_touch = x_rq + 0.9;
    // The bullet on the target's left, turned in by 12° as in a PIT, its inner front corner
    // 2 cm into the target's side at x_touch (the contact pose of `mpc::reference`).
    let pose = mpc::reference::pit_stage_at(
        &p,
        mpc::Side::Left,
        x_touch,
        12f64.to_radians(),
        0.02,
        1.0,
        (0.0, 1.0),
    );
    let xb = BulletState::from_column_slice(&[
        xt[6] + pose.rel_pos.x,
        xt[7] + pose.rel_pos.y,
        pose.rel_heading,
        21.0,
        0.0,
        0.0,
    ]);
    let mut pl = planner(PlannerSettings::default());
    let mut inp = input(&road, &[], xt, xb);
    inp.side = Some(mpc::Side::Left);
    inp.best_effort = true;
    let pkg = pl.plan(&inp).unwrap();
    assert_eq!(pkg.mode, Mode::Pit, "{pkg:?}");
    assert!(
        (pkg.contact_point.x - x_rq).abs() <= 1e-9,
        "contact point x {} against {x_rq}",
        pkg.contact_point.x
    );
    assert!(pkg.contact_point.y > 0.0, "left side");
}

/// `Planner::judge` is the plan's own verdict: judging the push a plan chose (its side,
/// window and forces) gives that plan's predicted heading error back and calls it feasible;
/// no push leaves a target driving straight on far from its reversed heading; a harder
/// shove turns it further; a bad push is an error.
#[test]
fn judging_a_plans_own_push_gives_its_verdict() {
    let s = PlannerSettings {
        contact_offsets: vec![0.0],
        ..PlannerSettings::default()
    };
    let road = road();
    let mut p = planner(s.clone());
    let (xt, xb) = states(&road, -4.3, 2.2, 15.0, 16.0);
    let inp = input(&road, &[], xt, xb);
    let pkg = p.plan(&inp).unwrap().clone();
    assert_eq!(pkg.mode, Mode::Pit, "{:?}", pkg.infeasible);
    let start = ((pkg.window.0 - pkg.time) / s.dt).round() as usize;
    let forces: Vec<_> = pkg.steps[start..start + s.window_steps()]
        .iter()
        .map(|st| st.force)
        .collect();
    let j = p.judge(&inp, pkg.side, start, &forces).unwrap();
    assert!(
        (j.heading_error - pkg.predicted_heading_error).abs() < 1e-9,
        "judged {} against planned {}",
        j.heading_error,
        pkg.predicted_heading_error
    );
    assert!(j.feasible, "{j:?}");
    // The package is the plan's, whatever was judged since.
    assert_eq!(p.package(), &pkg);

    let none = p.judge(&inp, pkg.side, 0, &[]).unwrap();
    assert!(!none.feasible && none.heading_error > 3.0, "{none:?}");
    let m = params().target.mass;
    let shove = |dv: f64| [dynamics::geometry::Vec2::new(m * dv / 0.15, 0.0); 3];
    let (weak, hard) = (
        p.judge(&inp, pkg.side, 0, &shove(0.3)).unwrap(),
        p.judge(&inp, pkg.side, 0, &shove(1.5)).unwrap(),
    );
    assert!(
        hard.heading_error < weak.heading_error && weak.heading_error < none.heading_error,
        "none {none:?}, weak {weak:?}, hard {hard:?}"
    );

    let too_long = vec![dynamics::geometry::Vec2::zeros(); s.window_steps() + 1];
    assert_eq!(
        p.judge(&inp, pkg.side, 0, &too_long).unwrap_err(),
        planner::PlanError::TooManyForces
    );
    assert_eq!(
        p.judge(&inp, pkg.side, s.steps(), &shove(1.0)).unwrap_err(),
        planner::PlanError::TooManyForces
    );
    let nan = [dynamics::geometry::Vec2::new(f64::NAN, 0.0)];
    assert_eq!(
        p.judge(&inp, pkg.side, 0, &nan).unwrap_err(),
        planner::PlanError::NonFiniteState
    );
}

/// The closed loop of the push: `push_done` says whether the target, left alone now, would
/// reach the reversed heading inside the road. A target sliding on at 8 m/s with its body
/// turned 90° does if it still spins at 1.5 rad/s, not without a spin (it stays across the
/// road) nor spinning at 4 rad/s (it turns on past the reversed heading); the tolerance
/// binds, and the package is left as it was. Judged at 0.6 rad: at the default 0.9 rad the
/// target spinning at 4 rad/s ends near enough to reversed.
#[test]
fn a_push_is_done_once_the_target_left_alone_reverses() {
    let road = road();
    let mut p = planner(PlannerSettings::default());
    let (xt0, xb) = states(&road, -4.3, 2.2, 15.0, 16.0);
    let pkg = p.plan(&input(&road, &[], xt0, xb)).unwrap().clone();
    let spun = |r: f64| {
        let mut xt = xt0;
        let (turned, v) = (std::f64::consts::FRAC_PI_2, 8.0);
        xt[2] = turned;
        xt[0] = v * turned.cos();
        xt[1] = -v * turned.sin();
        xt[3] = r;
        let mut inp = input(&road, &[], xt, xb);
        inp.side = Some(mpc::Side::Right);
        inp
    };
    let release = Release::heading(0.6);
    assert!(p.push_done(&spun(1.5), &release).unwrap());
    assert!(p
        .push_done(
            &spun(4.0),
            &Release::heading(PlannerSettings::default().heading_tol)
        )
        .unwrap());
    assert!(!p.push_done(&spun(0.0), &release).unwrap(), "no spin");
    assert!(!p.push_done(&spun(4.0), &release).unwrap(), "spinning past");
    assert!(
        !p.push_done(&spun(1.5), &Release::heading(0.0)).unwrap(),
        "a zero tolerance"
    );
    assert!(
        !p.push_done(&input(&road, &[], xt0, xb), &release).unwrap(),
        "a target driving on"
    );
    assert_eq!(p.package(), &pkg);
    let mut bad = spun(1.5);
    bad.target[3] = f64::NAN;
    assert_eq!(
        p.push_done(&bad, &release).unwrap_err(),
        planner::PlanError::NonFiniteState
    );
}

/// A target that will have stopped by the end of the look-ahead has no spin left: the
/// release asks for its heading within `release_rest_heading_tol` (0.3 rad), not the 0.9 rad
/// that a target still sliding on may lack. Turned round but for 0.45 rad and moving along
/// the road at 2 m/s, the push is not done (it is with the heading tolerance alone); 0.2 rad
/// short it is; at 15 m/s the target slides on past the look-ahead, and the rest tolerance
/// does not apply.
#[test]
fn a_target_coming_to_rest_is_released_only_nearly_reversed() {
    let road = road();
    let short = |off: f64, v: f64| {
        let (mut xt, xb) = states(&road, -4.3, 2.2, 15.0, 16.0);
        // Pushed from the right the target turns clockwise, towards −π.
        let psi = -std::f64::consts::PI + off;
        xt[2] = psi;
        xt[0] = v * psi.cos();
        xt[1] = -v * psi.sin();
        xt[3] = 0.0;
        let mut inp = input(&road, &[], xt, xb);
        inp.side = Some(mpc::Side::Right);
        inp
    };
    let release = PhaseSettings::default().release(false);
    assert!((release.rest_heading_tol - 0.3).abs() < 1e-12 && release.rest_speed > 2.0);
    let heading_only = Release::heading(release.heading_tol);
    let mut p = planner(PlannerSettings::default());
    assert!(p.push_done(&short(0.45, 2.0), &heading_only).unwrap());
    assert!(!p.push_done(&short(0.45, 2.0), &release).unwrap());
    assert!(p.push_done(&short(0.2, 2.0), &release).unwrap());
    for off in [0.12, 0.45] {
        // A target sliding on: the rest tolerance does not apply.
        let fast = short(off, 15.0);
        assert_eq!(
            p.push_done(&fast, &release).unwrap(),
            p.push_done(&fast, &heading_only).unwrap(),
            "{off}"
        );
    }
    assert!(p.push_done(&short(0.12, 15.0), &release).unwrap());
}

/// The push waits for the open-road release (0.2 rad, not 0.9) only on a straight road at
/// least `open_road_half_width` from its centre to either edge, with no obstacle within
/// `open_road_clear` of the target, and a target no faster than `open_road_speed`: a curve
/// ahead, a narrower road, a stopped car ahead or a fast target each keep the default.
#[test]
fn the_open_road_release_needs_a_straight_wide_clear_road_and_a_pit_speed() {
    use dynamics::target::idx;
    use planner::controller::{open_road, ControllerInput};
    let s = PhaseSettings::default();
    assert!((s.release(true).heading_tol - 0.2).abs() < 1e-12);
    assert!((s.release(false).heading_tol - 0.9).abs() < 1e-12);
    let wide = Road::straight(1000.0, 3, 3.6, 2.2); // 7.6 m to either edge
    let narrow = Road::straight(1000.0, 3, 3.6, 1.0); // 6.4 m
    let bend = Road::curved(400.0, 300.0, 200.0, 0.0, 3, 3.6, 2.2);
    let car = |x: f64| Obstacle {
        x,
        y: 0.0,
        heading: 0.0,
        vx: 0.0,
        vy: 0.0,
        length: 4.5,
        width: 1.8,
    };
    let open = |road: &Road, x: f64, speed: f64, obstacles: &[Obstacle]| {
        let mut target = TargetState::zeros();
        target[idx::VX] = speed;
        target[idx::X] = x;
        target[idx::Y] = -3.6;
        let input = ControllerInput {
            time: 0.0,
            target,
            bullet: BulletState::zeros(),
            target_input: TargetInput::zeros(),
            road,
            obstacles,
        };
        open_road(&s, &input)
    };
    assert!(open(&wide, 500.0, 18.0, &[]));
    assert!(!open(&narrow, 500.0, 18.0, &[]));
    assert!(
        !open(&wide, 500.0, 25.0, &[]),
        "faster than a PIT is done at"
    );
    assert!(
        !open(&wide, 500.0, 18.0, &[car(600.0)]),
        "a stopped car 100 m ahead"
    );
    assert!(open(&wide, 500.0, 18.0, &[car(700.0)]), "... 200 m ahead");
    assert!(
        !open(&bend, 300.0, 18.0, &[]),
        "the bend begins 100 m ahead"
    );
    assert!(open(&bend, 100.0, 18.0, &[]), "... 300 m ahead");
}

/// On a slippery road the spin left at the end of the look-ahead turns the target further
/// (the tyres' friction moment that stops it scales with μ): the projected heading's τ, which
/// the package reports with its terminal set, is `yaw_decay` from μ 0.6 up, `yaw_decay` ·
/// 0.6 / μ below, and at most twice `yaw_decay`.
#[test]
fn on_a_slippery_road_the_projected_heading_counts_more_of_the_spin() {
    let road = road();
    let s = PlannerSettings::default();
    let (xt, xb) = states(&road, -4.3, 2.2, 15.0, 16.0);
    let tau = |mu: f64| {
        let mut p = planner(s.clone());
        p.set_mu(mu);
        p.plan(&input(&road, &[], xt, xb))
            .unwrap()
            .terminal
            .yaw_decay
    };
    let close = |a: f64, b: f64| (a - b).abs() < 1e-12;
    assert!(close(tau(0.9), s.yaw_decay));
    assert!(close(tau(0.6), s.yaw_decay));
    assert!(close(tau(0.45), s.yaw_decay * 0.6 / 0.45));
    assert!(close(tau(0.3), 2.0 * s.yaw_decay));
    assert!(close(tau(0.2), 2.0 * s.yaw_decay));
}

/// The release does not wait for the stopping point: a target already reversed but for
/// 0.12 rad, rolling backwards at 15 m/s, drifts 1.8 m/s across the road. Over the
/// look-ahead it stays inside; rolling on with only its stalled driveline to slow it, its
/// stopping point lies beyond the edge. The plan, which judges the stopping point, finds the
/// free motion short of the terminal set (it does not stabilise); `push_done` lets go,
/// since pushing on would only turn the target further. Reversed square to the road, both
/// agree.
#[test]
fn a_push_is_done_without_waiting_for_the_stopping_point() {
    let road = road();
    let reversed = |off: f64| {
        let (mut xt, xb) = states(&road, -4.3, 2.2, 15.0, 16.0);
        xt[2] = std::f64::consts::PI + off;
        xt[0] = -15.0;
        let mut inp = input(&road, &[], xt, xb);
        inp.side = Some(mpc::Side::Right);
        inp
    };
    let mut p = planner(PlannerSettings::default());
    let release = Release::heading(PlannerSettings::default().heading_tol);
    assert!(p.push_done(&reversed(0.12), &release).unwrap());
    let pkg = p.plan(&reversed(0.12)).unwrap();
    assert_ne!(pkg.mode, Mode::Stabilise);
    assert!(
        pkg.predicted_stop_margin < 0.0,
        "{}",
        pkg.predicted_stop_margin
    );
    assert!(p.push_done(&reversed(0.0), &release).unwrap());
    assert_eq!(p.plan(&reversed(0.0)).unwrap().mode, Mode::Stabilise);
}

/// A push that turns the target round (`push_round`, the half-scale platform): over the
/// window the bullet's contact pose keeps its distance and bearing from the target's
/// rear-quarter point while the target turns (without it, from the target's c.g., so a
/// target turned 1 rad since the push began has its rear quarter swung away from the
/// bullet); and while the push is under way the planner does not end it on the prediction
/// that the target reverses by itself, as it does for a push without it (or before one).
#[test]
fn a_push_round_follows_the_rear_quarter_and_is_not_ended_by_the_prediction() {
    use planner::href::{fill_reference, Timing};
    let road = road();
    let (xt, xb) = states(&road, -4.3, 2.2, 15.0, 16.0);
    let pkg = planner(PlannerSettings::default())
        .plan(&input(&road, &[], xt, xb))
        .unwrap()
        .clone();
    assert_eq!(pkg.mode, Mode::Pit);
    let (t0, t1) = pkg.window;
    let psi0 = xt[2] - 1.0;
    let timing = Timing {
        time: t0,
        dt: 0.05,
        pit_frame: Some(psi0),
        length_scale: 1.0,
        back_off: false,
    };
    let (cp, rel0) = (pkg.contact_point, pkg.contact_rel_pos);
    let mut r = mpc::Reference::new(20);
    for round in [false, true] {
        let s = PlannerSettings {
            push_round: round,
            ..PlannerSettings::default()
        };
        fill_reference(&pkg, &s, &mut r, &xt, &xb, timing);
        let mut checked = 0;
        for (k, st) in r.stages.iter().enumerate() {
            let tau = t0 + (k + 1) as f64 * 0.05;
            if tau > t1 {
                break;
            }
            let psi = xt[2] + pkg.heading_at(tau).unwrap() - pkg.heading_at(t0).unwrap();
            let anchor = if round { cp } else { Vec2::zeros() };
            let offset = rotate(psi, st.rel_pos - anchor) - rotate(psi0, rel0 - anchor);
            assert!(
                offset.norm() < 1e-9,
                "push_round {round}, stage {k}: {offset:?}"
            );
            let from_quarter = (st.rel_pos - cp).norm() - (rel0 - cp).norm();
            if round {
                assert!(from_quarter.abs() < 1e-9, "stage {k}: {from_quarter}");
            } else {
                assert!(from_quarter > 1.0, "stage {k}: {from_quarter}");
            }
            checked += 1;
        }
        assert!(checked > 5, "{checked} stages in the window");
    }

    let reversed = |best_effort: bool| {
        let (mut xt, xb) = states(&road, -4.3, 2.2, 15.0, 16.0);
        xt[2] = std::f64::consts::PI;
        xt[0] = -15.0;
        let mut inp = input(&road, &[], xt, xb);
        inp.side = Some(mpc::Side::Right);
        inp.best_effort = best_effort;
        inp
    };
    let round = PlannerSettings {
        push_round: true,
        ..PlannerSettings::default()
    };
    let mut p = planner(round);
    assert_eq!(p.plan(&reversed(false)).unwrap().mode, Mode::Stabilise);
    assert_ne!(p.plan(&reversed(true)).unwrap().mode, Mode::Stabilise);
    let mut p = planner(PlannerSettings::default());
    assert_eq!(p.plan(&reversed(true)).unwrap().mode, Mode::Stabilise);
}
