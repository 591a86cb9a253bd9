//! Run closed-loop episodes of the scenario dataset and print one line each.
//!
//! `cargo run --release -p picopit-sim --example episodes -- [CONFIG] [FIRST] [COUNT] [FILE]`
//! (CONFIG: a preset name or a JSON configuration; defaults picopinn 0 8
//! data/scenarios.jsonl).

use sim::episode::{run_episode, EpisodeConfig};

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let config = args.first().map_or("picopinn", String::as_str);
    let first: usize = args.get(1).and_then(|s| s.parse().ok()).unwrap_or(0);
    let count: usize = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(8);
    let file = args.get(3).map_or("data/scenarios.jsonl", String::as_str);
    let cfg = match EpisodeConfig::parse(config) {
        Ok(c) => c,
        Err(e) => {
            eprintln!("{e}");
            std::process::exit(2);
        }
    };
    let scenarios = match sim::load_jsonl(file) {
        Ok(s) => s,
        Err(e) => {
            eprintln!("{e}");
            std::process::exit(2);
        }
    };
    let (mut ok, mut n, mut wall) = (0, 0, 0.0);
    for sc in scenarios.iter().skip(first).take(count) {
        match run_episode(sc, &cfg, 0) {
            Ok(r) => {
                n += 1;
                ok += usize::from(r.success());
                wall += r.wall_time;
                println!(
                    "{} {:16} {:8} {:>20} {:7} at {:5.2} s | herr {:5.2} margin {:6.2} contacts {} | plan {:5.2}/{:5.2} ms ({}) ctrl {:5.2}/{:5.2} ms | {:?} {:?} | fail {} budget {} | wall {:.2} s | impact {} | reversed {}",
                    r.scenario,
                    sc.category.name(),
                    sc.adhesion.name(),
                    r.metrics.cause.map_or("success", |c| c.name()),
                    r.metrics.failed_vehicle.map_or(String::new(), |v| format!("{v:?}")),
                    r.metrics.decided_at.unwrap_or(f64::NAN),
                    r.metrics.terminal_heading_error,
                    r.metrics.min_margin,
                    r.metrics.contacts,
                    r.plan.median_ms,
                    r.plan.p99_ms,
                    r.plan.count,
                    r.ctrl.median_ms,
                    r.ctrl.p99_ms,
                    r.final_phase,
                    r.abort,
                    r.mpc_failures,
                    r.mpc_time_budget,
                    r.wall_time,
                    match (r.metrics.impact_point, r.metrics.impact_speed) {
                        (Some([x, y]), Some(v)) => format!("x {x:.2} y {y:.2} v {v:.2}"),
                        _ => "-".to_owned(),
                    },
                    match (r.metrics.reversed_at, r.metrics.reversed_speed) {
                        (Some(t), Some(v)) => format!("t {t:.2} v {v:.2}"),
                        _ => "-".to_owned(),
                    },
                );
            }
            Err(e) => println!("{}: error: {e}", sc.id),
        }
    }
    println!("{ok}/{n} succeeded, {wall:.1} s of episodes");
}
