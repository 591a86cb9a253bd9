//! The chase on scripted situations: where a waiting bullet has arrived at its contact
//! station (the band of contact points, and the metre off it on a slippery road), a race the
//! target loses before any push can begin, and a stand-off line blocked ahead that holds the
//! chase back.

use dynamics::road::Obstacle;
use dynamics::TargetInput;
mod common;

use common::{input, params, planner, planner_on, road, states};
use planner::{Infeasible, Mode, PlannerSettings};
/// A bullet waiting on the stand-off line a little behind the rear-quarter station is at a
/// station already: the contact points the planner tries (`contact_offsets`, the rear
/// quarter and 0.4 m behind it) form a band, and its earliest arrival is at the point of the
/// band nearest to where it would come to rest. On a slippery road (μ 0.3, a slow relative
/// approach) the same bullet 0.3 m behind commits; 2 m behind, beyond the band and the
/// metre a waiting bullet may be off it, it chases.
#[test]
fn a_bullet_waiting_within_the_band_of_contact_points_commits() {
    let s = PlannerSettings::default();
    let p = params();
    let mu = 0.3;
    let mut planner = planner_on(s.clone(), mu);
    let x_rq = mpc::reference::rear_quarter_x(&p);
    let c = mpc::reference::pit_stage_at(
        &p,
        mpc::Side::Left,
        x_rq,
        s.contact_angle,
        s.overlap,
        s.push_speed,
        (0.0, 0.0),
    );
    let road = road();
    for (behind, commits) in [(0.3, true), (2.0, false)] {
        let (xt, xb) = states(
            &road,
            c.rel_pos.x - behind,
            c.rel_pos.y + s.standoff,
            12.0,
            12.0,
        );
        let pkg = planner.plan(&input(&road, &[], xt, xb)).unwrap();
        if commits {
            assert_ne!(pkg.mode, Mode::Chase, "{behind} m behind: {:?}", pkg.mode);
            assert!(pkg.candidates > 0);
            let x = pkg.contact_point.x;
            assert!(
                x <= x_rq + 1e-9 && x >= x_rq - 0.4 - 1e-9,
                "contact point {x} outside the band [{}, {x_rq}]",
                x_rq - 0.4
            );
        } else {
            assert_eq!(pkg.mode, Mode::Chase, "{behind} m behind: {:?}", pkg.mode);
        }
    }
}

/// On a very slippery road (μ 0.15: the approach closes at 0.6 μ g, 0.88 m/s²) a bullet
/// waiting on the stand-off line up to a metre off the band of contact stations, ahead of it
/// or behind it, as the MPC holds a waiting bullet (0.4 m ahead on a curve in `sc-01655`),
/// has arrived: it commits. Closing 0.8 m first would take 1.9 s and leave no window in the
/// look-ahead, plan after plan. So does one drifting off the band at 0.5 m/s that stops
/// within that metre (0.14 m on): it has arrived once it has stopped, 0.57 s on. The same
/// bullet drifting at 1.5 m/s stops 1.3 m on, beyond the metre: it chases. One closing in
/// at 0.5 m/s from 0.8 m off the band would stop inside the metre too, but it is on its way
/// to its station and keeps its approach (1.5 s): it chases.
#[test]
fn a_bullet_waiting_just_off_the_band_commits_on_a_slippery_road() {
    let s = PlannerSettings::default();
    let p = params();
    let mu = 0.15;
    let mut planner = planner_on(s.clone(), mu);
    let c = mpc::reference::pit_stage_at(
        &p,
        mpc::Side::Left,
        mpc::reference::rear_quarter_x(&p),
        s.contact_angle,
        s.overlap,
        s.push_speed,
        (0.0, 0.0),
    );
    // The band of the bullet's stations: the rear quarter and 0.4 m behind it.
    let (front, back) = (c.rel_pos.x, c.rel_pos.x - 0.4);
    let road = road();
    for (rx, drift, commits) in [
        (back - 0.8, 0.0, true),
        (front + 0.8, 0.0, true),
        (back - 0.25, -0.5, true),
        (front + 0.25, 0.5, true),
        (back - 0.25, -1.5, false),
        (front + 0.25, 1.5, false),
        (back - 0.8, 0.5, false),
        (front + 0.8, -0.5, false),
    ] {
        let (xt, xb) = states(&road, rx, c.rel_pos.y + s.standoff, 12.0, 12.0 + drift);
        let pkg = planner.plan(&input(&road, &[], xt, xb)).unwrap();
        if commits {
            assert!(pkg.candidates > 0, "{rx} drifting at {drift}: no window");
            assert_ne!(pkg.mode, Mode::Chase, "{rx} drifting at {drift}");
        } else {
            assert_eq!(pkg.mode, Mode::Chase, "{rx} drifting at {drift}");
        }
    }
}

