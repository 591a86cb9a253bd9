//! What the scene examples share: numeric arguments, the scene loader and a scene-parallel
//! map (each example uses some of them).
#![allow(dead_code)]

use sim::episode::{ModelKind, PlanRecord};
use sim::Scenario;

/// The `i`-th argument as a non-negative integer, `default` when absent; anything else
/// exits with code 2 naming the argument.
pub fn number(args: &[String], i: usize, name: &str, default: usize) -> usize {
    args.get(i).map_or(default, |s| {
        s.parse().unwrap_or_else(|_| {
            eprintln!("{name}: {s:?} is not a non-negative integer");
            std::process::exit(2);
        })
    })
}

/// A target model's name (`4dof`, `pinn`, `picopinn`) given as argument `name`; anything
/// else exits with code 2 naming the argument.
pub fn model_kind(k: &str, name: &str) -> ModelKind {
    serde_json::from_str(&format!("\"{k}\"")).unwrap_or_else(|_| {
        eprintln!("{name}: {k:?} is not one of 4dof, pinn, picopinn");
        std::process::exit(2);
    })
}

/// One line on a recorded plan: its time and mode, the span of plan steps with a planned
/// push (`dt`: the plan's step) and the push's peak normal force, and the predicted
/// heading error.
pub fn plan_line(p: &PlanRecord, dt: f64) -> String {
    let pushed: Vec<_> = p.predicted.iter().filter(|s| s.2[0] > 0.0).collect();
    let window = match (pushed.first(), pushed.last()) {
        (Some(a), Some(b)) => format!("{:.2}–{:.2} s", a.0, b.0 + dt),
        _ => "none".to_owned(),
    };
    let peak = pushed.iter().map(|s| s.2[0]).fold(0.0, f64::max);
    format!(
        "plan t={:5.2} {:?} push {window} peak {peak:.0} N, predicted heading error {:5.2} rad",
        p.time, p.mode, p.predicted_heading_error
    )
}

/// Scenes `first .. first + count` of `data/scenarios.jsonl` (exit code 2 if it does not
/// load).
pub fn scenes(first: usize, count: usize) -> Vec<Scenario> {
    let all = sim::load_jsonl("data/scenarios.jsonl").unwrap_or_else(|e| {
        eprintln!("{e}");
        std::process::exit(2);
    });
    all.into_iter().skip(first).take(count).collect()
}

/// `f` over the scenes on `threads` threads (scene `i` on thread `i mod threads`), the
/// results in scene order.
pub fn map_scenes<R: Send>(
    scenes: &[Scenario],
    threads: usize,
    f: impl Fn(&Scenario) -> R + Sync,
) -> Vec<R> {
    let threads = threads.max(1);
    let mut results: Vec<(usize, R)> = std::thread::scope(|s| {
        let hs: Vec<_> = (0..threads)
            .map(|w| {
                let f = &f;
                s.spawn(move || {
                    scenes
                        .iter()
                        .enumerate()
                        .filter(|(i, _)| i % threads == w)
                        .map(|(i, sc)| (i, f(sc)))
                        .collect::<Vec<_>>()
                })
            })
            .collect();
        hs.into_iter()
            .flat_map(|h| h.join().expect("oracle worker panicked"))
            .collect()
    });
    results.sort_by_key(|(i, _)| *i);
    results.into_iter().map(|(_, r)| r).collect()
}
