//! The numbers of `blurset tradeoff` (DESIGN §8): image error against a reference and
//! the Pareto front of (seconds, PSNR).
use crate::error::{Error, Result};
use crate::image::color::{composite_over, srgb_encode_f64};
use crate::image::{covers, CH};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// Error of an image against a reference, both premultiplied linear RGBA.
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
pub struct ImageError {
    /// PSNR (dB, peak 1) of the sRGB-encoded RGB composited over the background: the
    /// image a PNG of the build holds, before 8-bit quantization.
    pub psnr: f64,
    /// PSNR (dB, peak 1) of the linear premultiplied RGBA itself.
    pub psnr_linear: f64,
    pub mse: f64,
    pub mse_linear: f64,
}

/// PSNR in dB for a mean squared error at peak 1; identical images give +inf, which
/// callers cap for output (`PSNR_CAP_DB`).
pub fn psnr_from_mse(mse: f64) -> f64 {
    if mse > 0.0 {
        -10.0 * mse.log10()
    } else {
        f64::INFINITY
    }
}

/// What an output file says for identical images.
pub const PSNR_CAP_DB: f64 = 200.0;

/// Compare `image` with `reference` (same size, premultiplied linear RGBA, row-major).
pub fn image_error(image: &[f32], reference: &[f32], background: [f64; 3]) -> Result<ImageError> {
    if image.len() != reference.len() || image.is_empty() || !image.len().is_multiple_of(CH) {
        return Err(Error::Shape(format!(
            "image has {} values and reference {}: both must be the same non-empty RGBA size",
            image.len(),
            reference.len()
        )));
    }
    let px = |p: &[f32]| [p[0], p[1], p[2], p[3]].map(f64::from);
    let (se, se_lin) = image
        .par_chunks_exact(CH)
        .zip(reference.par_chunks_exact(CH))
        .map(|(a, b)| {
            let (a, b) = (px(a), px(b));
            let (ca, cb) = (composite_over(a, background), composite_over(b, background));
            let se: f64 = (0..3)
                .map(|c| (srgb_encode_f64(ca[c]) - srgb_encode_f64(cb[c])).powi(2))
                .sum();
            let se_lin: f64 = (0..CH).map(|c| (a[c] - b[c]).powi(2)).sum();
            (se, se_lin)
        })
        .reduce(|| (0.0, 0.0), |x, y| (x.0 + y.0, x.1 + y.1));
    let n = (image.len() / CH) as f64;
    let (mse, mse_linear) = (se / (3.0 * n), se_lin / (CH as f64 * n));
    if !(mse.is_finite() && mse_linear.is_finite()) {
        return Err(Error::Value(
            "image or reference holds a non-finite value".into(),
        ));
    }
    Ok(ImageError {
        psnr: psnr_from_mse(mse).min(PSNR_CAP_DB),
        psnr_linear: psnr_from_mse(mse_linear).min(PSNR_CAP_DB),
        mse,
        mse_linear,
    })
}

/// The error of an image against a reference on the object's pixels (DESIGN §8): those
/// with coverage (alpha above [`COVERAGE_EPS`], Cycles' rounding) in the image or in the
/// reference. The background is exact in
/// both, so a whole-frame figure reads 10·log10(1 / coverage) dB high; this one is the
/// per-pixel figure the 8-bit floor (58.9 dB) is.
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
pub struct ObjectError {
    /// PSNR (dB, peak 1) of the sRGB-encoded RGB composited over the background, on
    /// object pixels (capped at `PSNR_CAP_DB`; the cap when there are none).
    pub psnr: f64,
    pub mse: f64,
    /// Fraction of the frame's pixels that are object pixels.
    pub coverage: f64,
    pub object_px: u64,
}

/// Pixels one task of [`object_se`] sums in order: the sums are then added in the order
/// of their chunks, so they are the same bits on any number of threads (rayon's own
/// `reduce` associates as its work stealing happens to split, and a target build's
/// rounds stop on comparisons of these sums).
const SE_CHUNK_PX: usize = 4096;

/// Squared sRGB error over the object pixels of two premultiplied linear RGBA images:
/// its sum, the sum of each pixel's (its three channels together) squared, and the count.
fn object_se(a: &[f32], b: &[f32], background: [f64; 3]) -> Result<(f64, f64, u64)> {
    pixel_sums(a, b, background, |ca, cb| {
        (0..3)
            .map(|c| (srgb_encode_f64(ca[c]) - srgb_encode_f64(cb[c])).powi(2))
            .sum()
    })
}

