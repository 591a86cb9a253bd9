//! How well does the upper layer's prediction come true in closed loop?
//!
//! `cargo run --release -p picopit-sim --example plan_calibration -- CONFIG [FIRST] [COUNT] [THREADS] [REPLAY]`
//! (CONFIG: a preset name or JSON, as `episodes` takes it; defaults scenes 0..64, 2 threads;
//! REPLAY: `4dof`, `pinn` or `picopinn`, the model of the replay table, by default the
//! plan's own).
//!
//! Every PIT plan of every episode predicts the target's state over the look-ahead; the
//! recorded truth says what happened. Per horizon (0.5, 1 and 2 s after the plan), over
//! the plans whose horizon the episode reached: the heading's RMSE; its mean optimism, the
//! truth's distance from the reversed heading minus the plan's (positive: the plan promised
//! more than came); the share of plans more than 0.3 rad optimistic; the position RMSE. For
//! all PIT plans and for those made in contact. The truth includes how well the MPC
//! executed the plan, so read the models against each other, not alone; the last table
//! sets the plan's normal force over its first 0.5 s against the contact force delivered.
//!
//! The replay table splits the plan's error into its parts. From the true state at each
//! PIT plan made in contact, the plan's own model is rolled out again under each mix of
//! {planned, delivered} contact and {held, true} driver command, and set against the truth
//! 0.5 and 1 s later: the planned contact with the held command reproduces the plan; the
//! delivered contact (the plant's step-averaged force, normal and point of action) with the
//! true command is the model's own error on the closed loop's contacts. Between them, the
//! force's size and its geometry (point and normal) are swapped one at a time.
//!
//! With REPLAY another model replays the same plans. Its first row is then that model's
//! prediction of the plan's own push: set against the plan's model on the same plans, and
//! on the plans another planner made, it says whether a planner's optimiser seeks out
//! pushes on which its own model promises more than the others do.
mod common;

use dynamics::{TargetInput, TargetModel, TargetState};
use sim::episode::{run_episode, target_model, EpisodeConfig, PlanRecord, Sample};
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

/// Replay variants: (name, size from the delivered contact, geometry from the delivered
/// contact, true driver command).
const VARIANTS: [(&str, bool, bool, bool); 6] = [
    (
        "planned contact, held command (the plan)",
        false,
        false,
        false,
    ),
    ("planned contact, true command", false, false, true),
    (
        "delivered size, planned point and normal, held command",
        true,
        false,
        false,
    ),
    (
        "planned size, delivered point and normal, held command",
        false,
        true,
        false,
    ),
    ("delivered contact, held command", true, true, false),
    (
        "delivered contact, true command (model error)",
        true,
        true,
        true,
    ),
];
const REPLAY_HORIZONS: [usize; 2] = [10, 20];

/// Per variant and replay horizon: (n, Σ heading error², Σ optimism), plus geometry sums
/// over the delivered contact steps of the first 0.5 s: (steps, Σ Δx of the point, Σ Δy,
/// Σ normal's angle from the planned one, Σ planned F_n, Σ delivered F_n, Σ planned F_n · lever,
/// Σ delivered F_n · lever) where lever is the point's |x| (the yaw moment's arm).
#[derive(Default, Clone, Copy)]
struct Replay {
    acc: [[(usize, f64, f64); 2]; 6],
    geometry: [f64; 8],
    plan_mismatch: f64,
}

