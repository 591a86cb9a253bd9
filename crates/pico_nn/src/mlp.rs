//! The tanh MLP of `docs/model-format.md`: forward pass and input Jacobian into
//! preallocated buffers.
//!
//! Layout. Every layer's expanded weights ŵ are kept twice, transposed (`[in][out]`,
//! for the forward pass as a sum of scaled columns and for the reverse-mode Jacobian) and
//! row-major (`[out][in]`, for the forward-mode Jacobian). The Jacobian products are small
//! matrix products `(m × n) · (n × K)` with `K` = 8 outputs (reverse mode) or 10 features
//! (forward mode), four rows at a time so that the compiler keeps 4·K accumulators in
//! vector registers; see `docs/pico_nn.md` for the measurements behind these choices.
//!
//! Kernels. The same code is compiled three times: with plain `a·b + c` for any CPU, and
//! with fused multiply-adds under `avx2,fma` and under `avx512f,fma`, the fastest chosen at
//! load. Every output element is accumulated in the same order whatever the vector width,
//! so the two FMA kernels agree bit for bit; they differ from the portable one only in
//! rounding (≈ 1e-16 relative per operation). [`Kernel::Portable`] gives bit-identical
//! results on every machine.

use crate::format::{Parsed, MU, N_FEATURES, N_IN, N_OUT};

/// Which compiled variant of the arithmetic runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kernel {
    /// Separate multiply and add, baseline instruction set: bit-reproducible everywhere.
    Portable,
    /// AVX2 vectors with fused multiply-add (x86-64 CPUs that have both).
    Avx2Fma,
    /// AVX-512 vectors with fused multiply-add.
    Avx512,
}

impl Kernel {
    /// The widest kernel this CPU runs (AVX-512, else AVX2, else portable). A loaded net
    /// starts on the faster of the two FMA kernels for its widths, timed at load, when the
    /// CPU has both; this is the choice where it has one or none.
    #[must_use]
    pub fn detect() -> Self {
        [Self::Avx512, Self::Avx2Fma]
            .into_iter()
            .find(|k| k.available())
            .unwrap_or(Self::Portable)
    }

    /// Whether this CPU can run the kernel.
    #[must_use]
    pub fn available(self) -> bool {
        match self {
            Self::Portable => true,
            #[cfg(target_arch = "x86_64")]
            Self::Avx2Fma => {
                std::arch::is_x86_feature_detected!("avx2")
                    && std::arch::is_x86_feature_detected!("fma")
            }
            #[cfg(target_arch = "x86_64")]
            Self::Avx512 => {
                std::arch::is_x86_feature_detected!("avx512f")
                    && std::arch::is_x86_feature_detected!("fma")
            }
            #[cfg(not(target_arch = "x86_64"))]
            Self::Avx2Fma | Self::Avx512 => false,
        }
    }
}

/// How the input Jacobian is accumulated.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum JacobianMode {
    /// Back-propagate the 8 output rows (`K = 8`); the default (faster, see the docs).
    Reverse,
    /// Push the 10 feature directions forward (`K = 10`).
    Forward,
}

/// Multiply-add, `a·b + c`, plain or fused.
trait Mac {
    fn mac(a: f64, b: f64, c: f64) -> f64;
}

struct Plain;
impl Mac for Plain {
    #[inline(always)]
    fn mac(a: f64, b: f64, c: f64) -> f64 {
        a * b + c
    }
}

#[cfg(target_arch = "x86_64")]
struct Fused;
#[cfg(target_arch = "x86_64")]
impl Mac for Fused {
    #[inline(always)]
    fn mac(a: f64, b: f64, c: f64) -> f64 {
        a.mul_add(b, c)
    }
}

/// Expanded weights and statistics (immutable after load, except the first layer's bias,
/// into which the constant μ input is folded).
#[derive(Debug, Clone)]
struct Weights {
    /// The file's widths, `[N_FEATURES, …, N_OUT]`.
    widths: Vec<usize>,
    /// The widths the arithmetic runs on: the file's, with the μ input folded away
    /// (`dims[0] = N_IN`).
    dims: Vec<usize>,
    /// Per layer, ŵ transposed: `wt[l][j * out + i] = ŵ_l[i][j]`.
    wt: Vec<Vec<f64>>,
    /// Per layer, ŵ row-major: `w[l][i * in + j] = ŵ_l[i][j]`.
    w: Vec<Vec<f64>>,
    b: Vec<Vec<f64>>,
    /// `∂o/∂h_{L−1}` transposed, `out_std[k] · ŵ_L[k][i]` at `[i * 8 + k]`.
    out_gt: Vec<f64>,
    in_mean: [f64; N_IN],
    in_std: [f64; N_IN],
    out_mean: [f64; N_OUT],
    out_std: [f64; N_OUT],
    /// The first layer's bias as stored in the file.
    b1_file: Vec<f64>,
    /// The first layer's μ column, `ŵ_1[i][MU]`.
    w1_mu: Vec<f64>,
    mu_mean: f64,
    mu_std: f64,
}

