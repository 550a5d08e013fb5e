//! The raw pipeline of the raw noise models (issue 61), per frame:
//! linear RGB → camera RGB (inverse colour matrix) → inverse white balance → RGGB
//! mosaic → DN (`black + x · (white − black)`) → noise per photosite → quantization and
//! clipping → minus black, normalised → demosaic → white balance → colour matrix →
//! linear RGB (`linear/*.exr`, unclipped) → transfer (and tone curve) → 8-bit codes.
//!
//! The demosaic interpolates what the noise changed at each photosite (noisy − clean
//! raw), added to the clean camera image at full resolution: the noise is spatially
//! and chromatically correlated as a demosaicked raw's, and the clean image gains no
//! demosaic artefacts, so a run without noise returns its input.
//!
//! Randomness: frame key `derive_seed(key, [fnv1a64("raw_noise"), stream])`; sensor
//! row r draws its photosites from Philox stream 2r and its row noise from stream
//! 2r + 1, so every value is a function of (key, stream, row) at any thread count.
use super::draws::{normal, poisson, round_exact, tukey};
use super::kernel::Noisy;
use super::linear::LinearRgb;
use super::matrix::apply;
use super::mosaic::{cfa_channel, demosaic_at};
use super::raw_model::{RawModel, RawNoise};
use crate::error::Result;
use crate::image::io::{Image, Samples};
use crate::rng::{self, Stream};
use rayon::prelude::*;

/// Brooks' smoothstep tone curve and its inverse on [0, 1] (the curve itself runs as
/// [`code_steps`]; the tests check those against it).
#[cfg(test)]
fn smoothstep(x: f64) -> f64 {
    let x = x.clamp(0.0, 1.0);
    x * x * (3.0 - 2.0 * x)
}

fn smoothstep_inverse(y: f64) -> f64 {
    let y = y.clamp(0.0, 1.0);
    0.5 - libm::sin(libm::asin(1.0 - 2.0 * y) / 3.0)
}

/// A clean linear value (what the loaders read) → the camera's scene-linear value.
pub fn to_scene(m: &RawModel, l: f64) -> f64 {
    let l = l.clamp(0.0, 1.0);
    if m.tone_curve {
        libm::pow(smoothstep_inverse(m.gamma.encode(l)), 2.2)
    } else {
        l
    }
}

/// A scene-linear value → code value in [0, 1]: the curve [`code_steps`] rounds.
#[cfg(test)]
pub fn to_code(m: &RawModel, s: f64) -> f64 {
    if m.tone_curve {
        smoothstep(libm::pow(s.clamp(0.0, 1.0), 1.0 / 2.2))
    } else {
        m.gamma.encode(s.clamp(0.0, 1.0))
    }
}

/// The scene-linear value of a code value in [0, 1] (the inverse of [`to_code`]).
fn from_code(m: &RawModel, c: f64) -> f64 {
    if m.tone_curve {
        libm::pow(smoothstep_inverse(c), 2.2)
    } else {
        m.gamma.decode(c)
    }
}

/// The 255 scene-linear values where the 8-bit code steps up: the code of `s` is the
/// number of them at or below it, which is `round(255 · to_code(s))` without a
/// transcendental function per value.
fn code_steps(m: &RawModel) -> Vec<f64> {
    (0..255)
        .map(|k| from_code(m, (f64::from(k) + 0.5) / 255.0))
        .collect()
}

/// [`code_steps`] with a table of where to start counting: the code of `s` is found
/// from the count at `s`'s bin of [0, 1] (a power of two of bins, so `s · BINS` is
/// exact and the bin's lower edge is at or below `s`) plus the steps in between: the
/// same count as a binary search over the steps, without its branches.
struct Codes {
    steps: Vec<f64>,
    start: Vec<u8>,
}

impl Codes {
    const BINS: usize = 4096;

    fn new(m: &RawModel) -> Codes {
        let steps = code_steps(m);
        let start = (0..=Self::BINS)
            .map(|i| {
                let edge = i as f64 / Self::BINS as f64;
                steps.partition_point(|t| edge >= *t) as u8
            })
            .collect();
        Codes { steps, start }
    }

