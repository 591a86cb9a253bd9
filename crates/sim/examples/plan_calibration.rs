//! How well does the upper layer's prediction come true in closed loop?
//!
//! `cargo run --release -p picopit-sim --example plan_calibration -- CONFIG [FIRST] [COUNT] [THREADS]`
//! (CONFIG: a preset name or JSON, as `episodes` takes it; defaults scenes 0..64, 2 threads).
//!
//! Every PIT plan of every episode predicts the target's state over the look-ahead; the
//! recorded truth says what happened. Per horizon (0.5, 1 and 2 s after the plan), over
//! the plans whose horizon the episode reached: the heading's RMSE; its mean optimism, the
//! truth's distance from the reversed heading minus the plan's (positive: the plan promised
//! more than came); the share of plans more than 0.3 rad optimistic; the position RMSE. For
//! all PIT plans and for those made in contact. The truth includes how well the MPC
//! executed the plan, so read the models against each other, not alone; the last table
//! sets the plan's normal force over its first 0.5 s against the contact force delivered.
mod common;

use sim::episode::{run_episode, EpisodeConfig};
use sim::EpisodeResult;

const HORIZONS: [f64; 3] = [0.5, 1.0, 2.0];

#[derive(Default, Clone, Copy)]
struct Acc {
    n: usize,
    heading_sq: f64,
    optimism: f64,
    optimistic: usize,
    position_sq: f64,
}

fn wrap(a: f64) -> f64 {
    a.sin().atan2(a.cos())
}

/// Per horizon, (all PIT plans, PIT plans made in contact).
fn calibrate(r: &EpisodeResult, dt: f64, acc: &mut [[Acc; 2]; 3]) {
    let truth_at = |t: f64| {
        r.trajectory
            .iter()
            .find(|s| (s.time - t).abs() < 1e-6)
            .copied()
    };
    for p in r.plans.iter().filter(|p| p.mode == planner::Mode::Pit) {
        let in_contact = truth_at(p.time).is_some_and(|s| s.contact_force[0] > 0.0);
        for (h, a) in HORIZONS.iter().zip(acc.iter_mut()) {
            let k = (h / dt).round() as usize;
            let (Some(&(tp, xp, _)), Some(s)) = (p.predicted.get(k), truth_at(p.time + h)) else {
                continue;
            };
            debug_assert!((tp - p.time - h).abs() < 1e-6);
            let xt = s.target;
            let e = wrap(xp[2] - xt[2]);
            let o = wrap(xt[2] - p.reversed_heading).abs() - wrap(xp[2] - p.reversed_heading).abs();
            let d2 = (xp[6] - xt[6]).powi(2) + (xp[7] - xt[7]).powi(2);
            for (i, c) in a.iter_mut().enumerate() {
                if i == 1 && !in_contact {
                    continue;
                }
                c.n += 1;
                c.heading_sq += e * e;
                c.optimism += o;
                c.optimistic += usize::from(o > 0.3);
                c.position_sq += d2;
            }
        }
    }
}

/// Over the first `k` steps of every PIT plan made in contact: (steps, Σ planned F_n,
/// Σ delivered F_n, Σ |planned − delivered|).
fn force_gap(r: &EpisodeResult, k: usize, gap: &mut [f64; 4]) {
    for p in r.plans.iter().filter(|p| p.mode == planner::Mode::Pit) {
        let steps: Vec<_> = r
            .trajectory
            .iter()
            .filter(|s| s.time > p.time + 1e-6)
            .take(k)
            .collect();
        let in_contact = steps.first().is_some_and(|s| s.contact_force[0] > 0.0);
        if !in_contact || steps.len() < k || p.predicted.len() < k {
            continue;
        }
        for (s, (_, _, f)) in steps.iter().zip(&p.predicted) {
            gap[0] += 1.0;
            gap[1] += f[0];
            gap[2] += s.contact_force[0];
            gap[3] += (f[0] - s.contact_force[0]).abs();
        }
    }
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let Some(config) = args.first() else {
        eprintln!("usage: plan_calibration CONFIG [FIRST] [COUNT] [THREADS]");
        std::process::exit(2);
    };
    let mut cfg = EpisodeConfig::parse(config).unwrap_or_else(|e| {
        eprintln!("{e}");
        std::process::exit(2);
    });
    cfg.record = true;
    let first = common::number(&args, 1, "FIRST", 0);
    let count = common::number(&args, 2, "COUNT", 64);
    let threads = common::number(&args, 3, "THREADS", 2);
    let scenes = common::scenes(first, count);
    let dt = cfg.controller.mpc.dt;
    let results = common::map_scenes(&scenes, threads, |sc| {
        run_episode(sc, &cfg, 0).unwrap_or_else(|e| {
            eprintln!("{}: {e}", sc.id);
            std::process::exit(1);
        })
    });
    let mut acc = [[Acc::default(); 2]; 3];
    let successes = results.iter().filter(|r| r.success()).count();
    let mut gap = [0.0; 4];
    for r in &results {
        calibrate(r, dt, &mut acc);
        force_gap(r, (0.5 / dt).round() as usize, &mut gap);
    }
    println!("{config}: {} scenes, {successes} successes", results.len());
    println!("| horizon | plans | n | heading RMSE (rad) | mean optimism (rad) | > 0.3 rad optimistic | position RMSE (m) |");
    println!("|---|---|---|---|---|---|---|");
    for (h, a) in HORIZONS.iter().zip(acc.iter()) {
        for (name, c) in ["all PIT", "in contact"].iter().zip(a.iter()) {
            let n = c.n.max(1) as f64;
            println!(
                "| {h:.1} s | {name} | {} | {:.3} | {:+.3} | {:.2} | {:.2} |",
                c.n,
                (c.heading_sq / n).sqrt(),
                c.optimism / n,
                c.optimistic as f64 / n,
                (c.position_sq / n).sqrt()
            );
        }
    }
    let n = gap[0].max(1.0);
    println!(
        "\nplanned vs delivered normal force over the first 0.5 s of the PIT plans made in contact \
         ({} steps): planned mean {:.0} N, delivered mean {:.0} N, mean |difference| {:.0} N",
        gap[0], gap[1] / n, gap[2] / n, gap[3] / n
    );
}
