//! The ideal-PIT bound over the scenario dataset (`sim::oracle`): for each scenario, whether
//! any single rear-quarter shove at a time the bullet could be there ends in success by the
//! benchmark's test; one line per scenario, then the share by category, adhesion band,
//! driver and parameter set.
//!
//! `cargo run --release -p picopit-sim --example oracle -- [FIRST] [COUNT] [FILE] [THREADS]
//! [SETTINGS]` (defaults 0, all, data/scenarios.jsonl, 2, `{}`; SETTINGS is JSON of
//! `sim::OracleSettings`, e.g. `'{"shoves":[0.5,1,1.5,2,2.5,3],"time_step":0.1}'`).

mod common;

use sim::oracle::{ideal_pit, OracleSettings};
use std::collections::BTreeMap;

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let first = common::number(&args, 0, "FIRST", 0);
    let count = common::number(&args, 1, "COUNT", usize::MAX);
    let file = args.get(2).map_or("data/scenarios.jsonl", String::as_str);
    let threads = common::number(&args, 3, "THREADS", 2);
    let scenarios = match sim::load_jsonl(file) {
        Ok(s) => s,
        Err(e) => {
            eprintln!("{e}");
            std::process::exit(2);
        }
    };
    let chosen: Vec<_> = scenarios.into_iter().skip(first).take(count).collect();
    let settings: OracleSettings =
        match serde_json::from_str(args.get(4).map_or("{}", String::as_str)) {
            Ok(s) => s,
            Err(e) => {
                eprintln!("oracle settings: {e}");
                std::process::exit(2);
            }
        };
    let t0 = std::time::Instant::now();
    let results = common::map_scenes(&chosen, threads, |sc| ideal_pit(sc, &settings));
    let mut groups: BTreeMap<String, (usize, usize)> = BTreeMap::new();
    let mut total = (0, 0);
    for (sc, r) in chosen.iter().zip(&results) {
        let r = match r {
            Ok(r) => r,
            Err(e) => {
                println!("{}: error: {e}", sc.id);
                continue;
            }
        };
        let ok = r.feasible.is_some();
        match &r.feasible {
            Some(f) => println!(
                "{} feasible   shove at {:5.2} s side {:+.0} dv {:.1} m/s -> success at {:5.2} s ({}) | reach {:5.2} s, tried {}, succeeded {}",
                sc.id,
                f.time,
                f.side,
                f.dv,
                f.decided_at,
                if f.at_rest { "at rest" } else { "settled" },
                r.t_reach,
                r.tried,
                r.successes
            ),
            None => println!(
                "{} infeasible | reach {:5.2} s, tried {}, alone fails at {}",
                sc.id,
                r.t_reach,
                r.tried,
                r.alone_fails_at.map_or("-".to_owned(), |t| format!("{t:.2} s"))
            ),
        }
        total.1 += 1;
        total.0 += usize::from(ok);
        for key in [
            format!("category {}", sc.category.name()),
            format!("adhesion {}", sc.adhesion.name()),
            format!("driver {}", sc.driver.kind()),
            format!("params {}", sc.params.name()),
        ] {
            let g = groups.entry(key).or_default();
            g.1 += 1;
            g.0 += usize::from(ok);
        }
    }
    let pct = |a: usize, b: usize| 100.0 * a as f64 / b.max(1) as f64;
    println!(
        "ideally feasible: {}/{} ({:.1} %) in {:.1} s",
        total.0,
        total.1,
        pct(total.0, total.1),
        t0.elapsed().as_secs_f64()
    );
    for (k, (a, b)) in &groups {
        println!("  {k:28} {a:5}/{b:<5} {:5.1} %", pct(*a, *b));
    }
}
