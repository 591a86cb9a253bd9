//! The network and the step: a naive reference forward pass, Jacobians against central
//! finite differences, and the teacher and clustered layouts of the same ŵ.

mod common;

use common::{base_matrix, clustered, random_dense, statistics, teacher};
use dynamics::geometry::Vec2;
use dynamics::{ContactInput, TargetInput, TargetJacobians, TargetModel, TargetState};
use pico_nn::{JacobianMode, Kernel, SurrogateModel};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

const SHAPES: [&[usize]; 4] = [
    &[11, 8],
    &[11, 24, 24, 24, 8],
    &[11, 32, 32, 8],
    &[11, 64, 64, 64, 8],
];

/// The map of docs/model-format.md written as plainly as possible: the network on all 11
/// features, plus the linear base B z (`common::base_matrix`).
fn reference(dense: &[(Vec<f64>, Vec<f64>)], z: &[f64; 11]) -> [f64; 8] {
    let [im, is, om, os] = statistics();
    let mut h: Vec<f64> = (0..11).map(|j| (z[j] - im[j]) / is[j]).collect();
    for (l, (w, b)) in dense.iter().enumerate() {
        let n_in = h.len();
        let mut y: Vec<f64> = b
            .iter()
            .enumerate()
            .map(|(i, bi)| bi + (0..n_in).map(|j| w[i * n_in + j] * h[j]).sum::<f64>())
            .collect();
        if l + 1 < dense.len() {
            y.iter_mut().for_each(|v| *v = v.tanh());
        }
        h = y;
    }
    let b = base_matrix();
    std::array::from_fn(|k| om[k] + os[k] * h[k] + (0..11).map(|j| b[k][j] * z[j]).sum::<f64>())
}

/// The 11 features: the model's 10 per-step ones and μ.
fn with_mu(z: &[f64; 10], mu: f64) -> [f64; 11] {
    std::array::from_fn(|j| if j < 10 { z[j] } else { mu })
}

fn random_case(rng: &mut ChaCha8Rng) -> (TargetState, TargetInput, ContactInput) {
    let speed = rng.random_range(3.0..30.0);
    let psi = rng.random_range(-7.0..7.0);
    let x = TargetState::from([
        speed,
        rng.random_range(-2.0..2.0),
        psi,
        rng.random_range(-1.0..1.0),
        rng.random_range(-0.3..0.3),
        rng.random_range(-0.05..0.05),
        // Small positions keep the finite differences of X⁺, Y⁺ clear of round-off.
        rng.random_range(-10.0..10.0),
        rng.random_range(-10.0..10.0),
    ]);
    let u = TargetInput::new(rng.random_range(-0.3..0.3), rng.random_range(0.0..2000.0));
    let f_n = if rng.random_bool(0.2) {
        0.0
    } else {
        rng.random_range(0.0..15000.0)
    };
    let c = ContactInput {
        fc: Vec2::new(f_n, rng.random_range(-0.5..0.5) * f_n),
        gamma: psi + rng.random_range(-2.5..2.5),
        point_in_body: Vec2::new(rng.random_range(-2.5..2.5), rng.random_range(-0.9..0.9)),
    };
    (x, u, c)
}

fn load(bytes: &[u8], kernel: Kernel, mode: JacobianMode) -> SurrogateModel {
    SurrogateModel::from_bytes(bytes)
        .expect("valid model")
        .with_kernel(kernel)
        .with_jacobian_mode(mode)
}

/// Every kernel and Jacobian mode (a kernel the CPU lacks falls back to the portable one).
const VARIANTS: [(Kernel, JacobianMode); 6] = [
    (Kernel::Portable, JacobianMode::Reverse),
    (Kernel::Portable, JacobianMode::Forward),
    (Kernel::Avx2Fma, JacobianMode::Reverse),
    (Kernel::Avx2Fma, JacobianMode::Forward),
    (Kernel::Avx512, JacobianMode::Reverse),
    (Kernel::Avx512, JacobianMode::Forward),
];

