//! The Magic Formula tyre model (Pacejka), pure and combined slip, in the form CommonRoad's
//! multi-body model evaluates it: peak friction and slip stiffnesses proportional to the load.
//!
//! Slip conventions (ours, uniform across the crate):
//! * longitudinal slip `κ = (ω R_w − v_x) / max(|v_x|, v_low)`, force `F_x = +MF_x(κ)`;
//! * slip angle `α = atan(v_y / sqrt(v_x² + v_low²))` in the wheel frame, force
//!   `F_y = −MF_y(α)` (the force opposes the lateral sliding velocity, for any travel
//!   direction, including a spinning vehicle sliding sideways or backwards).
//!
//! The road adhesion μ scales the peak: `λ_μ = μ / p_dy1`, so that at nominal load the
//! lateral peak friction equals μ. Cornering and slip stiffness do not depend on μ.

use crate::params::TyreParams;

/// Speed (m/s) below which slip denominators are regularised: `sqrt(v_x² + V_LOW²)` for the
/// slip angle and `max(|v_x|, V_LOW)` for the slip ratio. Below it tyres act as dampers, so a
/// vehicle comes to rest smoothly instead of chattering.
pub const V_LOW: f64 = 0.5;

/// Lateral slip `α* = tan α = v_y / sqrt(v_x² + V_LOW²)` of a wheel moving with wheel-frame
/// velocity `(vx, vy)`: the slip the Magic Formula is evaluated on (MF-Tyre 5.2/6.1
/// convention), one arc-tangent cheaper than the angle.
#[inline]
#[must_use]
pub fn tan_slip(vx: f64, vy: f64) -> f64 {
    vy / (vx * vx + V_LOW * V_LOW).sqrt()
}

/// Slip angle of a wheel moving with wheel-frame velocity `(vx, vy)`:
/// `α = atan(v_y / sqrt(v_x² + V_LOW²))`.
#[inline]
#[must_use]
pub fn slip_angle(vx: f64, vy: f64) -> f64 {
    (vy / (vx * vx + V_LOW * V_LOW).sqrt()).atan()
}

/// The Magic Formula `y = D sin(C atan(B x − E (B x − atan(B x))))`.
#[inline]
#[must_use]
pub fn magic_formula(x: f64, b: f64, c: f64, d: f64, e: f64) -> f64 {
    let bx = b * x;
    d * (c * (bx - e * (bx - bx.atan())).atan()).sin()
}

/// The Magic Formula and its derivative with respect to `x`.
#[inline]
#[must_use]
pub fn magic_formula_d(x: f64, b: f64, c: f64, d: f64, e: f64) -> (f64, f64) {
    let bx = b * x;
    // inner = B x − E (B x − atan(B x)), d inner / dx = B (1 − E + E / (1 + (Bx)²)).
    let (inner, dinner) = if e == 0.0 {
        (bx, b)
    } else {
        (
            bx - e * (bx - bx.atan()),
            b * (1.0 - e + e / (1.0 + bx * bx)),
        )
    };
    let phi = c * inner.atan();
    let (s, co) = phi.sin_cos();
    (d * s, d * co * c * dinner / (1.0 + inner * inner))
}

/// A lateral force curve of one axle for the control-oriented models: the Magic Formula
/// with coefficients fixed at the static axle load and the road μ.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AxleCurve {
    pub b: f64,
    pub c: f64,
    pub d: f64,
    pub e: f64,
}

impl AxleCurve {
    /// The curve of an axle with two tyres carrying `fz_axle` in total on a road of
    /// adhesion `mu`. Peak `D = μ_y F_z,axle`, cornering stiffness `2 K_y(F_z,axle / 2)`.
    #[must_use]
    pub fn new(tyre: &TyreParams, fz_axle: f64, mu: f64) -> Self {
        let d = tyre.mu_scale(mu) * tyre.pdy1 * fz_axle;
        let k = tyre.cornering_stiffness(fz_axle);
        let c = tyre.pcy1;
        Self {
            b: k / (c * d),
            c,
            d,
            e: tyre.pey1,
        }
    }

