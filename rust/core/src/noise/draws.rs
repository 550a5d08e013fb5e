//! The random draws of the raw noise models, each a pure function of a Philox stream
//! ([`crate::rng::Stream`]) so that a row's draws depend only on its key and row:
//! standard normals (Box–Muller), Poisson counts (inversion below 10, Hörmann's
//! transformed rejection PTRS above, as numpy's generator does it) and Tukey-lambda
//! variates by their quantile function.
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

/// A Tukey-lambda variate of shape `lambda` (scale 1).
pub fn tukey(s: &mut Stream, lambda: f64) -> f64 {
    tukey_quantile(open_uniform(s), lambda)
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

/// Multiply uniforms until the product falls below e^−λ (small means).
fn poisson_inversion(s: &mut Stream, lam: f64) -> f64 {
    let limit = libm::exp(-lam);
    let (mut k, mut prod) = (0.0, s.uniform());
    while prod > limit {
        k += 1.0;
        prod *= s.uniform();
    }
    k
}

/// Hörmann (1993), "The transformed rejection method for generating Poisson random
/// variables", algorithm PTRS (λ ≥ 10).
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
        let k = libm::floor((2.0 * a / us + b) * u + lam + 0.43);
        if us >= 0.07 && v <= vr {
            return k;
        }
        if k < 0.0 || (us < 0.013 && v > us) {
            continue;
        }
        let lhs = libm::log(v) + libm::log(inv_alpha) - libm::log(a / (us * us) + b);
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
