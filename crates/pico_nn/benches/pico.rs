//! Step-with-Jacobians timings of the learned target surrogates over a fixed, seeded set of
//! 64 driving states, half of them in contact, for nets of the teacher's size and of
//! plausible PicoPINN sizes built from random weights (the timing depends on the widths,
//! not on the values), plus every model file shipped under `models/`.
//!
//! `cargo bench -p picopit-pico-nn --bench pico`. Each iteration is one call on the next
//! state of the set, so the reported time is per call.

#[path = "../tests/common/mod.rs"]
mod common;

use criterion::{criterion_group, criterion_main, Criterion};
use dynamics::geometry::Vec2;
use dynamics::{ContactInput, TargetInput, TargetJacobians, TargetModel, TargetState};
use pico_nn::{JacobianMode, Kernel, SurrogateModel};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::hint::black_box;
use std::path::Path;
use std::time::Duration;

const SEED: u64 = 0xBE7C_0003;
const STATES: usize = 64;

type Sample = (TargetState, TargetInput, ContactInput);

fn samples() -> Vec<Sample> {
    let mut rng = ChaCha8Rng::seed_from_u64(SEED);
    (0..STATES)
        .map(|k| {
            let speed = rng.random_range(5.0..30.0);
            let psi = rng.random_range(-3.0..3.0);
            let f_n = if k % 2 == 1 {
                rng.random_range(0.0..2e4)
            } else {
                0.0
            };
            (
                TargetState::from([
                    speed,
                    rng.random_range(-1.0..1.0),
                    psi,
                    rng.random_range(-0.8..0.8),
                    rng.random_range(-0.3..0.3),
                    rng.random_range(-0.05..0.05),
                    rng.random_range(0.0..300.0),
                    rng.random_range(-5.0..5.0),
                ]),
                TargetInput::new(rng.random_range(-0.2..0.2), rng.random_range(0.0..1500.0)),
                ContactInput {
                    fc: Vec2::new(f_n, rng.random_range(-0.4..0.4) * f_n),
                    gamma: psi + rng.random_range(1.0..2.0),
                    point_in_body: Vec2::new(-2.0, -0.8),
                },
            )
        })
        .collect()
}

fn random_model(widths: &[usize]) -> SurrogateModel {
    let mut rng = ChaCha8Rng::seed_from_u64(SEED);
    SurrogateModel::from_bytes(&common::random_teacher(widths, &mut rng).to_bytes())
        .expect("a valid generated model")
}

fn name(widths: &[usize]) -> String {
    widths
        .iter()
        .map(ToString::to_string)
        .collect::<Vec<_>>()
        .join("_")
}

fn bench_step_jac(
    c: &mut Criterion,
    group: &str,
    id: &str,
    model: &mut SurrogateModel,
    data: &[Sample],
) {
    let mut g = c.benchmark_group(group);
    g.bench_function(id, |b| {
        let mut i = 0;
        let mut jac = TargetJacobians::default();
        b.iter(|| {
            i = (i + 1) % STATES;
            let (x, u, ct) = &data[i];
            let xn = model.step_jac(black_box(x), black_box(u), black_box(ct), &mut jac);
            black_box((&xn, &jac));
        });
    });
    g.finish();
}

fn pico(c: &mut Criterion) {
    bench_ref::bench(c, "pico", bench_ref::At::Start);
    let data = samples();
    // The gated configurations: the default kernel and Jacobian mode.
    for widths in [
        &[11, 64, 64, 64, 8][..],
        &[11, 40, 40, 8],
        // A wider student: does it fit the 2 µs budget? (docs/surrogates.md)
        &[11, 48, 48, 8],
        &[11, 32, 32, 8],
        &[11, 24, 24, 24, 8],
        &[11, 16, 16, 8],
    ] {
        let mut m = random_model(widths);
        bench_step_jac(
            c,
            "pico",
            &format!("step_jac_{}", name(widths)),
            &mut m,
            &data,
        );
    }
    // The step alone at the shipped PicoPINN's widths.
    let mut m = random_model(&[11, 40, 40, 8]);
    let mut g = c.benchmark_group("pico");
    g.bench_function("step_11_40_40_8", |b| {
        let mut i = 0;
        b.iter(|| {
            i = (i + 1) % STATES;
            let (x, u, ct) = &data[i];
            black_box(m.step(black_box(x), black_box(u), black_box(ct)))
        });
    });
    g.finish();

    // The alternatives the defaults were chosen against (docs/pico_nn.md).
    for widths in [&[11, 64, 64, 64, 8][..], &[11, 40, 40, 8]] {
        for (kernel, mode, tag) in [
            (Kernel::Portable, JacobianMode::Reverse, "portable_reverse"),
            (Kernel::Portable, JacobianMode::Forward, "portable_forward"),
            (Kernel::Avx2Fma, JacobianMode::Reverse, "avx2_reverse"),
            (Kernel::Avx2Fma, JacobianMode::Forward, "avx2_forward"),
            (Kernel::Avx512, JacobianMode::Reverse, "avx512_reverse"),
            (Kernel::Avx512, JacobianMode::Forward, "avx512_forward"),
        ] {
            let mut m = random_model(widths)
                .with_kernel(kernel)
                .with_jacobian_mode(mode);
            if m.network().kernel() != kernel {
                continue;
            }
            bench_step_jac(
                c,
                "pico_variants",
                &format!("{tag}_{}", name(widths)),
                &mut m,
                &data,
            );
        }
    }

    // Shipped models, if any: models/<parameter set>/<kind>.safetensors.
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../models");
    let mut files: Vec<_> = std::fs::read_dir(root)
        .into_iter()
        .flatten()
        .flatten()
        .flat_map(|set| {
            std::fs::read_dir(set.path())
                .into_iter()
                .flatten()
                .flatten()
        })
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|e| e == "safetensors"))
        .collect();
    files.sort();
    for path in files {
        let id = path
            .strip_prefix(Path::new(env!("CARGO_MANIFEST_DIR")).join("../../models"))
            .unwrap_or(&path)
            .with_extension("")
            .to_string_lossy()
            .replace(['/', '\\'], "_");
        match SurrogateModel::from_path(&path) {
            Ok(mut m) => bench_step_jac(c, "pico_models", &format!("step_jac_{id}"), &mut m, &data),
            Err(e) => eprintln!("skipping {}: {e}", path.display()),
        }
    }
    bench_ref::bench(c, "pico", bench_ref::At::End);
}

criterion_group! {
    name = benches;
    config = Criterion::default()
        .sample_size(50)
        .warm_up_time(Duration::from_secs(1))
        .measurement_time(Duration::from_secs(2));
    targets = pico
}
criterion_main!(benches);
