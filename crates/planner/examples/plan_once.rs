//! One decision of the upper layer on a straight road, printed.
//!
//! `cargo run --release -p picopit-planner --example plan_once [rel_x rel_y v_target v_bullet]`

use dynamics::params::ParamSet;
use dynamics::road::Road;
use dynamics::target4dof::FourDofTarget;
use dynamics::{TargetInput, TargetState};
use planner::{Planner, PlannerInput, PlannerSettings};

fn main() {
    let a: Vec<f64> = std::env::args()
        .skip(1)
        .map(|v| v.parse().unwrap())
        .collect();
    let (rx, ry, vt, vb) = if a.len() == 4 {
        (a[0], a[1], a[2], a[3])
    } else {
        (-6.0, 2.5, 15.0, 17.0)
    };
    let params = ParamSet::builtin("full_size").unwrap();
    let mu = 0.9;
    let s = PlannerSettings::default();
    let model = Box::new(FourDofTarget::new(&params.target, mu, s.dt));
    let mut p = Planner::new(&params, mu, model, s).unwrap();
    let road = Road::straight(2000.0, 3, 3.5, 1.0);
    let lane = road.lane_center_offset(1);
    let mut xt = TargetState::zeros();
    xt[0] = vt;
    xt[6] = 100.0;
    xt[7] = lane;
    let xb = dynamics::bullet::BulletState::from_column_slice(&[
        100.0 + rx,
        lane + ry,
        0.0,
        vb,
        0.0,
        0.0,
    ]);
    let input = PlannerInput {
        time: 0.0,
        target: xt,
        bullet: xb,
        target_input: TargetInput::zeros(),
        road: &road,
        obstacles: &[],
        side: None,
        best_effort: false,
    };
    let mut times = Vec::new();
    for _ in 0..400 {
        let t = std::time::Instant::now();
        p.plan(&input).unwrap();
        times.push(t.elapsed().as_secs_f64() * 1e3);
    }
    let pkg = p.package().clone();
    times.sort_by(f64::total_cmp);
    println!("{p:?}");
    println!(
        "plan: median {:.2} ms, min {:.2} ms (20 runs)",
        times[200], times[0]
    );
    println!(
        "mode {:?} {:?} side {:?} window {:?} cands {}/{} obj {:.3} head_err {:.3} road {:.2} clear {:.2} stop {:.2}",
        pkg.mode, pkg.infeasible, pkg.side, pkg.window, pkg.feasible_candidates, pkg.candidates,
        pkg.objective, pkg.predicted_heading_error, pkg.predicted_road_margin, pkg.predicted_clearance, pkg.predicted_stop_margin
    );
    for st in pkg.steps.iter().step_by(2) {
        println!(
            "t={:.2} F=({:7.0},{:6.0}) C=({:6.0},{:6.0}) psi={:7.1}° r={:5.2} v={:5.2} X={:6.1} Y={:5.2}",
            st.time, st.force.x, st.force.y, st.corridor.0, st.corridor.1,
            st.target[2].to_degrees(), st.target[3], st.target[0].hypot(st.target[1]), st.target[6], st.target[7]
        );
    }
}
