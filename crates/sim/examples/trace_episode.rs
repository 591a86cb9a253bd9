//! Trace one episode of the dataset step by step (both vehicles relative to the road, the
//! phase, the command and the contact force), then its metrics.
//!
//! `cargo run --release -p picopit-sim --example trace_episode -- ID [CONFIG]`
//!
//! With `STATE_AT=T` it also prints the full recorded states at time `T` (s): the target's
//! `[vx, vy, ψ, r, p, φ, X, Y]`, its driver's input and the bullet's state.
mod common;

use sim::episode::{run_episode, EpisodeConfig};
fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let state_at: Option<f64> = std::env::var("STATE_AT").ok().map(|t| {
        t.parse().unwrap_or_else(|_| {
            eprintln!("STATE_AT: expected a time in seconds, got {t:?}");
            std::process::exit(2)
        })
    });
    let id = &args[0];
    let mut cfg = EpisodeConfig::parse(args.get(1).map_or("picopinn", String::as_str)).unwrap();
    cfg.record = true;
    let scenarios = sim::load_jsonl("data/scenarios.jsonl").unwrap();
    let sc = scenarios.iter().find(|s| &s.id == id).unwrap();
    let road = sc.build_road().unwrap();
    for o in sc.obstacles() {
        let fp = o.footprint_at(0.0);
        let f = road.project(fp.center);
        println!("obstacle at s={:.1} d={:.2} ({:?})", f.s, f.d, o);
    }
    let r = run_episode(sc, &cfg, 0).unwrap();
    for s in r.trajectory.iter().step_by(2) {
        let ft = road.project(dynamics::geometry::Vec2::new(s.target[6], s.target[7]));
        let fb = road.project(dynamics::geometry::Vec2::new(s.bullet[0], s.bullet[1]));
        println!("t={:5.2} {:?} Δs={:6.2} T: d={:5.2} ψ-h={:6.1}° v={:5.2} | B: d={:5.2} ψ-h={:6.1}° v={:5.2} | cmd ({:6.3},{:7.1}) Fn={:6.0}",
            s.time, s.phase, fb.s - ft.s, ft.d, (s.target[2]-ft.heading).to_degrees(), s.target[0].hypot(s.target[1]),
            fb.d, (s.bullet[2]-fb.heading).to_degrees(), s.bullet[3], s.command[0], s.command[1], s.contact_force[0]);
    }
    // STATE_AT=T: the full recorded states and the target driver's input at time T (s).
    if let Some(t) = state_at {
        let half = 0.5 * cfg.controller.mpc.dt;
        for s in r.trajectory.iter().filter(|s| (s.time - t).abs() <= half) {
            println!(
                "state t={:.2} target {:?} target_input {:?} bullet {:?}",
                s.time, s.target, s.target_command, s.bullet
            );
        }
    }
    for p in &r.plans {
        println!("{}", common::plan_line(p, cfg.controller.planner.dt));
    }
    println!("{:?} half width {:.2}", r.metrics, road.half_width());
}
