//! Does a model of the target driver's reaction help a chooser that does not know the
//! driver's law? For each scenario the grid of single shoves (`sim::oracle::shove_grid`) is
//! simulated in the true world, with the driver's command held from the shove on, and under
//! each reaction hypothesis of `sim::DriverHypothesis` (lane keeping, letting go, braking,
//! counter-steering, each with the middle of the dataset's parameter ranges). A chooser picks
//! the most forgiving shove (the fullest ±0.1 s × ±25 % box) in its world; the pick is
//! judged in the true world, exactly (`<view>`) and as the expected success when the push
//! lands anywhere in the box (`<view>-exp`). `mix` picks the shove with the most successes
//! summed over the four hypotheses' boxes (a planner that plans against all four).
//!
//! `cargo run --release -p picopit-sim --example oracle_driver_models -- [FIRST] [COUNT]
//! [THREADS]` (defaults 0, 128, 2; the grid of `oracle_tiers`). One `scene` line per scenario,
//! then the shares overall and by driver.

use sim::oracle::{shove_grid, DriverView, GridChoice, OracleSettings, ShoveGrid};
use sim::DriverHypothesis;
use std::collections::BTreeMap;

const HYPOTHESES: [DriverHypothesis; 4] = [
    DriverHypothesis::LaneKeep,
    DriverHypothesis::Release,
    DriverHypothesis::Brake,
    DriverHypothesis::CounterSteer,
];
const VIEWS: [&str; 6] = [
    "held",
    "lane_keep",
    "release",
    "brake",
    "counter_steer",
    "mix",
];

/// The cell whose ±1 × ±1 boxes hold the most successes summed over `grids` (ties: the
/// earliest), among cells that succeed in at least one of them.
fn pick_sum(grids: &[ShoveGrid]) -> Option<GridChoice> {
    let g0 = &grids[0];
    let mut best: Option<GridChoice> = None;
    for it in 0..g0.times.len() {
        for iv in 0..g0.shoves.len() {
            for is in 0..g0.sides.len() {
                if !grids.iter().any(|g| g.get(it as isize, is, iv as isize)) {
                    continue;
                }
                let score = grids.iter().map(|g| g.box_score(it, is, iv, 1, 1)).sum();
                if best.is_none_or(|b| score > b.score) {
                    best = Some(GridChoice {
                        time: it,
                        side: is,
                        shove: iv,
                        score,
                        of: 9 * grids.len(),
                    });
                }
            }
        }
    }
    best
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let number = |i: usize, name: &str, default: usize| -> usize {
        args.get(i).map_or(default, |s| {
            s.parse().unwrap_or_else(|_| {
                eprintln!("{name}: {s:?} is not a non-negative integer");
                std::process::exit(2);
            })
        })
    };
    let first = number(0, "FIRST", 0);
    let count = number(1, "COUNT", 128);
    let threads = number(2, "THREADS", 2).max(1);
    let settings: OracleSettings = serde_json::from_str(
        r#"{"shoves":[0.4,0.5,0.63,0.8,1.0,1.25,1.6,2.0,2.5,3.15],"time_step":0.1}"#,
    )
    .expect("the built-in oracle settings parse");
    let scenarios = sim::load_jsonl("data/scenarios.jsonl").unwrap_or_else(|e| {
        eprintln!("{e}");
        std::process::exit(2);
    });
    let chosen: Vec<_> = scenarios.iter().skip(first).take(count).collect();
    let t0 = std::time::Instant::now();
    let mut results: Vec<_> = std::thread::scope(|s| {
        let hs: Vec<_> = (0..threads)
            .map(|w| {
                let (chosen, settings) = (&chosen, &settings);
                s.spawn(move || {
                    chosen
                        .iter()
                        .enumerate()
                        .filter(|(i, _)| i % threads == w)
                        .map(|(i, sc)| {
                            let views = [DriverView::True, DriverView::Held]
                                .into_iter()
                                .chain(HYPOTHESES.map(DriverView::Assume));
                            let r: Result<Vec<ShoveGrid>, _> =
                                views.map(|v| shove_grid(sc, settings, v)).collect();
                            (i, r)
                        })
                        .collect::<Vec<_>>()
                })
            })
            .collect();
        hs.into_iter()
            .flat_map(|h| h.join().expect("oracle worker panicked"))
            .collect()
    });
    results.sort_by_key(|(i, _)| *i);
    // Per group: scenes, ideal, then per view (exact, expected).
    let mut groups: BTreeMap<String, (usize, f64, [[f64; 2]; 6])> = BTreeMap::new();
    for (i, r) in &results {
        let sc = chosen[*i];
        let grids = match r {
            Ok(g) => g,
            Err(e) => {
                println!("{}: error: {e}", sc.id);
                continue;
            }
        };
        let truth = &grids[0];
        let judge = |c: Option<GridChoice>| -> [f64; 2] {
            c.map_or([0.0; 2], |c| {
                [
                    f64::from(u8::from(truth.get(
                        c.time as isize,
                        c.side,
                        c.shove as isize,
                    ))),
                    truth.box_score(c.time, c.side, c.shove, 1, 1) as f64 / 9.0,
                ]
            })
        };
        let mut v = [[0.0; 2]; 6];
        for k in 0..5 {
            v[k] = judge(grids[k + 1].most_robust(1, 1));
        }
        v[5] = judge(pick_sum(&grids[2..]));
        let ideal = f64::from(u8::from(truth.earliest().is_some()));
        println!(
            "scene {} {} {} ideal={ideal} | {}",
            sc.id,
            sc.category.name(),
            sc.driver.kind(),
            VIEWS
                .iter()
                .zip(v)
                .map(|(n, [a, e])| format!("{n}={a:.0} {n}-exp={e:.2}"))
                .collect::<Vec<_>>()
                .join(" ")
        );
        for key in ["all".to_owned(), format!("driver {}", sc.driver.kind())] {
            let g = groups.entry(key).or_default();
            g.0 += 1;
            g.1 += ideal;
            for k in 0..6 {
                g.2[k][0] += v[k][0];
                g.2[k][1] += v[k][1];
            }
        }
    }
    println!(
        "{} scenes in {:.1} s",
        results.len(),
        t0.elapsed().as_secs_f64()
    );
    print!("{:22} {:>6} {:>7}", "group", "scenes", "ideal");
    for n in VIEWS {
        print!(" {:>14} {:>18}", n, format!("{n}-exp"));
    }
    println!();
    for (k, (n, ideal, v)) in &groups {
        let pc = |x: f64| 100.0 * x / (*n).max(1) as f64;
        print!("{k:22} {n:6} {:>6.1}%", pc(*ideal));
        for [a, e] in v {
            print!(" {:>13.1}% {:>17.1}%", pc(*a), pc(*e));
        }
        println!();
    }
}
