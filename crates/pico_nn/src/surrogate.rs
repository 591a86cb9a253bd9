//! A learned target surrogate (teacher PINN or PicoPINN) behind [`TargetModel`].

use crate::error::ModelError;
use crate::format::{self, MU, N_FEATURES, N_IN, N_OUT};
use crate::mlp::{JacobianMode, Kernel, Mlp};
use dynamics::target::idx;
use dynamics::{ContactInput, TargetInput, TargetJacobians, TargetModel, TargetState};
use std::collections::BTreeMap;
use std::path::Path;

/// Columns of the stacked Jacobian `[∂/∂x | ∂/∂u | ∂/∂f_c]`.
const NJ: usize = 12;

/// Files larger than this are refused before they are read (a real model is kilobytes).
pub const MAX_FILE_BYTES: u64 = 256 << 20;

/// Output indices into the network output `o` (`docs/model-format.md`).
mod out {
    pub const DVX: usize = 0;
    pub const DVY: usize = 1;
    pub const DR: usize = 2;
    pub const DP: usize = 3;
    pub const DPHI: usize = 4;
    pub const DPSI: usize = 5;
    pub const DXB: usize = 6;
    pub const DYB: usize = 7;
}

/// Feature indices into `z`.
mod feat {
    pub const VX: usize = 0;
    pub const VY: usize = 1;
    pub const R: usize = 2;
    pub const P: usize = 3;
    pub const PHI: usize = 4;
    pub const DELTA: usize = 5;
    pub const TB: usize = 6;
    pub const FBX: usize = 7;
    pub const FBY: usize = 8;
    pub const MZ: usize = 9;
}

/// The state row each increment `o_k` adds to, for the rows that are plain sums.
const ROW_OF: [(usize, usize); 6] = [
    (idx::VX, out::DVX),
    (idx::VY, out::DVY),
    (idx::R, out::DR),
    (idx::P, out::DP),
    (idx::PHI, out::DPHI),
    (idx::PSI, out::DPSI),
];

/// The contact force in the body frame and its moment, the heading-invariant part of the
/// features.
#[derive(Debug, Clone, Copy)]
struct BodyForce {
    sin: f64,
    cos: f64,
    fbx: f64,
    fby: f64,
}

impl BodyForce {
    fn new(psi: f64, c: &ContactInput) -> Self {
        let (sin, cos) = (c.gamma - psi).sin_cos();
        let (fn_, ft) = (c.fc.x, c.fc.y);
        Self {
            sin,
            cos,
            fbx: cos * fn_ - sin * ft,
            fby: sin * fn_ + cos * ft,
        }
    }
}

/// A teacher PINN or PicoPINN loaded from a `picopit-mlp` v3 file.
///
/// The road adhesion μ is the network's last input and a property of the instance, as it
/// is of [`dynamics::FourDofTarget`]: it starts at the file's `mu_default` (0.9 for the
/// shipped models) and is set with [`SurrogateModel::with_mu`] / [`SurrogateModel::set_mu`]
/// within the file's `mu_range` (the adhesion the model was trained on).
#[derive(Debug, Clone)]
pub struct SurrogateModel {
    net: Mlp,
    kind: String,
    dt: f64,
    mu: f64,
    mu_range: (f64, f64),
    n_free: usize,
    metadata: BTreeMap<String, String>,
    /// The file's linear base `o += B z` over all features (`docs/model-format.md`).
    base: [[f64; N_FEATURES]; N_OUT],
    jz: [[f64; N_IN]; N_OUT],
}

impl SurrogateModel {
    /// Load and validate a model file.
    ///
    /// # Errors
    /// [`ModelError`] naming the metadata key or tensor at fault.
    pub fn from_path(path: impl AsRef<Path>) -> Result<Self, ModelError> {
        let path = path.as_ref();
        let io = |source| ModelError::Io {
            path: path.to_owned(),
            source,
        };
        let len = std::fs::metadata(path).map_err(io)?.len();
        if len > MAX_FILE_BYTES {
            return Err(ModelError::Container(format!(
                "{}: {len} bytes, more than the {MAX_FILE_BYTES} a model file may have",
                path.display()
            )));
        }
        let bytes = std::fs::read(path).map_err(io)?;
        Self::from_bytes(&bytes)
    }

    /// Load and validate a model held in memory.
    ///
    /// # Errors
    /// [`ModelError`] naming the metadata key or tensor at fault.
    pub fn from_bytes(bytes: &[u8]) -> Result<Self, ModelError> {
        let p = format::parse(bytes)?;
        let mut m = Self {
            net: Mlp::from_parsed(&p),
            kind: p.kind,
            dt: p.dt,
            mu: p.mu_default,
            mu_range: p.mu_range,
            n_free: p.n_free,
            metadata: p.metadata,
            base: p.base,
            jz: [[0.0; N_IN]; N_OUT],
        };
        m.check_runs(&p.in_mean, &p.in_std)?;
        Ok(m)
    }

