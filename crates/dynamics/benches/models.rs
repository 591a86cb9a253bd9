//! Step and step-with-Jacobians timings of the control models (bullet single-track and
//! 4-DOF target) over a fixed, seeded set of 64 driving states, half of them in contact.
//!
//! `cargo bench -p picopit-dynamics --bench models`. Each iteration is one call on the
//! next state of the set, so the reported time is per call.

use criterion::{criterion_group, criterion_main, Criterion};
use dynamics::bullet::{BulletInput, BulletJacobians, BulletModel, BulletState};
use dynamics::geometry::Vec2;
use dynamics::params::ParamSet;
use dynamics::target4dof::FourDofTarget;
use dynamics::{ContactInput, TargetInput, TargetJacobians, TargetModel, TargetState};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::hint::black_box;
use std::time::Duration;

const DT: f64 = 0.05;
const MU: f64 = 0.9;
const SEED: u64 = 0xBE7C_0001;
const STATES: usize = 64;

/// One recorded-like sample for both vehicles.
struct Sample {
    xb: BulletState,
    ub: BulletInput,
    cb: ContactInput,
    xt: TargetState,
    ut: TargetInput,
    ct: ContactInput,
}

fn samples(set: &ParamSet) -> Vec<Sample> {
    let mut rng = ChaCha8Rng::seed_from_u64(SEED);
    let (pb, pt) = (&set.bullet, &set.target);
    (0..STATES)
        .map(|k| {
            let speed = rng.random_range(5.0..30.0);
            let beta: f64 = rng.random_range(-0.3..0.3);
            let psi = rng.random_range(-3.0..3.0);
            let r = rng.random_range(-0.8..0.8);
            let (x, y) = (rng.random_range(0.0..300.0), rng.random_range(-5.0..5.0));
            let in_contact = k % 2 == 1;
            let f_n = if in_contact {
                rng.random_range(0.0..2e4)
            } else {
                0.0
            };
            let fc = Vec2::new(f_n, rng.random_range(-0.4..0.4) * f_n);
            let gamma = psi + rng.random_range(1.0..2.0);
            let rear = pt.length - pt.cg_to_front;
            Sample {
                xb: BulletState::new(x - 3.0, y - 1.5, psi, speed * 1.05, speed * beta.sin(), r),
                ub: BulletInput::new(
                    rng.random_range(-0.2..0.2),
                    rng.random_range(0.0..pb.drive_torque_max),
                ),
                cb: ContactInput {
                    fc,
                    gamma,
                    point_in_body: Vec2::new(pb.cg_to_front, 0.4 * pb.width),
                },
                xt: TargetState::from([
                    speed * beta.cos(),
                    speed * beta.sin(),
                    psi,
                    r,
                    rng.random_range(-0.3..0.3),
                    rng.random_range(-0.05..0.05),
                    x,
                    y,
                ]),
                ut: TargetInput::new(
                    rng.random_range(-0.2..0.2),
                    rng.random_range(0.0..pt.brake_torque_max),
                ),
                ct: ContactInput {
                    fc,
                    gamma,
                    point_in_body: Vec2::new(-rear + 0.3, -0.5 * pt.width),
                },
            }
        })
        .collect()
}

fn models(c: &mut Criterion) {
    bench_ref::bench(c, "models", bench_ref::At::Start);
    let set = ParamSet::builtin("full_size").expect("built-in set");
    let data = samples(&set);
    // One RK4 step over dt (the unit of the 1 µs goal) and the default, stable sub-stepping.
    let bullet = BulletModel::new(&set.bullet, MU, DT).with_substeps(1);
    let mut target = FourDofTarget::new(&set.target, MU, DT).with_substeps(1);
    let mut target4 = FourDofTarget::new(&set.target, MU, DT);

    let mut g = c.benchmark_group("models");
    g.bench_function("bullet_step", |b| {
        let mut i = 0;
        b.iter(|| {
            i = (i + 1) % STATES;
            let s = &data[i];
            black_box(bullet.step(black_box(&s.xb), black_box(&s.ub), black_box(&s.cb)))
        });
    });
    g.bench_function("bullet_step_jac", |b| {
        let mut i = 0;
        let mut jac = BulletJacobians::default();
        b.iter(|| {
            i = (i + 1) % STATES;
            let s = &data[i];
            let xn = bullet.step_jac(
                black_box(&s.xb),
                black_box(&s.ub),
                black_box(&s.cb),
                &mut jac,
            );
            black_box((&xn, &jac));
        });
    });
    g.bench_function("target4dof_step", |b| {
        let mut i = 0;
        b.iter(|| {
            i = (i + 1) % STATES;
            let s = &data[i];
            black_box(target.step(black_box(&s.xt), black_box(&s.ut), black_box(&s.ct)))
        });
    });
    g.bench_function("target4dof_step_jac", |b| {
        let mut i = 0;
        let mut jac = TargetJacobians::default();
        b.iter(|| {
            i = (i + 1) % STATES;
            let s = &data[i];
            let xn = target.step_jac(
                black_box(&s.xt),
                black_box(&s.ut),
                black_box(&s.ct),
                &mut jac,
            );
            black_box((&xn, &jac));
        });
    });
    g.bench_function("target4dof_step_jac_default_substeps", |b| {
        let mut i = 0;
        let mut jac = TargetJacobians::default();
        b.iter(|| {
            i = (i + 1) % STATES;
            let s = &data[i];
            let xn = target4.step_jac(
                black_box(&s.xt),
                black_box(&s.ut),
                black_box(&s.ct),
                &mut jac,
            );
            black_box((&xn, &jac));
        });
    });
    g.finish();
    bench_ref::bench(c, "models", bench_ref::At::End);
}

criterion_group! {
    name = benches;
    config = Criterion::default()
        .sample_size(50)
        .warm_up_time(Duration::from_secs(1))
        .measurement_time(Duration::from_secs(3));
    targets = models
}
criterion_main!(benches);
