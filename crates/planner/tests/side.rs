//! The side the push comes from: the inside of a curve, against a driverless target's drift on
//! a straight, else the roomier side of a straight, and the speed of a bullet crossing behind
//! the target to its far side.

mod common;

use common::{input, planner, planner_on, road, states};
use dynamics::road::Road;
use dynamics::TargetInput;
use planner::{Planner, PlannerSettings};

/// On a curve the bullet works on the inside (its push turns the target's nose into the
/// curve, and the spin's path bends with the road), from whichever side it starts; on a
/// straight it keeps its own side. The curve begins 20 m ahead of the target, within the
/// look-ahead of the side choice.
#[test]
fn on_a_curve_the_push_comes_from_the_inside() {
    let side_for = |radius: Option<f64>, ry: f64| {
        let road = match radius {
            Some(r) => Road::curved(120.0, r, 400.0, 30.0, 3, 3.5, 1.0),
            None => road(),
        };
        let (xt, xb) = states(&road, -8.0, ry, 18.0, 20.0);
        let mut p = planner(PlannerSettings::default());
        p.plan(&input(&road, &[], xt, xb)).unwrap().side
    };
    use mpc::reference::Side;
    // A left curve: inside is the target's left, whether the bullet starts right or left.
    assert_eq!(side_for(Some(150.0), -3.5), Side::Left);
    assert_eq!(side_for(Some(150.0), 3.5), Side::Left);
    // A right curve: inside is the right.
    assert_eq!(side_for(Some(-150.0), 3.5), Side::Right);
    // A straight road: the bullet's own side.
    assert_eq!(side_for(None, -3.5), Side::Right);
    assert_eq!(side_for(None, 3.5), Side::Left);
}

/// On a straight road a target that drifts across it under its own held steer (a driver off
/// the controls) is pushed from the side away from its drift, so that the spin bends its path
/// back onto the road. The planner decides it once, at a plan a second after the first, if
/// the steer has not moved: a target running straight, or one whose driver steers, keeps the
/// bullet's own side; a new maneuver (`reset`) decides afresh.
#[test]
fn on_a_straight_the_push_works_against_the_targets_drift() {
    use mpc::reference::Side;
    let road = road();
    let plans = |p: &mut Planner, steers: [f64; 2], heading: f64, ry: f64| {
        let (mut xt, xb) = states(&road, -8.0, ry, 18.0, 20.0);
        xt[2] = heading;
        let mut sides = [Side::Left; 2];
        for (k, steer) in steers.into_iter().enumerate() {
            let mut inp = input(&road, &[], xt, xb);
            inp.time = 3.0 + k as f64;
            inp.target_input = TargetInput::new(steer, 0.0);
            sides[k] = p.plan(&inp).unwrap().side;
        }
        sides
    };
    let side_for = |steer: f64, heading: f64, ry: f64| {
        plans(
            &mut planner(PlannerSettings::default()),
            [steer; 2],
            heading,
            ry,
        )
    };
    // Steering left (it curves towards the left edge): pushed from the right, wherever the
    // bullet starts, once the steer has been seen held; and the other way round.
    assert_eq!(side_for(0.006, 0.0, 3.5), [Side::Left, Side::Right]);
    assert_eq!(side_for(0.006, 0.0, -3.5), [Side::Right, Side::Right]);
    assert_eq!(side_for(-0.006, 0.0, 3.5), [Side::Left, Side::Left]);
    assert_eq!(side_for(-0.006, 0.0, -3.5), [Side::Right, Side::Left]);
    // Its course off the road's heading counts with its curve: heading right but curving
    // left so that it ends up left of its lane.
    assert_eq!(side_for(0.006, -0.01, 3.5)[1], Side::Right);
    // No drift, or too little to matter: the bullet's own side.
    assert_eq!(side_for(0.0, 0.0, 3.5)[1], Side::Left);
    assert_eq!(side_for(0.0005, 0.0, 3.5)[1], Side::Left);
    assert_eq!(side_for(0.0005, 0.0, -3.5)[1], Side::Right);
    // A driver who steers is not taken at a held command.
    let mut p = planner(PlannerSettings::default());
    assert_eq!(plans(&mut p, [0.004, 0.006], 0.0, 3.5)[1], Side::Left);
    // Decided once per maneuver: later plans keep it, a reset decides afresh.
    assert_eq!(plans(&mut p, [0.006; 2], 0.0, 3.5)[1], Side::Left);
    p.reset();
    assert_eq!(plans(&mut p, [0.006; 2], 0.0, 3.5)[1], Side::Right);
}

