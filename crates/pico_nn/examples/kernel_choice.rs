//! Does the load-time choice between the AVX2 and AVX-512 kernels pay? For each model file
//! given, load it `LOADS` times (each load gets its own heap buffers, so alignment varies as
//! it does in a deployment) and, per load, time `step_jac` under both kernels interleaved
//! (the least time of 40 batches of 200 calls each, so co-tenant noise is filtered out the
//! same way for both), and report which kernel the load picked and what it gained.
//!
//! `cargo run --release -p picopit-pico-nn --example kernel_choice -- models/full_size/picopinn.safetensors models/full_size/pinn.safetensors`

use dynamics::geometry::Vec2;
use dynamics::{ContactInput, TargetInput, TargetJacobians, TargetModel, TargetState};
use pico_nn::{Kernel, SurrogateModel};
use std::hint::black_box;
use std::time::{Duration, Instant};

const LOADS: usize = 20;
const BATCHES: usize = 40;
const CALLS: usize = 200;

fn per_call(m: &mut SurrogateModel, kernel: Kernel, best: &mut Duration) {
    m.network().set_kernel(kernel);
    let x = TargetState::from([15.0, 0.2, 0.1, 0.3, 0.0, 0.01, 10.0, 1.0]);
    let u = TargetInput::new(0.02, 300.0);
    let c = ContactInput {
        fc: Vec2::new(8000.0, 900.0),
        gamma: 1.7,
        point_in_body: Vec2::new(-2.0, -0.8),
    };
    let mut jac = TargetJacobians::default();
    let start = Instant::now();
    for _ in 0..CALLS {
        black_box(m.step_jac(black_box(&x), &u, &c, &mut jac));
    }
    *best = (*best).min(start.elapsed() / CALLS as u32);
}

fn main() {
    if !(Kernel::Avx2Fma.available() && Kernel::Avx512.available()) {
        println!("this CPU lacks AVX2+FMA or AVX-512: nothing to choose");
        return;
    }
    for path in std::env::args().skip(1) {
        let (mut picked_avx2, mut loss, mut t_chosen, mut t_avx512) = (0, 0.0f64, 0.0, 0.0);
        for _ in 0..LOADS {
            let mut m = match SurrogateModel::from_path(&path) {
                Ok(m) => m,
                Err(e) => {
                    eprintln!("{path}: {e}");
                    std::process::exit(2);
                }
            };
            let chosen = m.network().kernel();
            let (mut a2, mut a5) = (Duration::MAX, Duration::MAX);
            for _ in 0..BATCHES {
                per_call(&mut m, Kernel::Avx2Fma, &mut a2);
                per_call(&mut m, Kernel::Avx512, &mut a5);
            }
            let (a2, a5) = (a2.as_secs_f64() * 1e6, a5.as_secs_f64() * 1e6);
            let t = if chosen == Kernel::Avx2Fma { a2 } else { a5 };
            picked_avx2 += usize::from(chosen == Kernel::Avx2Fma);
            loss = loss.max(t - a2.min(a5));
            t_chosen += t;
            t_avx512 += a5;
        }
        let n = LOADS as f64;
        println!(
            "{path}: AVX2 picked in {picked_avx2}/{LOADS} loads; step_jac mean of per-load minima: chosen {:.3} µs, always AVX-512 {:.3} µs ({:+.1} %); worst loss against the better kernel {:.3} µs",
            t_chosen / n,
            t_avx512 / n,
            100.0 * (t_chosen - t_avx512) / t_avx512,
            loss,
        );
    }
}
