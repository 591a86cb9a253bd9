//! Model files built in code for the tests and benches: random weights, a teacher layout
//! (R = identity) or a clustered one (shared indices, signs, zeros), serialised with the
//! safetensors crate exactly as `docs/model-format.md` lays them out.
#![allow(dead_code)]

use rand::Rng;
use rand_chacha::ChaCha8Rng;
use safetensors::tensor::TensorView;
use safetensors::Dtype;
use std::collections::HashMap;

/// Dense layers: `(W row-major [out][in], b)` each.
pub type Dense = Vec<(Vec<f64>, Vec<f64>)>;

/// One named tensor: dtype, shape and little-endian bytes.
#[derive(Debug, Clone)]
pub struct Raw {
    pub name: String,
    pub dtype: Dtype,
    pub shape: Vec<usize>,
    pub data: Vec<u8>,
}

impl Raw {
    pub fn f64s(name: &str, shape: &[usize], v: &[f64]) -> Self {
        Self {
            name: name.into(),
            dtype: Dtype::F64,
            shape: shape.to_vec(),
            data: v.iter().flat_map(|x| x.to_le_bytes()).collect(),
        }
    }
    pub fn i32s(name: &str, shape: &[usize], v: &[i32]) -> Self {
        Self {
            name: name.into(),
            dtype: Dtype::I32,
            shape: shape.to_vec(),
            data: v.iter().flat_map(|x| x.to_le_bytes()).collect(),
        }
    }
    pub fn i8s(name: &str, shape: &[usize], v: &[i8]) -> Self {
        Self {
            name: name.into(),
            dtype: Dtype::I8,
            shape: shape.to_vec(),
            data: v.iter().map(|&x| x as u8).collect(),
        }
    }
}

/// A whole model file before serialisation.
#[derive(Debug, Clone)]
pub struct Spec {
    pub tensors: Vec<Raw>,
    pub metadata: HashMap<String, String>,
}

pub const FEATURES: &str = "vx,vy,r,p,phi,delta,T_b,f_bx,f_by,M_z,mu";
pub const OUTPUTS: &str = "dvx,dvy,dr,dp,dphi,dpsi,dx_b,dy_b";

/// Plausible feature and output statistics of a full-size target (SI units).
pub fn statistics() -> [Vec<f64>; 4] {
    [
        vec![15.0, 0.0, 0.0, 0.0, 0.0, 0.0, 500.0, 0.0, 0.0, 0.0, 0.55],
        vec![
            6.0, 1.0, 0.4, 0.2, 0.03, 0.1, 800.0, 4000.0, 4000.0, 6000.0, 0.25,
        ],
        vec![-0.1, 0.0, 0.0, 0.0, 0.0, 0.0, 0.75, 0.0],
        vec![0.3, 0.2, 0.1, 0.05, 0.01, 0.02, 0.3, 0.05],
    ]
}

/// A linear base `B` (8 × 11, row-major) shaped like the one the training writes: the
/// kinematic increments dt·[p, r, vx, vy] and the rigid-body impulse of the contact force
/// and moment (m = 1500 kg, I_z = 2500 kg m²), plus a small μ column so that every kind
/// of entry is exercised.
pub fn base_matrix() -> [[f64; 11]; 8] {
    let (dt, m, iz) = (0.05, 1500.0, 2500.0);
    let mut b = [[0.0; 11]; 8];
    b[4][3] = dt; // Δφ ← p
    b[5][2] = dt; // Δψ ← r
    b[6][0] = dt; // Δx_b ← vx
    b[7][1] = dt; // Δy_b ← vy
    b[0][7] = dt / m; // Δvx ← f_bx
    b[1][8] = dt / m; // Δvy ← f_by
    b[2][9] = dt / iz; // Δr ← M_z
    b[5][9] = 0.5 * dt * dt / iz; // Δψ ← M_z
    b[6][7] = 0.5 * dt * dt / m; // Δx_b ← f_bx
    b[7][8] = 0.5 * dt * dt / m; // Δy_b ← f_by
    b[0][10] = -0.01; // Δvx ← μ
    b
}

pub fn metadata(kind: &str, widths: &[usize]) -> HashMap<String, String> {
    let layers = widths
        .iter()
        .map(ToString::to_string)
        .collect::<Vec<_>>()
        .join(",");
    [
        ("format", "picopit-mlp"),
        ("version", "3"),
        ("kind", kind),
        ("activation", "tanh"),
        ("layers", layers.as_str()),
        ("features", FEATURES),
        ("outputs", OUTPUTS),
        ("dt", "0.05"),
        ("param_set", "full_size"),
        ("mu_range", "0.15,1.0"),
        ("mu_default", "0.9"),
        ("seed", "7"),
    ]
    .into_iter()
    .map(|(k, v)| (k.to_owned(), v.to_owned()))
    .collect()
}