    /// The number of steps at or below `v` (0 for NaN), as `partition_point` counts.
    fn code(&self, v: f64) -> u8 {
        let mut c = if v > 0.0 {
            // `as` saturates: values past 1 start at the last bin.
            usize::from(self.start[((v * Self::BINS as f64) as usize).min(Self::BINS)])
        } else {
            0
        };
        while c < self.steps.len() && v >= self.steps[c] {
            c += 1;
        }
        c as u8
    }
}

/// [`to_scene`] through a small cache keyed by the value's bits: an image decoded from
/// 8-bit codes holds at most 256 values per channel, so the curves run once per value.
struct SceneCache<'a> {
    m: &'a RawModel,
    slots: Vec<(u32, f64)>,
}

impl<'a> SceneCache<'a> {
    fn new(m: &'a RawModel) -> Self {
        SceneCache {
            m,
            slots: vec![(f32::NAN.to_bits(), 0.0); 4096],
        }
    }

    fn get(&mut self, l: f32) -> f64 {
        if !self.m.tone_curve {
            return to_scene(self.m, f64::from(l));
        }
        let bits = l.to_bits();
        let slot = &mut self.slots[(bits.wrapping_mul(0x9E37_79B1) >> 20) as usize];
        if slot.0 != bits {
            *slot = (bits, to_scene(self.m, f64::from(l)));
        }
        slot.1
    }
}

/// The clean camera raw per pixel and channel (signal units, white = 1).
pub fn clean_raw(img: &LinearRgb, m: &RawModel) -> Vec<f64> {
    let mut out = vec![0.0; img.rgb.len()];
    let chunk = (img.width as usize * 3 * 64).max(3);
    out.par_chunks_mut(chunk)
        .zip(img.rgb.par_chunks(chunk))
        .for_each(|(o, p)| {
            let mut cache = SceneCache::new(m);
            for (o, p) in o.chunks_exact_mut(3).zip(p.chunks_exact(3)) {
                let s = [0, 1, 2].map(|c| cache.get(p[c]) * m.white_level);
                let cam = apply(&m.cam_from_rgb, s);
                for c in 0..3 {
                    o[c] = cam[c] / m.wb[c];
                }
            }
        });
    out
}

/// The noisy value at one photosite of signal `x` (white = 1), in signal units.
fn photosite(m: &RawModel, x: f64, row_dn: f64, s: &mut Stream) -> f64 {
    match m.noise {
        RawNoise::Gaussian { shot, read } => {
            x + libm::sqrt((shot * x.max(0.0) + read).max(0.0)) * normal(s)
        }
        RawNoise::Physics {
            k,
            read_scale,
            lambda,
            ..
        } => {
            let range = m.white - m.black;
            let signal = x * range;
            let shot = poisson(s, signal.max(0.0) / k) * k;
            let read = read_scale * tukey(s, lambda);
            let mut dn = m.black + shot + read + row_dn;
            if m.quantize {
                dn = round_exact(dn).clamp(0.0, m.white);
            }
            (dn - m.black) / range
        }
    }
}

/// Sensor row `y` of the noisy RGGB mosaic of a clean raw into `row` (`w` values,
/// signal units); `residual`: minus the clean value at each photosite.
fn mosaic_row(m: &RawModel, clean: &[f64], frame: u64, y: usize, row: &mut [f64], residual: bool) {
    let w = row.len();
    let mut s = Stream::new(frame, 2 * y as u64);
    let row_dn = match m.noise {
        RawNoise::Physics { row_sigma, .. } => {
            row_sigma * normal(&mut Stream::new(frame, 2 * y as u64 + 1))
        }
        RawNoise::Gaussian { .. } => 0.0,
    };
    let clean_row = &clean[y * w * 3..(y + 1) * w * 3];
    for (x, v) in row.iter_mut().enumerate() {
        let clean_x = clean_row[x * 3 + cfa_channel(x, y)];
        let noisy = photosite(m, clean_x, row_dn, &mut s);
        *v = if residual { noisy - clean_x } else { noisy };
    }
}

fn frame_key(key: u64, stream: u64) -> u64 {
    rng::derive_seed(key, &[rng::fnv1a64(b"raw_noise"), stream])
}

