//! Per-decision times of the upper layer over the recorded closed-loop states: median, p99
//! and max per target model, each state planned `REPEAT` times (default 5).
//!
//! `cargo run --release -p picopit-planner --example plan_step_stats`

use dynamics::params::ParamSet;
use planner::{Mode, Planner, PlannerSettings};
use std::time::Instant;

mod common;
use common::record::{models, obstacles, record, road, MU};

fn main() {
    let repeat: usize = match std::env::var("REPEAT") {
        Ok(v) => v.parse().expect("REPEAT must be a positive integer"),
        Err(_) => 5,
    };
    let params = ParamSet::builtin("full_size").unwrap();
    let records = record(&params);
    let road = road();
    let obstacles = obstacles();
    let settings = PlannerSettings::default();
    println!("{} recorded states x {repeat}", records.len());
    for (name, model) in models(&params, settings.dt) {
        let mut p = Planner::new(&params, MU, model, settings.clone()).unwrap();
        let mut t = Vec::new();
        let mut modes = [0usize; 4];
        for _ in 0..repeat {
            for r in &records {
                let t0 = Instant::now();
                let pkg = p.plan(&r.input(&road, &obstacles)).unwrap();
                t.push(t0.elapsed().as_secs_f64() * 1e3);
                modes[match pkg.mode {
                    Mode::Chase => 0,
                    Mode::Pit => 1,
                    Mode::Stabilise => 2,
                    Mode::Abort => 3,
                }] += 1;
            }
        }
        t.sort_by(f64::total_cmp);
        let q = |f: f64| t[((t.len() - 1) as f64 * f).round() as usize];
        println!(
            "plan_step/{name}: median {:.2} ms, p99 {:.2} ms, max {:.2} ms ({} plans; chase/pit/stabilise/abort {:?})",
            q(0.5), q(0.99), t[t.len() - 1], t.len(), modes
        );
    }
}