/// Random dense weights `(W row-major [out][in], b)` per layer, scaled 1/sqrt(in).
pub fn random_dense(widths: &[usize], rng: &mut ChaCha8Rng) -> Dense {
    widths
        .windows(2)
        .map(|w| {
            let (n_in, n_out) = (w[0], w[1]);
            let scale = 1.5 / (n_in as f64).sqrt();
            let wt = (0..n_in * n_out)
                .map(|_| scale * rng.random_range(-1.0..1.0))
                .collect();
            let b = (0..n_out)
                .map(|_| 0.2 * rng.random_range(-1.0..1.0))
                .collect();
            (wt, b)
        })
        .collect()
}

/// The teacher layout of dense weights: θ = all weights and biases in order, idx = identity,
/// sign = +1.
pub fn teacher(kind: &str, widths: &[usize], dense: &[(Vec<f64>, Vec<f64>)]) -> Spec {
    let mut theta = Vec::new();
    let mut tensors = Vec::new();
    for (l, ((w, b), ww)) in dense.iter().zip(widths.windows(2)).enumerate() {
        let (n_in, n_out) = (ww[0], ww[1]);
        for (part, values, shape) in [("weight", w, vec![n_out, n_in]), ("bias", b, vec![n_out])] {
            let start = theta.len() as i32;
            let idx: Vec<i32> = (0..values.len() as i32).map(|i| start + i).collect();
            theta.extend_from_slice(values);
            tensors.push(Raw::i32s(
                &format!("layer{}.{part}.idx", l + 1),
                &shape,
                &idx,
            ));
            tensors.push(Raw::i8s(
                &format!("layer{}.{part}.sign", l + 1),
                &shape,
                &vec![1; values.len()],
            ));
        }
    }
    finish(kind, widths, theta, tensors)
}

/// A clustered layout: `n_free` shared centres, every weight `sign · θ[idx]` with random
/// idx and sign ∈ {−1, 0, +1}. Returns the spec and its expanded dense weights.
pub fn clustered(widths: &[usize], n_free: usize, rng: &mut ChaCha8Rng) -> (Spec, Dense) {
    let theta: Vec<f64> = (0..n_free).map(|_| rng.random_range(0.05..0.6)).collect();
    let mut tensors = Vec::new();
    let mut dense = Vec::new();
    for (l, ww) in widths.windows(2).enumerate() {
        let (n_in, n_out) = (ww[0], ww[1]);
        let mut layer = Vec::new();
        for (part, shape) in [("weight", vec![n_out, n_in]), ("bias", vec![n_out])] {
            let n: usize = shape.iter().product();
            let idx: Vec<i32> = (0..n).map(|_| rng.random_range(0..n_free as i32)).collect();
            let sign: Vec<i8> = (0..n).map(|_| rng.random_range(-1..=1)).collect();
            layer.push(
                idx.iter()
                    .zip(&sign)
                    .map(|(&i, &s)| f64::from(s) * theta[i as usize])
                    .collect::<Vec<f64>>(),
            );
            tensors.push(Raw::i32s(
                &format!("layer{}.{part}.idx", l + 1),
                &shape,
                &idx,
            ));
            tensors.push(Raw::i8s(
                &format!("layer{}.{part}.sign", l + 1),
                &shape,
                &sign,
            ));
        }
        let b = layer.pop().unwrap();
        dense.push((layer.pop().unwrap(), b));
    }
    (finish("picopinn", widths, theta, tensors), dense)
}

fn finish(kind: &str, widths: &[usize], theta: Vec<f64>, mut tensors: Vec<Raw>) -> Spec {
    let [im, is, om, os] = statistics();
    tensors.push(Raw::f64s("theta", &[theta.len()], &theta));
    tensors.push(Raw::f64s("in_mean", &[11], &im));
    tensors.push(Raw::f64s("in_std", &[11], &is));
    tensors.push(Raw::f64s("out_mean", &[8], &om));
    tensors.push(Raw::f64s("out_std", &[8], &os));
    let b: Vec<f64> = base_matrix().iter().flatten().copied().collect();
    tensors.push(Raw::f64s("base", &[8, 11], &b));
    Spec {
        tensors,
        metadata: metadata(kind, widths),
    }
}

impl Spec {
    pub fn to_bytes(&self) -> Vec<u8> {
        let views: Vec<(String, TensorView<'_>)> = self
            .tensors
            .iter()
            .map(|t| {
                (
                    t.name.clone(),
                    TensorView::new(t.dtype, t.shape.clone(), &t.data).expect("consistent tensor"),
                )
            })
            .collect();
        safetensors::serialize(views, Some(self.metadata.clone())).expect("serialise")
    }

    pub fn tensor_mut(&mut self, name: &str) -> &mut Raw {
        self.tensors
            .iter_mut()
            .find(|t| t.name == name)
            .unwrap_or_else(|| panic!("no tensor {name}"))
    }

    pub fn without_tensor(mut self, name: &str) -> Self {
        self.tensors.retain(|t| t.name != name);
        self
    }
}

/// A random teacher-layout model of these widths.
pub fn random_teacher(widths: &[usize], rng: &mut ChaCha8Rng) -> Spec {
    let dense = random_dense(widths, rng);
    teacher("pinn", widths, &dense)
}