/// Per-call working memory, sized at load.
#[derive(Debug, Clone)]
struct Scratch {
    /// `h[0]` the normalised features, `h[l]` the activations of hidden layer `l`.
    h: Vec<Vec<f64>>,
    /// Two `max width × 10` buffers for the Jacobian products.
    ga: Vec<f64>,
    gb: Vec<f64>,
}

/// `forward_jac` calls per kernel and round when the FMA kernel is chosen at load.
const CALIBRATION_CALLS: usize = 32;

/// A loaded tanh MLP with its scratch memory.
#[derive(Debug, Clone)]
pub struct Mlp {
    w: Weights,
    s: Scratch,
    kernel: Kernel,
    mode: JacobianMode,
}

impl Mlp {
    pub(crate) fn from_parsed(p: &Parsed) -> Self {
        let widths = p.widths.clone();
        let mut dims = widths.clone();
        dims[0] = N_IN;
        let n_layers = widths.len() - 1;
        let mut wt = Vec::with_capacity(n_layers);
        let mut w = Vec::with_capacity(n_layers);
        let mut b = Vec::with_capacity(n_layers);
        for (l, layer) in p.layers.iter().enumerate() {
            let (n_file, n_in, n_out) = (widths[l], dims[l], widths[l + 1]);
            // Layer 1 keeps the per-step feature columns only; its μ column is folded
            // into the bias by `set_mu`.
            let mut t = vec![0.0; n_in * n_out];
            let mut r = vec![0.0; n_in * n_out];
            for i in 0..n_out {
                for j in 0..n_in {
                    t[j * n_out + i] = layer.weight[i * n_file + j];
                    r[i * n_in + j] = layer.weight[i * n_file + j];
                }
            }
            wt.push(t);
            w.push(r);
            b.push(layer.bias.clone());
        }
        let n1 = widths[1];
        let w1_mu = (0..n1)
            .map(|i| p.layers[0].weight[i * N_FEATURES + MU])
            .collect();
        let (n_last, stride) = (dims[n_layers - 1], widths[n_layers - 1]);
        let last = &p.layers[n_layers - 1].weight;
        let mut out_gt = vec![0.0; n_last * N_OUT];
        for k in 0..N_OUT {
            for i in 0..n_last {
                out_gt[i * N_OUT + k] = p.out_std[k] * last[k * stride + i];
            }
        }
        let max_width = dims.iter().copied().max().unwrap_or(N_IN);
        let h = dims[..n_layers].iter().map(|&n| vec![0.0; n]).collect();
        let mut mlp = Self {
            w: Weights {
                b1_file: b[0].clone(),
                widths,
                dims,
                wt,
                w,
                b,
                out_gt,
                in_mean: std::array::from_fn(|j| p.in_mean[j]),
                in_std: std::array::from_fn(|j| p.in_std[j]),
                out_mean: p.out_mean,
                out_std: p.out_std,
                w1_mu,
                mu_mean: p.in_mean[MU],
                mu_std: p.in_std[MU],
            },
            s: Scratch {
                h,
                ga: vec![0.0; max_width * N_IN],
                gb: vec![0.0; max_width * N_IN],
            },
            kernel: Kernel::detect(),
            mode: JacobianMode::Reverse,
        };
        mlp.set_mu(p.mu_default);
        mlp.kernel = mlp.faster_fma_kernel();
        mlp
    }