    /// A model must run: finite increments at its own input mean and one standard
    /// deviation either side (all features at once), and a finite input Jacobian at the
    /// mean. Finite weights can still overflow (θ = 1e308 passes every other check).
    fn check_runs(
        &mut self,
        mean: &[f64; N_FEATURES],
        std: &[f64; N_FEATURES],
    ) -> Result<(), ModelError> {
        for (at, k) in [
            ("in_mean", 0.0),
            ("in_mean + in_std", 1.0),
            ("in_mean - in_std", -1.0),
        ] {
            let z: [f64; N_FEATURES] = std::array::from_fn(|j| mean[j] + k * std[j]);
            let o = self.forward_features(&z);
            if let Some(i) = o.iter().position(|v| !v.is_finite()) {
                return Err(ModelError::DoesNotRun {
                    at,
                    output: format::OUTPUTS[i],
                    value: o[i],
                });
            }
        }
        let z: [f64; N_IN] = std::array::from_fn(|j| mean[j]);
        let _ = self.net.forward_jac(&z, &mut self.jz);
        if let Some(i) = self
            .jz
            .iter()
            .position(|row| row.iter().any(|v| !v.is_finite()))
        {
            let value = self.jz[i].iter().copied().find(|v| !v.is_finite());
            return Err(ModelError::DoesNotRun {
                at: "in_mean",
                output: format::OUTPUTS[i],
                value: value.unwrap_or(f64::NAN),
            });
        }
        Ok(())
    }

    /// The same model on a road of adhesion `mu`.
    ///
    /// # Errors
    /// [`ModelError::Mu`] if `mu` is not finite or outside the file's `mu_range`.
    pub fn with_mu(mut self, mu: f64) -> Result<Self, ModelError> {
        self.set_mu(mu)?;
        Ok(self)
    }

    /// Set the road adhesion μ used by every following step.
    ///
    /// # Errors
    /// [`ModelError::Mu`] if `mu` is not finite or outside the file's `mu_range`; the
    /// model keeps its previous μ.
    pub fn set_mu(&mut self, mu: f64) -> Result<(), ModelError> {
        let (lo, hi) = self.mu_range;
        if !(mu.is_finite() && (lo..=hi).contains(&mu)) {
            return Err(ModelError::Mu { value: mu, lo, hi });
        }
        self.mu = mu;
        self.net.set_mu(mu);
        Ok(())
    }

    /// The road adhesion μ in use.
    #[must_use]
    pub fn mu(&self) -> f64 {
        self.mu
    }

    /// The adhesion range `(lo, hi)` the model was trained on (the file's `mu_range`).
    #[must_use]
    pub fn mu_range(&self) -> (f64, f64) {
        self.mu_range
    }

    /// Use `kernel` (or the portable one if this CPU cannot run it).
    #[must_use]
    pub fn with_kernel(mut self, kernel: Kernel) -> Self {
        self.net.set_kernel(kernel);
        self
    }

    /// Choose forward- or reverse-mode accumulation of the network Jacobian.
    #[must_use]
    pub fn with_jacobian_mode(mut self, mode: JacobianMode) -> Self {
        self.net.set_jacobian_mode(mode);
        self
    }

    /// The header metadata, every key of the file.
    #[must_use]
    pub fn metadata(&self) -> &BTreeMap<String, String> {
        &self.metadata
    }

    /// Layer widths, input first (`[11, …, 8]`).
    #[must_use]
    pub fn layers(&self) -> &[usize] {
        self.net.widths()
    }

    /// The network itself (forward pass and input Jacobian on raw features).
    pub fn network(&mut self) -> &mut Mlp {
        &mut self.net
    }

    /// The 10 per-step network features `z = [vx, vy, r, p, φ, δ, T_b, f_bx, f_by, M_z]`
    /// (the 11th, μ, is the model's).
    #[must_use]
    pub fn features(x: &TargetState, u: &TargetInput, c: &ContactInput) -> [f64; N_IN] {
        Self::features_with(x, u, c, &BodyForce::new(x[idx::PSI], c))
    }

    fn features_with(
        x: &TargetState,
        u: &TargetInput,
        c: &ContactInput,
        f: &BodyForce,
    ) -> [f64; N_IN] {
        let p = c.point_in_body;
        [
            x[idx::VX],
            x[idx::VY],
            x[idx::R],
            x[idx::P],
            x[idx::PHI],
            u[0],
            u[1],
            f.fbx,
            f.fby,
            p.x * f.fby - p.y * f.fbx,
        ]
    }

    /// The increments `o` (the linear base included) for the per-step features `z` at the
    /// model's μ.
    pub fn forward(&mut self, z: &[f64; N_IN]) -> [f64; N_OUT] {
        let mut o = self.net.forward(z);
        self.add_base(z, self.mu, &mut o);
        o
    }

    /// The increments `o` for all 11 features, μ included (for parity tests; μ is not
    /// range-checked here and the model's own μ is left as it was).
    pub fn forward_features(&mut self, z: &[f64; N_FEATURES]) -> [f64; N_OUT] {
        let zs: [f64; N_IN] = std::array::from_fn(|j| z[j]);
        self.net.set_mu(z[MU]);
        let mut o = self.net.forward(&zs);
        self.add_base(&zs, z[MU], &mut o);
        self.net.set_mu(self.mu);
        o
    }