/// On a straight road, with no drift to work against, the bullet works on the side of the
/// target with the more road beyond it: a rear-quarter push bends the spinning target's path
/// towards the bullet's side. On a four-lane road (edges 8 m either side of the centre line)
/// a target in the second lane from the left has 6.25 m of road on its left and 9.75 m on
/// its right: a bullet starting on its left works on its right. Pushed from the middle
/// lanes' shared line (the target in lane 2, the bullet on its right) the room differs by
/// 3.5 m too; a target on the centre line keeps the bullet's own side.
#[test]
fn on_a_straight_the_push_comes_from_the_roomier_side() {
    use mpc::reference::Side;
    let road = Road::straight(3000.0, 4, 3.5, 1.0);
    let side_for = |target_d: f64, ry: f64| {
        let (mut xt, mut xb) = states(&road, -8.0, ry, 18.0, 20.0);
        xt[7] = target_d;
        xb[1] = target_d + ry;
        let mut p = planner(PlannerSettings::default());
        p.plan(&input(&road, &[], xt, xb)).unwrap().side
    };
    let left_lane = road.lane_center_offset(2);
    assert!((left_lane - 1.75).abs() < 1e-12);
    // Room on the right: the bullet crosses to it, from either side.
    assert_eq!(side_for(left_lane, 3.5), Side::Right);
    assert_eq!(side_for(left_lane, -3.5), Side::Right);
    // And the mirror image.
    assert_eq!(side_for(-left_lane, 3.5), Side::Left);
    assert_eq!(side_for(-left_lane, -3.5), Side::Left);
    // Half a metre off the centre line: too little difference, the bullet's own side.
    assert_eq!(side_for(0.5, 3.5), Side::Left);
    assert_eq!(side_for(0.5, -3.5), Side::Right);
}

/// A bullet crossing behind the target to its far side crosses at `crossing_speed`, and as
/// much faster as the target drifts across its line: with the target heading 5° across the
/// road towards a bullet that holds the road's course at 17 m/s, at `crossing_speed` plus
/// 17 sin 5° ≈ 1.48 m/s; across from a target that keeps its course or drifts away, at
/// `crossing_speed` alone; towards its own side at `lateral_speed`; never faster than the
/// approach's `approach_speed` (a target heading 80° across the road towards the bullet),
/// nor slower than `lateral_speed`. A chase on the inside of a curve carries the crossing
/// speed in its package.
#[test]
fn a_target_drifting_across_the_bullets_line_speeds_its_crossing() {
    use mpc::reference::Side;
    let road = road();
    let s = PlannerSettings::default();
    let p = planner(s.clone());
    // The bullet on the target's right, 8 m behind.
    let (xt0, xb) = states(&road, -8.0, -3.5, 16.0, 17.0);
    let crossing = |psi: f64, side: Side| {
        let mut xt = xt0;
        xt[2] = psi;
        p.crossing_speed(side, &road, &xt, &xb)
    };
    let drift = 17.0 * 5f64.to_radians().sin();
    // Heading 5° to the right: towards the bullet on the right.
    assert!(s.crossing_speed > s.lateral_speed);
    let far = crossing(-5f64.to_radians(), Side::Left);
    assert!(
        (far - (s.crossing_speed + drift)).abs() < 1e-9,
        "far side {far} against {}",
        s.crossing_speed + drift
    );
    assert_eq!(crossing(-5f64.to_radians(), Side::Right), s.lateral_speed);
    assert_eq!(crossing(0.0, Side::Left), s.crossing_speed);
    assert_eq!(crossing(5f64.to_radians(), Side::Left), s.crossing_speed);
    assert!(s.crossing_speed + 17.0 * 80f64.to_radians().sin() > s.approach_speed);
    assert_eq!(crossing(-80f64.to_radians(), Side::Left), s.approach_speed);
    // A crossing speed below the closing-in speed is raised to it.
    let slow = planner(PlannerSettings {
        crossing_speed: 0.5,
        ..s.clone()
    });
    assert_eq!(
        slow.crossing_speed(Side::Left, &road, &xt0, &xb),
        s.lateral_speed
    );
    // A left curve ahead, the bullet on the right and the target heading 5° to the right:
    // the chase goes to the inside (the far side), and its package crosses at the
    // drift-assisted speed.
    let curve = Road::curved(120.0, 150.0, 400.0, 30.0, 3, 3.5, 1.0);
    let (mut xt, xb) = states(&curve, -8.0, -3.5, 18.0, 20.0);
    xt[2] = -5f64.to_radians();
    let mut q = planner(s.clone());
    let pkg = q.plan(&input(&curve, &[], xt, xb)).unwrap().clone();
    assert_eq!(pkg.side, Side::Left);
    let expected = s.crossing_speed + 20.0 * 5f64.to_radians().sin();
    assert!(
        (pkg.lateral_speed - expected).abs() < 1e-9,
        "{} against {expected}",
        pkg.lateral_speed
    );
}

