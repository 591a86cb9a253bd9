//! Per-step wall time of the RTI control step for each surrogate over the recorded
//! closed-loop PIT states of the `ctrl_step` bench (5 s at 20 Hz): median, p99 and max, split
//! into coupled QPs (contact admissible somewhere in the horizon) and bullet-only QPs.
//! Criterion's p99 is over sample means; this is over single control steps.
//!
//! `cargo run --release -p picopit-mpc --example ctrl_step_stats [repeats]`

use dynamics::bullet::{BulletInput, BulletState};
use dynamics::params::ParamSet;
use dynamics::plant::{Plant, PlantConfig, VehicleInit};
use dynamics::road::Road;
use dynamics::target4dof::FourDofTarget;
use dynamics::{TargetInput, TargetModel, TargetState};
use mpc::reference::DefaultPit;
use mpc::{CoupledMpc, MpcInput, MpcSettings, Reference, Side};
use std::path::Path;
use std::time::Instant;

const MU: f64 = 0.9;

struct Record {
    target: TargetState,
    bullet: BulletState,
    last: BulletInput,
    reference: Reference,
}

fn record(params: &ParamSet, road: &Road) -> Vec<Record> {
    let settings = MpcSettings::default();
    let target = Box::new(FourDofTarget::new(&params.target, MU, settings.dt));
    let mut mpc = CoupledMpc::new(params, MU, target, settings.clone()).unwrap();
    let mut plant = Plant::new(
        params,
        PlantConfig {
            mu: MU,
            ..PlantConfig::default()
        },
    )
    .unwrap();
    let lane = road.lane_center_offset(1);
    plant.reset(
        &VehicleInit {
            x: 40.0,
            y: lane + 3.0,
            yaw: 0.0,
            vx: 17.0,
            vy: 0.0,
            r: 0.0,
        },
        &VehicleInit {
            x: 50.0,
            y: lane,
            yaw: 0.0,
            vx: 15.0,
            vy: 0.0,
            r: 0.0,
        },
    );
    let pit = DefaultPit::new(params, Side::Left);
    let mut reference = Reference::new(settings.horizon);
    let mut last = BulletInput::zeros();
    let mut out = Vec::new();
    for _ in 0..100 {
        let (xt, xb) = (plant.target_state(), plant.bullet_state());
        pit.fill(
            &mut reference,
            xt.as_slice(),
            xb.as_slice(),
            settings.dt,
            0.0,
        );
        out.push(Record {
            target: xt,
            bullet: xb,
            last,
            reference: reference.clone(),
        });
        let input = MpcInput {
            time: 0.0,
            target: xt,
            bullet: xb,
            target_input: TargetInput::zeros(),
            last_command: last,
            road: Some(road),
            obstacles: &[],
            reference: &reference,
        };
        last = mpc.solve(&input).unwrap().command;
        plant.set_bullet_command_blended(last[0], last[1]);
        plant.advance(settings.dt);
    }
    out
}

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
    let repeats: usize = std::env::args()
        .nth(1)
        .and_then(|a| a.parse().ok())
        .unwrap_or(5);
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
        for _ in 0..repeats {
            mpc.reset();
            for r in &records {
                let input = MpcInput {
                    time: 0.0,
                    target: r.target,
                    bullet: r.bullet,
                    target_input: TargetInput::zeros(),
                    last_command: r.last,
                    road: Some(&road),
                    obstacles: &[],
                    reference: &r.reference,
                };
                let t0 = Instant::now();
                let out = mpc.solve(&input).unwrap();
                let ms = t0.elapsed().as_secs_f64() * 1e3;
                std::hint::black_box(out);
                all.push(ms);
                if mpc.last_qp_coupled() {
                    coupled.push(ms)
                } else {
                    bullet.push(ms)
                }
            }
        }
        println!("{name:>9} all:         {}", stats(&mut all));
        println!("{name:>9} coupled:     {}", stats(&mut coupled));
        println!("{name:>9} bullet-only: {}", stats(&mut bullet));
    }
}
