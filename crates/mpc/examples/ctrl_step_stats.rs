//! Per-step wall time of the RTI control step for each surrogate over the recorded
//! closed-loop PIT states of the `ctrl_step` bench (5 s at 20 Hz): median, p99 and max, split
//! into coupled QPs (contact admissible somewhere in the horizon) and bullet-only QPs.
//! Criterion's p99 is over sample means; this is over single control steps.
//!
//! `cargo run --release -p picopit-mpc --example ctrl_step_stats [repeats]`

use dynamics::params::ParamSet;
use dynamics::road::Road;
use dynamics::target4dof::FourDofTarget;
use dynamics::TargetModel;
use mpc::{CoupledMpc, MpcSettings};
use std::path::Path;

mod common {
    pub mod record;
}
use common::record::{record, MU};
use std::time::Instant;

fn stats(v: &mut [f64]) -> String {
    if v.is_empty() {
        return "—".to_owned();
    }
    v.sort_by(f64::total_cmp);
    let q = |p: f64| v[((v.len() - 1) as f64 * p).round() as usize];
    format!(
        "median {:6.2} ms  p99 {:6.2} ms  max {:6.2} ms  (n={})",
        q(0.5),
        q(0.99),
        v[v.len() - 1],
        v.len()
    )
}

fn main() {
    let repeats: usize = match std::env::args().nth(1) {
        None => 5,
        Some(a) => match a.parse::<usize>() {
            Ok(n) if n > 0 => n,
            _ => {
                eprintln!("ctrl_step_stats: repeats = {a:?}: expected a positive integer");
                std::process::exit(2);
            }
        },
    };
    let params = ParamSet::builtin("full_size").unwrap();
    let road = Road::straight(2000.0, 3, 3.5, 1.0);
    let records = record(&params, &road);
    let dt = MpcSettings::default().dt;
    let models = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../models/full_size");
    let mut surrogates: Vec<(String, Box<dyn TargetModel + Send + Sync>)> = vec![(
        "4dof".into(),
        Box::new(FourDofTarget::new(&params.target, MU, dt)),
    )];
    for kind in ["pinn", "picopinn"] {
        match pico_nn::SurrogateModel::from_path(models.join(format!("{kind}.safetensors")))
            .and_then(|m| m.with_mu(MU))
        {
            Ok(m) => surrogates.push((kind.into(), Box::new(m))),
            Err(e) => eprintln!("{kind}: skipped ({e})"),
        }
    }
    println!(
        "{} recorded states x {repeats} passes; machine load: {}",
        records.len(),
        std::fs::read_to_string("/proc/loadavg")
            .unwrap_or_default()
            .trim()
    );
    for (name, target) in surrogates {
        let mut mpc = CoupledMpc::new(&params, MU, target, MpcSettings::default()).unwrap();
        let (mut all, mut coupled, mut bullet) = (Vec::new(), Vec::new(), Vec::new());
        // Coupled steps: summed phase times (ms) and IPM iterations, for the means.
        let (mut lin, mut asm, mut qp, mut iters) = (0.0, 0.0, 0.0, 0usize);
        for _ in 0..repeats {
            mpc.reset();
            for r in &records {
                let input = r.input(&road);
                let t0 = Instant::now();
                let out = mpc.solve(&input).unwrap();
                let ms = t0.elapsed().as_secs_f64() * 1e3;
                all.push(ms);
                if mpc.last_qp_coupled() {
                    lin += out.times.linearise * 1e3;
                    asm += out.times.assemble * 1e3;
                    qp += out.times.qp * 1e3;
                    iters += out.qp_iterations as usize;
                    coupled.push(ms)
                } else {
                    bullet.push(ms)
                }
            }
        }
        println!("{name:>9} all:         {}", stats(&mut all));
        println!("{name:>9} coupled:     {}", stats(&mut coupled));
        println!("{name:>9} bullet-only: {}", stats(&mut bullet));
        let k = coupled.len().max(1) as f64;
        println!(
            "{name:>9} coupled means: linearise {:.2} ms, assemble {:.2} ms, QP {:.2} ms, {:.1} IPM iterations",
            lin / k,
            asm / k,
            qp / k,
            iters as f64 / k
        );
    }
}
