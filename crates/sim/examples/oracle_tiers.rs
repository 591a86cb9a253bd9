//! How much of the ideal-PIT bound (`sim::oracle`) a controller could reach, in tiers of what
//! it knows and how precisely it acts. For each scenario the whole grid of single shoves is
//! simulated twice: with the target driver's true law, and with the driver's command at the
//! shove held from then on (what a planner that sees only the current command believes).
//! Each tier picks a shove in its world and is judged in the true one:
//!
//! * `ideal`: some shove succeeds (the ideal-PIT bound);
//! * `robust-t`, `robust-v`, `robust-tv`: some shove succeeds together with its neighbours
//!   ±1 time step (0.1 s), ±1 size step (×/÷ 1.25), or both (a 3 × 3 box): the bound for a
//!   controller whose push lands that far off;
//! * `ideal-exp`: the best expected success if the push lands anywhere in the 3 × 3 box of the
//!   chosen shove, equally likely, the choice made with the truth;
//! * `held-first`: the earliest shove that succeeds under the held command, judged true;
//! * `held-robust`: the shove with the most successes in its 3 × 3 box under the held
//!   command, judged true;
//! * `held-exp`: that choice's expected true success when the push lands anywhere in its box.
//!
//! `cargo run --release -p picopit-sim --example oracle_tiers -- [FIRST] [COUNT] [THREADS]
//! [SETTINGS]` (defaults 0, 192, 2, a 10-size geometric grid 0.4–3.15 m/s every 0.1 s).
//! One `scene` line per scenario, then the shares overall and by driver and category.

mod common;

use sim::oracle::{shove_grid, DriverView, GridChoice, OracleSettings, ShoveGrid};
use std::collections::BTreeMap;

const TIERS: [&str; 8] = [
    "ideal",
    "robust-t",
    "robust-v",
    "robust-tv",
    "ideal-exp",
    "held-first",
    "held-robust",
    "held-exp",
];

/// Per tier, the chance of success (0 or 1, or the share of a box that succeeds).
fn tiers(truth: &ShoveGrid, held: &ShoveGrid) -> [f64; 8] {
    let whole = |g: &ShoveGrid, rt: usize, rv: usize| {
        f64::from(u8::from(
            g.most_robust(rt, rv).is_some_and(|c| c.score == c.of),
        ))
    };
    let at = |c: Option<GridChoice>| {
        f64::from(u8::from(c.is_some_and(|c| {
            truth.get(c.time as isize, c.side, c.shove as isize)
        })))
    };
    // Expected success when the executed shove lands anywhere in the ±1 × ±1 box of the
    // chosen one, equally likely.
    let expected = |c: Option<GridChoice>| {
        c.map_or(0.0, |c| {
            truth.box_score(c.time, c.side, c.shove, 1, 1) as f64 / 9.0
        })
    };
    let pick = held.most_robust(1, 1);
    let best = truth.most_robust(1, 1);
    [
        at(truth.earliest()),
        whole(truth, 1, 0),
        whole(truth, 0, 1),
        f64::from(u8::from(best.is_some_and(|c| c.score == c.of))),
        best.map_or(0.0, |c| c.score as f64 / c.of as f64),
        at(held.earliest()),
        at(pick),
        expected(pick),
    ]
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let first = common::number(&args, 0, "FIRST", 0);
    let count = common::number(&args, 1, "COUNT", 192);
    let threads = common::number(&args, 2, "THREADS", 2);
    let default = r#"{"shoves":[0.4,0.5,0.63,0.8,1.0,1.25,1.6,2.0,2.5,3.15],"time_step":0.1}"#;
    let settings: OracleSettings =
        match serde_json::from_str(args.get(3).map_or(default, String::as_str)) {
            Ok(s) => s,
            Err(e) => {
                eprintln!("oracle settings: {e}");
                std::process::exit(2);
            }
        };
    let chosen = common::scenes(first, count);
    let t0 = std::time::Instant::now();
    let results = common::map_scenes(&chosen, threads, |sc| {
        shove_grid(sc, &settings, DriverView::True)
            .and_then(|t| shove_grid(sc, &settings, DriverView::Held).map(|h| (t, h)))
    });
    let mut groups: BTreeMap<String, (usize, [f64; 8])> = BTreeMap::new();
    for (sc, r) in chosen.iter().zip(&results) {
        let (truth, held) = match r {
            Ok(g) => g,
            Err(e) => {
                println!("{}: error: {e}", sc.id);
                continue;
            }
        };
        let t = tiers(truth, held);
        let share = |g: &ShoveGrid| {
            g.success.iter().filter(|&&b| b).count() as f64 / g.success.len().max(1) as f64
        };
        println!(
            "scene {} {} {} {} true_share {:.3} held_share {:.3} | {}",
            sc.id,
            sc.category.name(),
            sc.driver.kind(),
            sc.params.name(),
            share(truth),
            share(held),
            TIERS
                .iter()
                .zip(t)
                .map(|(n, b)| format!("{n}={b:.2}"))
                .collect::<Vec<_>>()
                .join(" ")
        );
        for key in [
            "all".to_owned(),
            format!("driver {}", sc.driver.kind()),
            format!("category {}", sc.category.name()),
        ] {
            let g = groups.entry(key).or_default();
            g.0 += 1;
            for (k, b) in t.iter().enumerate() {
                g.1[k] += *b;
            }
        }
    }
    println!(
        "{} scenes in {:.1} s",
        results.len(),
        t0.elapsed().as_secs_f64()
    );
    println!(
        "{:28} {:>6} {}",
        "group",
        "scenes",
        TIERS.map(|n| format!("{n:>12}")).join("")
    );
    for (k, (n, c)) in &groups {
        println!(
            "{k:28} {n:6} {}",
            c.map(|v| format!("{:>11.1}%", 100.0 * v / (*n).max(1) as f64))
                .join("")
        );
    }
}
