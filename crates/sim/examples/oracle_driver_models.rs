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

mod common;

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

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let first = common::number(&args, 0, "FIRST", 0);
    let count = common::number(&args, 1, "COUNT", 128);
    let threads = common::number(&args, 2, "THREADS", 2);
    let settings: OracleSettings = serde_json::from_str(
        r#"{"shoves":[0.4,0.5,0.63,0.8,1.0,1.25,1.6,2.0,2.5,3.15],"time_step":0.1}"#,
    )
    .expect("the built-in oracle settings parse");
    let chosen = common::scenes(first, count);
    let t0 = std::time::Instant::now();
    let results = common::map_scenes(&chosen, threads, |sc| {
        [DriverView::True, DriverView::Held]
            .into_iter()
            .chain(HYPOTHESES.map(DriverView::Assume))
            .map(|v| shove_grid(sc, &settings, v))
            .collect::<Result<Vec<ShoveGrid>, _>>()
    });
    // Per group: scenes, ideal, then per view (exact, expected).
    let mut groups: BTreeMap<String, (usize, f64, [[f64; 2]; 6])> = BTreeMap::new();
    for (sc, r) in chosen.iter().zip(&results) {
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
        v[5] = judge(ShoveGrid::most_robust_over(&grids[2..], 1, 1));
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
            for (sum, [a, e]) in g.2.iter_mut().zip(v) {
                sum[0] += a;
                sum[1] += e;
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
