//! Where the controller's PIT stands against the ideal-PIT bound (`sim::oracle`): for each
//! scenario the controller reached a contact on, whether one ideal shove would have saved it
//! at the controller's contact time (±0.25 s) on the side the bullet chose, on the other
//! side, or only earlier; and the yaw rate the controller's push gave the target.
//!
//! `cargo run --release -p picopit-sim --example oracle_vs_controller -- [CONFIG] [FIRST] [COUNT] [THREADS]`
//! (defaults: `{"preset":"picopinn","clock":"simulated"}`, 0, 192, 2).

use sim::episode::{run_episode, EpisodeConfig};
use sim::oracle::{ideal_pit, OracleSettings};

const SHOVES: [f64; 6] = [0.5, 1.0, 1.5, 2.0, 2.5, 3.0];

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let config = args.first().map_or(
        r#"{"preset":"picopinn","clock":"simulated"}"#,
        String::as_str,
    );
    let first: usize = args.get(1).and_then(|s| s.parse().ok()).unwrap_or(0);
    let count: usize = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(192);
    let threads: usize = args.get(3).and_then(|s| s.parse().ok()).unwrap_or(2).max(1);
    let mut cfg = match EpisodeConfig::parse(config) {
        Ok(c) => c,
        Err(e) => {
            eprintln!("{e}");
            std::process::exit(2);
        }
    };
    cfg.record = true;
    let scenarios = sim::load_jsonl("data/scenarios.jsonl").unwrap_or_else(|e| {
        eprintln!("{e}");
        std::process::exit(2);
    });
    let chosen: Vec<_> = scenarios.iter().skip(first).take(count).collect();
    let mut lines: Vec<(usize, String, [bool; 4])> = std::thread::scope(|s| {
        let hs: Vec<_> = (0..threads)
            .map(|w| {
                let (chosen, cfg) = (&chosen, &cfg);
                s.spawn(move || {
                    let mut out = Vec::new();
                    for (i, sc) in chosen.iter().enumerate().filter(|(i, _)| i % threads == w) {
                        let Ok(r) = run_episode(sc, cfg, 0) else { continue };
                        let Some(k) = r.trajectory.iter().position(|s| s.contact_force[0] > 0.0)
                        else {
                            continue;
                        };
                        let smp = &r.trajectory[k];
                        let (t, b) = (smp.target, smp.bullet);
                        let (sn, cs) = t[2].sin_cos();
                        let lat = -sn * (b[0] - t[6]) + cs * (b[1] - t[7]);
                        let side = if lat >= 0.0 { 1.0 } else { -1.0 };
                        let r_before = if k > 0 { r.trajectory[k - 1].target[3] } else { t[3] };
                        // The largest target yaw rate change within 1 s of the contact.
                        let dr = r.trajectory[k..r.trajectory.len().min(k + 20)]
                            .iter()
                            .map(|s| (s.target[3] - r_before).abs())
                            .fold(0.0, f64::max);
                        let tc = smp.time;
                        let qd = |shoves: Vec<f64>, sides: Vec<f64>, window: [f64; 2]| {
                            let st = OracleSettings {
                                shoves,
                                time_step: 0.05,
                                sides,
                                window: Some(window),
                                ..OracleSettings::default()
                            };
                            ideal_pit(sc, &st).map(|o| o.feasible.is_some()).unwrap_or(false)
                        };
                        let q = |sides: Vec<f64>, window: [f64; 2]| qd(SHOVES.to_vec(), sides, window);
                        // Which shove sizes work on the bullet's side near its contact time.
                        let sizes: Vec<f64> = SHOVES
                            .iter()
                            .copied()
                            .filter(|&dv| qd(vec![dv], vec![side], [tc - 0.25, tc + 0.25]))
                            .collect();
                        let same = q(vec![side], [tc - 0.25, tc + 0.25]);
                        let other = q(vec![-side], [tc - 0.25, tc + 0.25]);
                        let earlier = q(vec![1.0, -1.0], [0.0, tc - 0.25]);
                        let ok = r.success();
                        out.push((
                            i,
                            format!(
                                "{} {:>20} contact {:5.2} s side {:+.0} Δr {:4.2} rad/s | ideal: same side {} other side {} earlier {} | sizes {:?}",
                                sc.id,
                                r.metrics.cause.map_or("success", |c| c.name()),
                                tc,
                                side,
                                dr,
                                same,
                                other,
                                earlier,
                                sizes
                            ),
                            [ok, same, other, earlier],
                        ));
                    }
                    out
                })
            })
            .collect();
        hs.into_iter().flat_map(|h| h.join().unwrap()).collect()
    });
    lines.sort_by_key(|l| l.0);
    for l in &lines {
        println!("{}", l.1);
    }
    let failed: Vec<_> = lines.iter().filter(|l| !l.2[0]).collect();
    let n = failed.len();
    let c = |f: &dyn Fn(&[bool; 4]) -> bool| failed.iter().filter(|l| f(&l.2)).count();
    println!("episodes with a contact: {} ({} failed)", lines.len(), n);
    println!("  of the failed: a shove at the controller's time would have saved it on its side {}, only on the other side {}, on neither but earlier {}, never near or before {}",
        c(&|b| b[1]), c(&|b| !b[1] && b[2]), c(&|b| !b[1] && !b[2] && b[3]), c(&|b| !b[1] && !b[2] && !b[3]));
    let okc = lines.iter().filter(|l| l.2[0]).count();
    println!(
        "  of the {okc} successes: a shove on the same side would have saved it {}",
        lines.iter().filter(|l| l.2[0] && l.2[1]).count()
    );
}
