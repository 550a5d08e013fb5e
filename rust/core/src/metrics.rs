//! The numbers of `blurset tradeoff` (DESIGN §8): image error against a reference and
//! the Pareto front of (seconds, PSNR).
use crate::error::{Error, Result};
use crate::image::color::{composite_over, srgb_encode_f64};
use crate::image::CH;
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

/// High-frequency energy of an image (issue 28): the mean squared 4-neighbour Laplacian
/// of its luma (Rec. 709 weights) in sRGB, composited over `background`, over the
/// interior pixels of a `width`-wide premultiplied linear RGBA image. Texture and edges
/// carry it; render noise adds to it and a denoiser that smooths texture removes it.
pub fn detail_energy(image: &[f32], width: usize, background: [f64; 3]) -> Result<f64> {
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
    let sum: f64 = (1..height - 1)
        .into_par_iter()
        .map(|y| {
            (1..width - 1)
                .map(|x| {
                    let i = y * width + x;
                    let lap = luma[i - 1] + luma[i + 1] + luma[i - width] + luma[i + width]
                        - 4.0 * luma[i];
                    lap * lap
                })
                .sum::<f64>()
        })
        .sum();
    Ok(sum / ((width - 2) * (height - 2)) as f64)
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
    fn pareto_front_keeps_the_undominated() -> Result<()> {
        let s = [1.0, 2.0, 3.0, 2.5, 1.0];
        let q = [20.0, 30.0, 29.0, 35.0, 19.0];
        assert_eq!(pareto_front(&s, &q)?, vec![true, true, false, true, false]);
        assert!(pareto_front(&s, &q[..2]).is_err());
        assert!(pareto_front(&[f64::NAN], &[1.0]).is_err());
        Ok(())
    }
}