#[test]
fn forward_matches_the_plain_reference() {
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    for widths in SHAPES {
        let dense = random_dense(widths, &mut rng);
        let bytes = teacher("pinn", widths, &dense).to_bytes();
        for (kernel, mode) in VARIANTS {
            let mut m = load(&bytes, kernel, mode);
            assert_eq!(m.layers(), widths);
            for _ in 0..50 {
                let (x, u, c) = random_case(&mut rng);
                let mu = rng.random_range(0.15..=1.0);
                m.set_mu(mu).unwrap();
                let z = SurrogateModel::features(&x, &u, &c);
                let o = m.forward(&z);
                let r = reference(&dense, &with_mu(&z, mu));
                // All 11 features at once, μ outside the trained range too (the raw map).
                let mu_raw = rng.random_range(0.0..2.0);
                let o_raw = m.forward_features(&with_mu(&z, mu_raw));
                let r_raw = reference(&dense, &with_mu(&z, mu_raw));
                assert_eq!(m.mu(), mu, "forward_features leaves the model's mu");
                for (o, r) in [(o, r), (o_raw, r_raw)] {
                    for k in 0..8 {
                        let tol = 1e-12 * r[k].abs().max(1.0);
                        assert!(
                            (o[k] - r[k]).abs() <= tol,
                            "{widths:?} {kernel:?} o[{k}] = {} vs {}",
                            o[k],
                            r[k]
                        );
                    }
                }
            }
        }
    }
}

#[test]
fn step_follows_the_next_state_formula() {
    let mut rng = ChaCha8Rng::seed_from_u64(12);
    let widths = [11, 16, 8];
    let dense = random_dense(&widths, &mut rng);
    let mut m =
        SurrogateModel::from_bytes(&teacher("picopinn", &widths, &dense).to_bytes()).unwrap();
    assert_eq!(m.name(), "picopinn");
    assert_eq!(m.dt(), 0.05);
    assert_eq!(m.param_count(), 11 * 16 + 16 + 16 * 8 + 8);
    assert_eq!(m.mu(), 0.9, "the file's mu_default");
    assert_eq!(m.mu_range(), (0.15, 1.0));
    for _ in 0..20 {
        let (x, u, c) = random_case(&mut rng);
        // Features by hand: the force in the body frame and its moment.
        let a = c.gamma - x[2];
        let fb = Vec2::new(
            a.cos() * c.fc.x - a.sin() * c.fc.y,
            a.sin() * c.fc.x + a.cos() * c.fc.y,
        );
        let mz = c.point_in_body.x * fb.y - c.point_in_body.y * fb.x;
        let z = [x[0], x[1], x[3], x[4], x[5], u[0], u[1], fb.x, fb.y, mz];
        let zm = SurrogateModel::features(&x, &u, &c);
        for j in 0..10 {
            assert!(
                (z[j] - zm[j]).abs() <= 1e-12 * z[j].abs().max(1.0),
                "feature {j}"
            );
        }
        let mu = rng.random_range(0.15..=1.0);
        m.set_mu(mu).unwrap();
        let o = reference(&dense, &with_mu(&z, mu));
        let next = m.step(&x, &u, &c);
        let (s, co) = x[2].sin_cos();
        let expect = [
            x[0] + o[0],
            x[1] + o[1],
            x[2] + o[5],
            x[3] + o[2],
            x[4] + o[3],
            x[5] + o[4],
            x[6] + co * o[6] - s * o[7],
            x[7] + s * o[6] + co * o[7],
        ];
        for i in 0..8 {
            assert!(
                (next[i] - expect[i]).abs() <= 1e-11 * expect[i].abs().max(1.0),
                "x+[{i}]"
            );
        }
    }
}