    /// The file's linear base matrix `B` (`o += B z`; rows: outputs, columns: the 11
    /// features).
    #[must_use]
    pub fn base(&self) -> &[[f64; N_FEATURES]; N_OUT] {
        &self.base
    }

    /// `o += B [z, μ]`.
    fn add_base(&self, z: &[f64; N_IN], mu: f64, o: &mut [f64; N_OUT]) {
        for (ok, bk) in o.iter_mut().zip(&self.base) {
            *ok += bk[..N_IN].iter().zip(z).map(|(b, z)| b * z).sum::<f64>() + bk[MU] * mu;
        }
    }

    /// `x⁺` from `x` and the increments `o`.
    fn next_state(x: &TargetState, o: &[f64; N_OUT]) -> TargetState {
        let mut next = *x;
        for (row, k) in ROW_OF {
            next[row] += o[k];
        }
        let (s, c) = x[idx::PSI].sin_cos();
        next[idx::X] += c * o[out::DXB] - s * o[out::DYB];
        next[idx::Y] += s * o[out::DXB] + c * o[out::DYB];
        next
    }
}

impl TargetModel for SurrogateModel {
    fn name(&self) -> &str {
        &self.kind
    }

    fn dt(&self) -> f64 {
        self.dt
    }

    fn param_count(&self) -> usize {
        self.n_free
    }

    fn step(&mut self, x: &TargetState, u: &TargetInput, c: &ContactInput) -> TargetState {
        let z = Self::features(x, u, c);
        let o = self.forward(&z);
        Self::next_state(x, &o)
    }

    fn step_jac(
        &mut self,
        x: &TargetState,
        u: &TargetInput,
        c: &ContactInput,
        jac: &mut TargetJacobians,
    ) -> TargetState {
        let f = BodyForce::new(x[idx::PSI], c);
        let z = Self::features_with(x, u, c, &f);
        let mut o = self.net.forward_jac(&z, &mut self.jz);
        self.add_base(&z, self.mu, &mut o);
        for (jk, bk) in self.jz.iter_mut().zip(&self.base) {
            for (j, b) in jk.iter_mut().zip(bk) {
                *j += b;
            }
        }
        let (px, py) = (c.point_in_body.x, c.point_in_body.y);

        // d[k] = [∂o_k/∂x (8) | ∂o_k/∂u (2) | ∂o_k/∂f_c (2)] through the feature map.
        // With f_b = R(γ − ψ) f_c: ∂f_b/∂ψ = [f_by, −f_bx], ∂f_b/∂F_n = [cos, sin],
        // ∂f_b/∂F_t = [−sin, cos]; M_z = p_x f_by − p_y f_bx.
        let mut d = [[0.0; NJ]; N_OUT];
        for (dk, j) in d.iter_mut().zip(&self.jz) {
            let d_fbx = j[feat::FBX] - py * j[feat::MZ];
            let d_fby = j[feat::FBY] + px * j[feat::MZ];
            dk[idx::VX] = j[feat::VX];
            dk[idx::VY] = j[feat::VY];
            dk[idx::PSI] = d_fbx * f.fby - d_fby * f.fbx;
            dk[idx::R] = j[feat::R];
            dk[idx::P] = j[feat::P];
            dk[idx::PHI] = j[feat::PHI];
            dk[8] = j[feat::DELTA];
            dk[9] = j[feat::TB];
            dk[10] = f.cos * d_fbx + f.sin * d_fby;
            dk[11] = -f.sin * d_fbx + f.cos * d_fby;
        }

        // Through the next-state formula: rows of [A | B | F].
        let mut rows = [[0.0; NJ]; 8];
        for (row, k) in ROW_OF {
            rows[row] = d[k];
        }
        let (s, cs) = x[idx::PSI].sin_cos();
        let (ox, oy) = (&d[out::DXB], &d[out::DYB]);
        for col in 0..NJ {
            rows[idx::X][col] = cs * ox[col] - s * oy[col];
            rows[idx::Y][col] = s * ox[col] + cs * oy[col];
        }
        // The rotation of the displacement into the world depends on ψ itself.
        rows[idx::X][idx::PSI] -= s * o[out::DXB] + cs * o[out::DYB];
        rows[idx::Y][idx::PSI] += cs * o[out::DXB] - s * o[out::DYB];
        for (i, r) in rows.iter_mut().enumerate() {
            r[i] += 1.0;
        }
        for (i, r) in rows.iter().enumerate() {
            for (col, &v) in r[..8].iter().enumerate() {
                jac.a[(i, col)] = v;
            }
            jac.b[(i, 0)] = r[8];
            jac.b[(i, 1)] = r[9];
            jac.f[(i, 0)] = r[10];
            jac.f[(i, 1)] = r[11];
        }
        Self::next_state(x, &o)
    }
}
