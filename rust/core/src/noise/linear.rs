//! Noise from a build's linear float images instead of its sRGB PNGs (issue 9).
//!
//! Linear path, per colour value of a view with linear premultiplied RGBA `L` (what
//! `blurset build --keep-linear` stores): composite over the build's background exactly
//! as its PNG was (`rgb + (1 − a)·bg`), clip to [0, 1] (the PNG's white point), then
//! `y = white_level · L / wb[c]` and `y' = y + sqrt(σ_r² + σ_s²·y) · n` with the same
//! model and the same standard normals `n` as the PNG path of [`super::kernel`] (same
//! key, stream and value index). The PNG path's clean value is `decode(code / 255)`
//! instead of `L`, so with the shared draws the two paths differ only by what the 8-bit
//! PNG (and, for `gamma = 2.2`, its curve) did to the clean image.
use super::kernel::{add_noise, code_thresholds, Noisy};
use super::model::{Gamma, NoiseModel};
use crate::error::{Error, Result};
use crate::image::color::composite_over;
use crate::image::exr::read::read_exr;
use crate::image::io::{Image, Samples};
use crate::image::resample::area_mean;
use rayon::prelude::*;
use std::path::Path;

/// A linear RGB image (3 f32 per pixel, row-major), composited over its background.
#[derive(Clone, Debug, PartialEq)]
pub struct LinearRgb {
    pub width: u32,
    pub height: u32,
    pub rgb: Vec<f32>,
}

impl LinearRgb {
    pub fn new(width: u32, height: u32, rgb: Vec<f32>) -> Result<Self> {
        let n = width as usize * height as usize * 3;
        if rgb.len() != n || n == 0 {
            return Err(Error::Shape(format!(
                "{} values for a {width} x {height} RGB image, expected {n} (> 0)",
                rgb.len()
            )));
        }
        if let Some(i) = rgb.iter().position(|v| !v.is_finite()) {
            return Err(Error::Value(format!(
                "linear image has a non-finite value {} at pixel {} channel {}",
                rgb[i],
                i / 3,
                i % 3
            )));
        }
        Ok(LinearRgb { width, height, rgb })
    }
}

impl LinearRgb {
    /// The image clipped to [0, 1] per pixel (the white point its PNG shows) and
    /// area-averaged over `factor × factor` blocks in linear light, as the build's
    /// `images_<f>/`: the clean image noise is drawn on at that size.
    pub fn downsample(&self, factor: u32) -> Result<LinearRgb> {
        let data: Vec<f64> = self
            .rgb
            .iter()
            .map(|&v| f64::from(v).clamp(0.0, 1.0))
            .collect();
        let small = area_mean(self.width, self.height, 3, &data, factor)?;
        LinearRgb::new(
            self.width / factor,
            self.height / factor,
            small.into_iter().map(|v| v as f32).collect(),
        )
    }
}

/// The linear RGB of an 8/16-bit RGB image through `gamma` (no white balance: the
/// noise applies it), as the PNG path's kernel decodes each code.
pub fn linear_from_codes(img: &Image, gamma: Gamma) -> Result<LinearRgb> {
    if img.channels != 3 {
        return Err(Error::Shape(format!(
            "{} channels; downsampled noise needs RGB images",
            img.channels
        )));
    }
    let max = f64::from(img.samples.max_code());
    let rgb = match &img.samples {
        Samples::U8(s) => s
            .iter()
            .map(|&c| gamma.decode(f64::from(c) / max) as f32)
            .collect(),
        Samples::U16(s) => s
            .iter()
            .map(|&c| gamma.decode(f64::from(c) / max) as f32)
            .collect(),
    };
    LinearRgb::new(img.width, img.height, rgb)
}

/// Premultiplied linear RGBA composited over `background` (linear RGB), as the build's
/// PNG encoding does it ([`composite_over`]), unclipped.
pub fn composite(width: u32, height: u32, rgba: &[f32], background: [f64; 3]) -> Result<LinearRgb> {
    let n = width as usize * height as usize;
    if rgba.len() != n * 4 {
        return Err(Error::Shape(format!(
            "{} values for a {width} x {height} RGBA image, expected {}",
            rgba.len(),
            n * 4
        )));
    }
    let rgb = rgba
        .par_chunks_exact(4)
        .flat_map_iter(|p| {
            composite_over([p[0], p[1], p[2], p[3]].map(f64::from), background).map(|v| v as f32)
        })
        .collect();
    LinearRgb::new(width, height, rgb)
}

/// Read a linear EXR written by the build (`linear/<view>.exr`, premultiplied RGBA;
/// opaque when it has no alpha) and composite it over `background`. NaN or inf in the
/// file is an image error naming it.
pub fn read_linear(path: &Path, background: [f64; 3]) -> Result<LinearRgb> {
    let f = read_exr(path)?;
    if let Some(i) = f.rgba.iter().position(|v| !v.is_finite()) {
        let w = (f.width as usize).max(1);
        return Err(Error::Image {
            reason: format!(
                "non-finite value {} at pixel ({}, {}) channel {}",
                f.rgba[i],
                (i / 4) % w,
                (i / 4) / w,
                "RGBA".as_bytes()[i % 4] as char
            ),
            path: path.to_path_buf(),
        });
    }
    composite(f.width, f.height, &f.rgba, background)
}

