//! What the scene examples share: numeric arguments, the scene loader and a scene-parallel
//! map (each example uses some of them).
#![allow(dead_code)]

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