/// The noisy RGGB mosaic of a clean raw (`clean`: 3 values per pixel), signal units
/// (the tests' view of the sensor).
#[cfg(test)]
pub fn noisy_mosaic(m: &RawModel, clean: &[f64], w: usize, key: u64, stream: u64) -> Vec<f64> {
    let frame = frame_key(key, stream);
    let h = clean.len() / 3 / w.max(1);
    let mut out = vec![0.0; w * h];
    out.par_chunks_mut(w.max(1))
        .enumerate()
        .for_each(|(y, row)| mosaic_row(m, clean, frame, y, row, false));
    out
}

/// What the noise changed at each photosite (noisy − clean), signal units.
fn mosaic_residual(m: &RawModel, clean: &[f64], w: usize, key: u64, stream: u64) -> Vec<f64> {
    let frame = frame_key(key, stream);
    let h = clean.len() / 3 / w.max(1);
    let mut out = vec![0.0; w * h];
    out.par_chunks_mut(w.max(1))
        .enumerate()
        .for_each(|(y, row)| mosaic_row(m, clean, frame, y, row, true));
    out
}

/// One frame of a raw model: the noisy linear RGB (unclipped) and its 8-bit codes.
/// One pass per sensor row draws the noise (the residual mosaic), and one per image
/// row demosaics it, adds it to the clean raw and writes linear RGB and codes.
pub fn raw_frame(img: &LinearRgb, m: &RawModel, key: u64, stream: u64) -> Result<Noisy> {
    let (w, h) = (img.width as usize, img.height as usize);
    let raw = clean_raw(img, m);
    let noise = m.noisy.then(|| mosaic_residual(m, &raw, w, key, stream));
    let codes_of = Codes::new(m);
    let mut linear = vec![0.0f32; raw.len()];
    let mut codes = vec![0u8; raw.len()];
    let row_len = (w * 3).max(1);
    linear
        .par_chunks_mut(row_len)
        .zip(codes.par_chunks_mut(row_len))
        .enumerate()
        .for_each(|(y, (lin_row, code_row))| {
            let raw_row = &raw[y * w * 3..(y + 1) * w * 3];
            for x in 0..w {
                let p = &raw_row[x * 3..x * 3 + 3];
                let mut v = [p[0], p[1], p[2]];
                if let Some(n) = &noise {
                    let d = demosaic_at(n, w, h, x, y);
                    for c in 0..3 {
                        v[c] += d[c];
                    }
                }
                let cam = [0, 1, 2].map(|c| v[c] * m.wb[c]);
                let rgb = apply(&m.rgb_from_cam, cam).map(|v| v / m.white_level);
                for c in 0..3 {
                    lin_row[x * 3 + c] = rgb[c] as f32;
                    code_row[x * 3 + c] = codes_of.code(rgb[c]);
                }
            }
        });
    Ok(Noisy {
        linear,
        linear_channels: 3,
        processed: Image::new(img.width, img.height, 3, Samples::U8(codes))?,
    })
}

#[cfg(test)]
mod tests {
    // Property tests of the raw pipeline (issue 61): round trip, variance against signal
    // per CFA channel, row-noise power, the read noise's Tukey-lambda shape, extremes,
    // thread-count independence.
    use super::*;
    use crate::noise::camera::{eld_camera, EldCamera};
    use crate::noise::draws::{tukey_quantile, tukey_variance};
    use crate::noise::model::{Gamma, WhiteBalance};
    use crate::noise::raw_model::{Display, RawModel};

    fn display(gamma: Gamma) -> Display {
        Display {
            gamma,
            white_balance: Some(WhiteBalance {
                red: 2.1,
                blue: 1.7,
            }),
            white_level: 1.0,
        }
    }