fn replay_plan(model: &mut dyn TargetModel, p: &PlanRecord, steps: &[&Sample], out: &mut Replay) {
    let k_max = REPLAY_HORIZONS[1];
    if steps.len() < k_max || p.predicted.len() <= k_max {
        return;
    }
    let x0 = TargetState::from_column_slice(&p.predicted[0].1);
    for (v, &(_, size_delivered, geometry_delivered, true_driver)) in VARIANTS.iter().enumerate() {
        let mut x = x0;
        for (k, s) in steps.iter().take(k_max).enumerate() {
            let planned = p.predicted[k].2;
            let psi = x[2];
            let c = match (size_delivered, geometry_delivered) {
                (false, false) => p.contact_with(planned, psi),
                (true, true) => s.contact(),
                (true, false) => p.contact_with(s.contact_force, psi),
                (false, true) => {
                    let mut c = p.contact_with(planned, psi);
                    if s.contact_force[0] > 0.0 && c.fc.x > 0.0 {
                        let d = s.contact();
                        c.gamma = d.gamma;
                        c.point_in_body = d.point_in_body;
                    }
                    c
                }
            };
            let u = if true_driver {
                s.target_command
            } else {
                p.target_input
            };
            x = model.step(&x, &TargetInput::new(u[0], u[1]), &c);
            if v == 0 && k + 1 < p.predicted.len() {
                let e = (x - TargetState::from_column_slice(&p.predicted[k + 1].1)).amax();
                out.plan_mismatch = out.plan_mismatch.max(e);
            }
            for (h, &kh) in REPLAY_HORIZONS.iter().enumerate() {
                if k + 1 == kh {
                    let truth = steps[k].target[2];
                    let e = wrap(x[2] - truth);
                    let o = wrap(truth - p.reversed_heading).abs()
                        - wrap(x[2] - p.reversed_heading).abs();
                    let a = &mut out.acc[v][h];
                    a.0 += 1;
                    a.1 += e * e;
                    a.2 += o;
                }
            }
        }
    }
    for (k, s) in steps.iter().take(REPLAY_HORIZONS[0]).enumerate() {
        if s.contact_force[0] <= 0.0 {
            continue;
        }
        let g = &mut out.geometry;
        let planned_gamma = steps[k].target[2] - p.side_sign * std::f64::consts::FRAC_PI_2;
        g[0] += 1.0;
        g[1] += s.contact_point[0] - p.contact_point[0];
        g[2] += s.contact_point[1] - p.contact_point[1];
        g[3] += wrap(s.contact_gamma - planned_gamma);
        g[4] += p.predicted[k].2[0];
        g[5] += s.contact_force[0];
        g[6] += p.predicted[k].2[0] * p.contact_point[0].abs();
        g[7] += s.contact_force[0] * s.contact_point[0].abs();
    }
}

fn replay(r: &EpisodeResult, model: &mut dyn TargetModel, out: &mut Replay) {
    for p in r.plans.iter().filter(|p| p.mode == planner::Mode::Pit) {
        let steps: Vec<&Sample> = r
            .trajectory
            .iter()
            .filter(|s| s.time > p.time + 1e-6)
            .take(REPLAY_HORIZONS[1])
            .collect();
        let in_contact = r
            .trajectory
            .iter()
            .find(|s| (s.time - p.time).abs() < 1e-6)
            .is_some_and(|s| s.contact_force[0] > 0.0);
        if in_contact {
            replay_plan(model, p, &steps, out);
        }
    }
}

/// Bins of the target's turn since the first contact, s·(ψ − ψ_0), 0.1 rad wide.
const TURN_BINS: usize = 14;

