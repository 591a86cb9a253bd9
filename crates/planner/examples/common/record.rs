//! The recorded states shared by the `plan_step` bench and the `plan_step_stats` example: the
//! states the upper layer plans from in a closed-loop PIT on the plant (the whole controller
//! with 4-DOF predictions, straight three-lane road, 20 Hz), from the approach through the
//! contact, with a moving car in the next lane.

use dynamics::bullet::BulletState;
use dynamics::params::ParamSet;
use dynamics::plant::{Plant, PlantConfig, VehicleInit};
use dynamics::road::{Obstacle, Road};
use dynamics::target4dof::FourDofTarget;
use dynamics::{TargetInput, TargetModel, TargetState};
use planner::{ControllerInput, ControllerSettings, PitController, PlannerInput};

pub const MU: f64 = 0.9;

pub struct Record {
    pub time: f64,
    pub target: TargetState,
    pub bullet: BulletState,
}

pub fn road() -> Road {
    Road::straight(3000.0, 3, 3.5, 1.0)
}

pub fn obstacles() -> Vec<Obstacle> {
    vec![Obstacle {
        x: 160.0,
        y: -3.5,
        heading: 0.0,
        vx: 13.0,
        vy: 0.0,
        length: 4.5,
        width: 1.8,
    }]
}

impl Record {
    pub fn input<'a>(&self, road: &'a Road, obstacles: &'a [Obstacle]) -> PlannerInput<'a> {
        PlannerInput {
            time: self.time,
            target: self.target,
            bullet: self.bullet,
            target_input: TargetInput::zeros(),
            road,
            obstacles,
            side: None,
            best_effort: false,
        }
    }
}

/// Every control step of the closed loop while the bullet is within 12 m of the target and
/// the maneuver is active (where decisions are made).
pub fn record(params: &ParamSet) -> Vec<Record> {
    let settings = ControllerSettings::default();
    let dt = settings.mpc.dt;
    let model = || -> Box<dyn TargetModel + Send + Sync> {
        Box::new(FourDofTarget::new(&params.target, MU, dt))
    };
    let mut ctl = PitController::new(params, MU, model(), model(), settings).unwrap();
    let road = road();
    let obstacles = obstacles();
    let lane = road.lane_center_offset(1);
    let mut plant = Plant::new(
        params,
        PlantConfig {
            mu: MU,
            ..PlantConfig::default()
        },
    )
    .unwrap();
    plant.reset(
        &VehicleInit {
            x: 88.0,
            y: lane + 3.0,
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
    let mut out = Vec::new();
    for step in 0..120 {
        let time = step as f64 * dt;
        let target = plant.target_state();
        let bullet = plant.bullet_state();
        let o = ctl
            .step(&ControllerInput {
                time,
                target,
                bullet,
                target_input: TargetInput::zeros(),
                road: &road,
                obstacles: &obstacles,
            })
            .unwrap();
        let d = (bullet[0] - target[6]).hypot(bullet[1] - target[7]);
        if o.phase.is_active() && d < 12.0 {
            out.push(Record {
                time,
                target,
                bullet,
            });
        }
        plant.set_bullet_command_blended(o.command[0], o.command[1]);
        plant.advance(dt);
    }
    assert!(out.len() >= 20, "only {} recorded states", out.len());
    out
}

/// The target models the benches compare: 4-DOF and, where the shipped files load, the PINN
/// and PicoPINN.
pub fn models(
    params: &ParamSet,
    dt: f64,
) -> Vec<(&'static str, Box<dyn TargetModel + Send + Sync>)> {
    let mut v: Vec<(&'static str, Box<dyn TargetModel + Send + Sync>)> =
        vec![("4dof", Box::new(FourDofTarget::new(&params.target, MU, dt)))];
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../models/full_size");
    for kind in ["pinn", "picopinn"] {
        let path = dir.join(format!("{kind}.safetensors"));
        match pico_nn::SurrogateModel::from_path(&path).and_then(|m| m.with_mu(MU)) {
            Ok(m) => v.push((kind, Box::new(m))),
            Err(e) => eprintln!("{kind}: skipped ({}: {e})", path.display()),
        }
    }
    v
}