/// Central differences of `step` in every argument, compared with `step_jac`.
#[test]
fn jacobians_match_central_differences() {
    let mut rng = ChaCha8Rng::seed_from_u64(13);
    for widths in SHAPES {
        let dense = random_dense(widths, &mut rng);
        let bytes = teacher("pinn", widths, &dense).to_bytes();
        for (kernel, mode) in VARIANTS {
            let mut m = load(&bytes, kernel, mode);
            let mut jac = TargetJacobians::default();
            for _ in 0..20 {
                let (x, u, c) = random_case(&mut rng);
                let next = m.step_jac(&x, &u, &c, &mut jac);
                let plain = m.step(&x, &u, &c);
                assert_eq!(next, plain, "step_jac and step give the same state");
                // Fourth-order central differences: truncation O(h⁴), so the tolerance is
                // mostly the round-off of differencing x⁺.
                let check = |name: &str,
                             col: usize,
                             h: f64,
                             exact: &dyn Fn(usize) -> f64,
                             perturb: &dyn Fn(f64) -> TargetState| {
                    let (p2, p1, m1, m2) =
                        (perturb(2.0 * h), perturb(h), perturb(-h), perturb(-2.0 * h));
                    for i in 0..8 {
                        let fd = (8.0 * (p1[i] - m1[i]) - (p2[i] - m2[i])) / (12.0 * h);
                        let e = exact(i);
                        let tol = 1e-6 * fd.abs().max(e.abs()).max(1e-3)
                            + 1e-14 * p1[i].abs().max(1.0) / h;
                        assert!((fd - e).abs() <= tol, "{widths:?} {kernel:?} {mode:?} d x+[{i}] / d {name}[{col}]: exact {e}, fd {fd}");
                    }
                };
                for col in 0..8 {
                    let h = 1e-5 * x[col].abs().max(1.0);
                    let perturb = |d: f64| {
                        let mut xp = x;
                        xp[col] += d;
                        m.clone().step(&xp, &u, &c)
                    };
                    check("x", col, h, &|i| jac.a[(i, col)], &perturb);
                }
                for col in 0..2 {
                    let h = 1e-5 * u[col].abs().max(1.0);
                    let perturb = |d: f64| {
                        let mut up = u;
                        up[col] += d;
                        m.clone().step(&x, &up, &c)
                    };
                    check("u", col, h, &|i| jac.b[(i, col)], &perturb);
                    let h = 1e-5 * c.fc[col].abs().max(1.0);
                    let perturb = |d: f64| {
                        let mut cp = c;
                        cp.fc[col] += d;
                        m.clone().step(&x, &u, &cp)
                    };
                    check("fc", col, h, &|i| jac.f[(i, col)], &perturb);
                }
            }
        }
    }
}

/// Both Jacobian modes and both kernels agree to rounding.
#[test]
fn kernels_and_modes_agree() {
    let mut rng = ChaCha8Rng::seed_from_u64(14);
    let widths = [11, 64, 64, 64, 8];
    let bytes = teacher("pinn", &widths, &random_dense(&widths, &mut rng)).to_bytes();
    let mut models: Vec<SurrogateModel> = VARIANTS
        .iter()
        .map(|&(k, md)| load(&bytes, k, md))
        .collect();
    for _ in 0..50 {
        let (x, u, c) = random_case(&mut rng);
        let mut jacs = vec![TargetJacobians::default(); models.len()];
        let nexts: Vec<TargetState> = models
            .iter_mut()
            .zip(&mut jacs)
            .map(|(m, j)| m.step_jac(&x, &u, &c, j))
            .collect();
        for (n, j) in nexts.iter().zip(&jacs).skip(1) {
            assert!((n - nexts[0]).amax() <= 1e-12 * nexts[0].amax().max(1.0));
            assert!((j.a - jacs[0].a).amax() <= 1e-12 * jacs[0].a.amax().max(1.0));
            assert!((j.b - jacs[0].b).amax() <= 1e-12 * jacs[0].b.amax().max(1e-3));
            assert!((j.f - jacs[0].f).amax() <= 1e-12 * jacs[0].f.amax().max(1e-6));
        }
    }
}

/// A clustered file and the teacher layout of the same expanded ŵ are the same model,
/// bit for bit.
#[test]
fn clustered_and_teacher_layouts_are_identical() {
    let mut rng = ChaCha8Rng::seed_from_u64(15);
    for widths in [&[11, 24, 24, 24, 8][..], &[11, 32, 32, 8]] {
        let (spec, dense) = clustered(widths, 40, &mut rng);
        assert!(
            dense.iter().any(|(w, _)| w.contains(&0.0)),
            "some weights are pruned"
        );
        let mut pico = SurrogateModel::from_bytes(&spec.to_bytes()).unwrap();
        let mut full =
            SurrogateModel::from_bytes(&teacher("pinn", widths, &dense).to_bytes()).unwrap();
        assert_eq!(pico.param_count(), 40);
        assert_eq!(pico.name(), "picopinn");
        assert!(full.param_count() > 1000);
        let (mut ja, mut jb) = (TargetJacobians::default(), TargetJacobians::default());
        for _ in 0..50 {
            let (x, u, c) = random_case(&mut rng);
            assert_eq!(
                pico.step_jac(&x, &u, &c, &mut ja),
                full.step_jac(&x, &u, &c, &mut jb)
            );
            assert_eq!(ja, jb);
        }
    }
}