    /// The curve the control-oriented models use: [`AxleCurve::new`] with the curvature
    /// factor E set to 0, which saves one arc-tangent per evaluation. The built-in tyres
    /// have |E_y| < 0.01, so the curve moves by less than 0.3 % of the peak; the cornering
    /// stiffness and the peak are unchanged.
    #[must_use]
    pub fn control(tyre: &TyreParams, fz_axle: f64, mu: f64) -> Self {
        Self {
            e: 0.0,
            ..Self::new(tyre, fz_axle, mu)
        }
    }

    /// Cornering stiffness B C D at zero slip (N/rad).
    #[inline]
    #[must_use]
    pub fn cornering_stiffness(&self) -> f64 {
        self.b * self.c * self.d
    }

    /// Lateral force for slip α (our convention: `F_y = −MF(α)`).
    #[inline]
    #[must_use]
    pub fn force(&self, alpha: f64) -> f64 {
        if self.e == 0.0 {
            // The control curve: one arc-tangent less.
            -self.d * (self.c * (self.b * alpha).atan()).sin()
        } else {
            -magic_formula(alpha, self.b, self.c, self.d, self.e)
        }
    }

    /// Lateral force and dF_y/dα.
    #[inline]
    #[must_use]
    pub fn force_d(&self, alpha: f64) -> (f64, f64) {
        let (f, df) = magic_formula_d(alpha, self.b, self.c, self.d, self.e);
        (-f, -df)
    }
}

/// Forces of one tyre under combined slip.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct TyreForces {
    /// Longitudinal force in the wheel frame (N).
    pub fx: f64,
    /// Lateral force in the wheel frame (N).
    pub fy: f64,
    /// Longitudinal slip stiffness K_x at this load (N per unit slip), used by the plant's
    /// implicit wheel-spin update.
    pub kx: f64,
}

/// Magic Formula with combined slip (MF-Tyre 5.2 structure as CommonRoad's multi-body
/// model evaluates it, without camber, shifts or aligning moment).
///
/// `kappa` is the longitudinal slip κ and `alpha` the lateral slip *as MF-Tyre evaluates
/// it*: `α* = tan α` (the plant passes `v_y / sqrt(v_x² + V_LOW²)` in the wheel frame, see
/// [`tan_slip`]); for small slip α* ≈ α, and sliding sideways (α* → ±∞) gives the
/// saturated force. The force opposes the slip: `F_y = −MF_y(α*)`.
///
/// Combined slip uses the cosine weighting functions
/// `G_xα = cos(r_Cx1 atan(B_xα α − r_Ex1 (B_xα α − atan(B_xα α))))`,
/// `B_xα = r_Bx1 cos(atan(r_Bx2 κ))` and the same for `G_yκ` with `r_Cy1`, `r_Ey1` and
/// `B_yκ = r_By1 cos(atan(r_By2 α))`;
/// the weighting's argument is capped at π/2 so that a tyre sliding at large slip keeps
/// a non-negative force share (the fitted weighting goes negative far outside its data).
#[inline(always)]
#[must_use]
pub fn combined_slip(t: &TyreParams, mu_scale: f64, fz: f64, kappa: f64, alpha: f64) -> TyreForces {
    use std::f64::consts::FRAC_PI_2;
    // Every force is proportional to the load, so the curves are evaluated per newton of
    // load (a lifted wheel, F_z ≤ 0, carries nothing). Branch-free so that
    // `combined_slip4` vectorises.
    let load = fz.max(0.0);
    // Pure longitudinal slip.
    let dx = mu_scale * t.pdx1;
    let fx0 = magic_formula(kappa, t.pkx1 / (t.pcx1 * dx), t.pcx1, dx, t.pex1);
    // Pure lateral slip.
    let dy = mu_scale * t.pdy1;
    let fy0 = -magic_formula(alpha, t.pky1 / (t.pcy1 * dy), t.pcy1, dy, t.pey1);
    // Combined-slip weighting (odd in its argument, so evaluated on the magnitude).
    let shape = |x: f64, e: f64| x - e * (x - x.atan());
    let bxa = t.rbx1 / (1.0 + (t.rbx2 * kappa).powi(2)).sqrt();
    let gxa = (t.rcx1 * shape((bxa * alpha).abs(), t.rex1).atan())
        .min(FRAC_PI_2)
        .cos();
    let byk = t.rby1 / (1.0 + (t.rby2 * alpha).powi(2)).sqrt();
    let gyk = (t.rcy1 * shape((byk * kappa).abs(), t.rey1).atan())
        .min(FRAC_PI_2)
        .cos();
    TyreForces {
        fx: fx0 * gxa * load,
        fy: fy0 * gyk * load,
        kx: t.pkx1 * load,
    }
}

