//! `ctrl_step/<surrogate>`: one RTI control step of the coupled MPC (linearisation, QP
//! assembly, Clarabel, rollout) over a fixed set of recorded states: a closed-loop PIT
//! approach and contact on the plant (5 s at 20 Hz, 4-DOF prediction, default reference),
//! replayed in order so that each step starts from the previous step's shifted plan, as on
//! the vehicle.

use criterion::{criterion_group, criterion_main, Criterion};
use dynamics::params::ParamSet;
use dynamics::road::Road;
use dynamics::target4dof::FourDofTarget;
use dynamics::TargetModel;
use mpc::{CoupledMpc, MpcSettings};
use std::path::Path;

#[path = "../examples/common/record.rs"]
mod record;
use record::{record, Record, MU};

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
            let input = r.input(road);
            std::hint::black_box(mpc.solve(&input).unwrap())
        });
    });
    group.finish();
}

fn ctrl_step(c: &mut Criterion) {
    bench_ref::bench(c, "ctrl_step", bench_ref::At::Start);
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
    bench_ref::bench(c, "ctrl_step", bench_ref::At::End);
}

criterion_group!(benches, ctrl_step);
criterion_main!(benches);