    /// On a CPU with both FMA kernels, the faster of the two for this net, timed once at
    /// load: the least time of 5 rounds of [`CALIBRATION_CALLS`] `forward_jac` calls per
    /// kernel (about 1 ms for a teacher-sized net). Which one wins depends on the CPU and the
    /// widths (docs/pico_nn.md: on an AMD EPYC VM AVX2 was faster for every student width,
    /// AVX-512 for the teacher's). The two give bit-identical results, so the choice changes
    /// the time only, never a number. Elsewhere: [`Kernel::detect`].
    fn faster_fma_kernel(&mut self) -> Kernel {
        if !(Kernel::Avx2Fma.available() && Kernel::Avx512.available()) {
            return Kernel::detect();
        }
        let z = self.w.in_mean;
        let mut jz = [[0.0; N_IN]; N_OUT];
        let mut best = (std::time::Duration::MAX, Kernel::Avx512);
        for _ in 0..5 {
            for kernel in [Kernel::Avx512, Kernel::Avx2Fma] {
                self.kernel = kernel;
                let start = std::time::Instant::now();
                for _ in 0..CALIBRATION_CALLS {
                    std::hint::black_box(self.forward_jac(std::hint::black_box(&z), &mut jz));
                }
                let t = start.elapsed();
                if t < best.0 {
                    best = (t, kernel);
                }
            }
        }
        best.1
    }

    /// Fix the μ input (the last feature) at `mu`: the first layer's bias becomes
    /// `b_1 + ŵ_1[·][μ] · (μ − mean_μ)/std_μ`. No range check here (the model does it).
    pub fn set_mu(&mut self, mu: f64) {
        let h = (mu - self.w.mu_mean) / self.w.mu_std;
        for ((b, &b0), &wm) in self.w.b[0]
            .iter_mut()
            .zip(&self.w.b1_file)
            .zip(&self.w.w1_mu)
        {
            *b = wm.mul_add(h, b0);
        }
    }

    /// Layer widths of the file, input first (`[11, …, 8]`).
    #[must_use]
    pub fn widths(&self) -> &[usize] {
        &self.w.widths
    }

    /// The kernel in use.
    #[must_use]
    pub fn kernel(&self) -> Kernel {
        self.kernel
    }

    /// Use `kernel`, or [`Kernel::Portable`] if this CPU cannot run it; returns the
    /// kernel now in use.
    pub fn set_kernel(&mut self, kernel: Kernel) -> Kernel {
        self.kernel = if kernel.available() {
            kernel
        } else {
            Kernel::Portable
        };
        self.kernel
    }

    /// The Jacobian accumulation in use.
    #[must_use]
    pub fn jacobian_mode(&self) -> JacobianMode {
        self.mode
    }

    /// Choose the Jacobian accumulation (both give the same Jacobian up to rounding).
    pub fn set_jacobian_mode(&mut self, mode: JacobianMode) {
        self.mode = mode;
    }

    /// The de-normalised network output `out_mean + out_std ⊙ y` for the per-step
    /// features `z` and the μ last set.
    pub fn forward(&mut self, z: &[f64; N_IN]) -> [f64; N_OUT] {
        match self.kernel {
            #[cfg(target_arch = "x86_64")]
            // SAFETY: `Avx2Fma` is only ever set after `available()` confirmed the CPU
            // features (`set_kernel`, `Kernel::detect`).
            Kernel::Avx2Fma => unsafe { forward_fma(&self.w, &mut self.s, z) },
            #[cfg(target_arch = "x86_64")]
            // SAFETY: as above.
            Kernel::Avx512 => unsafe { forward_avx512(&self.w, &mut self.s, z) },
            _ => forward::<Plain>(&self.w, &mut self.s, z),
        }
    }