/// The clean linear values `y` the noise is added to: `white_level · clip(L, 0, 1) / wb[c]`.
pub fn clean_from_linear(img: &LinearRgb, model: &NoiseModel) -> Result<Vec<f32>> {
    model.validate()?;
    let scale = [0, 1, 2].map(|c| model.channel_scale(c, 3));
    Ok(img
        .rgb
        .par_iter()
        .enumerate()
        .map(|(i, &l)| (scale[i % 3] * f64::from(l).clamp(0.0, 1.0)) as f32)
        .collect())
}

/// The standard normals the noise kernel draws for an RGB image of this size in
/// `stream` under `key`, value `v = pixel · 3 + c`. Taken from [`add_noise`]
/// itself (a black image at σ_r = 1, σ_s = 0 gives `0 + 1 · n`), so both paths share
/// their draws bit for bit whatever that kernel's implementation.
pub fn standard_normals(width: u32, height: u32, key: u64, stream: u64) -> Result<Vec<f32>> {
    let black = Image::new(
        width,
        height,
        3,
        Samples::U8(vec![0; width as usize * height as usize * 3]),
    )?;
    let unit = NoiseModel {
        sigma_read: 1.0,
        sigma_shot: 0.0,
        gamma: Gamma::Power22,
        white_balance: None,
        white_level: 1.0,
    };
    Ok(add_noise(&black, &unit, key, stream)?.linear)
}

