//! `ctrl_step/<surrogate>`: one RTI control step of the coupled MPC (linearisation, QP
//! assembly, Clarabel, rollout) over a fixed set of recorded states: a closed-loop PIT
//! approach and contact on the plant (5 s at 20 Hz, 4-DOF prediction, default reference),
//! replayed in order so that each step starts from the previous step's shifted plan, as on
//! the vehicle.

use criterion::{criterion_group, criterion_main, Criterion};
use dynamics::bullet::{BulletInput, BulletState};
use dynamics::params::ParamSet;
use dynamics::plant::{Plant, PlantConfig, VehicleInit};
use dynamics::road::Road;
use dynamics::target4dof::FourDofTarget;
use dynamics::{TargetInput, TargetModel, TargetState};
use mpc::reference::DefaultPit;
use mpc::{CoupledMpc, MpcInput, MpcSettings, Reference, Side};
use std::path::Path;

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

fn bench_surrogate(
    c: &mut Criterion,
    name: &str,
    params: &ParamSet,
    road: &Road,
    records: &[Record],
    target: Box<dyn TargetModel + Send + Sync>,
) {
    let mut mpc = CoupledMpc::new(params, MU, target, MpcSettings::default()).unwrap();
    let mut i = 0;
    let mut group = c.benchmark_group("ctrl_step");
    group
        .sample_size(60)
        .measurement_time(std::time::Duration::from_secs(4));
    group.bench_function(name, |b| {
        b.iter(|| {
            let r = &records[i % records.len()];
            if i % records.len() == 0 {
                mpc.reset();
            }
            i += 1;
            let input = MpcInput {
                time: 0.0,
                target: r.target,
                bullet: r.bullet,
                target_input: TargetInput::zeros(),
                last_command: r.last,
                road: Some(road),
                obstacles: &[],
                reference: &r.reference,
            };
            std::hint::black_box(mpc.solve(&input).unwrap())
        });
    });
    group.finish();
}

fn ctrl_step(c: &mut Criterion) {
    let params = ParamSet::builtin("full_size").unwrap();
    let road = Road::straight(2000.0, 3, 3.5, 1.0);
    let records = record(&params, &road);
    let dt = MpcSettings::default().dt;
    bench_surrogate(
        c,
        "4dof",
        &params,
        &road,
        &records,
        Box::new(FourDofTarget::new(&params.target, MU, dt)),
    );
    let models = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../models/full_size");
    for kind in ["pinn", "picopinn"] {
        let path = models.join(format!("{kind}.safetensors"));
        match pico_nn::SurrogateModel::from_path(&path).and_then(|m| m.with_mu(MU)) {
            Ok(m) => bench_surrogate(c, kind, &params, &road, &records, Box::new(m)),
            Err(e) => eprintln!("ctrl_step/{kind}: skipped ({}: {e})", path.display()),
        }
    }
}

criterion_group!(benches, ctrl_step);
criterion_main!(benches);
