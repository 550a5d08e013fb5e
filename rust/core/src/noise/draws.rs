//! The random draws of the raw noise models, each a pure function of a Philox stream
//! ([`crate::rng::Stream`]) so that a row's draws depend only on its key and row:
//! standard normals (Box–Muller), Poisson counts (inversion of the CDF by sequential
//! search from one uniform below 10, Hörmann's transformed rejection PTRS above, as
//! numpy's generator does it) and Tukey-lambda variates by their quantile function.
use crate::rng::Stream;
// The plan draws standard normals too (a hand's shake): they live with the stream.
pub use crate::rng::{normal, open_uniform};

/// The Tukey-lambda quantile `Q(p) = (p^λ − (1 − p)^λ) / λ` (the logistic `ln(p/(1−p))`
/// at λ = 0).
pub fn tukey_quantile(p: f64, lambda: f64) -> f64 {
    if lambda.abs() < 1e-12 {
        libm::log(p / (1.0 - p))
    } else {
        // exp(λ ln p) rather than pow: the same function, a cheaper path in libm.
        (libm::exp(lambda * libm::log(p)) - libm::exp(lambda * libm::log(1.0 - p))) / lambda
    }
}

/// The variance of a standard Tukey-lambda variate (λ > −1/2):
/// `2/λ² · (1/(1 + 2λ) − Γ(λ + 1)² / Γ(2λ + 2))`, `π²/3` at λ = 0.
pub fn tukey_variance(lambda: f64) -> f64 {
    if lambda.abs() < 1e-6 {
        return std::f64::consts::PI * std::f64::consts::PI / 3.0;
    }
    let g = libm::tgamma(lambda + 1.0);
    2.0 / (lambda * lambda)
        * (1.0 / (1.0 + 2.0 * lambda) - g * g / libm::tgamma(2.0 * lambda + 2.0))
}

/// `e^t` for |t| ≤ 0.18 by its Taylor series to t¹²/12! (the truncation under
/// 10⁻¹⁹ relative), in plain IEEE operations: the same bits on every machine.
fn exp_small(t: f64) -> f64 {
    const C: [f64; 13] = [
        1.0,
        1.0,
        1.0 / 2.0,
        1.0 / 6.0,
        1.0 / 24.0,
        1.0 / 120.0,
        1.0 / 720.0,
        1.0 / 5040.0,
        1.0 / 40320.0,
        1.0 / 362_880.0,
        1.0 / 3_628_800.0,
        1.0 / 39_916_800.0,
        1.0 / 479_001_600.0,
    ];
    C.iter().rev().fold(0.0, |acc, c| acc * t + c)
}

/// A Tukey-lambda variate of shape `lambda` (scale 1; ELD's λ lie in [−0.25, 0.2]):
/// `Q(p)` at `p = 1/2 ± p'`, drawn as a sign and `p' ∈ (0, 1/2)` from one 64-bit word
/// (Q is odd about 1/2: `Q(1 − p) = −Q(p)`); `(1 − p')^λ = e^{λ ln(1 − p')}` with
/// `|λ ln(1 − p')| ≤ 0.25 ln 2` (|λ| ≤ 0.25) by [`exp_small`]; other λ by
/// [`tukey_quantile`].
pub fn tukey(s: &mut Stream, lambda: f64) -> f64 {
    let bits = s.next_u64();
    // 52 bits: the midpoint of one of 2^52 cells of (0, 1/2).
    let p = ((bits >> 12) as f64 + 0.5) * (1.0 / (1u64 << 53) as f64);
    let sign = if bits & 1 == 1 { 1.0 } else { -1.0 };
    let q = 1.0 - p;
    let v = if lambda.abs() < 1e-12 {
        libm::log(p / q)
    } else if lambda.abs() <= 0.25 {
        (libm::exp(lambda * libm::log(p)) - exp_small(lambda * libm::log(q))) / lambda
    } else {
        tukey_quantile(p, lambda)
    };
    sign * v
}

/// `x` rounded to the nearest integer, halves away from zero (`f64::round`), by the
/// integer conversion (exact for |x| < 2^52; larger values are integers already).
#[inline]
pub fn round_exact(x: f64) -> f64 {
    if x.abs() < 4_503_599_627_370_496.0 {
        let i = x as i64;
        let frac = x - i as f64;
        let r = if frac >= 0.5 {
            i + 1
        } else if frac <= -0.5 {
            i - 1
        } else {
            i
        };
        // The sign of a zero as `round` keeps it (−0.3 → −0).
        (r as f64).copysign(x)
    } else {
        x.round()
    }
}

/// `⌊x⌋` (`f64::floor`) by the integer conversion (exact for |x| < 2^52).
#[inline]
fn floor_exact(x: f64) -> f64 {
    if x.abs() < 4_503_599_627_370_496.0 {
        let i = x as i64 as f64;
        if i > x {
            i - 1.0
        } else {
            i
        }
    } else {
        x.floor()
    }
}

/// A Poisson count of mean `lam` (≥ 0; NaN or negative give 0).
pub fn poisson(s: &mut Stream, lam: f64) -> f64 {
    if lam.is_nan() || lam <= 0.0 {
        return 0.0;
    }
    if lam < 10.0 {
        return poisson_inversion(s, lam);
    }
    poisson_ptrs(s, lam)
}