    fn camera(name: &str) -> &'static EldCamera {
        eld_camera(name).expect("an ELD camera")
    }

    fn eld(name: &str, gain: f64) -> RawModel {
        RawModel::eld(camera(name), gain, display(Gamma::Srgb)).expect("model")
    }

    /// Every model at one gain: the five ELD cameras and unprocess.
    fn all_models(gain: f64, gamma: Gamma) -> Vec<RawModel> {
        let mut out: Vec<RawModel> = crate::noise::camera::ELD_CAMERAS
            .iter()
            .map(|c| RawModel::eld(c, gain, display(gamma)).expect("model"))
            .collect();
        out.push(RawModel::unprocess(7, gain, display(gamma)).expect("model"));
        out
    }

    fn flat(w: u32, h: u32, v: f32) -> LinearRgb {
        LinearRgb::new(w, h, vec![v; (w * h * 3) as usize]).expect("image")
    }

    fn moments(v: &[f64]) -> (f64, f64) {
        let n = v.len() as f64;
        let m = v.iter().sum::<f64>() / n;
        (
            m,
            v.iter().map(|x| (x - m) * (x - m)).sum::<f64>() / (n - 1.0),
        )
    }

    /// The model's variance (DN² for ELD, signal² for Brooks) at clean raw `x`.
    fn model_variance(m: &RawModel, x: f64) -> f64 {
        match m.noise {
            RawNoise::Physics {
                k,
                read_scale,
                lambda,
                row_sigma,
            } => {
                let read = read_scale * read_scale * tukey_variance(lambda);
                k * x * (m.white - m.black) + read + row_sigma * row_sigma + 1.0 / 12.0
            }
            RawNoise::Gaussian { shot, read } => shot * x + read,
        }
    }

    #[test]
    fn without_noise_the_round_trip_returns_every_code() -> Result<()> {
        // Every 8-bit code in every channel, decoded as the PNG path decodes it.
        let (w, h) = (64u32, 12u32);
        let codes: Vec<u8> = (0..w * h * 3)
            .map(|i| ((i * 7 + i / 3) % 256) as u8)
            .collect();
        for gamma in [Gamma::Power22, Gamma::Srgb] {
            let lin: Vec<f32> = codes
                .iter()
                .map(|&c| gamma.decode(f64::from(c) / 255.0) as f32)
                .collect();
            let img = LinearRgb::new(w, h, lin)?;
            for m in all_models(4.0, gamma) {
                let out = raw_frame(&img, &m.clean(), 1, 2)?;
                let Samples::U8(got) = &out.processed.samples else {
                    panic!("8-bit output");
                };
                let worst = got
                    .iter()
                    .zip(&codes)
                    .map(|(a, b)| (i32::from(*a) - i32::from(*b)).abs())
                    .max();
                assert_eq!(worst, Some(0), "{} {gamma:?}", m.name);
            }
        }
        Ok(())
    }

    /// Per CFA channel (R, G, B) of the noisy mosaic of a flat image at linear `level`:
    /// (clean raw x, sample variance) in the model's units (DN for ELD).
    fn cfa_variances(m: &RawModel, level: f32, size: u32) -> [(f64, f64); 3] {
        let img = flat(size, size, level);
        let raw = clean_raw(&img, m);
        let w = size as usize;
        let noisy = noisy_mosaic(m, &raw, w, 3, 4);
        let unit = if m.quantize { m.white - m.black } else { 1.0 };
        [0, 1, 2].map(|c| {
            let v: Vec<f64> = noisy
                .iter()
                .enumerate()
                .filter(|(i, _)| cfa_channel(i % w, i / w) == c)
                .map(|(_, v)| v * unit)
                .collect();
            (raw[c], moments(&v).1)
        })
    }

    #[test]
    fn variance_against_signal_per_cfa_channel_is_the_models() {
        let mut worst: f64 = 0.0;
        let models = [
            eld("SonyA7S2", 8.0),
            eld("CanonEOS70D", 20.0),
            eld("NikonD850", 1.0),
        ];
        let unprocess = RawModel::unprocess(3, 4.0, display(Gamma::Srgb)).expect("model");
        for m in models.iter().chain([&unprocess]) {
            for level in [0.0f32, 0.02, 0.2, 0.6] {
                for (c, (x, var)) in cfa_variances(m, level, 512).into_iter().enumerate() {
                    let want = model_variance(m, x);
                    let ratio = var / want;
                    worst = worst.max((ratio - 1.0).abs());
                    assert!(
                        (ratio - 1.0).abs() < 0.05,
                        "{} level {level} channel {c}: {ratio}",
                        m.name
                    );
                }
            }
        }
        eprintln!("variance / model: worst |ratio - 1| = {worst:.4}");
    }

    #[test]
    fn row_noise_has_the_calibrated_power() {
        // Canon 70D at gain 20: row σ ≈ 1.8 DN beside ≈ 12 DN of Tukey read noise.
        let m = eld("CanonEOS70D", 20.0);
        let RawNoise::Physics { row_sigma, .. } = m.noise else {
            panic!("physics");
        };
        let (w, h) = (1024usize, 1024usize);
        let raw = clean_raw(&flat(w as u32, h as u32, 0.0), &m);
        let noisy = noisy_mosaic(&m, &raw, w, 5, 6);
        let range = m.white - m.black;
        let rows: Vec<(f64, f64)> = noisy
            .chunks_exact(w)
            .map(|r| moments(&r.iter().map(|v| v * range).collect::<Vec<_>>()))
            .collect();
        let (_, var_of_means) = moments(&rows.iter().map(|r| r.0).collect::<Vec<_>>());
        let within = rows.iter().map(|r| r.1).sum::<f64>() / h as f64;
        let row_power = var_of_means - within / w as f64;
        let ratio = row_power / (row_sigma * row_sigma);
        eprintln!(
            "row power {row_power:.4} DN^2, model {:.4}: ratio {ratio:.4}",
            row_sigma * row_sigma
        );
        assert!((ratio - 1.0).abs() < 0.15, "{ratio}");
    }

    #[test]
    fn read_noise_has_the_published_tukey_lambda_shape() {
        // Canon 70D at gain 20: λ < 0 (heavier tails than a normal), scale ≈ 12 DN.
        let m = eld("CanonEOS70D", 20.0);
        let RawNoise::Physics {
            read_scale, lambda, ..
        } = m.noise
        else {
            panic!("physics");
        };
        assert!(lambda < -0.1, "{lambda}");
        let (w, h) = (2048usize, 512usize);
        let raw = clean_raw(&flat(w as u32, h as u32, 0.0), &m);
        let noisy = noisy_mosaic(&m, &raw, w, 8, 9);
        let range = m.white - m.black;
        // Minus each row's mean (its row noise), in DN.
        let mut read: Vec<f64> = noisy
            .chunks_exact(w)
            .flat_map(|r| {
                let mean = r.iter().sum::<f64>() / w as f64;
                r.iter().map(move |v| (v - mean) * range)
            })
            .collect();
        read.sort_by(f64::total_cmp);
        let n = read.len() as f64;
        for p in [0.001, 0.01, 0.1, 0.25, 0.75, 0.9, 0.99, 0.999] {
            let got = read[(p * n) as usize];
            let want = read_scale * tukey_quantile(p, lambda);
            assert!(
                (got - want).abs() < 0.05 * want.abs() + 0.6,
                "p {p}: {got} vs {want}"
            );
        }
        // The tails are the Tukey's, heavier than a normal of the same variance.
        let sd = read_scale * tukey_variance(lambda).sqrt();
        assert!(read[(0.999 * n) as usize] > 3.09 * sd * 1.05);
    }

    #[test]
    fn black_saturated_and_largest_gain_stay_finite_and_bounded() -> Result<()> {
        for gain in [1.0, 20.0, 64.0, 1.0e4] {
            for m in all_models(gain, Gamma::Srgb) {
                for level in [0.0f32, 1.0] {
                    let out = raw_frame(&flat(16, 8, level), &m, 1, 1)?;
                    assert!(
                        out.linear.iter().all(|v| v.is_finite()),
                        "{} {gain}",
                        m.name
                    );
                    if m.quantize {
                        // Raw clipped to [0, white]: linear stays within the matrices' reach.
                        let bound = 4.0 * m.wb.iter().fold(1.0f64, |a, b| a.max(*b));
                        let big = out.linear.iter().map(|v| v.abs()).fold(0.0f32, f32::max);
                        assert!(f64::from(big) <= bound, "{} {gain}: {big}", m.name);
                    }
                }
            }
        }
        // A saturated white stays white at the base gain (the raw clips at the white level).
        let out = raw_frame(&flat(16, 8, 1.0), &eld("SonyA7S2", 1.0), 1, 1)?;
        let Samples::U8(codes) = &out.processed.samples else {
            panic!("8-bit");
        };
        assert!(codes.iter().all(|&c| c >= 250), "{:?}", &codes[..6]);
        Ok(())
    }

    #[test]
    fn identical_for_any_thread_count_and_keyed() -> Result<()> {
        let img = LinearRgb::new(
            33,
            17,
            (0..33 * 17 * 3).map(|i| (i % 97) as f32 / 97.0).collect(),
        )?;
        for m in all_models(8.0, Gamma::Srgb) {
            let run = |threads: usize| {
                rayon::ThreadPoolBuilder::new()
                    .num_threads(threads)
                    .build()
                    .expect("pool")
                    .install(|| raw_frame(&img, &m, 42, 7))
            };
            let (a, b) = (run(1)?, run(4)?);
            assert_eq!(a.linear, b.linear, "{}", m.name);
            assert_eq!(a.processed, b.processed);
            assert_ne!(a.linear, raw_frame(&img, &m, 42, 8)?.linear);
            assert_ne!(a.linear, raw_frame(&img, &m, 43, 7)?.linear);
        }
        Ok(())
    }

    #[test]
    fn demosaicked_noise_is_correlated_in_space_and_across_channels() -> Result<()> {
        // The paper's noise is independent per pixel and channel (correlation 0); a
        // demosaicked raw's is not.
        let m = eld("SonyA7S2", 20.0);
        let (w, h) = (256usize, 256usize);
        let img = flat(w as u32, h as u32, 0.2);
        let clean = raw_frame(&img, &m.clean(), 1, 1)?.linear;
        let noisy = raw_frame(&img, &m, 1, 1)?.linear;
        let n: Vec<f64> = noisy
            .iter()
            .zip(&clean)
            .map(|(a, b)| f64::from(a - b))
            .collect();
        let corr = |a: &[f64], b: &[f64]| {
            let (ma, va) = moments(a);
            let (mb, vb) = moments(b);
            let cov = a
                .iter()
                .zip(b)
                .map(|(x, y)| (x - ma) * (y - mb))
                .sum::<f64>()
                / a.len() as f64;
            cov / (va * vb).sqrt()
        };
        let chan = |c: usize| -> Vec<f64> { n.iter().skip(c).step_by(3).copied().collect() };
        let (r, g) = (chan(0), chan(1));
        let pairs: Vec<usize> = (0..h)
            .flat_map(|y| (0..w - 1).map(move |x| y * w + x))
            .collect();
        let right: Vec<f64> = pairs.iter().map(|&i| g[i + 1]).collect();
        let left: Vec<f64> = pairs.iter().map(|&i| g[i]).collect();
        let (space, across) = (corr(&left, &right), corr(&r, &g));
        eprintln!("green neighbour correlation {space:.3}, red-green {across:.3}");
        assert!(space > 0.2, "{space}");
        assert!(across.abs() > 0.05, "{across}");
        // The paper's model on the same image: both near zero.
        let paper = crate::noise::model::NoiseModel {
            sigma_read: 0.02,
            sigma_shot: 0.05,
            gamma: Gamma::Srgb,
            white_balance: None,
            white_level: 1.0,
        };
        let p = crate::noise::linear::add_noise_linear(&img, &paper, 1, 1)?.linear;
        let n: Vec<f64> = p.iter().map(|v| f64::from(*v) - 0.2).collect();
        let chan = |c: usize| -> Vec<f64> { n.iter().skip(c).step_by(3).copied().collect() };
        let (r, g) = (chan(0), chan(1));
        let right: Vec<f64> = pairs.iter().map(|&i| g[i + 1]).collect();
        let left: Vec<f64> = pairs.iter().map(|&i| g[i]).collect();
        let (space, across) = (corr(&left, &right), corr(&r, &g));
        eprintln!("paper: green neighbour correlation {space:.4}, red-green {across:.4}");
        assert!(
            space.abs() < 0.02 && across.abs() < 0.02,
            "{space} {across}"
        );
        Ok(())
    }

    #[test]
    fn code_steps_round_the_forward_curve() {
        for gamma in [Gamma::Power22, Gamma::Srgb] {
            for m in all_models(2.0, gamma) {
                let steps = code_steps(&m);
                for i in 0..20_000 {
                    let s = -0.1 + 1.2 * f64::from(i) / 20_000.0;
                    let by_steps = steps.partition_point(|t| s >= *t);
                    let by_curve = libm::round(to_code(&m, s) * 255.0) as usize;
                    assert_eq!(by_steps, by_curve, "{} {gamma:?} at {s}", m.name);
                }
            }
        }
    }
}
