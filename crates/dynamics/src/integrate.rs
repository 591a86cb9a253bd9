//! Fixed-step integrators for the control-oriented models: classic RK4 (optionally in equal
//! sub-steps) and RK4 with the exact Jacobian of the discrete map, propagated through the
//! stages (`docs/models.md`, "Discretisation and Jacobians"). Static sizes, no allocation.

use nalgebra::{SMatrix, SVector};
use std::ops::Range;

/// One classic RK4 step of length `h` for `ẋ = f(x)`.
#[inline]
#[must_use]
pub(crate) fn rk4<const N: usize>(
    x: &SVector<f64, N>,
    h: f64,
    f: impl Fn(&SVector<f64, N>) -> SVector<f64, N>,
) -> SVector<f64, N> {
    let k1 = f(x);
    let k2 = f(&(x + k1 * (0.5 * h)));
    let k3 = f(&(x + k2 * (0.5 * h)));
    let k4 = f(&(x + k3 * h));
    x + (k1 + (k2 + k3) * 2.0 + k4) * (h / 6.0)
}

/// `n` RK4 sub-steps covering `dt`.
#[inline]
#[must_use]
pub(crate) fn rk4_substeps<const N: usize>(
    x: &SVector<f64, N>,
    dt: f64,
    n: usize,
    f: impl Fn(&SVector<f64, N>) -> SVector<f64, N>,
) -> SVector<f64, N> {
    let h = dt / n as f64;
    let mut xk = rk4(x, h, &f);
    for _ in 1..n {
        xk = rk4(&xk, h, &f);
    }
    xk
}

/// `D ← E + alpha · A · D` in place, with `A` the first N columns of the N × M matrix
/// `a_of`, of which only the columns `active` may be nonzero (in the vehicle models the
/// columns of the positions X, Y are zero: nothing depends on where the car is). The
/// inactive state columns of `D` and `E` are then zero as well and are left alone.
///
/// With `accumulate = Some((jac, w))` each new column is also added, scaled by `w`, to
/// `jac` while it is still in registers (RK4's `jac += w D_i`).
#[inline]
fn stage_update<const N: usize, const M: usize>(
    d: &mut SMatrix<f64, N, M>,
    alpha: f64,
    a_of: &SMatrix<f64, N, M>,
    e: &SMatrix<f64, N, M>,
    active: Range<usize>,
    mut accumulate: Option<(&mut SMatrix<f64, N, M>, f64)>,
) {
    // ArrayStorage is column-major `[[f64; N]; M]`.
    let a = &a_of.data.0;
    debug_assert!((0..N).filter(|k| !active.contains(k)).all(|k| a[k]
        .iter()
        .chain(&d.data.0[k])
        .chain(&e.data.0[k])
        .all(|&v| v == 0.0)));
    for (col, (dc, ec)) in d.data.0.iter_mut().zip(&e.data.0).enumerate() {
        if col < N && !active.contains(&col) {
            // ∂/∂(inactive state) is zero in every stage.
            continue;
        }
        let mut acc = *ec;
        for k in active.clone() {
            let s = alpha * dc[k];
            for (oi, ai) in acc.iter_mut().zip(&a[k]) {
                *oi += ai * s;
            }
        }
        if let Some((jac, w)) = accumulate.as_mut() {
            for (o, v) in jac.data.0[col].iter_mut().zip(&acc) {
                *o += *w * v;
            }
        }
        *dc = acc;
    }
}

/// `y += alpha · x` (plain loops over the column arrays, which the compiler unrolls).
#[inline]
fn add_scaled<const N: usize, const M: usize>(
    y: &mut SMatrix<f64, N, M>,
    alpha: f64,
    x: &SMatrix<f64, N, M>,
) {
    for (yc, xc) in y.data.0.iter_mut().zip(&x.data.0) {
        for (yi, xi) in yc.iter_mut().zip(xc) {
            *yi += alpha * xi;
        }
    }
}

/// Split a stacked `[A | B | F]` (N × (N + 4)) into its blocks.
#[inline]
pub(crate) fn split_columns<const N: usize, const M: usize>(
    j: &SMatrix<f64, N, M>,
    a: &mut SMatrix<f64, N, N>,
    b: &mut SMatrix<f64, N, 2>,
    f: &mut SMatrix<f64, N, 2>,
) {
    debug_assert_eq!(M, N + 4);
    let cols = &j.data.0;
    a.data.0.copy_from_slice(&cols[..N]);
    b.data.0.copy_from_slice(&cols[N..N + 2]);
    f.data.0.copy_from_slice(&cols[N + 2..N + 4]);
}