/// [`object_se`] of two halves of an image, as the noise of the image their mean writes:
/// each pixel's q = 2 Σ_c [(g(a) − g(m))² + (g(b) − g(m))²], g the sRGB encoding (clamped
/// to [0, 1]) and m the halves' mean in linear light, composited. Where g is linear over
/// the halves' spread this is (g(a) − g(b))², the plain squared difference. Where it is not
/// (dark pixels, where g is steep, and highlights near its clamp, where a firefly lands),
/// the difference of the halves measures neither the written image's scatter, whose
/// steps are half a half's, nor its bias: the PNG is g of a noisy mean, and g's curvature
/// moves its expectation off g(μ) by ½ g″ Var. Expanded about m, the two one-sided steps
/// cancel g's odd terms and keep (½ g″ d²)², d = (a − b) / 2, whose mean is at least that
/// bias squared: the estimate is of the image's whole error, not its scatter alone.
/// Measured by `bench/check_half_noise.py` (a sharp view's halves on independent seed
/// pairs at 15 sample counts against a reference; the rule replayed on them, on our
/// specular orb and on a held-out glossy model): the plain difference read low at few
/// samples on both, this less so, and where the rule stops the bound holds on more
/// images (its rows in bench/results.json, `half_noise_*`).
fn halves_se(a: &[f32], b: &[f32], background: [f64; 3]) -> Result<(f64, f64, u64)> {
    pixel_sums(a, b, background, |ca, cb| {
        (0..3)
            .map(|c| {
                let m = srgb_encode_f64(0.5 * (ca[c] + cb[c]));
                2.0 * ((srgb_encode_f64(ca[c]) - m).powi(2) + (srgb_encode_f64(cb[c]) - m).powi(2))
            })
            .sum()
    })
}

/// Σ q, Σ q² and the count over the pixels of `a` and `b` covered in either, q = `pixel`
/// of the two pixels' RGB composited over `background` (a non-finite value: an error).
fn pixel_sums(
    a: &[f32],
    b: &[f32],
    background: [f64; 3],
    pixel: impl Fn([f64; 3], [f64; 3]) -> f64 + Sync,
) -> Result<(f64, f64, u64)> {
    if a.len() != b.len() || a.is_empty() || !a.len().is_multiple_of(CH) {
        return Err(Error::Shape(format!(
            "image has {} values and reference {}: both must be the same non-empty RGBA size",
            a.len(),
            b.len()
        )));
    }
    let px = |p: &[f32]| [p[0], p[1], p[2], p[3]].map(f64::from);
    let pixel = |a: &[f32], b: &[f32]| -> Option<(f64, f64)> {
        if !a.iter().chain(b).all(|v| v.is_finite()) {
            return Some((f64::NAN, f64::NAN));
        }
        if !covers(a[3]) && !covers(b[3]) {
            return None;
        }
        let q = pixel(
            composite_over(px(a), background),
            composite_over(px(b), background),
        );
        Some((q, q * q))
    };
    let chunks: Vec<(f64, f64, u64)> = a
        .par_chunks(CH * SE_CHUNK_PX)
        .zip(b.par_chunks(CH * SE_CHUNK_PX))
        .map(|(a, b)| {
            a.chunks_exact(CH)
                .zip(b.chunks_exact(CH))
                .filter_map(|(a, b)| pixel(a, b))
                .fold((0.0, 0.0, 0u64), |x, (se, se2)| {
                    (x.0 + se, x.1 + se2, x.2 + 1)
                })
        })
        .collect();
    let (se, se2, n) = chunks
        .iter()
        .fold((0.0, 0.0, 0u64), |x, y| (x.0 + y.0, x.1 + y.1, x.2 + y.2));
    if !se.is_finite() {
        return Err(Error::Value(
            "image or reference holds a non-finite value".into(),
        ));
    }
    Ok((se, se2, n))
}

/// [`ObjectError`] of `image` against `reference` (same size, premultiplied linear RGBA).
pub fn object_error(image: &[f32], reference: &[f32], background: [f64; 3]) -> Result<ObjectError> {
    let (se, _, n) = object_se(image, reference, background)?;
    let mse = if n == 0 { 0.0 } else { se / (3.0 * n as f64) };
    Ok(ObjectError {
        psnr: psnr_from_mse(mse).min(PSNR_CAP_DB),
        mse,
        coverage: n as f64 / (image.len() / CH) as f64,
        object_px: n,
    })
}

/// The render noise of the mean of two halves of an image rendered on independent
/// sequences with equal samples, estimated from the halves themselves: the difference of
/// two independent estimates has twice the variance of either, their mean half of it, so
/// the mean's expected squared error is MSE(h₁, h₂) / 4 (on object pixels, sRGB over the
/// background, as [`object_error`] measures it against a converged reference), taken
/// about the image the mean writes where sRGB bends over the halves' spread
/// ([`halves_se`]).
pub fn half_noise(half_a: &[f32], half_b: &[f32], background: [f64; 3]) -> Result<ObjectError> {
    Ok(half_noise_bound(half_a, half_b, background)?.estimate)
}

/// How many standard deviations of its own scatter the bound of [`half_noise_bound`]
/// adds to the estimate: the one-sided Vysochanskij–Petunin quantile for 5 %,
/// √(4 / (9 · 0.05) − 1) = 2.809. For any unimodal distribution with that variance,
/// P(X − μ ≥ λσ) ≤ 4 / (9 (1 + λ²)) (λ² ≥ 5/3), whatever its tails: the normal quantile
/// (1.645, before) holds only where the pixels' sum is near normal, which a few fireflies
/// carrying the error (specular PBR surfaces: 2 of 30 images measured 0.8–2.2 dB under a
/// 1.645 bound) make it not.
pub const NOISE_BOUND_Z: f64 = 2.808_716_591_058_786;

