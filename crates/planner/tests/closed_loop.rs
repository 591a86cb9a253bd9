//! The whole controller on the plant (the truth): a PIT on a straight three-lane road at
//! 15 m/s from behind either side reverses the target, which comes to rest inside the road
//! (its driver holds its speed with the throttle until the contact and lets go of it then,
//! as an out-of-control driver of the dataset does; in gear, its stalled engine stops it);
//! the same maneuver without the upper layer (the paper's ablation) runs through its phases
//! as well.

use dynamics::params::ParamSet;
use dynamics::plant::{Plant, PlantConfig, VehicleInit};
use dynamics::road::Road;
use dynamics::target4dof::FourDofTarget;
use dynamics::TargetInput;
use planner::decision::wrap;
use planner::{ControllerInput, ControllerSettings, Phase, PitController};

struct Run {
    phases: Vec<Phase>,
    heading_error: f64,
    lateral: f64,
    speed: f64,
    abort: Option<planner::AbortReason>,
    plans: usize,
}

fn run(side: f64, upper: bool) -> Run {
    let params = ParamSet::builtin("full_size").unwrap();
    let mu = 0.9;
    let mut settings = ControllerSettings {
        upper_layer: upper,
        ..ControllerSettings::default()
    };
    // Wall-clock limits out of the way (the test profile is slower than a release build):
    // the outcome then does not depend on the machine.
    settings.mpc.time_budget = 10.0;
    settings.mpc.qp.time_limit = 10.0;
    settings.planner.qp.time_limit = 10.0;
    let dt = settings.mpc.dt;
    let model = || Box::new(FourDofTarget::new(&params.target, mu, dt));
    let mut ctl = PitController::new(&params, mu, model(), model(), settings).unwrap();
    let road = Road::straight(3000.0, 3, 3.5, 1.0);
    let lane = road.lane_center_offset(1);
    let mut plant = Plant::new(
        &params,
        PlantConfig {
            mu,
            ..PlantConfig::default()
        },
    )
    .unwrap();
    plant.reset(
        &VehicleInit {
            x: 90.0,
            y: lane + side * 3.0,
            yaw: 0.0,
            vx: 17.0,
            vy: 0.0,
            r: 0.0,
        },
        &VehicleInit {
            x: 100.0,
            y: lane,
            yaw: 0.0,
            vx: 15.0,
            vy: 0.0,
            r: 0.0,
        },
    );
    let mut phases = vec![Phase::Chasing];
    let mut plans = 0;
    let mut first_contact: Option<f64> = None;
    for step in 0..240 {
        let time = step as f64 * dt;
        // The target's driver holds 15 m/s with the throttle until the contact, then lets go.
        let target_input = match first_contact {
            Some(_) => TargetInput::zeros(),
            None => TargetInput::new(0.0, -params.target.cruise_wheel_torque(15.0)),
        };
        plant.set_target_command(target_input[0], target_input[1]);
        let out = ctl
            .step(&ControllerInput {
                time,
                target: plant.target_state(),
                bullet: plant.bullet_state(),
                target_input,
                road: &road,
                obstacles: &[],
            })
            .unwrap();
        assert!(out.command.iter().all(|v| v.is_finite()));
        plans += usize::from(out.replanned);
        if *phases.last().unwrap() != out.phase {
            phases.push(out.phase);
        }
        plant.set_bullet_command_blended(out.command[0], out.command[1]);
        plant.advance(dt);
        if first_contact.is_none() && plant.take_contact_average().is_some() {
            first_contact = Some(time);
        }
    }
    let xt = plant.target_state();
    Run {
        phases,
        heading_error: wrap(xt[2] - std::f64::consts::PI).abs(),
        lateral: xt[7],
        speed: xt[0].hypot(xt[1]),
        abort: ctl.abort_reason(),
        plans,
    }
}

#[test]
fn the_controller_reverses_the_target_from_either_side() {
    for side in [1.0, -1.0] {
        let r = run(side, true);
        assert_eq!(r.abort, None, "side {side}: {:?}", r.phases);
        assert_eq!(
            &r.phases[..3],
            &[Phase::Chasing, Phase::Pit, Phase::Stabilising],
            "side {side}"
        );
        assert!(
            r.heading_error < 0.35,
            "side {side}: heading error {:.2} rad",
            r.heading_error
        );
        assert!(
            r.lateral.abs() < 6.25,
            "side {side}: the target left the road (Y {:.2})",
            r.lateral
        );
        assert!(
            r.speed < 0.5,
            "side {side}: the target is still moving at {:.2} m/s",
            r.speed
        );
        assert!(r.plans >= 4, "side {side}: {} plans", r.plans);
    }
}

#[test]
fn without_the_upper_layer_the_maneuver_still_runs_its_phases() {
    let r = run(1.0, false);
    assert_eq!(r.plans, 0);
    assert_eq!(
        &r.phases[..2],
        &[Phase::Chasing, Phase::Pit],
        "{:?}",
        r.phases
    );
}

/// A lost race ends the chase at the first plan, without waiting out the controller's
/// patience with infeasible plans: the target runs onto a car parked 20 m ahead in its lane
/// long before the bullet, 12 m behind, could begin a push.
#[test]
fn a_lost_race_is_decision_infeasible_at_once() {
    use dynamics::bullet::BulletState;
    use dynamics::road::Obstacle;
    use dynamics::TargetState;
    use planner::{AbortReason, Infeasible};
    let params = ParamSet::builtin("full_size").unwrap();
    let mu = 0.9;
    let mut settings = ControllerSettings::default();
    settings.mpc.time_budget = 10.0;
    settings.mpc.qp.time_limit = 10.0;
    settings.planner.qp.time_limit = 10.0;
    assert!(settings.phases.infeasible_patience > 1);
    let dt = settings.mpc.dt;
    let model = || Box::new(FourDofTarget::new(&params.target, mu, dt));
    let mut ctl = PitController::new(&params, mu, model(), model(), settings).unwrap();
    let road = Road::straight(3000.0, 3, 3.5, 1.0);
    let lane = road.lane_center_offset(1);
    let mut target = TargetState::zeros();
    target[0] = 15.0;
    target[6] = 100.0;
    target[7] = lane;
    let parked = [Obstacle {
        x: 120.0,
        y: lane,
        heading: 0.0,
        vx: 0.0,
        vy: 0.0,
        length: 4.5,
        width: 1.8,
    }];
    let out = ctl
        .step(&ControllerInput {
            time: 0.0,
            target,
            bullet: BulletState::from_column_slice(&[88.0, lane, 0.0, 15.0, 0.0, 0.0]),
            target_input: TargetInput::zeros(),
            road: &road,
            obstacles: &parked,
        })
        .unwrap();
    assert_eq!(out.phase, Phase::Aborted);
    assert_eq!(
        ctl.abort_reason(),
        Some(AbortReason::DecisionInfeasible(
            Infeasible::ObstacleClearance
        ))
    );
}
