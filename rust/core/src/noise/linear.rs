//! Noise on a whole build (issue 9): the seed of every (setting, level), noise that
//! starts from the build's linear float images instead of its sRGB PNGs, and the
//! numbers a preview sheet shows about a thumbnail.
//!
//! Linear path, per colour value of a view with linear premultiplied RGBA `L` (what
//! `blurset build --keep-linear` stores): composite over the build's background exactly
//! as its PNG was (`rgb + (1 − a)·bg`), clip to [0, 1] (the PNG's white point), then
//! `y = white_level · L / wb[c]` and `y' = y + sqrt(σ_r² + σ_s²·y) · n` with the same
//! model and the same standard normals `n` as the PNG path of [`super::kernel`] (same
//! key, stream and value index). The PNG path's clean value is `decode(code / 255)`
//! instead of `L`, so with the shared draws the two paths differ only by what the 8-bit
//! PNG (and, for `gamma = 2.2`, its curve) did to the clean image.
use super::kernel::{self as noise, Gamma, NoiseModel, Noisy, Variant};
use crate::error::{Error, Result};
use crate::image::color::{self, composite_over, srgb_encode_u8};
use crate::image::exr::read::read_exr;
use crate::image::exr::write::exr_bytes;
use crate::image::io::{self as image_io, Image, Samples};
use crate::rng;
use rayon::prelude::*;
use std::path::{Path, PathBuf};

/// The noise seed of one level of one setting of a build, from the one seed given to
/// `blurset noise BUILD`: `derive_seed(seed, [fnv1a64("build_noise"), fnv1a64(setting),
/// fnv1a64(level)])`. It depends on neither the gains nor the levels chosen, so adding
/// a gain or a level later reproduces what exists. It plays the role of `--seed` of the
/// single-scene command (white balance and `noise_key(seed, gain)` come from it).
pub fn scene_seed(seed: u64, setting: &str, level: &str) -> u64 {
    rng::derive_seed(
        seed,
        &[
            rng::fnv1a64(b"build_noise"),
            rng::fnv1a64(setting.as_bytes()),
            rng::fnv1a64(level.as_bytes()),
        ],
    )
}

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

/// Premultiplied linear RGBA composited over `background` (linear RGB), as the build's
/// PNG encoding does it (`accumulate::composite_over`), unclipped.
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

/// Linear value per unit of processed value of colour channel `c` (of 3).
fn channel_scale(model: &NoiseModel, c: usize) -> f64 {
    let wb = model
        .white_balance
        .map_or(1.0, |wb| [wb.red, 1.0, wb.blue][c]);
    model.white_level / wb
}

/// The clean linear values `y` the noise is added to: `white_level · clip(L, 0, 1) / wb[c]`.
pub fn clean_from_linear(img: &LinearRgb, model: &NoiseModel) -> Result<Vec<f32>> {
    model.validate()?;
    let scale = [0, 1, 2].map(|c| channel_scale(model, c));
    Ok(img
        .rgb
        .par_iter()
        .enumerate()
        .map(|(i, &l)| (scale[i % 3] * f64::from(l).clamp(0.0, 1.0)) as f32)
        .collect())
}