/// Per bin of the turn since the first contact: (steps in contact, Σ point x, Σ kinematic
/// x, Σ F_n). The kinematic x is where a bullet corner fixed in a non-rotating frame at
/// the first contact point sits on the turned target: x_0 cos Δψ + s (w/2) sin Δψ.
fn migration(r: &EpisodeResult, half_width: f64, bins: &mut [[f64; 4]; TURN_BINS]) {
    let Some(i0) = r.trajectory.iter().position(|s| s.contact_force[0] > 0.0) else {
        return;
    };
    let s0 = &r.trajectory[i0];
    let side = s0.contact_point[1].signum();
    for s in &r.trajectory[i0..] {
        if s.contact_force[0] <= 0.0 || s.contact_point[1].signum() != side {
            continue;
        }
        let turn = side * wrap(s.target[2] - s0.target[2]);
        if turn < 0.0 {
            continue;
        }
        let b = ((turn / 0.1) as usize).min(TURN_BINS - 1);
        let kin = s0.contact_point[0] * turn.cos() + half_width * turn.sin();
        bins[b][0] += 1.0;
        bins[b][1] += s.contact_point[0];
        bins[b][2] += kin;
        bins[b][3] += s.contact_force[0];
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
    let replay_kind = args.get(4).map(|k| common::model_kind(k, "REPLAY"));
    let scenes = common::scenes(first, count);
    let dt = cfg.controller.mpc.dt;
    let runs = common::map_scenes(&scenes, threads, |sc| {
        let r = run_episode(sc, &cfg, 0).unwrap_or_else(|e| {
            eprintln!("{}: {e}", sc.id);
            std::process::exit(1);
        });
        let kind = replay_kind.unwrap_or(cfg.planner_model.unwrap_or(cfg.model));
        let path = cfg.model_path.as_deref().filter(|_| kind == cfg.model);
        let mut model = sc
            .params
            .load()
            .map_err(|e| e.to_string())
            .and_then(|params| {
                target_model(kind, &cfg.models_dir, path, sc, &params, dt)
                    .map_err(|e| e.to_string())
            })
            .unwrap_or_else(|e| {
                eprintln!("{}: {e}", sc.id);
                std::process::exit(1);
            });
        let mut rep = Replay::default();
        replay(&r, model.as_mut(), &mut rep);
        (r, rep)
    });
    let mut bins = [[0.0; 4]; TURN_BINS];
    for ((r, _), sc) in runs.iter().zip(&scenes) {
        let w = sc.params.load().map_or(1.8, |p| p.target.width);
        migration(r, 0.5 * w, &mut bins);
    }
    let mut rep = Replay::default();
    for (_, x) in &runs {
        for (a, b) in rep.acc.iter_mut().zip(x.acc.iter()) {
            for (p, q) in a.iter_mut().zip(b.iter()) {
                p.0 += q.0;
                p.1 += q.1;
                p.2 += q.2;
            }
        }
        for (a, b) in rep.geometry.iter_mut().zip(x.geometry.iter()) {
            *a += b;
        }
        rep.plan_mismatch = rep.plan_mismatch.max(x.plan_mismatch);
    }
    let results: Vec<EpisodeResult> = runs.into_iter().map(|(r, _)| r).collect();
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
    let replay_name = replay_kind.map_or("the plan's model", |k| k.name());
    println!(
        "\nreplay of the PIT plans made in contact with {replay_name}, from the true state \
         (largest state difference between the plan and its replay: {:.1e})",
        rep.plan_mismatch
    );
    println!("| contact, driver | n | heading RMSE 0.5 s | optimism 0.5 s | heading RMSE 1 s | optimism 1 s |");
    println!("|---|---|---|---|---|---|");
    for ((name, ..), a) in VARIANTS.iter().zip(rep.acc.iter()) {
        let f = |h: usize| {
            let n = a[h].0.max(1) as f64;
            ((a[h].1 / n).sqrt(), a[h].2 / n)
        };
        let ((e0, o0), (e1, o1)) = (f(0), f(1));
        println!(
            "| {name} | {} | {e0:.3} | {o0:+.3} | {e1:.3} | {o1:+.3} |",
            a[0].0
        );
    }
    let g = rep.geometry;
    let n = g[0].max(1.0);
    println!(
        "\ndelivered against planned contact over the first 0.5 s, {} steps in contact: point \
         Δx {:+.3} m, Δy {:+.3} m, normal {:+.3} rad; mean F_n planned {:.0} N, delivered {:.0} N; \
         mean F_n·|x| planned {:.0} N m, delivered {:.0} N m",
        g[0],
        g[1] / n,
        g[2] / n,
        g[3] / n,
        g[4] / n,
        g[5] / n,
        g[6] / n,
        g[7] / n
    );
    println!("\nwhere the bullet touches as the target turns (first contact's side)");
    println!("| turn since first contact (rad) | steps | mean point x (m) | kinematic x (m) | mean F_n (N) |");
    println!("|---|---|---|---|---|");
    for (i, b) in bins.iter().enumerate() {
        let n = b[0].max(1.0);
        println!(
            "| {:.1}–{:.1} | {} | {:+.2} | {:+.2} | {:.0} |",
            0.1 * i as f64,
            0.1 * (i + 1) as f64,
            b[0],
            b[1] / n,
            b[2] / n,
            b[3] / n
        );
    }
}