/// [`half_noise`] with a bound on it that holds where the noise is heavy-tailed.
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
pub struct HalfNoise {
    /// The estimate ([`half_noise`]): unbiased, but on a specular surface a few
    /// fireflies carry much of it, so one round's figure scatters by decibels.
    pub estimate: ObjectError,
    /// The estimate plus [`NOISE_BOUND_Z`] standard deviations of the mean's real error
    /// about it (see [`half_noise_bound`]): the render MSE the merged image has at most.
    pub mse_bound: f64,
    /// [`Self::mse_bound`] as a PSNR: the render PSNR the image reaches at least.
    pub psnr_bound: f64,
    /// (Σq)² / Σq² over the object pixels' squared differences q: how many pixels the
    /// estimate effectively rests on.
    pub n_eff: f64,
}

/// [`half_noise`] of two halves with its upper bound ([`HalfNoise`]).
///
/// What the image is judged by is the real error of the mean of its halves, R, not its
/// expectation. Per pixel and channel, with the halves' errors e_a and e_b about the
/// truth, ((e_a + e_b) / 2)² = ((e_a − e_b) / 2)² + e_a·e_b: the real error is the
/// estimate plus D = Σ e_a·e_b / 3n, exactly, whatever the noise. Independent halves make
/// D's mean 0 and its variance Σ‖Σ_p‖² / 9n² (Σ_p a pixel's channel covariance in one
/// half). A pixel's q = |a − b|² (three channels) has E[q²] ≥ 12‖Σ_p‖², with equality
/// for Gaussian noise alike in the three channels (independent channels, or heavier
/// tails, only make it larger), so Σq² / 108n² bounds Var D from above, and relative to
/// the estimate Σq / 12n, sd(D) / estimate ≤ √(4/3 · Σq² / (Σq)²) = √(4 / (3 n_eff)).
/// The bound is the estimate plus [`NOISE_BOUND_Z`] of that: it holds on at least 95 % of
/// images where the pixels show their noise's tail. (The previous bound, 1.645 standard errors
/// of the estimate as an estimate of the mean noise, left out R's own scatter about that
/// mean: on smooth noise its standard deviation about the estimate is √2 times the
/// estimate's standard error, so that bound held on ~88 % of images, not 95 %.) A tail
/// no pixel of either half has hit yet is beyond what two halves can show: the bound
/// does not claim it. No object pixel, or identical halves: 0, exact.
///
/// Each image is bounded from its own halves only, not pooled with its view's other
/// images: their noise per sample (MSE × samples × coverage) is not one figure, it rises
/// with the level as each frame gets fewer samples and less of the sampler's
/// stratification (sharp to blur_4: 1.6 to 3.2 on the specular vase's view 0), the sharp
/// images render in a phase of their own, and on the specular models the median of a
/// view's other images predicted an image's measured noise worse than its own halves
/// did (RMS log error 0.59 against 0.49; 0.26 against 0.07 on the demo objects).
pub fn half_noise_bound(half_a: &[f32], half_b: &[f32], background: [f64; 3]) -> Result<HalfNoise> {
    let (se, se2, n) = halves_se(half_a, half_b, background)?;
    let mse = if n == 0 { 0.0 } else { se / (12.0 * n as f64) };
    let estimate = ObjectError {
        psnr: psnr_from_mse(mse).min(PSNR_CAP_DB),
        mse,
        coverage: n as f64 / (half_a.len() / CH) as f64,
        object_px: n,
    };
    let (n_eff, rel_sd) = if se > 0.0 && n > 0 {
        let share2 = se2 / (se * se); // Σq² / (Σq)² = 1 / n_eff
        (1.0 / share2, (4.0 / 3.0 * share2).sqrt())
    } else {
        (n as f64, 0.0)
    };
    let mse_bound = estimate.mse * (1.0 + NOISE_BOUND_Z * rel_sd);
    Ok(HalfNoise {
        estimate,
        mse_bound,
        psnr_bound: psnr_from_mse(mse_bound).min(PSNR_CAP_DB),
        n_eff,
    })
}

/// The worst value, the 5th percentile (nearest rank) and the mean of per-image figures
/// (PSNR: higher is better), for a verdict on many images that the mean alone would hide.
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
pub struct Spread {
    pub worst: f64,
    pub p5: f64,
    pub mean: f64,
    pub n: usize,
}

/// [`Spread`] of `values` (none: an error).
pub fn spread(values: &[f64]) -> Result<Spread> {
    if values.is_empty() || values.iter().any(|v| v.is_nan()) {
        return Err(Error::Value("no values, or a NaN among them".into()));
    }
    let mut v = values.to_vec();
    v.sort_by(f64::total_cmp);
    let rank = ((0.05 * v.len() as f64).ceil() as usize).clamp(1, v.len());
    Ok(Spread {
        worst: v[0],
        p5: v[rank - 1],
        mean: v.iter().sum::<f64>() / v.len() as f64,
        n: v.len(),
    })
}