/// One noisy frame from linear light: the unclipped linear noisy RGB and the processed
/// 8-bit RGB image (forward white balance, `model.gamma` encoding, rounded).
pub fn add_noise_linear(
    img: &LinearRgb,
    model: &NoiseModel,
    key: u64,
    stream: u64,
) -> Result<Noisy> {
    model.validate()?;
    let normals = standard_normals(img.width, img.height, key, stream)?;
    let scale = [0, 1, 2].map(|c| model.channel_scale(c, 3));
    // Forward processing as the kernel rounds it: the code is the number of thresholds
    // `decode((k + 0.5) / 255) · scale` at or below the noisy value.
    let thresholds = scale.map(|s| code_thresholds(model.gamma, 255, s));
    // The kernel's arithmetic: clean and std rounded to f32, then clean + std · n in f32.
    let (linear, codes): (Vec<f32>, Vec<u8>) = img
        .rgb
        .par_iter()
        .zip(normals.par_iter())
        .enumerate()
        .map(|(i, (&l, &n))| {
            let c = i % 3;
            let y = scale[c] * f64::from(l).clamp(0.0, 1.0);
            let std = model.noise_std(y) as f32;
            let noisy = y as f32 + std * n;
            let code = thresholds[c].partition_point(|t| noisy >= *t) as u8;
            (noisy, code)
        })
        .unzip();
    Ok(Noisy {
        linear,
        linear_channels: 3,
        processed: Image::new(img.width, img.height, 3, Samples::U8(codes))?,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::image::color::srgb_encode_u8;
    use crate::noise::model::{sample_white_balance, stream_id, NoiseLevels, WhiteBalance};

    fn model(sr: f64, ss: f64, wb: Option<WhiteBalance>, gamma: Gamma) -> NoiseModel {
        NoiseModel {
            sigma_read: sr,
            sigma_shot: ss,
            gamma,
            white_balance: wb,
            white_level: 1.0,
        }
    }

    #[test]
    fn linear_path_equals_png_path_on_code_values() -> Result<()> {
        let (w, h) = (64u32, 48u32);
        let codes: Vec<u8> = (0..w * h * 3).map(|i| (i * 7 % 256) as u8).collect();
        let png = Image::new(w, h, 3, Samples::U8(codes.clone()))?;
        let (sr, ss) = NoiseLevels::DEFAULT.sigmas(8.0)?;
        for gamma in [Gamma::Srgb, Gamma::Power22] {
            let m = model(sr, ss, Some(sample_white_balance(3)), gamma);
            let lin = LinearRgb::new(
                w,
                h,
                codes
                    .iter()
                    .map(|&c| gamma.decode(f64::from(c) / 255.0) as f32)
                    .collect(),
            )?;
            // The PNG path decodes in f64; feed the linear path the same f64 values
            // rounded to f32 and compare within f32 rounding of y.
            let a = add_noise(&png, &m, 99, stream_id(3, 1))?;
            let b = add_noise_linear(&lin, &m, 99, stream_id(3, 1))?;
            let worst = a
                .linear
                .iter()
                .zip(&b.linear)
                .map(|(x, y)| (x - y).abs())
                .fold(0.0f32, f32::max);
            assert!(worst < 1e-6, "{gamma:?}: {worst}");
            let Samples::U8(pa) = &a.processed.samples else {
                panic!("depth")
            };
            let Samples::U8(pb) = &b.processed.samples else {
                panic!("depth")
            };
            let off = pa.iter().zip(pb).filter(|(x, y)| x != y).count();
            // Same thresholds; only values within f32 rounding of one may differ.
            assert!(off * 1000 <= pa.len(), "{off} codes differ");
        }
        Ok(())
    }

    #[test]
    fn variance_follows_the_model_and_black_stays_signed() -> Result<()> {
        let (w, h) = (300u32, 200u32);
        let (sr, ss) = (0.01, 0.05);
        for level in [0.0f32, 0.02, 0.5, 1.0] {
            let img = LinearRgb::new(w, h, vec![level; (w * h * 3) as usize])?;
            let m = model(sr, ss, None, Gamma::Srgb);
            let noisy = add_noise_linear(&img, &m, 5, 0)?;
            let n = noisy.linear.len() as f64;
            let mean = noisy.linear.iter().map(|&v| f64::from(v)).sum::<f64>() / n;
            let var = noisy
                .linear
                .iter()
                .map(|&v| (f64::from(v) - mean).powi(2))
                .sum::<f64>()
                / n;
            let want = sr * sr + ss * ss * f64::from(level);
            assert!((mean - f64::from(level)).abs() < 4.0 * (want / n).sqrt());
            assert!((var / want - 1.0).abs() < 0.02, "{level}: {var} vs {want}");
            if level == 0.0 {
                assert!(noisy.linear.iter().any(|&v| v < 0.0));
            }
        }
        Ok(())
    }

    #[test]
    fn downsampled_noise_keeps_sigma_at_the_smaller_size() -> Result<()> {
        // Noise drawn at full size and then averaged over 4 x 4 blocks has 1/4 of its
        // std; noise drawn on the averaged image has the model's std.
        let (w, h) = (256u32, 256u32);
        let img = LinearRgb::new(w, h, vec![0.25; (w * h * 3) as usize])?;
        let m = model(0.02, 0.04, None, Gamma::Srgb);
        let want = (0.02f64 * 0.02 + 0.04 * 0.04 * 0.25).sqrt();
        let std = |v: &[f32]| {
            let n = v.len() as f64;
            (v.iter()
                .map(|&x| (f64::from(x) - 0.25).powi(2))
                .sum::<f64>()
                / n)
                .sqrt()
        };
        let full = add_noise_linear(&img, &m, 3, 0)?;
        let averaged = LinearRgb::new(w, h, full.linear)?.downsample(4)?;
        assert!((std(&averaged.rgb) / want - 0.25).abs() < 0.02);
        let small = add_noise_linear(&img.downsample(4)?, &m, 3, 0)?;
        assert!((std(&small.linear) / want - 1.0).abs() < 0.03);
        Ok(())
    }

    #[test]
    fn codes_decode_through_the_curve() -> Result<()> {
        let img = Image::new(1, 1, 3, Samples::U8(vec![0, 128, 255]))?;
        let lin = linear_from_codes(&img, Gamma::Srgb)?;
        assert_eq!(lin.rgb[0], 0.0);
        assert!((lin.rgb[1] - 0.215_860_5).abs() < 1e-6);
        assert_eq!(lin.rgb[2], 1.0);
        let gray = Image::new(1, 1, 1, Samples::U8(vec![3]))?;
        assert!(linear_from_codes(&gray, Gamma::Srgb).is_err());
        Ok(())
    }

    #[test]
    fn clean_clips_to_the_white_point_and_applies_white_balance() -> Result<()> {
        let img = LinearRgb::new(2, 1, vec![-0.1, 0.5, 1.7, 0.25, 0.25, 0.25])?;
        let wb = WhiteBalance {
            red: 2.0,
            blue: 1.6,
        };
        let y = clean_from_linear(&img, &model(0.0, 0.0, Some(wb), Gamma::Srgb))?;
        assert_eq!(
            y,
            vec![
                0.0,
                0.5,
                (1.0 / 1.6) as f32,
                0.125,
                0.25,
                (0.25 / 1.6) as f32
            ]
        );
        assert!(LinearRgb::new(1, 1, vec![0.0, f32::NAN, 0.0]).is_err());
        Ok(())
    }

    #[test]
    fn composite_matches_the_png_encoding() -> Result<()> {
        let rgba = [0.2f32, 0.1, 0.0, 0.5, 0.0, 0.0, 0.0, 0.0];
        let c = composite(2, 1, &rgba, [1.0, 1.0, 1.0])?;
        assert_eq!(c.rgb, vec![0.7, 0.6, 0.5, 1.0, 1.0, 1.0]);
        let mut acc = crate::image::accumulate::Accumulator::new(2, 1);
        acc.add_frame(&rgba)?;
        let bytes = acc.encode_rgb8([1.0; 3])?;
        let again: Vec<u8> = c
            .rgb
            .iter()
            .map(|&v| srgb_encode_u8(f64::from(v)))
            .collect();
        assert_eq!(bytes, again);
        Ok(())
    }
}
