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
use super::draws::{normal, poisson, tukey};
use super::kernel::Noisy;
use super::linear::LinearRgb;
use super::matrix::apply;
use super::mosaic::{cfa_channel, demosaic_bilinear};
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
                dn = libm::round(dn).clamp(0.0, m.white);
            }
            (dn - m.black) / range
        }
    }
}

/// The noisy RGGB mosaic of a clean raw (`clean`: 3 values per pixel), signal units.
pub fn noisy_mosaic(m: &RawModel, clean: &[f64], w: usize, key: u64, stream: u64) -> Vec<f64> {
    let frame = rng::derive_seed(key, &[rng::fnv1a64(b"raw_noise"), stream]);
    let h = clean.len() / 3 / w.max(1);
    let mut out = vec![0.0; w * h];
    out.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
        let mut s = Stream::new(frame, 2 * y as u64);
        let row_dn = match m.noise {
            RawNoise::Physics { row_sigma, .. } => {
                row_sigma * normal(&mut Stream::new(frame, 2 * y as u64 + 1))
            }
            RawNoise::Gaussian { .. } => 0.0,
        };
        for (x, v) in row.iter_mut().enumerate() {
            let clean_x = clean[(y * w + x) * 3 + cfa_channel(x, y)];
            *v = photosite(m, clean_x, row_dn, &mut s);
        }
    });
    out
}

/// The demosaicked noise of a frame: noisy − clean at each photosite, demosaicked.
fn demosaicked_noise(m: &RawModel, raw: &[f64], w: usize, key: u64, stream: u64) -> Vec<f64> {
    let h = raw.len() / 3 / w.max(1);
    let noisy = noisy_mosaic(m, raw, w, key, stream);
    let residual: Vec<f64> = noisy
        .iter()
        .enumerate()
        .map(|(i, v)| v - raw[i * 3 + cfa_channel(i % w, i / w)])
        .collect();
    demosaic_bilinear(&residual, w, h)
}

/// One frame of a raw model: the noisy linear RGB (unclipped) and its 8-bit codes.
pub fn raw_frame(img: &LinearRgb, m: &RawModel, key: u64, stream: u64) -> Result<Noisy> {
    let w = img.width as usize;
    let mut raw = clean_raw(img, m);
    if m.noisy {
        let noise = demosaicked_noise(m, &raw, w, key, stream);
        raw.par_iter_mut()
            .zip(noise.par_iter())
            .for_each(|(r, n)| *r += n);
    }
    let steps = code_steps(m);
    let (linear, codes): (Vec<[f32; 3]>, Vec<[u8; 3]>) = raw
        .par_chunks_exact(3)
        .map(|p| {
            let cam = [0, 1, 2].map(|c| p[c] * m.wb[c]);
            let rgb = apply(&m.rgb_from_cam, cam).map(|v| v / m.white_level);
            let code = rgb.map(|v| steps.partition_point(|t| v >= *t) as u8);
            (rgb.map(|v| v as f32), code)
        })
        .unzip();
    Ok(Noisy {
        linear: linear.into_iter().flatten().collect(),
        linear_channels: 3,
        processed: Image::new(
            img.width,
            img.height,
            3,
            Samples::U8(codes.into_iter().flatten().collect()),
        )?,
    })
}

#[cfg(test)]
#[path = "raw_tests.rs"]
mod tests;