/// On the outside of a curve the bullet waits `outside_standoff` beside the contact line:
/// turning in towards the inside it has the curve's share of its grip less, and from the
/// narrower stand-off it touches shallower and slower than on the inside. The wider
/// stand-off is the turn-in's to close: a bullet waiting on it is given the window a bullet
/// waiting on the narrower line is. The inside keeps `standoff`, and so does a slippery
/// road (`outside_standoff_mu`).
#[test]
fn on_the_outside_of_a_curve_the_bullet_waits_wider_for_the_same_window() {
    use mpc::reference::Side;
    // A left curve 20 m ahead: the target's right is its outside.
    let road = Road::curved(120.0, 150.0, 400.0, 30.0, 3, 3.5, 1.0);
    let plan_on = |outside_standoff: f64, side: Side, mu: f64| {
        let s = PlannerSettings {
            outside_standoff,
            ..PlannerSettings::default()
        };
        let c = contact_pose(&s, side);
        let wait = if side == Side::Right {
            outside_standoff
        } else {
            s.standoff
        };
        let (xt, xb) = states(
            &road,
            c.rel_pos.x,
            c.rel_pos.y + side.sign() * wait,
            18.0,
            18.0,
        );
        let mut inp = input(&road, &[], xt, xb);
        inp.side = Some(side);
        let pkg = planner_on(s, mu).plan(&inp).unwrap().clone();
        (pkg.standoff, pkg.mode, pkg.window.0)
    };
    let plan = |outside_standoff: f64, side: Side| plan_on(outside_standoff, side, 0.9);
    let narrow = plan(0.6, Side::Right);
    let wide = plan(1.2, Side::Right);
    assert_eq!((narrow.0, wide.0), (0.6, 1.2));
    assert_eq!(wide.1, planner::Mode::Pit, "{wide:?}");
    assert!(
        wide.2.is_finite() && (wide.2 - narrow.2).abs() < 1e-9,
        "{narrow:?} {wide:?}"
    );
    let inside = plan(1.2, Side::Left);
    assert_eq!(inside.0, 0.6);
    // Below `outside_standoff_mu` the turn-in would not close the extra width: the outside
    // keeps `standoff` too.
    let slippery = PlannerSettings::default().outside_standoff_mu - 0.1;
    assert_eq!(plan_on(1.2, Side::Right, slippery).0, 0.6);
}

/// The width the turn-in closes on the outside of a curve is still to be crossed: a bullet
/// half-way across it, on the inside's narrower line, has not arrived at its contact pose,
/// and its window does not open at once (before the fix it did, plan after plan, while the
/// bullet never touched: `picopit trace sc-00019`).
#[test]
fn half_way_across_the_outside_stand_off_is_not_at_the_contact_pose() {
    use mpc::reference::Side;
    let road = Road::curved(120.0, 150.0, 400.0, 30.0, 3, 3.5, 1.0);
    let s = PlannerSettings::default();
    let c = contact_pose(&s, Side::Right);
    let at = |off: f64| {
        let (xt, xb) = states(&road, c.rel_pos.x, c.rel_pos.y - off, 18.0, 18.0);
        let mut inp = input(&road, &[], xt, xb);
        inp.side = Some(Side::Right);
        let pkg = planner(s.clone()).plan(&inp).unwrap().clone();
        assert_eq!(pkg.mode, planner::Mode::Pit, "{pkg:?}");
        (pkg.standoff, pkg.window.0 - inp.time)
    };
    let (standoff, touching) = at(0.0);
    assert_eq!(standoff, s.outside_standoff);
    assert!(
        touching < 1e-9,
        "at the contact pose the window opens now: {touching}"
    );
    let (_, half_way) = at(s.standoff);
    assert!(
        half_way >= s.settle_time - 1e-9,
        "0.6 m off the contact line the window opens after the settle time: {half_way}"
    );
}

/// The bullet's contact pose on `side` at the rear quarter, with `s`'s contact geometry.
fn contact_pose(s: &PlannerSettings, side: mpc::reference::Side) -> mpc::reference::StageReference {
    let p = common::params();
    mpc::reference::pit_stage_at(
        &p,
        side,
        mpc::reference::rear_quarter_x(&p),
        s.contact_angle,
        s.overlap,
        s.push_speed,
        (0.0, 0.0),
    )
}