/// High-frequency energy of an image (issue 28): the mean squared 4-neighbour Laplacian
/// of its luma (Rec. 709 weights) in sRGB, composited over `background`, over the
/// interior pixels of a `width`-wide premultiplied linear RGBA image. Texture and edges
/// carry it; render noise adds to it and a denoiser that smooths texture removes it.
pub fn detail_energy(image: &[f32], width: usize, background: [f64; 3]) -> Result<f64> {
    let lap = laplacian(image, width, background)?;
    Ok(mean_product(&lap, &lap))
}

/// The share of a reference's texture and edges an image keeps, with render noise on
/// neither side: the mean product of the image's luma Laplacian (as [`detail_energy`])
/// with each of two renders of the reference on independent seeds, over the mean product
/// of the two renders'. Noise independent of the other side averages out of every
/// product, so noise on top of the image does not read as detail (as it does in
/// [`detail_ratio`]) and the reference's own noise does not hide it: 1 kept, < 1
/// smoothed away. A reference without texture (a product ≤ 0) gives NaN.
pub fn detail_kept(
    image: &[f32],
    reference: [&[f32]; 2],
    width: usize,
    background: [f64; 3],
) -> Result<f64> {
    if reference.iter().any(|r| r.len() != image.len()) {
        return Err(Error::Shape(format!(
            "image has {} values and the references {} and {}",
            image.len(),
            reference[0].len(),
            reference[1].len()
        )));
    }
    let img = laplacian(image, width, background)?;
    let r1 = laplacian(reference[0], width, background)?;
    let r2 = laplacian(reference[1], width, background)?;
    let shared = mean_product(&r1, &r2);
    let kept = (mean_product(&img, &r1) + mean_product(&img, &r2)) / 2.0;
    Ok(if shared > 0.0 {
        kept / shared
    } else {
        f64::NAN
    })
}

/// The 4-neighbour Laplacian of an image's sRGB luma over `background`, at its interior
/// pixels (row-major).
fn laplacian(image: &[f32], width: usize, background: [f64; 3]) -> Result<Vec<f64>> {
    if width == 0 || image.is_empty() || !image.len().is_multiple_of(CH * width) {
        return Err(Error::Shape(format!(
            "{} values are not rows of {width} RGBA pixels",
            image.len()
        )));
    }
    let height = image.len() / (CH * width);
    if width < 3 || height < 3 {
        return Err(Error::Shape(format!(
            "detail energy needs at least 3x3 pixels, got {width}x{height}"
        )));
    }
    let luma: Vec<f64> = image
        .par_chunks_exact(CH)
        .map(|p| {
            let c = composite_over([p[0], p[1], p[2], p[3]].map(f64::from), background);
            (0..3).map(|k| LUMA[k] * srgb_encode_f64(c[k])).sum()
        })
        .collect();
    Ok((1..height - 1)
        .into_par_iter()
        .flat_map_iter(|y| {
            let luma = &luma;
            (1..width - 1).map(move |x| {
                let i = y * width + x;
                luma[i - 1] + luma[i + 1] + luma[i - width] + luma[i + width] - 4.0 * luma[i]
            })
        })
        .collect())
}

/// The mean of the products of two equally long sequences.
fn mean_product(a: &[f64], b: &[f64]) -> f64 {
    let sum: f64 = a.par_iter().zip(b.par_iter()).map(|(x, y)| x * y).sum();
    sum / a.len() as f64
}

/// Rec. 709 luma weights.
const LUMA: [f64; 3] = [0.2126, 0.7152, 0.0722];

/// The detail ratio of an image against its reference: [`detail_energy`] of the image
/// over the reference's (1: the same texture and edges; < 1: smoothed, as a denoiser
/// that erases texture; > 1: noise on top). A flat reference (energy 0) gives +inf for
/// any detail and 1 for none.
pub fn detail_ratio(
    image: &[f32],
    reference: &[f32],
    width: usize,
    background: [f64; 3],
) -> Result<f64> {
    if image.len() != reference.len() {
        return Err(Error::Shape(format!(
            "image has {} values and reference {}",
            image.len(),
            reference.len()
        )));
    }
    let (a, b) = (
        detail_energy(image, width, background)?,
        detail_energy(reference, width, background)?,
    );
    Ok(if b > 0.0 {
        a / b
    } else if a > 0.0 {
        f64::INFINITY
    } else {
        1.0
    })
}