/// The race: a target driving at 15 m/s onto a car parked in its lane 20 m ahead (it hits
/// it within 1.1 s, whether its driver holds the wheel or keeps the lane), with the bullet
/// 12 m behind, cannot be pushed before it hits: the decision is infeasible now
/// (`race_lost`, for the obstacle). With the car 60 m ahead the bullet chases; and a
/// target whose held steer would take it off the road within the look-ahead, but which a
/// lane-keeping driver keeps on it, is no lost race either.
#[test]
fn a_target_that_fails_before_any_push_can_begin_is_a_lost_race() {
    let s = PlannerSettings::default();
    let road = road();
    let mut p = planner(s);
    let (xt, xb) = states(&road, -12.0, 0.0, 15.0, 15.0);
    let parked = |ahead: f64| Obstacle {
        x: xt[6] + ahead,
        y: xt[7],
        heading: 0.0,
        vx: 0.0,
        vy: 0.0,
        length: 4.5,
        width: 1.8,
    };
    let near = [parked(20.0)];
    let pkg = p.plan(&input(&road, &near, xt, xb)).unwrap();
    assert_eq!(pkg.mode, Mode::Abort);
    assert!(pkg.race_lost);
    assert_eq!(pkg.infeasible, Some(Infeasible::ObstacleClearance));

    let far = [parked(60.0)];
    let pkg = p.plan(&input(&road, &far, xt, xb)).unwrap();
    assert_eq!(pkg.mode, Mode::Chase);
    assert!(!pkg.race_lost);

    // In the right lane, 0.05 rad of right steer: off the road within the look-ahead if
    // held.
    let shift = road.lane_center_offset(0) - road.lane_center_offset(1);
    let (mut xt, mut xb) = (xt, xb);
    xt[7] += shift;
    xb[1] += shift;
    let mut inp = input(&road, &[], xt, xb);
    inp.target_input = TargetInput::new(-0.05, 0.0);
    let pkg = p.plan(&inp).unwrap();
    assert!(pkg.predicted_road_margin < -1.0, "held, it leaves the road");
    assert!(!pkg.race_lost, "{:?}", pkg.mode);
}

/// A car parked in the next lane on the bullet's side, 60 m ahead of the target: the
/// bullet, chasing 12 m behind, would be beside the target (some 4 s from now), in that
/// lane, when the target passes it, so its chase holds back behind the target
/// (`hold_back`), and the MPC's reference keeps it in its lane until it is behind the
/// target's rear, then takes it across to the target's line. A car 25 m ahead is passed by
/// the target before the bullet is beside it, but it stands in the bullet's way there, and
/// the chase holds back too; a car behind the bullet does not, and without a car it waits
/// on its stand-off line beside the target.
#[test]
fn a_stand_off_line_blocked_ahead_holds_the_chase_back() {
    use planner::href::{fill_reference, Timing, HOLD_BACK};
    let s = PlannerSettings::default();
    let road = road();
    let mut p = planner(s.clone());
    let ry = road.lane_center_offset(2) - road.lane_center_offset(1);
    let (xt, xb) = states(&road, -12.0, ry, 15.0, 15.0);
    let parked = |ahead: f64| {
        [Obstacle {
            x: xt[6] + ahead,
            y: xt[7] + ry,
            heading: 0.0,
            vx: 0.0,
            vy: 0.0,
            length: 4.5,
            width: 1.8,
        }]
    };
    let free = p.plan(&input(&road, &[], xt, xb)).unwrap().clone();
    assert_eq!(free.mode, Mode::Chase);
    assert!(!free.hold_back);
    let passed = parked(-20.0);
    let behind = p.plan(&input(&road, &passed, xt, xb)).unwrap();
    assert_eq!(behind.mode, Mode::Chase);
    assert!(!behind.hold_back);
    let in_the_way = parked(25.0);
    let early = p.plan(&input(&road, &in_the_way, xt, xb)).unwrap();
    assert_eq!(early.mode, Mode::Chase);
    assert!(early.hold_back);
    assert!(early.lateral_speed >= s.crossing_speed);
    let parked = parked(60.0);
    let pkg = p.plan(&input(&road, &parked, xt, xb)).unwrap().clone();
    assert_eq!(pkg.mode, Mode::Chase);
    assert!(pkg.hold_back);

    let timing = Timing {
        time: 3.0,
        dt: 0.05,
        pit_frame: None,
        length_scale: 1.0,
        back_off: false,
    };
    let behind = pkg.contact_rel_pos.x - HOLD_BACK;
    let mut r = mpc::Reference::new(20);
    // 12 m behind, beyond the hold-back station: across to the target's line at once.
    fill_reference(&pkg, &s, &mut r, &xt, &xb, timing);
    let last = r.stages.last().unwrap().rel_pos;
    assert!(last.y < ry - 0.5 && last.x <= behind + 1e-9, "{last:?}");
    // Beside the target: kept in its lane, dropping back.
    let (_, beside) = states(&road, -3.0, ry, 15.0, 15.0);
    fill_reference(&pkg, &s, &mut r, &xt, &beside, timing);
    assert!(r
        .stages
        .iter()
        .all(|st| (st.rel_pos.y - ry).abs() < 1e-9 && st.rel_pos.x <= -3.0 + 1e-9));
    // The free package waits beside the target.
    fill_reference(&free, &s, &mut r, &xt, &beside, timing);
    assert!(r.stages.iter().all(|st| st.rel_pos.y > 1.0));
}