    /// The output (as [`Mlp::forward`]) and its Jacobian `jz[k][j] = ∂o_k/∂z_j`.
    pub fn forward_jac(&mut self, z: &[f64; N_IN], jz: &mut [[f64; N_IN]; N_OUT]) -> [f64; N_OUT] {
        match self.kernel {
            #[cfg(target_arch = "x86_64")]
            // SAFETY: as in `forward`.
            Kernel::Avx2Fma => unsafe { forward_jac_fma(&self.w, &mut self.s, self.mode, z, jz) },
            #[cfg(target_arch = "x86_64")]
            // SAFETY: as in `forward`.
            Kernel::Avx512 => unsafe { forward_jac_avx512(&self.w, &mut self.s, self.mode, z, jz) },
            _ => forward_jac::<Plain, 4>(&self.w, &mut self.s, self.mode, z, jz),
        }
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn forward_fma(w: &Weights, s: &mut Scratch, z: &[f64; N_IN]) -> [f64; N_OUT] {
    forward::<Fused>(w, s, z)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn forward_jac_fma(
    w: &Weights,
    s: &mut Scratch,
    mode: JacobianMode,
    z: &[f64; N_IN],
    jz: &mut [[f64; N_IN]; N_OUT],
) -> [f64; N_OUT] {
    forward_jac::<Fused, 4>(w, s, mode, z, jz)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,fma")]
fn forward_jac_avx512(
    w: &Weights,
    s: &mut Scratch,
    mode: JacobianMode,
    z: &[f64; N_IN],
    jz: &mut [[f64; N_IN]; N_OUT],
) -> [f64; N_OUT] {
    forward_jac::<Fused, 8>(w, s, mode, z, jz)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,fma")]
fn forward_avx512(w: &Weights, s: &mut Scratch, z: &[f64; N_IN]) -> [f64; N_OUT] {
    forward::<Fused>(w, s, z)
}

/// `y[from..from + B] += Σ_j x_j · wt[j][from..from + B]` with `B` outputs held in
/// registers, accumulated in two interleaved halves of `j` (twice the independent chains).
#[inline(always)]
fn add_columns_block<M: Mac, const B: usize>(y: &mut [f64], wt: &[f64], x: &[f64], from: usize) {
    let n = y.len();
    let mut even = [0.0; B];
    let mut odd = [0.0; B];
    even.copy_from_slice(&y[from..from + B]);
    let mut pairs = x.chunks_exact(2);
    let mut rows = wt.chunks_exact(2 * n);
    for (xp, wp) in (&mut pairs).zip(&mut rows) {
        let (w0, w1) = wp.split_at(n);
        let (w0, w1) = (&w0[from..from + B], &w1[from..from + B]);
        for i in 0..B {
            even[i] = M::mac(xp[0], w0[i], even[i]);
            odd[i] = M::mac(xp[1], w1[i], odd[i]);
        }
    }
    if let (&[xl], Some(wl)) = (pairs.remainder(), rows.remainder().get(from..from + B)) {
        for i in 0..B {
            even[i] = M::mac(xl, wl[i], even[i]);
        }
    }
    for i in 0..B {
        y[from + i] = even[i] + odd[i];
    }
}

/// `y += Σ_j x_j · wt[j]` where `wt` holds `x.len()` rows of `y.len()`: blocks of 16, 8, 4
/// and 1 outputs.
#[inline(always)]
fn add_columns<M: Mac>(y: &mut [f64], wt: &[f64], x: &[f64]) {
    let n = y.len();
    let mut from = 0;
    while from + 16 <= n {
        add_columns_block::<M, 16>(y, wt, x, from);
        from += 16;
    }
    if from + 8 <= n {
        add_columns_block::<M, 8>(y, wt, x, from);
        from += 8;
    }
    if from + 4 <= n {
        add_columns_block::<M, 4>(y, wt, x, from);
        from += 4;
    }
    while from < n {
        add_columns_block::<M, 1>(y, wt, x, from);
        from += 1;
    }
}

/// `out (m × K) = a (m × n) · b (n × K)`, all row-major, `m = out.len() / K`, `R` rows
/// of `a` at a time (`R·K` accumulators in registers).
#[inline(always)]
fn gemm<M: Mac, const K: usize, const R: usize>(out: &mut [f64], a: &[f64], b: &[f64], n: usize) {
    let mut rows = a.chunks_exact(R * n);
    let mut outs = out.chunks_exact_mut(R * K);
    for (ar, or) in (&mut rows).zip(&mut outs) {
        let mut acc = [[0.0; K]; R];
        for (c, bc) in b.chunks_exact(K).enumerate() {
            for r in 0..R {
                let x = ar[r * n + c];
                for k in 0..K {
                    acc[r][k] = M::mac(x, bc[k], acc[r][k]);
                }
            }
        }
        for (o, acc) in or.chunks_exact_mut(K).zip(&acc) {
            o.copy_from_slice(acc);
        }
    }
    for (a1, o) in rows
        .remainder()
        .chunks_exact(n)
        .zip(outs.into_remainder().chunks_exact_mut(K))
    {
        let mut acc = [0.0; K];
        for (bc, &x) in b.chunks_exact(K).zip(a1) {
            for k in 0..K {
                acc[k] = M::mac(x, bc[k], acc[k]);
            }
        }
        o.copy_from_slice(&acc);
    }
}

#[inline(always)]
fn forward<M: Mac>(w: &Weights, s: &mut Scratch, z: &[f64; N_IN]) -> [f64; N_OUT] {
    for (j, h) in s.h[0].iter_mut().enumerate() {
        *h = (z[j] - w.in_mean[j]) / w.in_std[j];
    }
    let n_layers = w.wt.len();
    for l in 0..n_layers - 1 {
        let (prev, next) = s.h.split_at_mut(l + 1);
        let y = &mut next[0];
        y.copy_from_slice(&w.b[l]);
        add_columns::<M>(y, &w.wt[l], &prev[l]);
        crate::tanh::tanh_in_place(y);
    }
    let mut y = [0.0; N_OUT];
    y.copy_from_slice(&w.b[n_layers - 1]);
    add_columns::<M>(&mut y, &w.wt[n_layers - 1], &s.h[n_layers - 1]);
    let mut o = [0.0; N_OUT];
    for k in 0..N_OUT {
        o[k] = w.out_mean[k] + w.out_std[k] * y[k];
    }
    o
}

#[inline(always)]
fn forward_jac<M: Mac, const R: usize>(
    w: &Weights,
    s: &mut Scratch,
    mode: JacobianMode,
    z: &[f64; N_IN],
    jz: &mut [[f64; N_IN]; N_OUT],
) -> [f64; N_OUT] {
    let o = forward::<M>(w, s, z);
    match mode {
        JacobianMode::Reverse => reverse::<M, R>(w, s, jz),
        JacobianMode::Forward => tangent::<M, R>(w, s, jz),
    }
    o
}

/// Reverse mode: `G ← diag(1 − h_l²) G`, `G ← ŵ_lᵀ G` from the output down, `G` stored
/// `[unit][output]`.
#[inline(always)]
fn reverse<M: Mac, const R: usize>(w: &Weights, s: &mut Scratch, jz: &mut [[f64; N_IN]; N_OUT]) {
    let n_layers = w.wt.len();
    let widths = &w.dims;
    let Scratch { h, ga, gb } = s;
    let g0: &[f64] = if n_layers == 1 {
        &w.out_gt
    } else {
        for l in (1..n_layers).rev() {
            let n = widths[l];
            let src: &[f64] = if l == n_layers - 1 {
                &w.out_gt
            } else {
                &gb[..n * N_OUT]
            };
            let scaled = &mut ga[..n * N_OUT];
            for ((dst, src), &hi) in scaled
                .chunks_exact_mut(N_OUT)
                .zip(src.chunks_exact(N_OUT))
                .zip(&h[l])
            {
                let d = 1.0 - hi * hi;
                for k in 0..N_OUT {
                    dst[k] = src[k] * d;
                }
            }
            gemm::<M, N_OUT, R>(&mut gb[..widths[l - 1] * N_OUT], &w.wt[l - 1], scaled, n);
        }
        &gb[..N_IN * N_OUT]
    };
    for (j, row) in g0.chunks_exact(N_OUT).enumerate() {
        let inv = 1.0 / w.in_std[j];
        for k in 0..N_OUT {
            jz[k][j] = row[k] * inv;
        }
    }
}

/// Forward mode: `T_1 = diag(1 − h_1²) ŵ_1 diag(1/σ_in)`, `T_l = diag(1 − h_l²) ŵ_l T_{l−1}`,
/// `J = diag(σ_out) ŵ_L T_{L−1}`, `T` stored `[unit][feature]`.
#[inline(always)]
fn tangent<M: Mac, const R: usize>(w: &Weights, s: &mut Scratch, jz: &mut [[f64; N_IN]; N_OUT]) {
    let n_layers = w.wt.len();
    let widths = &w.dims;
    let Scratch { h, ga, gb } = s;
    // T_0 = diag(1/σ_in) folded into the first product.
    let first = &w.w[0];
    let n1 = widths[1];
    let d = |l: usize, i: usize| -> f64 {
        if l == n_layers {
            1.0
        } else {
            1.0 - h[l][i] * h[l][i]
        }
    };
    for i in 0..n1 {
        let di = d(1, i);
        for j in 0..N_IN {
            ga[i * N_IN + j] = di * first[i * N_IN + j] / w.in_std[j];
        }
    }
    for l in 2..=n_layers {
        let (n_in, n_out) = (widths[l - 1], widths[l]);
        gemm::<M, N_IN, R>(
            &mut gb[..n_out * N_IN],
            &w.w[l - 1],
            &ga[..n_in * N_IN],
            n_in,
        );
        for i in 0..n_out {
            let di = d(l, i);
            for j in 0..N_IN {
                ga[i * N_IN + j] = gb[i * N_IN + j] * di;
            }
        }
    }
    for k in 0..N_OUT {
        for j in 0..N_IN {
            jz[k][j] = w.out_std[k] * ga[k * N_IN + j];
        }
    }
}