/// One classic RK4 step of length `h` with the exact Jacobian of the discrete map.
///
/// Only the columns `active` of `∂f/∂x` may be nonzero (checked in debug builds).
///
/// `f(x, J)` returns `ẋ` and writes the stacked continuous Jacobian
/// `J = [∂f/∂x | ∂f/∂w]` (N × M, `w` the held inputs) into `J`: every structurally nonzero
/// entry, the same ones on every call (the matrices passed are zero-initialised once). On return
/// `jac` holds `[∂x⁺/∂x | ∂x⁺/∂w]`. With stage Jacobians `A_i = ∂f/∂x (x_i)`,
/// `G_i = ∂f/∂w (x_i)` and `D_i = [∂k_i/∂x | ∂k_i/∂w]`:
///
/// ```text
/// D_1 = [A_1 | G_1]
/// D_2 = [A_2 | G_2] + (h/2) A_2 D_1,   D_3 = [A_3 | G_3] + (h/2) A_3 D_2,
/// D_4 = [A_4 | G_4] + h A_4 D_3,
/// [∂x⁺/∂x | ∂x⁺/∂w] = [I | 0] + (h/6)(D_1 + 2 D_2 + 2 D_3 + D_4).
/// ```
#[inline]
pub(crate) fn rk4_jac<const N: usize, const M: usize>(
    x: &SVector<f64, N>,
    h: f64,
    active: Range<usize>,
    jac: &mut SMatrix<f64, N, M>,
    f: impl Fn(&SVector<f64, N>, &mut SMatrix<f64, N, M>) -> SVector<f64, N>,
) -> SVector<f64, N> {
    // `d` holds D_i; `jac` accumulates [I | 0] + (h/6)(D_1 + 2 D_2 + 2 D_3 + D_4).
    let mut d = SMatrix::<f64, N, M>::zeros();
    let k1 = f(x, &mut d);
    *jac = SMatrix::identity();
    add_scaled(jac, h / 6.0, &d);
    let mut j = SMatrix::<f64, N, M>::zeros();
    let mut stage = |xs: &SVector<f64, N>,
                     c: f64,
                     d: &mut SMatrix<f64, N, M>,
                     jac: &mut SMatrix<f64, N, M>,
                     w: f64| {
        let k = f(xs, &mut j);
        stage_update(d, c, &j, &j, active.clone(), Some((jac, w)));
        k
    };
    let k2 = stage(&(x + k1 * (0.5 * h)), 0.5 * h, &mut d, jac, h / 3.0);
    let k3 = stage(&(x + k2 * (0.5 * h)), 0.5 * h, &mut d, jac, h / 3.0);
    let _k4 = stage(&(x + k3 * h), h, &mut d, jac, h / 6.0);
    x + (k1 + (k2 + k3) * 2.0 + _k4) * (h / 6.0)
}

/// `n` RK4 sub-steps covering `dt`, with the Jacobian of the whole step chained through
/// the sub-steps: `[Φ_x | Φ_w] ← [A_k Φ_x | A_k Φ_w + G_k]`.
#[inline]
pub(crate) fn rk4_jac_substeps<const N: usize, const M: usize>(
    x: &SVector<f64, N>,
    dt: f64,
    n: usize,
    active: Range<usize>,
    jac: &mut SMatrix<f64, N, M>,
    f: impl Fn(&SVector<f64, N>, &mut SMatrix<f64, N, M>) -> SVector<f64, N>,
) -> SVector<f64, N> {
    let h = dt / n as f64;
    let mut xk = rk4_jac(x, h, active.clone(), jac, &f);
    if n > 1 {
        let mut js = SMatrix::<f64, N, M>::zeros();
        for _ in 1..n {
            xk = rk4_jac(&xk, h, active.clone(), &mut js, &f);
            // Φ ← [0 | G_k] + A_k Φ.
            let mut g = js;
            g.data.0[..N].fill([0.0; N]);
            // The sub-step's ∂x⁺/∂x has the identity in every column.
            stage_update(jac, 1.0, &js, &g, 0..N, None);
        }
    }
    xk
}