/// The standard normals the noise kernel draws for an RGB image of this size in
/// `stream` under `key`, value `v = pixel · 3 + c`. Taken from [`noise::add_noise`]
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
    Ok(noise::add_noise(&black, &unit, key, stream)?.linear)
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
    let scale = [0, 1, 2].map(|c| channel_scale(model, c));
    let (var_read, var_shot) = (
        model.sigma_read * model.sigma_read,
        model.sigma_shot * model.sigma_shot,
    );
    // Forward processing as the kernel rounds it: the code is the number of thresholds
    // `decode((k + 0.5) / 255) · scale` at or below the noisy value.
    let thresholds = scale.map(|s| {
        (0..255)
            .map(|k| (model.gamma.decode((f64::from(k) + 0.5) / 255.0) * s) as f32)
            .collect::<Vec<f32>>()
    });
    // The kernel's arithmetic: clean and std rounded to f32, then clean + std · n in f32.
    let (linear, codes): (Vec<f32>, Vec<u8>) = img
        .rgb
        .par_iter()
        .zip(normals.par_iter())
        .enumerate()
        .map(|(i, (&l, &n))| {
            let c = i % 3;
            let y = scale[c] * f64::from(l).clamp(0.0, 1.0);
            let std = libm::sqrt(var_read + var_shot * y) as f32;
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

/// The linear-path counterpart of [`noise::write_variants`]: read every linear EXR once
/// (composited over `background`) and write, per variant and frame,
/// `out_dir/images/<name>.png` (8-bit RGB) and `out_dir/linear/<name>.exr` (RGB float).
/// Keys and streams are those of the PNG path (`stream_id(view, frame)`). All images
/// must share one size. Files are written in place; callers make the tree atomic.
pub fn write_variants_linear(
    sources: &[PathBuf],
    names: &[String],
    frames: u32,
    variants: &[Variant],
    background: [f64; 3],
) -> Result<()> {
    if frames == 0 {
        return Err(Error::Value("frames must be at least 1".into()));
    }
    if names.len() != sources.len() * frames as usize {
        return Err(Error::Shape(format!(
            "{} output names for {} images x {frames} frames",
            names.len(),
            sources.len()
        )));
    }
    for v in variants {
        v.model.validate()?;
        for sub in ["images", "linear"] {
            let d = v.out_dir.join(sub);
            std::fs::create_dir_all(&d).map_err(|e| Error::io("cannot create directory", &d, e))?;
        }
    }
    let size = std::sync::OnceLock::new();
    sources.par_iter().enumerate().try_for_each(|(i, path)| {
        let img = read_linear(path, background)?;
        let (w0, h0, first) = *size.get_or_init(|| (img.width, img.height, i));
        if (img.width, img.height) != (w0, h0) {
            return Err(Error::Image {
                reason: format!(
                    "size {} x {} differs from {} x {} of {:?}",
                    img.width, img.height, w0, h0, sources[first]
                ),
                path: path.clone(),
            });
        }
        for v in variants {
            for k in 0..frames {
                let noisy = add_noise_linear(&img, &v.model, v.key, noise::stream_id(i as u32, k))?;
                let name = &names[i * frames as usize + k as usize];
                write_file(
                    &v.out_dir.join("images").join(format!("{name}.png")),
                    &image_io::png_bytes(&noisy.processed)?,
                )?;
                write_file(
                    &v.out_dir.join("linear").join(format!("{name}.exr")),
                    &exr_bytes(img.width, img.height, 3, &noisy.linear)?,
                )?;
            }
        }
        Ok(())
    })
}

fn write_file(path: &Path, bytes: &[u8]) -> Result<()> {
    std::fs::write(path, bytes).map_err(|e| Error::io("cannot write", path, e))
}

/// What a contact sheet says about one sharp thumbnail (8-bit RGB over a background).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ThumbnailQa {
    /// Fraction of pixels that differ from the background by more than `tolerance` codes.
    pub coverage: f64,
    /// Mean Rec. 709 luma (codes / 255) of those object pixels; 0 when there are none.
    pub object_luma: f64,
    /// Fraction of the one-pixel frame border covered by the object.
    pub border: f64,
}

/// Codes an object pixel must differ from the background by (any channel).
pub const QA_TOLERANCE: u8 = 8;

/// Coverage, object brightness and border contact of an RGB8 image whose background is
/// `background` (linear RGB, encoded to sRGB codes as the build's PNGs are).
pub fn thumbnail_qa(
    width: u32,
    height: u32,
    rgb: &[u8],
    background: [f64; 3],
) -> Result<ThumbnailQa> {
    let (w, h) = (width as usize, height as usize);
    if rgb.len() != w * h * 3 || w == 0 || h == 0 {
        return Err(Error::Shape(format!(
            "{} values for a {width} x {height} RGB8 image",
            rgb.len()
        )));
    }
    let bg = background.map(srgb_encode_u8);
    let is_object = |p: usize| (0..3).any(|c| rgb[p * 3 + c].abs_diff(bg[c]) > QA_TOLERANCE);
    let (mut count, mut luma) = (0usize, 0.0f64);
    for p in 0..w * h {
        if is_object(p) {
            count += 1;
            let [r, g, b] = [0, 1, 2].map(|c| f64::from(rgb[p * 3 + c]) / 255.0);
            luma += color::luma([r, g, b]);
        }
    }
    let border: Vec<usize> = (0..w)
        .flat_map(|x| [x, (h - 1) * w + x])
        .chain((1..h.saturating_sub(1)).flat_map(|y| [y * w, y * w + w - 1]))
        .collect();
    let touching = border.iter().filter(|&&p| is_object(p)).count();
    Ok(ThumbnailQa {
        coverage: count as f64 / (w * h) as f64,
        object_luma: if count > 0 { luma / count as f64 } else { 0.0 },
        border: touching as f64 / border.len().max(1) as f64,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::noise::kernel::{sample_white_balance, NoiseLevels, WhiteBalance};

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
    fn scene_seeds_differ_and_are_stable() {
        let a = scene_seed(7, "demo_box_000", "blur_2");
        assert_eq!(a, scene_seed(7, "demo_box_000", "blur_2"));
        assert_ne!(a, scene_seed(7, "demo_box_000", "blur_3"));
        assert_ne!(a, scene_seed(7, "demo_box_090", "blur_2"));
        assert_ne!(a, scene_seed(8, "demo_box_000", "blur_2"));
        // Not a plain concatenation: ("ab", "c") and ("a", "bc") differ.
        assert_ne!(scene_seed(0, "ab", "c"), scene_seed(0, "a", "bc"));
    }

    /// On a linear image whose values are exactly the decoded PNG codes, the linear
    /// path reproduces the PNG path's linear output bit for bit (shared draws and
    /// arithmetic), and its processed codes within one code (tie rounding).
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
            let a = noise::add_noise(&png, &m, 99, noise::stream_id(3, 1))?;
            let b = add_noise_linear(&lin, &m, 99, noise::stream_id(3, 1))?;
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

    #[test]
    fn exr_files_round_trip_through_the_writer() -> Result<()> {
        let dir = std::env::temp_dir().join(format!("blurset-noise-linear-{}", std::process::id()));
        let (w, h) = (8u32, 6u32);
        let rgba: Vec<f32> = (0..w * h * 4).map(|i| (i % 13) as f32 / 13.0).collect();
        let src = dir.join("src");
        let paths: Vec<PathBuf> = (0..2).map(|i| src.join(format!("{i:03}.exr"))).collect();
        for p in &paths {
            crate::image::exr::write::write_exr(p, w, h, &rgba)?;
        }
        let m = model(0.02, 0.03, None, Gamma::Srgb);
        let v = Variant {
            out_dir: dir.join("out"),
            model: m,
            key: 4,
        };
        let names = vec!["000".to_string(), "001".to_string()];
        write_variants_linear(&paths, &names, 1, std::slice::from_ref(&v), [1.0; 3])?;
        let back = read_exr(&dir.join("out/linear/001.exr"))?;
        let img = read_linear(&paths[1], [1.0; 3])?;
        let want = add_noise_linear(&img, &m, 4, noise::stream_id(1, 0))?;
        let got: Vec<f32> = back
            .rgba
            .chunks_exact(4)
            .flat_map(|p| [p[0], p[1], p[2]])
            .collect();
        assert_eq!(got, want.linear);
        let png = image_io::read_image(&dir.join("out/images/000.png"))?;
        assert_eq!((png.width, png.height, png.channels), (w, h, 3));
        // A NaN in a source names the file.
        let mut bad = rgba.clone();
        bad[5] = f32::NAN;
        crate::image::exr::write::write_exr(&paths[0], w, h, &bad)?;
        let e = write_variants_linear(&paths, &names, 1, &[v], [1.0; 3])
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
        assert!(e.contains("000.exr") && e.contains("non-finite"), "{e}");
        let _ = std::fs::remove_dir_all(&dir);
        Ok(())
    }

    #[test]
    fn qa_sees_empty_black_and_clipped() -> Result<()> {
        let (w, h) = (20u32, 10u32);
        let white = vec![255u8; (w * h * 3) as usize];
        let qa = thumbnail_qa(w, h, &white, [1.0; 3])?;
        assert_eq!((qa.coverage, qa.border), (0.0, 0.0));
        let mut img = white.clone();
        // A black 4 x 4 square inside, then one touching the left edge.
        for y in 3..7 {
            for x in 8..12 {
                img[(y * w as usize + x) * 3..][..3].fill(0);
            }
        }
        let qa = thumbnail_qa(w, h, &img, [1.0; 3])?;
        assert!((qa.coverage - 16.0 / 200.0).abs() < 1e-12);
        assert_eq!((qa.object_luma, qa.border), (0.0, 0.0));
        for y in 0..h as usize {
            img[y * w as usize * 3..][..3].fill(128);
        }
        let qa = thumbnail_qa(w, h, &img, [1.0; 3])?;
        // 10 left-column pixels of the 56 border pixels (2·20 + 2·8).
        assert!((qa.border - 10.0 / 56.0).abs() < 1e-12, "{}", qa.border);
        assert!(thumbnail_qa(w, h, &img[1..], [1.0; 3]).is_err());
        Ok(())
    }
}
