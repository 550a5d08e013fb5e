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
#[path = "raw_tests.rs"]
mod tests;
