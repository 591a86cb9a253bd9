//! Plant speed: a 10 s two-vehicle PIT episode at 1 kHz (goal ≤ 10 ms on one core, i.e.
//! ≥ 1000× real time), and a single step.

use criterion::{criterion_group, criterion_main, Criterion};
use dynamics::params::ParamSet;
use dynamics::plant::{Plant, PlantConfig, VehicleInit};
use std::hint::black_box;
use std::time::Duration;

fn pit_episode(p: &mut Plant) {
    let target = VehicleInit {
        vx: 15.0,
        ..Default::default()
    };
    let bullet = VehicleInit {
        x: -3.9,
        y: -2.4,
        yaw: 20f64.to_radians(),
        vx: 19.0,
        ..Default::default()
    };
    p.reset(&bullet, &target);
    // 10 s: 0.5 s pushing, then braking; the target spins and slides.
    for k in 0..10_000u32 {
        if k == 500 {
            p.set_bullet_command(0.0, -200.0);
        } else if k < 500 {
            p.set_bullet_command(0.08, 400.0);
        }
        p.step();
    }
}

fn bench(c: &mut Criterion) {
    bench_ref::bench(c, "plant", bench_ref::At::Start);
    let set = ParamSet::builtin("full_size").unwrap();
    let mut plant = Plant::new(&set, PlantConfig::default()).unwrap();
    let mut g = c.benchmark_group("plant");
    g.measurement_time(Duration::from_secs(5)).sample_size(30);
    g.bench_function("episode_10s_1khz", |b| {
        b.iter(|| {
            pit_episode(&mut plant);
            black_box(plant.target_state())
        });
    });
    g.finish();
    let mut g = c.benchmark_group("plant");
    g.measurement_time(Duration::from_secs(3)).sample_size(50);
    pit_episode(&mut plant);
    g.bench_function("step", |b| {
        b.iter(|| {
            plant.step();
            black_box(plant.time())
        });
    });
    g.finish();
    bench_ref::bench(c, "plant", bench_ref::At::End);
}

criterion_group!(benches, bench);
criterion_main!(benches);
