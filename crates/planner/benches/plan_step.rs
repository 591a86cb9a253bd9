//! `plan_step/<surrogate>`: one decision of the upper layer (the candidate search with its
//! SCP over Clarabel QPs) over the states recorded from a closed-loop PIT on the plant, from
//! the approach through the contact (`examples/common/record.rs`).

use criterion::{criterion_group, criterion_main, Criterion};
use dynamics::params::ParamSet;
use planner::{Planner, PlannerSettings};

#[path = "../examples/common/record.rs"]
mod record;
use record::{models, obstacles, record, road, MU};

fn plan_step(c: &mut Criterion) {
    let params = ParamSet::builtin("full_size").unwrap();
    let records = record(&params);
    let road = road();
    let obstacles = obstacles();
    let settings = PlannerSettings::default();
    let mut group = c.benchmark_group("plan_step");
    group
        .sample_size(30)
        .measurement_time(std::time::Duration::from_secs(5));
    for (name, model) in models(&params, settings.dt) {
        let mut p = Planner::new(&params, MU, model, settings.clone()).unwrap();
        let mut i = 0;
        group.bench_function(name, |b| {
            b.iter(|| {
                let r = &records[i % records.len()];
                i += 1;
                std::hint::black_box(p.plan(&r.input(&road, &obstacles)).unwrap().mode)
            });
        });
    }
    group.finish();
}

criterion_group!(benches, plan_step);
criterion_main!(benches);
