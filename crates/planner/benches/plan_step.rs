//! `plan_step/<surrogate>`: one decision of the upper layer (the candidate search with its
//! SCP over Clarabel QPs) over the states recorded from a closed-loop PIT on the plant, from
//! the approach through the contact (`examples/common/record.rs`).
//!
//! One iteration plans every recorded state in order and the time is reported per decision:
//! the states differ in cost by more than tenfold (a chase decision against a contact
//! search), so a sample that planned only a stretch of them would measure which stretch it
//! drew, not the planner.

use criterion::{criterion_group, criterion_main, Criterion};
use dynamics::params::ParamSet;
use planner::{Planner, PlannerSettings};

#[path = "../examples/common/record.rs"]
mod record;
use record::{models, obstacles, record, road, MU};

fn plan_step(c: &mut Criterion) {
    bench_ref::bench(c, "plan_step", bench_ref::At::Start);
    let params = ParamSet::builtin("full_size").unwrap();
    let records = record(&params);
    let road = road();
    let obstacles = obstacles();
    let settings = PlannerSettings::default();
    let mut group = c.benchmark_group("plan_step");
    group
        .sample_size(10)
        .sampling_mode(criterion::SamplingMode::Flat)
        .measurement_time(std::time::Duration::from_secs(10));
    for (name, model) in models(&params, settings.dt) {
        let mut p = Planner::new(&params, MU, model, settings.clone()).unwrap();
        group.bench_function(name, |b| {
            b.iter_custom(|iters| {
                let start = std::time::Instant::now();
                for _ in 0..iters {
                    for r in &records {
                        std::hint::black_box(p.plan(&r.input(&road, &obstacles)).unwrap().mode);
                    }
                }
                start.elapsed() / records.len() as u32
            });
        });
    }
    group.finish();
    bench_ref::bench(c, "plan_step", bench_ref::At::End);
}

criterion_group!(benches, plan_step);
criterion_main!(benches);
