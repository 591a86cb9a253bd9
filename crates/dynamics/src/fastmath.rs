//! Portable, fast elementary functions for the tyre model's hot path.
//!
//! The plant evaluates eleven arc-tangents, sines and cosines per tyre per millisecond. These
//! polynomial versions are about twice as fast as the platform libm and, being plain
//! IEEE-754 arithmetic, give bit-identical results on every platform (libm's last bit is
//! not specified), which keeps the plant deterministic across machines. Their absolute
//! error is below 1e-11 on the ranges used (tested against libm).

use std::f64::consts::{FRAC_PI_2, FRAC_PI_6};

const TAN_PI_12: f64 = 0.267_949_192_431_122_7;
const SQRT3: f64 = 1.732_050_807_568_877_2;

/// Arc-tangent, |error| < 1e-11 for all finite x.
#[inline]
#[must_use]
pub fn atan(x: f64) -> f64 {
    // NaN propagates through the arithmetic below; ±∞ maps to ±π/2 via 1/∞ = 0.
    let a = x.abs();
    let invert = a > 1.0;
    let mut t = if invert { 1.0 / a } else { a };
    let reduce = t > TAN_PI_12;
    let offset = if reduce { FRAC_PI_6 } else { 0.0 };
    if reduce {
        t = (t * SQRT3 - 1.0) / (t + SQRT3);
    }
    // Taylor series to t¹⁹ on |t| ≤ tan(π/12): remainder < 0.268²¹/21 ≈ 5e-14.
    let t2 = t * t;
    let poly = 1.0
        + t2 * (-1.0 / 3.0
            + t2 * (1.0 / 5.0
                + t2 * (-1.0 / 7.0
                    + t2 * (1.0 / 9.0
                        + t2 * (-1.0 / 11.0
                            + t2 * (1.0 / 13.0 + t2 * (-1.0 / 15.0 + t2 * (1.0 / 17.0 + t2 * (-1.0 / 19.0)))))))));
    let r = offset + t * poly;
    let r = if invert { FRAC_PI_2 - r } else { r };
    r.copysign(x)
}

/// Sine and cosine for |x| ≤ 2π (the Magic Formula's `C·atan(·)` stays within ±C·π/2);
/// falls back to libm outside that range. |error| < 1e-11.
#[inline]
#[must_use]
pub fn sin_cos(x: f64) -> (f64, f64) {
    if x.abs() > std::f64::consts::TAU {
        return x.sin_cos();
    }
    // Reduce to |y| ≤ π/4 by quadrant.
    // Nearest quadrant; `as i64` truncates natively (f64::round is a soft-float call on
    // baseline x86-64).
    let q = (x * std::f64::consts::FRAC_2_PI + 0.5f64.copysign(x)) as i64;
    let k = q as f64;
    // Two-part π/2 for the reduction (Cody–Waite).
    const PIO2_HI: f64 = std::f64::consts::FRAC_PI_2;
    const PIO2_LO: f64 = 6.123_233_995_736_766e-17;
    let y = (x - k * PIO2_HI) - k * PIO2_LO;
    let y2 = y * y;
    let s = y * (1.0
        + y2 * (-1.0 / 6.0
            + y2 * (1.0 / 120.0
                + y2 * (-1.0 / 5040.0 + y2 * (1.0 / 362_880.0 + y2 * (-1.0 / 39_916_800.0 + y2 * (1.0 / 6_227_020_800.0)))))));
    let c = 1.0
        + y2 * (-0.5
            + y2 * (1.0 / 24.0
                + y2 * (-1.0 / 720.0
                    + y2 * (1.0 / 40_320.0 + y2 * (-1.0 / 3_628_800.0 + y2 * (1.0 / 479_001_600.0 + y2 * (-1.0 / 87_178_291_200.0)))))));
    // Quadrant fix-up without branches (so loops over several tyres vectorise):
    // q mod 4 = 0: ( s,  c), 1: ( c, −s), 2: (−s, −c), 3: (−c,  s).
    let swap = q & 1 == 1;
    let (s1, c1) = if swap { (c, -s) } else { (s, c) };
    let negate = q & 2 == 2;
    if negate {
        (-s1, -c1)
    } else {
        (s1, c1)
    }
}

/// `exp(x)`, a Taylor series for |x| ≤ 0.5 (|relative error| < 2e-12; the tyre's load
/// sensitivity exponent stays in that range), libm beyond.
#[inline]
#[must_use]
pub fn exp_small(x: f64) -> f64 {
    if x.abs() > 0.5 {
        return x.exp();
    }
    1.0 + x
        * (1.0
            + x * (1.0 / 2.0
                + x * (1.0 / 6.0
                    + x * (1.0 / 24.0
                        + x * (1.0 / 120.0
                            + x * (1.0 / 720.0
                                + x * (1.0 / 5040.0
                                    + x * (1.0 / 40_320.0
                                        + x * (1.0 / 362_880.0 + x * (1.0 / 3_628_800.0 + x * (1.0 / 39_916_800.0 + x / 479_001_600.0)))))))))))
}

/// Sine for |x| ≤ 2π (see [`sin_cos`]).
#[inline]
#[must_use]
pub fn sin(x: f64) -> f64 {
    sin_cos(x).0
}

/// Cosine for |x| ≤ 2π (see [`sin_cos`]).
#[inline]
#[must_use]
pub fn cos(x: f64) -> f64 {
    sin_cos(x).1
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn atan_matches_libm() {
        let mut worst: f64 = 0.0;
        for i in -200_000..=200_000 {
            let x = f64::from(i) * 1e-4;
            for v in [x, x * x * x, 1.0 / (x + 1e-7)] {
                worst = worst.max((atan(v) - v.atan()).abs());
            }
        }
        assert!(worst < 1e-11, "worst atan error {worst:e}");
        assert_eq!(atan(0.0), 0.0);
        assert!((atan(f64::INFINITY) - FRAC_PI_2).abs() < 1e-15);
        assert!(atan(f64::NAN).is_nan());
    }

    #[test]
    fn exp_small_matches_libm() {
        for i in -1000..=1000 {
            let x = f64::from(i) * 1e-3;
            assert!((exp_small(x) - x.exp()).abs() <= 2e-12 * x.exp(), "x = {x}");
        }
    }

    #[test]
    fn sin_cos_match_libm() {
        let mut worst: f64 = 0.0;
        for i in -700_000..=700_000 {
            let x = f64::from(i) * 1e-5;
            let (s, c) = sin_cos(x);
            worst = worst.max((s - x.sin()).abs()).max((c - x.cos()).abs());
        }
        assert!(worst < 1e-11, "worst sin/cos error {worst:e}");
        assert_eq!(sin_cos(100.0), 100f64.sin_cos());
    }
}