/// Inversion of the CDF from one uniform (small means): the least k with
/// `u < F(k) = Σ_{j ≤ k} e^{−λ} λ^j / j!`, the terms by their recurrence. Past k = 200
/// (a tail under 10⁻¹⁵⁰ at λ < 10, where the sum has stopped growing) it stops.
fn poisson_inversion(s: &mut Stream, lam: f64) -> f64 {
    let u = s.uniform();
    let mut p = libm::exp(-lam);
    let (mut k, mut cdf) = (0.0, p);
    while u >= cdf && k < 200.0 {
        k += 1.0;
        p *= lam / k;
        cdf += p;
    }
    k
}

/// Hörmann (1993), "The transformed rejection method for generating Poisson random
/// variables", algorithm PTRS (λ ≥ 10); the acceptance test's three logarithms as one.
fn poisson_ptrs(s: &mut Stream, lam: f64) -> f64 {
    let slam = libm::sqrt(lam);
    let b = 0.931 + 2.53 * slam;
    let a = -0.059 + 0.02483 * b;
    let inv_alpha = 1.1239 + 1.1328 / (b - 3.4);
    let vr = 0.9277 - 3.6224 / (b - 2.0);
    loop {
        let u = s.uniform() - 0.5;
        let v = open_uniform(s);
        let us = 0.5 - u.abs();
        let k = floor_exact((2.0 * a / us + b) * u + lam + 0.43);
        if us >= 0.07 && v <= vr {
            return k;
        }
        if k < 0.0 || (us < 0.013 && v > us) {
            continue;
        }
        let lhs = libm::log(v * inv_alpha / (a / (us * us) + b));
        if lhs <= -lam + k * libm::log(lam) - libm::lgamma(k + 1.0) {
            return k;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn moments(v: &[f64]) -> (f64, f64) {
        let n = v.len() as f64;
        let m = v.iter().sum::<f64>() / n;
        (
            m,
            v.iter().map(|x| (x - m) * (x - m)).sum::<f64>() / (n - 1.0),
        )
    }

    #[test]
    fn poisson_mean_and_variance_are_lambda() {
        for lam in [0.3f64, 4.0, 9.9, 10.0, 57.0, 2.0e4] {
            let mut s = Stream::new(11, lam.to_bits());
            let v: Vec<f64> = (0..200_000).map(|_| poisson(&mut s, lam)).collect();
            let (m, var) = moments(&v);
            assert!((m / lam - 1.0).abs() < 0.01, "lambda {lam}: mean {m}");
            assert!(
                (var / lam - 1.0).abs() < 0.02,
                "lambda {lam}: variance {var}"
            );
            assert!(v.iter().all(|k| k.fract() == 0.0 && *k >= 0.0));
        }
        assert_eq!(poisson(&mut Stream::new(1, 1), 0.0), 0.0);
    }

    #[test]
    fn exp_small_is_exp_and_tukey_is_the_quantile_of_its_cell() {
        for i in 0..=2000 {
            let t = -0.18 + 0.36 * f64::from(i) / 2000.0;
            let (a, b) = (exp_small(t), libm::exp(t));
            assert!((a - b).abs() <= 2.0 * f64::EPSILON * b, "{t}: {a} {b}");
        }
        // The fast path is Q(p) of the drawn p to rounding, for λ on both sides of 0.
        for lambda in [-0.243, -0.1, 1e-13, 0.05, 0.2, 0.3] {
            for seed in 0..2000u64 {
                let mut s = Stream::new(seed, 1);
                let bits = s.clone().next_u64();
                let p = ((bits >> 12) as f64 + 0.5) / (1u64 << 53) as f64;
                let want = if bits & 1 == 1 {
                    tukey_quantile(p, lambda)
                } else {
                    -tukey_quantile(p, lambda)
                };
                let got = tukey(&mut s, lambda);
                assert!(
                    (got - want).abs() <= 1e-13 * want.abs().max(1.0),
                    "{lambda} {p}: {got} {want}"
                );
            }
        }
    }

    #[test]
    fn round_and_floor_are_stds() {
        let mut s = Stream::new(9, 9);
        let specials = [
            0.5,
            -0.5,
            1.5,
            -1.5,
            2.5,
            0.49999999999999994,
            -0.49999999999999994,
            4_503_599_627_370_495.5,
            4_503_599_627_370_497.0,
            1e300,
            -1e300,
            -0.0,
            0.0,
        ];
        for x in specials
            .into_iter()
            .chain((0..100_000).map(|_| (s.uniform() - 0.5) * 1e4))
        {
            assert_eq!(round_exact(x).to_bits(), x.round().to_bits(), "{x}");
            assert_eq!(floor_exact(x), x.floor(), "{x}");
        }
    }

    #[test]
    fn normals_are_standard() {
        let mut s = Stream::new(5, 0);
        let v: Vec<f64> = (0..200_000).map(|_| normal(&mut s)).collect();
        let (m, var) = moments(&v);
        assert!(m.abs() < 0.01 && (var - 1.0).abs() < 0.01, "{m} {var}");
    }

    #[test]
    fn tukey_variance_matches_samples_and_the_logistic() {
        for lambda in [-0.2, -0.1, 0.0, 0.05, 0.14] {
            let mut s = Stream::new(3, 0);
            let v: Vec<f64> = (0..400_000).map(|_| tukey(&mut s, lambda)).collect();
            let (_, var) = moments(&v);
            let want = tukey_variance(lambda);
            assert!(
                (var / want - 1.0).abs() < 0.02,
                "lambda {lambda}: {var} vs {want}"
            );
        }
        // λ → 0 is continuous with the logistic's π²/3.
        assert!((tukey_variance(1e-5) - tukey_variance(0.0)).abs() < 1e-3);
        assert!((tukey_quantile(0.7, 1e-9) - tukey_quantile(0.7, 0.0)).abs() < 1e-6);
    }
}