/// [`combined_slip`] for the four tyres of a vehicle at once (written as a branch-free loop
/// over lanes so that the compiler can evaluate tyres side by side).
#[must_use]
pub fn combined_slip4(
    t: &TyreParams,
    mu_scale: f64,
    fz: &[f64; 4],
    kappa: &[f64; 4],
    alpha: &[f64; 4],
) -> [TyreForces; 4] {
    let mut out = [TyreForces::default(); 4];
    for i in 0..4 {
        out[i] = combined_slip(t, mu_scale, fz[i], kappa[i], alpha[i]);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::params::ParamSet;

    fn tyre() -> TyreParams {
        ParamSet::builtin("full_size").unwrap().target.tyre
    }

    /// A wheel load (N): the full-size car's static load per wheel.
    const FZ: f64 = 2680.0;

    #[test]
    fn mf_peak_equals_d_and_slope_equals_bcd() {
        let (b, c, d, e) = (10.0, 1.35, 4000.0, -0.5);
        // Initial slope B C D.
        let h = 1e-7;
        let slope = (magic_formula(h, b, c, d, e) - magic_formula(-h, b, c, d, e)) / (2.0 * h);
        assert!(
            (slope - b * c * d).abs() / (b * c * d) < 1e-6,
            "slope {slope}"
        );
        // The peak value is D (scan fine).
        let peak = (0..200_000)
            .map(|i| magic_formula(f64::from(i) * 1e-5, b, c, d, e))
            .fold(f64::MIN, f64::max);
        assert!((peak - d).abs() / d < 1e-6, "peak {peak}");
        // Odd symmetry.
        assert!((magic_formula(0.1, b, c, d, e) + magic_formula(-0.1, b, c, d, e)).abs() < 1e-9);
    }

    #[test]
    fn mf_derivative_matches_finite_difference() {
        let (b, c, d, e) = (8.0, 1.6, 3000.0, 0.46);
        for &x in &[-0.8, -0.2, -0.01, 0.0, 0.03, 0.15, 0.6] {
            let h = 1e-6;
            let fd =
                (magic_formula(x + h, b, c, d, e) - magic_formula(x - h, b, c, d, e)) / (2.0 * h);
            let (_, an) = magic_formula_d(x, b, c, d, e);
            assert!(
                (fd - an).abs() <= 1e-5 * an.abs().max(1.0),
                "x={x} fd={fd} an={an}"
            );
        }
    }

    #[test]
    fn tyre_peak_and_stiffness_follow_parameters() {
        let t = tyre();
        let mu = 0.9;
        let fz = FZ;
        // Lateral: initial slope equals K_y, peak equals μ F_z.
        let h = 1e-7;
        let f = |a: f64| combined_slip(&t, t.mu_scale(mu), fz, 0.0, a).fy;
        let slope = -(f(h) - f(-h)) / (2.0 * h);
        let ky = t.cornering_stiffness(fz);
        assert!((slope - ky).abs() / ky < 1e-6);
        let peak = (0..20_000)
            .map(|i| -f(f64::from(i) * 5e-5))
            .fold(f64::MIN, f64::max);
        assert!(
            (peak - mu * fz).abs() / (mu * fz) < 1e-6,
            "peak {peak} vs {}",
            mu * fz
        );
        // Longitudinal: initial slope equals K_x = p_kx1 F_z .
        let g = |k: f64| combined_slip(&t, t.mu_scale(mu), fz, k, 0.0).fx;
        let kslope = (g(h) - g(-h)) / (2.0 * h);
        assert!((kslope - t.pkx1 * fz).abs() / (t.pkx1 * fz) < 1e-6);
    }

    #[test]
    fn forces_scale_with_load_as_in_commonroad() {
        // CommonRoad's tyre: D = μ F_z, K = p_K1 F_z, so every force is proportional to
        // the load at any slip; cross-check one point against the Magic Formula written
        // out from CommonRoad's formula (pure lateral slip, κ = 0).
        let t = tyre();
        let s = t.mu_scale(1.0);
        for (kappa, alpha) in [(0.0, 0.3), (0.05, 0.02), (-0.2, -0.1)] {
            let f1 = combined_slip(&t, s, FZ, kappa, alpha);
            let f2 = combined_slip(&t, s, 2.0 * FZ, kappa, alpha);
            assert!((f2.fx - 2.0 * f1.fx).abs() < 1e-9 * f1.fx.abs().max(1.0));
            assert!((f2.fy - 2.0 * f1.fy).abs() < 1e-9 * f1.fy.abs().max(1.0));
        }
        let (fz, alpha): (f64, f64) = (3000.0, 0.1);
        let (c, d, e): (f64, f64, f64) = (1.3507, 1.0489 * fz, -0.0074722);
        let b = 21.92 * fz / (c * d);
        let bx = b * alpha;
        let expect = d * (c * (bx - e * (bx - bx.atan())).atan()).sin();
        // λ_μ = 1: CommonRoad's tyre as published (road μ = p_dy1).
        let got = -combined_slip(&t, 1.0, fz, 0.0, alpha).fy;
        assert!((got - expect).abs() < 1e-9 * expect, "{got} vs {expect}");
    }

    #[test]
    fn combined_slip_reduces_lateral_force() {
        let t = tyre();
        let s = t.mu_scale(0.9);
        let alpha = 0.05;
        let pure = combined_slip(&t, s, FZ, 0.0, alpha).fy.abs();
        let mut last = pure;
        for &k in &[0.02, 0.05, 0.1, 0.3] {
            let fy = combined_slip(&t, s, FZ, k, alpha).fy.abs();
            assert!(fy < last, "|Fy| must fall as κ grows: κ={k} {fy} ≥ {last}");
            last = fy;
        }
        // And lateral slip reduces the longitudinal force.
        let fx0 = combined_slip(&t, s, FZ, 0.05, 0.0).fx;
        let fx1 = combined_slip(&t, s, FZ, 0.05, 0.1).fx;
        assert!(fx1 < fx0 && fx1 > 0.0);
    }

    #[test]
    fn four_lanes_match_scalar_and_lifted_wheels_carry_nothing() {
        let t = tyre();
        let s = t.mu_scale(0.7);
        let fz = [0.0, 0.5 * FZ, FZ, 2.5 * FZ];
        let kappa = [0.1, -0.05, 0.0, 0.4];
        let alpha = [0.2, 0.0, -0.3, 1.4];
        let four = combined_slip4(&t, s, &fz, &kappa, &alpha);
        for i in 0..4 {
            assert_eq!(four[i], combined_slip(&t, s, fz[i], kappa[i], alpha[i]));
        }
        assert_eq!(four[0], TyreForces::default());
        assert!(four[3].fy < 0.0 && four[3].fx > 0.0);
    }

    #[test]
    fn control_curve_keeps_stiffness_and_peak() {
        let t = tyre();
        let full = AxleCurve::new(&t, 2.0 * FZ, 0.8);
        let ctrl = AxleCurve::control(&t, 2.0 * FZ, 0.8);
        assert_eq!(full.cornering_stiffness(), ctrl.cornering_stiffness());
        let peak = |c: &AxleCurve| {
            (0..20_000)
                .map(|i| -c.force(f64::from(i) * 5e-5))
                .fold(f64::MIN, f64::max)
        };
        assert!((peak(&full) - peak(&ctrl)).abs() < 1e-6 * full.d);
        let worst = (0..2000)
            .map(|i| (full.force(f64::from(i) * 1e-3) - ctrl.force(f64::from(i) * 1e-3)).abs())
            .fold(0.0, f64::max);
        assert!(worst < 0.01 * full.d, "E = 0 moves the curve by {worst} N");
        // The derivative's E = 0 path agrees with finite differences too.
        for x in [-0.3, 0.0, 0.02, 0.2] {
            let h = 1e-7;
            let fd = (ctrl.force(x + h) - ctrl.force(x - h)) / (2.0 * h);
            assert!((ctrl.force_d(x).1 - fd).abs() < 1e-5 * fd.abs().max(1.0));
        }
    }

    #[test]
    fn axle_curve_matches_tyres() {
        let t = tyre();
        let fz_axle = 2.0 * FZ;
        let axle = AxleCurve::new(&t, fz_axle, 0.8);
        let two = 2.0 * combined_slip(&t, t.mu_scale(0.8), FZ, 0.0, 0.07).fy;
        assert!((axle.force(0.07) - two).abs() < 1e-9 * two.abs());
    }
}
