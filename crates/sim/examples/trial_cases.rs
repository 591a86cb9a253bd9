//! Run the half-scale trial cases (the paper's real-vehicle table, R1–R4) in process and
//! print, per case: the target's initial speed, the measured impact speed and angle, the
//! terminal heading error and the outcome.
//!
//! `cargo run --release -p picopit-sim --example trial_cases -- [SETTINGS] [NOISE] [SEED] [FILE]`
//!
//! * SETTINGS: a controller settings TOML (default `configs/controller_half_scale.toml`),
//!   or `default` for the built-in (full-size) settings;
//! * NOISE: `none` (default) or `paper`: the paper platform's sensing noise (position
//!   σ 0.01 m, angular rate σ 0.002 rad/s) and a 0.05 s latency;
//! * SEED: the episode seed (default 0); FILE: default `data/trials/half_scale.jsonl`.
//!
//! Set `TRACE=ID` to print that case step by step. The clock is simulated (reproducible).

mod common;

use sim::episode::{run_episode, ClockKind, EpisodeConfig, Uncertainty};

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let settings = args
        .first()
        .map_or("configs/controller_half_scale.toml", String::as_str);
    let noise = args.get(1).map_or("none", String::as_str);
    let seed: u64 = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(0);
    let file = args
        .get(3)
        .map_or("data/trials/half_scale.jsonl", String::as_str);
    let mut cfg = EpisodeConfig::preset("picopinn").expect("preset");
    if settings != "default" {
        let text = std::fs::read_to_string(settings).unwrap_or_else(|e| {
            eprintln!("{settings}: {e}");
            std::process::exit(2);
        });
        cfg.controller = planner::ControllerSettings::from_toml_str(&text).unwrap_or_else(|e| {
            eprintln!("{settings}: {e}");
            std::process::exit(2);
        });
    }
    cfg.clock = ClockKind::Simulated;
    cfg.uncertainty = match noise {
        "none" => Uncertainty::default(),
        "paper" => Uncertainty {
            position_std: 0.01,
            yaw_rate_std: 0.002,
            latency: 0.05,
            ..Uncertainty::default()
        },
        other => {
            eprintln!("NOISE: `none` or `paper`, not {other:?}");
            std::process::exit(2);
        }
    };
    let trace = std::env::var("TRACE").ok();
    let scenarios = sim::load_jsonl(file).unwrap_or_else(|e| {
        eprintln!("{e}");
        std::process::exit(2);
    });
    println!("settings {settings}, noise {noise}, seed {seed}");
    println!(
        "{:4} {:>9} {:>11} {:>10} {:>9} {:>8}  outcome",
        "case", "v_T km/h", "impact km/h", "angle deg", "herr rad", "at s"
    );
    let mut ok = 0;
    for sc in &scenarios {
        let mut c = cfg.clone();
        c.record = trace.as_deref() == Some(sc.id.as_str());
        let r = match run_episode(sc, &c, seed) {
            Ok(r) => r,
            Err(e) => {
                println!("{}: error: {e}", sc.id);
                continue;
            }
        };
        ok += usize::from(r.success());
        let m = &r.metrics;
        println!(
            "{:4} {:9.2} {:11.2} {:10.1} {:9.3} {:8.2}  {} (contacts {}, phase {:?}{})",
            sc.id,
            sc.target.vx.hypot(sc.target.vy) * 3.6,
            m.impact_speed.map_or(f64::NAN, |v| v * 3.6),
            m.impact_angle.map_or(f64::NAN, f64::to_degrees),
            m.terminal_heading_error,
            m.decided_at.unwrap_or(f64::NAN),
            m.cause
                .map_or(if m.success { "success" } else { "running" }, |c| c.name()),
            m.contacts,
            r.final_phase,
            r.abort.map_or(String::new(), |a| format!(", abort {a}")),
        );
        if c.record {
            let road = sc.build_road().expect("road");
            for s in &r.trajectory {
                let p = |x: f64, y: f64| road.project(dynamics::geometry::Vec2::new(x, y));
                let (ft, fb) = (p(s.target[6], s.target[7]), p(s.bullet[0], s.bullet[1]));
                println!(
                    "  t={:5.2} {:11} T: s={:6.2} d={:5.2} ψ={:6.1}° v={:4.2} r={:5.2} | B: s={:6.2} d={:5.2} ψ={:6.1}° v={:4.2} | cmd ({:6.3},{:6.1}) Fn={:5.0}",
                    s.time,
                    format!("{:?}", s.phase),
                    ft.s,
                    ft.d,
                    (s.target[2] - ft.heading).to_degrees(),
                    s.target[0].hypot(s.target[1]),
                    s.target[3],
                    fb.s,
                    fb.d,
                    (s.bullet[2] - fb.heading).to_degrees(),
                    s.bullet[3],
                    s.command[0],
                    s.command[1],
                    s.contact_force[0]
                );
            }
            for pl in &r.plans {
                println!("  {}", common::plan_line(pl, c.controller.planner.dt));
            }
            println!("  {m:?}, half width {:.2}", road.half_width());
        }
    }
    println!("{ok}/{} succeeded", scenarios.len());
}
