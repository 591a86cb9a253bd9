//! After load, `step`, `step_jac` and the raw forward pass allocate nothing (they run
//! N times per MPC linearisation, inside the control loop).

mod common;

use alloc_count::{allocations, CountingAlloc};
use dynamics::geometry::Vec2;
use dynamics::{ContactInput, TargetInput, TargetJacobians, TargetModel, TargetState};
use pico_nn::{JacobianMode, Kernel, SurrogateModel};
use rand_chacha::rand_core::SeedableRng;
use rand_chacha::ChaCha8Rng;

#[global_allocator]
static GLOBAL: CountingAlloc = CountingAlloc;

#[test]
fn step_and_step_jac_allocate_nothing() {
    let mut rng = ChaCha8Rng::seed_from_u64(31);
    let teacher = common::random_teacher(&[11, 64, 64, 64, 8], &mut rng).to_bytes();
    let pico = common::clustered(&[11, 24, 24, 24, 8], 50, &mut rng)
        .0
        .to_bytes();
    let mut models = Vec::new();
    for bytes in [&teacher, &pico] {
        for kernel in [Kernel::Portable, Kernel::detect()] {
            for mode in [JacobianMode::Reverse, JacobianMode::Forward] {
                models.push(
                    SurrogateModel::from_bytes(bytes)
                        .unwrap()
                        .with_kernel(kernel)
                        .with_jacobian_mode(mode),
                );
            }
        }
    }
    let mut jac = TargetJacobians::default();
    let before = allocations();
    let mut sum = 0.0;
    for m in &mut models {
        for k in 0..200 {
            let s = f64::from(k);
            let x = TargetState::from([10.0 + 0.05 * s, 0.1, 0.01 * s, 0.2, 0.0, 0.01, s, 0.0]);
            let u = TargetInput::new(0.02, 100.0);
            let c = ContactInput {
                fc: Vec2::new(if k % 2 == 0 { 0.0 } else { 3000.0 }, 200.0),
                gamma: 1.5,
                point_in_body: Vec2::new(-2.0, -0.8),
            };
            sum += m.step(&x, &u, &c)[0];
            sum += m.step_jac(&x, &u, &c, &mut jac)[0] + jac.a[(0, 0)];
            let z = SurrogateModel::features(&x, &u, &c);
            sum += m.forward(&z)[0];
        }
    }
    let after = allocations();
    assert!(sum.is_finite());
    assert_eq!(after - before, 0, "the surrogate allocated while stepping");
}
