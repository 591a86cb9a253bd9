//! The control step allocates nothing after construction: the whole controller (the upper
//! layer's replans, the MPC, the phase machine) over a closed-loop PIT on the plant, from
//! chasing through contact (a counting global allocator).

use alloc_count::{allocations, CountingAlloc};
use dynamics::params::ParamSet;
use dynamics::plant::{Plant, PlantConfig, VehicleInit};
use dynamics::road::{Obstacle, Road};
use dynamics::target4dof::FourDofTarget;
use dynamics::TargetInput;
use planner::{ControllerInput, ControllerSettings, Phase, PitController};

#[global_allocator]
static GLOBAL: CountingAlloc = CountingAlloc;

#[test]
fn the_controller_step_allocates_nothing() {
    let params = ParamSet::builtin("full_size").unwrap();
    let mu = 0.9;
    let mut settings = ControllerSettings::default();
    // Wall-clock limits out of the way: the test profile is slower than a release build.
    settings.mpc.time_budget = 10.0;
    settings.mpc.qp.time_limit = 10.0;
    settings.planner.qp.time_limit = 10.0;
    let dt = settings.mpc.dt;
    let model = || Box::new(FourDofTarget::new(&params.target, mu, dt));
    let mut ctl = PitController::new(&params, mu, model(), model(), settings).unwrap();
    let road = Road::straight(3000.0, 3, 3.5, 1.0);
    let lane = road.lane_center_offset(1);
    let obstacles = [Obstacle {
        x: 400.0,
        y: -3.5,
        heading: 0.0,
        vx: 12.0,
        vy: 0.0,
        length: 4.5,
        width: 1.8,
    }];
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
            x: 94.0,
            y: lane + 2.6,
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
    let (mut replans, mut phases) = (0, Vec::new());
    for step in 0..70 {
        let input = ControllerInput {
            time: step as f64 * dt,
            target: plant.target_state(),
            bullet: plant.bullet_state(),
            target_input: TargetInput::zeros(),
            road: &road,
            obstacles: &obstacles,
        };
        let before = allocations();
        let out = ctl.step(&input).unwrap();
        let n = allocations() - before;
        assert_eq!(
            n, 0,
            "step {step} ({:?}, replanned {}): {n} allocations",
            out.phase, out.replanned
        );
        replans += usize::from(out.replanned);
        if phases.last() != Some(&out.phase) {
            phases.push(out.phase);
        }
        plant.set_bullet_command_blended(out.command[0], out.command[1]);
        plant.advance(dt);
    }
    // The run covered what it claims to: several plans, and the contact.
    assert!(replans >= 3, "{replans} replans");
    assert!(phases.contains(&Phase::Pit), "phases {phases:?}");
}