/// `a` and `b` give the same step and Jacobians, bit for bit, on `n` random cases.
fn assert_same_bits(
    a: &mut SurrogateModel,
    b: &mut SurrogateModel,
    rng: &mut ChaCha8Rng,
    n: usize,
    what: &str,
) {
    let (mut ja, mut jb) = (TargetJacobians::default(), TargetJacobians::default());
    for _ in 0..n {
        let (x, u, c) = random_case(rng);
        assert_eq!(
            a.step_jac(&x, &u, &c, &mut ja),
            b.step_jac(&x, &u, &c, &mut jb),
            "{what}"
        );
        assert_eq!(ja, jb, "{what}");
    }
}

/// The two FMA kernels accumulate every element in the same order: bit-identical results
/// (when this CPU has both).
#[test]
fn fma_kernels_agree_bit_for_bit() {
    if !(Kernel::Avx2Fma.available() && Kernel::Avx512.available()) {
        eprintln!("skipped: this CPU lacks AVX2+FMA or AVX-512");
        return;
    }
    let mut rng = ChaCha8Rng::seed_from_u64(16);
    for widths in SHAPES {
        let bytes = teacher("pinn", widths, &random_dense(widths, &mut rng)).to_bytes();
        for mode in [JacobianMode::Reverse, JacobianMode::Forward] {
            let mut a = load(&bytes, Kernel::Avx2Fma, mode);
            let mut b = load(&bytes, Kernel::Avx512, mode);
            assert_same_bits(
                &mut a,
                &mut b,
                &mut rng,
                50,
                &format!("{widths:?} {mode:?}"),
            );
        }
    }
}

/// A loaded net starts on an FMA kernel when the CPU has one: with both, on whichever was
/// faster for its widths at load, and then its numbers are those of either (the choice is
/// timed, so the test pins nothing about which).
#[test]
fn a_loaded_net_starts_on_an_fma_kernel_with_the_same_numbers() {
    let both = Kernel::Avx2Fma.available() && Kernel::Avx512.available();
    let mut rng = ChaCha8Rng::seed_from_u64(19);
    for widths in SHAPES {
        let bytes = teacher("pinn", widths, &random_dense(widths, &mut rng)).to_bytes();
        let mut m = SurrogateModel::from_bytes(&bytes).unwrap();
        let kernel = m.network().kernel();
        if both {
            assert!(
                matches!(kernel, Kernel::Avx2Fma | Kernel::Avx512),
                "{kernel:?}"
            );
        } else {
            assert_eq!(kernel, Kernel::detect());
        }
        let mut pinned = load(&bytes, Kernel::detect(), JacobianMode::Reverse);
        assert_same_bits(&mut m, &mut pinned, &mut rng, 20, &format!("{widths:?}"));
    }
}

/// μ changes the prediction, is refused outside the trained range (the model keeps its
/// previous μ), and `with_mu` equals `set_mu`.
#[test]
fn mu_is_a_checked_property_of_the_model() {
    let mut rng = ChaCha8Rng::seed_from_u64(17);
    let widths = [11, 24, 24, 8];
    let bytes = teacher("pinn", &widths, &random_dense(&widths, &mut rng)).to_bytes();
    let mut m = SurrogateModel::from_bytes(&bytes).unwrap();
    let (x, u, c) = random_case(&mut rng);
    let at_default = m.step(&x, &u, &c);
    for bad in [0.1, 1.2, -0.5, f64::NAN, f64::INFINITY] {
        let e = m.set_mu(bad).unwrap_err();
        assert!(e.to_string().contains("mu"), "{e}");
        assert!(e.to_string().contains("mu_range"), "{e}");
        assert_eq!(m.mu(), 0.9);
    }
    assert_eq!(m.step(&x, &u, &c), at_default);
    m.set_mu(0.3).unwrap();
    let low = m.step(&x, &u, &c);
    assert_ne!(low, at_default, "mu is an input of the network");
    let mut w = SurrogateModel::from_bytes(&bytes)
        .unwrap()
        .with_mu(0.3)
        .unwrap();
    assert_eq!(w.step(&x, &u, &c), low);
    assert!(SurrogateModel::from_bytes(&bytes)
        .unwrap()
        .with_mu(1.01)
        .is_err());
    // Back to the default reproduces the first prediction bit for bit.
    m.set_mu(0.9).unwrap();
    assert_eq!(m.step(&x, &u, &c), at_default);
}