/// Which of the points (seconds, psnr) are Pareto-optimal: no other point is at least
/// as fast and at least as good, and strictly better in one of the two.
pub fn pareto_front(seconds: &[f64], psnr: &[f64]) -> Result<Vec<bool>> {
    if seconds.len() != psnr.len() {
        return Err(Error::Shape(format!(
            "{} times but {} PSNR values",
            seconds.len(),
            psnr.len()
        )));
    }
    if seconds.iter().chain(psnr).any(|v| v.is_nan()) {
        return Err(Error::Value("a time or PSNR value is NaN".into()));
    }
    let pts: Vec<(f64, f64)> = seconds.iter().copied().zip(psnr.iter().copied()).collect();
    Ok(pts
        .iter()
        .map(|&(s, q)| {
            !pts.iter()
                .any(|&(s2, q2)| s2 <= s && q2 >= q && (s2 < s || q2 > q))
        })
        .collect())
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // a failing unwrap is a failing test
mod tests {
    use super::*;

    #[test]
    fn identical_images_cap_and_known_errors_match() -> Result<()> {
        let a = vec![0.25f32, 0.5, 0.75, 1.0, 0.0, 0.0, 0.0, 0.0];
        let e = image_error(&a, &a, [1.0; 3])?;
        assert_eq!(
            (e.psnr, e.psnr_linear, e.mse),
            (PSNR_CAP_DB, PSNR_CAP_DB, 0.0)
        );
        // Transparent pixels composite to the background: 1.0 in sRGB. One opaque
        // pixel differs by 0.1 in linear red.
        let mut b = a.clone();
        b[0] += 0.1;
        let e = image_error(&b, &a, [1.0; 3])?;
        assert!((e.mse_linear - 0.01 / 8.0).abs() < 1e-9);
        let d = srgb_encode_f64(0.35) - srgb_encode_f64(0.25);
        assert!((e.mse - d * d / 6.0).abs() < 1e-6);
        assert!((e.psnr - psnr_from_mse(e.mse)).abs() < 1e-12);
        assert!(image_error(&a, &a[..4], [1.0; 3]).is_err());
        // Detail: the same image 1; a flat copy of it 0; added noise > 1.
        let (w, h) = (8usize, 6usize);
        let tex: Vec<f32> = (0..w * h)
            .flat_map(|i| {
                let v = if (i % w + i / w) % 2 == 0 { 0.8 } else { 0.2 };
                [v, v, v, 1.0]
            })
            .collect();
        let flat: Vec<f32> = (0..w * h).flat_map(|_| [0.5, 0.5, 0.5, 1.0]).collect();
        assert_eq!(detail_ratio(&tex, &tex, w, [1.0; 3])?, 1.0);
        assert_eq!(detail_ratio(&flat, &tex, w, [1.0; 3])?, 0.0);
        assert_eq!(detail_ratio(&flat, &flat, w, [1.0; 3])?, 1.0);
        let mut noisy = tex.clone();
        noisy[4 * 9] += 0.05;
        assert!(detail_ratio(&noisy, &tex, w, [1.0; 3])? > 1.0);
        assert!(detail_energy(&tex, 5, [1.0; 3]).is_err());
        assert!(detail_energy(&tex[..4 * 2 * w], w, [1.0; 3]).is_err());
        Ok(())
    }

    #[test]
    fn detail_kept_sees_texture_through_noise_on_either_side() -> Result<()> {
        // A textured truth, two references and an image each with its own render
        // noise (a small LCG: no dependency for a test).
        let (w, h) = (96usize, 96usize);
        let mut state = 0x2545_F491_u64;
        let mut noise = move |amp: f32| {
            state = state
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1);
            amp * (((state >> 33) as f32 / (1u64 << 31) as f32) - 0.5)
        };
        let truth: Vec<f32> = (0..w * h)
            .flat_map(|i| {
                let (x, y) = ((i % w) as f32, (i / w) as f32);
                let v = 0.45 + 0.2 * (x * 0.9).sin() * (y * 0.7).cos();
                [v, v, v, 1.0]
            })
            .collect();
        let mut noisy = |amp: f32| -> Vec<f32> {
            truth
                .chunks(4)
                .flat_map(|p| {
                    let v = p[0] + noise(amp);
                    [v, v, v, 1.0]
                })
                .collect()
        };
        let (r1, r2, image) = (noisy(0.1), noisy(0.1), noisy(0.1));
        let kept = detail_kept(&image, [&r1, &r2], w, [1.0; 3])?;
        assert!(
            (kept - 1.0).abs() < 0.05,
            "noisy image keeps its texture: {kept}"
        );
        // The energy ratio reads the image's noise as detail over the truth's.
        assert!(detail_ratio(&image, &truth, w, [1.0; 3])? > 1.1);
        // A 3-pixel box blur of the truth smooths texture away.
        let blurred: Vec<f32> = (0..w * h)
            .flat_map(|i| {
                let (x, y) = (i % w, i / w);
                let xs = [x.saturating_sub(1), x, (x + 1).min(w - 1)];
                let v = xs.iter().map(|&x| truth[4 * (y * w + x)]).sum::<f32>() / 3.0;
                [v, v, v, 1.0]
            })
            .collect();
        assert!(detail_kept(&blurred, [&r1, &r2], w, [1.0; 3])? < 0.8);
        let flat: Vec<f32> = (0..w * h).flat_map(|_| [0.5, 0.5, 0.5, 1.0]).collect();
        assert!(detail_kept(&image, [&flat, &flat], w, [1.0; 3])?.is_nan());
        assert!(detail_kept(&image, [&r1, &r1[..4 * w * 3]], w, [1.0; 3]).is_err());
        Ok(())
    }

    #[test]
    fn pareto_front_keeps_the_undominated() -> Result<()> {
        let s = [1.0, 2.0, 3.0, 2.5, 1.0];
        let q = [20.0, 30.0, 29.0, 35.0, 19.0];
        assert_eq!(pareto_front(&s, &q)?, vec![true, true, false, true, false]);
        assert!(pareto_front(&s, &q[..2]).is_err());
        assert!(pareto_front(&[f64::NAN], &[1.0]).is_err());
        Ok(())
    }

    #[test]
    fn object_error_ignores_the_background_and_records_coverage() {
        // 4 pixels: 1 object pixel differing by 0.1 in linear red, 3 transparent.
        let mut a = vec![0.0f32; 16];
        let mut b = vec![0.0f32; 16];
        a[..4].copy_from_slice(&[0.5, 0.5, 0.5, 1.0]);
        b[..4].copy_from_slice(&[0.6, 0.5, 0.5, 1.0]);
        let o = object_error(&a, &b, [1.0; 3]).unwrap();
        let w = image_error(&a, &b, [1.0; 3]).unwrap();
        assert_eq!((o.object_px, o.coverage), (1, 0.25));
        // The whole frame reads 10·log10(1/coverage) = 6.02 dB high.
        assert!((w.psnr - o.psnr - 10.0 * 4f64.log10()).abs() < 1e-9);
        // Coverage in either image counts.
        let mut c = b.clone();
        c[7] = 0.5;
        assert_eq!(object_error(&a, &c, [1.0; 3]).unwrap().object_px, 2);
        // Cycles' rounding on a background (alpha 1.6e-8, measured) is not coverage; one
        // sample's hit in 65,536 is.
        let mut fuzz = b.clone();
        for p in fuzz.chunks_exact_mut(CH).skip(1) {
            p[3] = 1.6e-8;
        }
        assert_eq!(object_error(&a, &fuzz, [1.0; 3]).unwrap().object_px, 1);
        fuzz[7] = 1.0 / 65_536.0;
        assert_eq!(object_error(&a, &fuzz, [1.0; 3]).unwrap().object_px, 2);
        // Nothing covered: exact.
        let z = vec![0.0f32; 16];
        let e = object_error(&z, &z, [1.0; 3]).unwrap();
        assert_eq!((e.object_px, e.psnr), (0, PSNR_CAP_DB));
        assert!(object_error(&a, &b[..8], [1.0; 3]).is_err());
        let mut nan = a.clone();
        nan[0] = f32::NAN;
        assert!(object_error(&nan, &b, [1.0; 3]).is_err());
    }

    #[test]
    fn half_noise_estimates_the_error_of_the_mean() {
        // Two halves = truth ± independent Gaussian noise: MSE(h1, h2)/4 matches the error
        // of their mean against the truth (in expectation; 64k samples here).
        let [a, b, mean, truth] = fireflies(7, 65_536, 0.0, 0.0);
        let est = half_noise(&a, &b, [1.0; 3]).unwrap();
        let real = object_error(&mean, &truth, [1.0; 3]).unwrap();
        assert!((est.psnr - real.psnr).abs() < 0.1, "{est:?} {real:?}");
    }

    /// Two halves of `n` pixels (value 0.4 ± noise) whose noise is Gaussian (σ 0.002)
    /// plus, with probability `p` per pixel and half, a firefly of +`f`; with the truth
    /// (0.4 + the fireflies' expected value), as RGBA.
    fn fireflies(seed: u64, n: usize, p: f64, f: f64) -> [Vec<f32>; 4] {
        let mut s = crate::rng::Stream::new(seed, 0);
        let draw = |s: &mut crate::rng::Stream| {
            let (u, v) = (s.uniform().max(1e-12), s.uniform());
            let g = (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos();
            0.002 * g + if s.uniform() < p { f } else { 0.0 }
        };
        let (mut a, mut b, mut mean, mut truth) = (vec![], vec![], vec![], vec![]);
        let t = 0.4 + p * f;
        for _ in 0..n {
            let (x, y) = (0.4 + draw(&mut s), 0.4 + draw(&mut s));
            for (img, v) in [
                (&mut a, x),
                (&mut b, y),
                (&mut mean, 0.5 * (x + y)),
                (&mut truth, t),
            ] {
                img.extend([v as f32, v as f32, v as f32, 1.0]);
            }
        }
        [a, b, mean, truth]
    }

    /// Halves of one sample a pixel on a highlight (linear 0 or 0.6, mean 0.3, each half its
    /// own draw): sRGB bends across that spread, so the halves' plain difference misses
    /// the written image's error (the mean's steps are half a half's, and g's curvature
    /// moves its expectation). Taken about the merged image, the estimate finds it.
    #[test]
    fn the_estimate_is_of_the_image_the_halves_write() {
        let mut s = crate::rng::Stream::new(11, 0);
        let (mut a, mut b, mut mean, mut truth) = (vec![], vec![], vec![], vec![]);
        for _ in 0..20_000 {
            let x = if s.uniform() < 0.5 { 0.6f32 } else { 0.0 };
            let y = if s.uniform() < 0.5 { 0.6f32 } else { 0.0 };
            for (img, v) in [
                (&mut a, x),
                (&mut b, y),
                (&mut mean, 0.5 * (x + y)),
                (&mut truth, 0.3),
            ] {
                img.extend([v, v, v, 1.0]);
            }
        }
        let real = object_error(&mean, &truth, [1.0; 3]).unwrap().mse;
        let plain = object_error(&a, &b, [1.0; 3]).unwrap().mse / 4.0;
        let est = half_noise(&a, &b, [1.0; 3]).unwrap().mse;
        assert!((est / real - 1.0).abs() < 0.05, "{est} {real}");
        assert!(plain / real < 0.9, "{plain} {real}");
        // Where sRGB is straight over the spread, it is the plain difference.
        let [a, b, ..] = fireflies(5, 4096, 0.0, 0.0);
        let plain = object_error(&a, &b, [1.0; 3]).unwrap().mse / 4.0;
        let est = half_noise(&a, &b, [1.0; 3]).unwrap().mse;
        assert!((est / plain - 1.0).abs() < 1e-4, "{est} {plain}");
    }

    #[test]
    fn the_bound_is_tight_on_smooth_noise_and_wide_on_fireflies() {
        // Smooth noise over 4096 pixels: sd(D) / estimate = 2 / √4096, so the bound adds
        // 2.809 · 2 / 64 = 8.8 % (0.37 dB).
        let [a, b, ..] = fireflies(3, 4096, 0.0, 0.0);
        let h = half_noise_bound(&a, &b, [1.0; 3]).unwrap();
        assert!(h.mse_bound >= h.estimate.mse);
        let gap = h.estimate.psnr - h.psnr_bound;
        assert!(gap > 0.3 && gap < 0.45, "{h:?}");
        assert!(h.n_eff > 1000.0, "{h:?}");
        // The estimate is half_noise's, bit for bit.
        assert_eq!(h.estimate, half_noise(&a, &b, [1.0; 3]).unwrap());
        // A few fireflies carry the error: the bound opens by decibels.
        let [a, b, ..] = fireflies(3, 4096, 0.002, 0.3);
        let h = half_noise_bound(&a, &b, [1.0; 3]).unwrap();
        assert!(h.n_eff < 50.0, "{h:?}");
        assert!(h.estimate.psnr - h.psnr_bound > 1.5, "{h:?}");
        // No noise: nothing to bound.
        let h = half_noise_bound(&a, &a, [1.0; 3]).unwrap();
        assert_eq!((h.mse_bound, h.estimate.mse), (0.0, 0.0));
        assert_eq!(h.psnr_bound, PSNR_CAP_DB);
    }

    /// The share of `trials` images of `n` pixels whose bound is at or above the real
    /// error of the mean of their halves (against the mean's expectation), and the share
    /// the previous bound (1.645 standard errors of the estimate) covered.
    fn coverage_of_the_bound(seed: u64, trials: u64, n: usize, p: f64, f: f64) -> (f64, f64) {
        let (mut now, mut before) = (0, 0);
        for t in 0..trials {
            let [a, b, mean, truth] = fireflies(seed + t, n, p, f);
            let h = half_noise_bound(&a, &b, [1.0; 3]).unwrap();
            let real = object_error(&mean, &truth, [1.0; 3]).unwrap().mse;
            let share2 = 1.0 / h.n_eff;
            let old = h.estimate.mse * (1.0 + 1.645 * (share2 - 1.0 / n as f64).max(0.0).sqrt());
            now += usize::from(h.mse_bound >= real);
            before += usize::from(old >= real);
        }
        (now as f64 / trials as f64, before as f64 / trials as f64)
    }

    #[test]
    fn the_bound_covers_the_real_error_not_only_its_expectation() {
        // Smooth Gaussian noise: the real error scatters about the estimate √2 times as
        // widely as the estimate about the expected error, so 1.645 standard errors of
        // the estimate covered only ~88 % of images; the bound covers ≥ 95 %.
        let (now, before) = coverage_of_the_bound(1000, 400, 1024, 0.0, 0.0);
        assert!(now >= 0.95, "bound covers {now}");
        assert!(before < 0.93, "the 1.645 bound covered {before}");
    }

    #[test]
    fn the_bound_holds_where_the_estimate_is_optimistic_on_fireflies() {
        // Heavy-tailed noise (fireflies in 0.4 % of a half's pixels carrying most of the
        // error): over many images, the estimate alone is below the real error of the
        // mean about half the time and off by decibels; the bound is at or above it in
        // at least 95 % of them, as a render target's stopping rule needs.
        let (mut est_ok, mut worst_est_db) = (0, 0f64);
        let trials = 200;
        for seed in 0..trials {
            let [a, b, mean, truth] = fireflies(100 + seed, 2048, 0.004, 0.25);
            let h = half_noise(&a, &b, [1.0; 3]).unwrap();
            let real = object_error(&mean, &truth, [1.0; 3]).unwrap();
            est_ok += usize::from(h.mse >= real.mse);
            worst_est_db = worst_est_db.max(h.psnr - real.psnr);
        }
        let share = est_ok as f64 / trials as f64;
        assert!(share < 0.75, "estimate at or above {share}");
        assert!(worst_est_db > 1.0, "{worst_est_db}");
        let (now, _) = coverage_of_the_bound(100, trials, 2048, 0.004, 0.25);
        assert!(now >= 0.95, "bound at or above {now}");
        // Rarer, brighter fireflies (0.1 % of pixels, each 0.6): the same.
        let (now, _) = coverage_of_the_bound(5000, trials, 2048, 0.001, 0.6);
        assert!(now >= 0.95, "bound at or above {now}");
    }

    #[test]
    fn the_bound_at_its_extremes() {
        let px = |v: [f32; 4], n: usize| -> Vec<f32> { (0..n).flat_map(|_| v).collect() };
        // No object pixel in either half: nothing to estimate, exact.
        let empty = px([0.0; 4], 16);
        let h = half_noise_bound(&empty, &empty, [1.0; 3]).unwrap();
        assert_eq!((h.estimate.object_px, h.estimate.coverage), (0, 0.0));
        assert_eq!((h.estimate.mse, h.mse_bound, h.n_eff), (0.0, 0.0, 0.0));
        assert_eq!(h.psnr_bound, PSNR_CAP_DB);
        // Identical halves: no difference seen, no bound beyond it.
        let grey = px([0.3, 0.3, 0.3, 1.0], 16);
        let h = half_noise_bound(&grey, &grey, [1.0; 3]).unwrap();
        assert_eq!((h.estimate.mse, h.mse_bound, h.n_eff), (0.0, 0.0, 16.0));
        // One object pixel that differs: the estimate rests on it alone (n_eff 1), and
        // the bound is the estimate times 1 + 2.809 · √(4/3).
        let mut a = empty.clone();
        let mut b = empty.clone();
        a[..4].copy_from_slice(&[0.5, 0.5, 0.5, 1.0]);
        b[..4].copy_from_slice(&[0.6, 0.6, 0.6, 1.0]);
        let h = half_noise_bound(&a, &b, [1.0; 3]).unwrap();
        assert!((h.n_eff - 1.0).abs() < 1e-12, "{h:?}");
        let factor = 1.0 + NOISE_BOUND_Z * (4.0f64 / 3.0).sqrt();
        assert!(
            (h.mse_bound / h.estimate.mse - factor).abs() < 1e-12,
            "{h:?}"
        );
        // The same difference spread evenly over 16 pixels: n_eff 16, a 4x narrower bound.
        let a = px([0.5, 0.5, 0.5, 1.0], 16);
        let b = px([0.6, 0.6, 0.6, 1.0], 16);
        let h = half_noise_bound(&a, &b, [1.0; 3]).unwrap();
        assert!((h.n_eff - 16.0).abs() < 1e-9, "{h:?}");
        let factor = 1.0 + NOISE_BOUND_Z * (4.0f64 / 3.0 / 16.0).sqrt();
        assert!(
            (h.mse_bound / h.estimate.mse - factor).abs() < 1e-12,
            "{h:?}"
        );
        // A non-finite pixel, or halves of different sizes: an error, not a bound.
        let mut nan = a.clone();
        nan[5] = f32::INFINITY;
        assert!(half_noise_bound(&nan, &b, [1.0; 3]).is_err());
        assert!(half_noise_bound(&a, &b[..8], [1.0; 3]).is_err());
        // The quantile is the one-sided Vysochanskij–Petunin one for 5 %.
        assert!((NOISE_BOUND_Z - (4.0f64 / (9.0 * 0.05) - 1.0).sqrt()).abs() < 1e-12);
        let tail = 4.0 / (9.0 * (1.0 + NOISE_BOUND_Z * NOISE_BOUND_Z));
        assert!((tail - 0.05).abs() < 1e-12);
    }

    #[test]
    fn the_bound_is_the_same_bits_on_any_number_of_threads() {
        // More pixels than one summing task holds: the chunks' sums are added in order,
        // so the rounds a target build stops on cannot depend on the machine's threads.
        let [a, b, ..] = fireflies(11, 3 * SE_CHUNK_PX + 123, 0.003, 0.4);
        let on = |threads: usize| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap()
                .install(|| half_noise_bound(&a, &b, [1.0; 3]).unwrap())
        };
        let one = on(1);
        for threads in [2, 3, 8] {
            let h = on(threads);
            assert_eq!(h.mse_bound.to_bits(), one.mse_bound.to_bits());
            assert_eq!(h.estimate.mse.to_bits(), one.estimate.mse.to_bits());
            assert_eq!(h.n_eff.to_bits(), one.n_eff.to_bits());
        }
    }

    #[test]
    fn spread_reports_worst_and_fifth_percentile() {
        let v: Vec<f64> = (1..=40).map(f64::from).collect();
        let s = spread(&v).unwrap();
        assert_eq!((s.worst, s.p5, s.mean, s.n), (1.0, 2.0, 20.5, 40));
        assert_eq!(spread(&[3.0]).unwrap().p5, 3.0);
        assert!(spread(&[]).is_err());
        assert!(spread(&[1.0, f64::NAN]).is_err());
    }
}
