//! The recorded states shared by the `ctrl_step` bench and the `ctrl_step_stats` example: a
//! closed-loop PIT approach and contact on the plant (5 s at 20 Hz, 4-DOF prediction, default
//! reference, straight three-lane road), each with the reference and last command it saw.

use dynamics::bullet::{BulletInput, BulletState};
use dynamics::params::ParamSet;
use dynamics::plant::{Plant, PlantConfig, VehicleInit};
use dynamics::road::Road;
use dynamics::target4dof::FourDofTarget;
use dynamics::{TargetInput, TargetState};
use mpc::reference::DefaultPit;
use mpc::{CoupledMpc, MpcInput, MpcSettings, Reference, Side};

pub const MU: f64 = 0.9;

pub struct Record {
    pub target: TargetState,
    pub bullet: BulletState,
    pub last: BulletInput,
    pub reference: Reference,
}

impl Record {
    /// The MPC input of this recorded step on `road`.
    pub fn input<'a>(&'a self, road: &'a Road) -> MpcInput<'a> {
        MpcInput {
            time: 0.0,
            target: self.target,
            bullet: self.bullet,
            target_input: TargetInput::zeros(),
            last_command: self.last,
            road: Some(road),
            obstacles: &[],
            reference: &self.reference,
        }
    }
}

pub fn record(params: &ParamSet, road: &Road) -> Vec<Record> {
    let settings = MpcSettings::default();
    let target = Box::new(FourDofTarget::new(&params.target, MU, settings.dt));
    let mut mpc = CoupledMpc::new(params, MU, target, settings.clone()).unwrap();
    let mut plant = Plant::new(
        params,
        PlantConfig {
            mu: MU,
            ..PlantConfig::default()
        },
    )
    .unwrap();
    let lane = road.lane_center_offset(1);
    plant.reset(
        &VehicleInit {
            x: 40.0,
            y: lane + 3.0,
            yaw: 0.0,
            vx: 17.0,
            vy: 0.0,
            r: 0.0,
        },
        &VehicleInit {
            x: 50.0,
            y: lane,
            yaw: 0.0,
            vx: 15.0,
            vy: 0.0,
            r: 0.0,
        },
    );
    let pit = DefaultPit::new(params, Side::Left);
    let mut reference = Reference::new(settings.horizon);
    let mut last = BulletInput::zeros();
    let mut out = Vec::new();
    for _ in 0..100 {
        let (xt, xb) = (plant.target_state(), plant.bullet_state());
        pit.fill(
            &mut reference,
            xt.as_slice(),
            xb.as_slice(),
            settings.dt,
            0.0,
        );
        out.push(Record {
            target: xt,
            bullet: xb,
            last,
            reference: reference.clone(),
        });
        let input = MpcInput {
            time: 0.0,
            target: xt,
            bullet: xb,
            target_input: TargetInput::zeros(),
            last_command: last,
            road: Some(road),
            obstacles: &[],
            reference: &reference,
        };
        last = mpc.solve(&input).unwrap().command;
        plant.set_bullet_command_blended(last[0], last[1]);
        plant.advance(settings.dt);
    }
    out
}
