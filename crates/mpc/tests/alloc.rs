//! The control step allocates nothing after construction: RTI and converged SCP, apart and
//! in contact, with a road and obstacles (a counting global allocator).
//!
//! This includes Clarabel: its `Info::reset` would clear the nested timer maps at every solve
//! (clarabel 0.11.1, `src/timers/timers.rs`) and re-create one `HashMap`; `Qp::solve` runs
//! each solve under its own root timer so that the maps survive (see `crates/mpc/src/qp.rs`).

mod common;

use alloc_count::{allocations, CountingAlloc};
use common::*;
use dynamics::road::Obstacle;
use mpc::{MpcSettings, ScpMode};

#[global_allocator]
static GLOBAL: CountingAlloc = CountingAlloc;

#[test]
fn the_control_step_allocates_nothing() {
    let (rx, ry) = touching_rel(0.03);
    let situations = [
        situation(-10.0, 3.0, 0.0, 15.0, 17.0),
        situation(rx, ry, -0.1, 15.0, 16.0),
        situation(-4.0, 2.5, 0.05, 15.0, 16.0),
    ];
    let obstacles = [Obstacle {
        x: 130.0,
        y: -3.5,
        heading: 0.0,
        vx: 10.0,
        vy: 0.0,
        length: 4.5,
        width: 1.8,
    }];
    let road = road();
    for mode in [ScpMode::Rti, ScpMode::Converged] {
        let mut settings = MpcSettings {
            mode,
            time_budget: 10.0,
            ..MpcSettings::default()
        };
        settings.qp.time_limit = 10.0;
        let mut m = mpc_with(settings, four_dof(&params()));
        for (i, s) in situations.iter().enumerate() {
            let mut inp = input(s, Some(&road));
            inp.obstacles = &obstacles;
            let before = allocations();
            let out = m.solve(&inp).unwrap();
            let n = allocations() - before;
            assert!(out.scp_iterations >= 1, "{out:?}");
            assert_eq!(n, 0, "{mode:?}, situation {i}: {n} allocations ({out:?})");
        }
    }
}
