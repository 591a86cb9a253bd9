//! Shared set-up for the MPC tests and benches: scripted PIT situations on a straight road.

#![allow(dead_code)]

use dynamics::bullet::{BulletInput, BulletState};
use dynamics::params::ParamSet;
use dynamics::road::Road;
use dynamics::target4dof::FourDofTarget;
use dynamics::{TargetInput, TargetModel, TargetState};
use mpc::reference::DefaultPit;
use mpc::{CoupledMpc, MpcInput, MpcSettings, Reference, Side};

pub const MU: f64 = 0.9;

pub fn params() -> ParamSet {
    ParamSet::builtin("full_size").unwrap()
}

pub fn four_dof(params: &ParamSet) -> Box<dyn TargetModel + Send + Sync> {
    Box::new(FourDofTarget::new(&params.target, MU, 0.05))
}

pub fn mpc_with(settings: MpcSettings, target: Box<dyn TargetModel + Send + Sync>) -> CoupledMpc {
    CoupledMpc::new(&params(), MU, target, settings).unwrap()
}

pub fn road() -> Road {
    Road::straight(2000.0, 3, 3.5, 1.0)
}

/// A scripted situation: target in the middle lane at 15 m/s heading along the road, the
/// bullet placed relative to it (in the target frame), both at the given speeds. The
/// target's driver holds its speed with the throttle, as an out-of-control car does until
/// it is hit.
pub struct Situation {
    pub target: TargetState,
    pub bullet: BulletState,
    pub reference: Reference,
    pub target_input: TargetInput,
}

pub fn situation(rel_x: f64, rel_y: f64, rel_yaw: f64, v_target: f64, v_bullet: f64) -> Situation {
    let p = params();
    let lane = road().lane_center_offset(1);
    let mut target = TargetState::zeros();
    target[0] = v_target;
    target[6] = 100.0;
    target[7] = lane;
    let mut bullet = BulletState::zeros();
    bullet[0] = 100.0 + rel_x;
    bullet[1] = lane + rel_y;
    bullet[2] = rel_yaw;
    bullet[3] = v_bullet;
    let mut reference = Reference::new(20);
    DefaultPit::new(&p, Side::Left).fill(
        &mut reference,
        target.as_slice(),
        bullet.as_slice(),
        0.05,
        0.0,
    );
    Situation {
        target,
        bullet,
        reference,
        target_input: TargetInput::new(0.0, -p.target.cruise_wheel_torque(v_target)),
    }
}

pub fn input<'a>(s: &'a Situation, road: Option<&'a Road>) -> MpcInput<'a> {
    MpcInput {
        time: 0.0,
        target: s.target,
        bullet: s.bullet,
        target_input: s.target_input,
        last_command: BulletInput::zeros(),
        road,
        obstacles: &[],
        reference: &s.reference,
    }
}

/// The bullet's c.g. such that its front-right corner overlaps the target's left side by
/// `overlap` metres at the rear quarter (bullet parallel to the target).
pub fn touching_rel(overlap: f64) -> (f64, f64) {
    let p = params();
    let (b, t) = (&p.bullet, &p.target);
    let x_c = -t.lr - 0.3;
    (x_c - b.cg_to_front, 0.5 * t.width + 0.5 * b.width - overlap)
}
