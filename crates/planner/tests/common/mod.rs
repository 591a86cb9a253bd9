//! Scripted situations shared by the planner's integration tests: the full-size
//! parameters, a planner with the QP's clock out of the way, a straight three-lane road, the
//! two vehicles placed on it and the planner's input.

use dynamics::bullet::BulletState;
use dynamics::params::ParamSet;
use dynamics::road::{Obstacle, Road};
use dynamics::target4dof::FourDofTarget;
use dynamics::{TargetInput, TargetState};
use planner::{Planner, PlannerInput, PlannerSettings};

pub fn params() -> ParamSet {
    ParamSet::builtin("full_size").unwrap()
}

/// A planner with the QP's wall-clock limit out of the way: an unoptimised build is some
/// 20x slower, and a QP stopped by the clock would make the outcome machine-dependent.
pub fn planner(settings: PlannerSettings) -> Planner {
    planner_on(settings, 0.9)
}

/// [`planner`] on a road of adhesion `mu`.
pub fn planner_on(mut settings: PlannerSettings, mu: f64) -> Planner {
    settings.qp.time_limit = 10.0;
    let p = params();
    let model = Box::new(FourDofTarget::new(&p.target, mu, settings.dt));
    Planner::new(&p, mu, model, settings).unwrap()
}

pub fn road() -> Road {
    Road::straight(3000.0, 3, 3.5, 1.0)
}

/// Target in the middle lane at `vt`, bullet at (`rx`, `ry`) from it at `vb`.
pub fn states(road: &Road, rx: f64, ry: f64, vt: f64, vb: f64) -> (TargetState, BulletState) {
    let lane = road.lane_center_offset(1);
    let mut xt = TargetState::zeros();
    xt[0] = vt;
    xt[6] = 100.0;
    xt[7] = lane;
    let xb = BulletState::from_column_slice(&[100.0 + rx, lane + ry, 0.0, vb, 0.0, 0.0]);
    (xt, xb)
}

pub fn input<'a>(
    road: &'a Road,
    obstacles: &'a [Obstacle],
    xt: TargetState,
    xb: BulletState,
) -> PlannerInput<'a> {
    PlannerInput {
        time: 3.0,
        target: xt,
        bullet: xb,
        target_input: TargetInput::zeros(),
        road,
        obstacles,
        side: None,
        best_effort: false,
    }
}
