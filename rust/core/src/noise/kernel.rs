//! The noise kernel of one image: noisy linear values and processed codes through
//! per-code tables, the normals drawn `LANES` Philox blocks at a time. With AVX2 the
//! 8-bit RGB case runs in `avx2`, bit for bit the scalar path.
use super::model::{Gamma, NoiseModel};
use super::ziggurat::{zig_normal, ziggurat, Ziggurat};
use crate::error::Result;
use crate::image::io::{Image, Samples};
use crate::rng::{self, PHILOX_M0, PHILOX_M1, PHILOX_W0, PHILOX_W1};
use rayon::prelude::*;

#[cfg(target_arch = "x86_64")]
#[path = "avx2.rs"]
mod avx2;

const LANES: usize = 16;

/// `rng::philox4x32` of blocks `first .. first + LANES` of `stream`, lane-major so the
/// compiler can interleave the rounds of many blocks and vectorize them.
#[inline(always)]
fn philox_lanes(key: u64, stream: u64, first: u64, out: &mut [u32]) {
    let mut c0 = [0u32; LANES];
    let mut c1 = [0u32; LANES];
    let mut c2 = [stream as u32; LANES];
    let mut c3 = [(stream >> 32) as u32; LANES];
    for j in 0..LANES {
        let b = first + j as u64;
        c0[j] = b as u32;
        c1[j] = (b >> 32) as u32;
    }
    let (mut k0, mut k1) = (key as u32, (key >> 32) as u32);
    for _ in 0..10 {
        for j in 0..LANES {
            let p0 = PHILOX_M0 as u64 * c0[j] as u64;
            let p1 = PHILOX_M1 as u64 * c2[j] as u64;
            let n0 = ((p1 >> 32) as u32) ^ c1[j] ^ k0;
            let n2 = ((p0 >> 32) as u32) ^ c3[j] ^ k1;
            c0[j] = n0;
            c1[j] = p1 as u32;
            c2[j] = n2;
            c3[j] = p0 as u32;
        }
        k0 = k0.wrapping_add(PHILOX_W0);
        k1 = k1.wrapping_add(PHILOX_W1);
    }
    for (j, o) in out.chunks_exact_mut(4).take(LANES).enumerate() {
        o.copy_from_slice(&[c0[j], c1[j], c2[j], c3[j]]);
    }
}

/// Maps a noisy linear value to the output code with exact thresholds: the code is
/// the number of thresholds `decode((k + 0.5) / max) · scale` at or below the value,
/// i.e. round-to-nearest of the forward curve, found through a bin table.
struct Encoder {
    thresholds: Vec<f32>,
    /// `start[b - first_bin]` = number of thresholds whose bin is below b, for the bins
    /// from the lowest threshold's to one past the highest one's (a few thousand
    /// entries: the table stays in L1 cache).
    start: Vec<u16>,
    first_bin: usize,
    last_bin: usize,
}

/// The forward processing's rounding points: code k + 1 starts at the linear value
/// `decode((k + 0.5) / max) · scale`, for k in 0..max.
pub(super) fn code_thresholds(gamma: Gamma, max_code: u32, scale: f64) -> Vec<f32> {
    (0..max_code)
        .map(|k| (gamma.decode((k as f64 + 0.5) / max_code as f64) * scale) as f32)
        .collect()
}

/// Bin of a value: the top 16 bits of its IEEE pattern (sign, exponent, 7 mantissa
/// bits), monotone in the value for v >= 0, so bins are log-spaced like the gamma
/// curve's codes; negative values (sign bit set) go to bin 0, below every threshold.
#[inline(always)]
fn encoder_bin(v: f32) -> usize {
    let b = v.to_bits();
    ((b >> 16) & !(((b as i32) >> 31) as u32)) as usize
}

impl Encoder {
    fn new(gamma: Gamma, max_code: u32, scale: f64) -> Self {
        let mut thresholds = code_thresholds(gamma, max_code, scale);
        // Binning is monotone, so the thresholds of bins below b lie below every value
        // of bin b and those of later bins above it. A value below the lowest
        // threshold's bin has code 0 and one above the highest's has code max: both
        // are clamped onto the window's ends, where the comparisons give those codes.
        let first_bin = thresholds.first().map_or(0, |&t| encoder_bin(t));
        let last_bin = thresholds.last().map_or(0, |&t| encoder_bin(t)) + 1;
        let mut start = vec![0u16; last_bin - first_bin + 2];
        for &t in &thresholds {
            start[encoder_bin(t) - first_bin + 1] += 1;
        }
        let mut acc = 0;
        for s in &mut start {
            acc += *s;
            *s = acc;
        }
        // Two sentinels let `code` compare twice without bounds logic.
        thresholds.extend([f32::INFINITY; 2]);
        Encoder {
            thresholds,
            start,
            first_bin,
            last_bin,
        }
    }

    /// The encoder's tables as plain locals for a hot loop.
    fn view(&self) -> EncoderView<'_> {
        EncoderView {
            thresholds: &self.thresholds,
            start: &self.start,
            first_bin: self.first_bin,
            span: self.last_bin - self.first_bin,
        }
    }

    #[cfg(test)]
    fn code(&self, v: f32) -> u32 {
        self.view().code(v)
    }
}

/// A borrowed copy of an [`Encoder`]'s fields: kept in registers across a loop that
/// also stores bytes (which the compiler must otherwise assume may alias the fields).
#[derive(Clone, Copy)]
struct EncoderView<'a> {
    thresholds: &'a [f32],
    start: &'a [u16],
    first_bin: usize,
    span: usize,
}

impl EncoderView<'_> {
    #[inline(always)]
    fn code(self, v: f32) -> u32 {
        let b = encoder_bin(v).saturating_sub(self.first_bin).min(self.span);
        let (lo, hi) = (self.start[b] as usize, self.start[b + 1] as usize);
        if hi - lo > 2 {
            return (lo + self.thresholds[lo..hi].partition_point(|t| v >= *t)) as u32;
        }
        // Thresholds past this bin lie above v, so two comparisons settle it
        // (branch-free: noise makes the outcome unpredictable).
        (lo + usize::from(v >= self.thresholds[lo]) + usize::from(v >= self.thresholds[lo + 1]))
            as u32
    }
}

/// Per-code tables of one (model, sample depth, colour layout): decoding and the
/// noise standard deviation depend only on the clean code, so they are looked up.
pub(super) struct Plan {
    codes: usize,
    /// [clean linear value, noise std] per (channel, code) (arrays, not tuples: the AVX2
    /// kernel reads them as 8-byte pairs and relies on the order).
    table: Vec<[f32; 2]>,
    encoders: Vec<Encoder>,
    /// The encoders of an 8-bit RGB plan in the AVX2 kernel's form.
    #[cfg(target_arch = "x86_64")]
    rgb8: Option<avx2::Rgb8Encoders>,
}

impl Plan {
    pub(super) fn new(model: &NoiseModel, max_code: u32, color_channels: usize) -> Self {
        let codes = max_code as usize + 1;
        let mut table = Vec::with_capacity(codes * color_channels);
        let mut encoders = Vec::with_capacity(color_channels);
        for c in 0..color_channels {
            let scale = model.channel_scale(c, color_channels);
            for code in 0..codes {
                let y = scale * model.gamma.decode(code as f64 / max_code as f64);
                table.push([y as f32, model.noise_std(y) as f32]);
            }
            encoders.push(Encoder::new(model.gamma, max_code, scale));
        }
        Plan {
            codes,
            table,
            #[cfg(target_arch = "x86_64")]
            rgb8: avx2::Rgb8Encoders::new(&encoders),
            encoders,
        }
    }
}

trait Sample: Copy + Send + Sync {
    fn code(self) -> usize;
    fn from_code(c: u32) -> Self;
    /// The samples as bytes, if they are 8-bit (for the AVX2 kernel).
    fn bytes(s: &[Self]) -> Option<&[u8]>;
    fn bytes_mut(s: &mut [Self]) -> Option<&mut [u8]>;
}

impl Sample for u8 {
    fn bytes(s: &[Self]) -> Option<&[u8]> {
        Some(s)
    }
    fn bytes_mut(s: &mut [Self]) -> Option<&mut [u8]> {
        Some(s)
    }
    #[inline(always)]
    fn code(self) -> usize {
        self as usize
    }
    #[inline(always)]
    fn from_code(c: u32) -> Self {
        c as u8
    }
}

impl Sample for u16 {
    fn bytes(_: &[Self]) -> Option<&[u8]> {
        None
    }
    fn bytes_mut(_: &mut [Self]) -> Option<&mut [u8]> {
        None
    }
    #[inline(always)]
    fn code(self) -> usize {
        self as usize
    }
    #[inline(always)]
    fn from_code(c: u32) -> Self {
        c as u16
    }
}

/// One noisy frame: the linear image (RGB, or RGBA when the source has alpha; a gray
/// source fills R, G and B with its one noisy channel) and the processed image in the
/// source's own layout and depth, alpha copied unchanged.
#[derive(Clone, Debug, PartialEq)]
pub struct Noisy {
    pub linear: Vec<f32>,
    pub linear_channels: usize,
    pub processed: Image,
}

/// Pixels per batch of a row: the batch's Philox words live on the stack.
const BATCH_PIXELS: usize = 256;
/// Words of one batch: up to 3 leading words of the first block belong to the value
/// before the batch, and blocks are made `LANES` at a time.
const BATCH_WORDS: usize = (3 + BATCH_PIXELS * 3).div_ceil(LANES * 4) * LANES * 4;

fn apply<T: Sample>(
    src: &[T],
    img: &Image,
    plan: &Plan,
    key: u64,
    stream: u64,
) -> (Vec<f32>, Vec<T>) {
    // One monomorphic kernel per layout, so the channel loops unroll.
    match (img.color_channels(), img.channels) {
        (1, 1) => apply_layout::<T, 1, 1>(src, img, plan, key, stream),
        (1, _) => apply_layout::<T, 1, 2>(src, img, plan, key, stream),
        (_, 3) => apply_layout::<T, 3, 3>(src, img, plan, key, stream),
        _ => apply_layout::<T, 3, 4>(src, img, plan, key, stream),
    }
}

/// The noise of `CC` colour channels of a `CH`-channel image (alpha, if any, last).
fn apply_layout<T: Sample, const CC: usize, const CH: usize>(
    src: &[T],
    img: &Image,
    plan: &Plan,
    key: u64,
    stream: u64,
) -> (Vec<f32>, Vec<T>) {
    let z = ziggurat();
    let w = img.width as usize;
    let lc = if CH > CC { 4 } else { 3 };
    let fallback_key = rng::derive_seed(key, &[rng::fnv1a64(b"ziggurat_fallback"), stream]);
    let cx = BatchCx::<CC> {
        plan,
        z,
        tables: std::array::from_fn(|c| &plan.table[c * plan.codes..(c + 1) * plan.codes]),
        encoders: std::array::from_fn(|c| plan.encoders[c].view()),
        fallback_key,
        max: img.samples.max_code() as f32,
    };
    let mut linear = vec![0.0f32; src.len() / CH * lc];
    let mut processed = src.to_vec();
    linear
        .par_chunks_mut(w * lc)
        .zip(processed.par_chunks_mut(w * CH))
        .zip(src.par_chunks(w * CH))
        .enumerate()
        .for_each_init(
            || vec![0u32; BATCH_WORDS],
            |words, (row, ((lin, out), src_row))| {
                for p0 in (0..w).step_by(BATCH_PIXELS) {
                    let np = BATCH_PIXELS.min(w - p0);
                    let v0 = ((row * w + p0) * CC) as u64;
                    // The batch's words: whole blocks from the one holding v0.
                    let skip = (v0 & 3) as usize;
                    let blocks = (skip + np * CC).div_ceil(4);
                    philox_fill(
                        key,
                        stream,
                        v0 >> 2,
                        &mut words[..blocks.div_ceil(LANES) * LANES * 4],
                    );
                    let src_b = &src_row[p0 * CH..(p0 + np) * CH];
                    let out_b = &mut out[p0 * CH..(p0 + np) * CH];
                    let lin_b = &mut lin[p0 * lc..(p0 + np) * lc];
                    let words = &words[skip..skip + np * CC];
                    let batch = Batch {
                        words,
                        src: src_b,
                        lin: lin_b,
                        out: out_b,
                        v0,
                    };
                    noise_batch::<T, CC, CH>(&cx, batch);
                }
            },
        );
    (linear, processed)
}

/// What every batch of one image's noise shares.
struct BatchCx<'a, const CC: usize> {
    plan: &'a Plan,
    z: &'a Ziggurat,
    tables: [&'a [[f32; 2]]; CC],
    encoders: [EncoderView<'a>; CC],
    fallback_key: u64,
    max: f32,
}

/// One batch of a row: its random words, source values and both outputs, from value
/// index `v0`.
struct Batch<'a, T> {
    words: &'a [u32],
    src: &'a [T],
    lin: &'a mut [f32],
    out: &'a mut [T],
    v0: u64,
}

/// The noise of one batch: the vector kernel where it applies, the scalar one for the
/// rest. Inlined so the per-layout loops unroll as they did in the caller.
#[inline(always)]
fn noise_batch<T: Sample, const CC: usize, const CH: usize>(cx: &BatchCx<'_, CC>, b: Batch<'_, T>) {
    let Batch {
        words,
        src: src_b,
        lin: lin_b,
        out: out_b,
        v0,
    } = b;
    let (z, fallback_key) = (cx.z, cx.fallback_key);
    let (tables, encoders) = (&cx.tables, &cx.encoders);
    let lc = if CH > CC { 4 } else { 3 };
    let np = src_b.len() / CH;
    let done = simd_batch::<T, CC, CH>(cx.plan, words, src_b, lin_b, out_b, v0, fallback_key);
    if done > 0 {
        // The few values the vector kernel left (RGB: value i is channel i % 3).
        for i in done..np * CC {
            let c = i % CC;
            let n = zig_normal(z, words[i], fallback_key, v0 + i as u64);
            let [clean, std] = tables[c][src_b[i].code()];
            let noisy = clean + std * n;
            lin_b[i] = noisy;
            out_b[i] = T::from_code(encoders[c].code(noisy));
        }
        return;
    }
    // Channel by channel, so each channel's tables stay in registers, and in two passes
    // (noise, then encoding), each with a short dependency chain per value so that many
    // values are in flight at once.
    for c in 0..CC {
        let table = tables[c];
        let mut v = v0 + c as u64;
        for k in 0..np {
            let n = zig_normal(z, words[k * CC + c], fallback_key, v);
            let [clean, std] = table[src_b[k * CH + c].code()];
            lin_b[k * lc + c] = clean + std * n;
            v += CC as u64;
        }
        let enc = encoders[c];
        for k in 0..np {
            out_b[k * CH + c] = T::from_code(enc.code(lin_b[k * lc + c]));
        }
        if CC == 1 {
            for l in lin_b.chunks_exact_mut(lc) {
                l[1] = l[0];
                l[2] = l[0];
            }
        }
    }
    if CH > CC {
        for (s, l) in src_b.chunks_exact(CH).zip(lin_b.chunks_exact_mut(lc)) {
            l[3] = s[CC].code() as f32 / cx.max;
        }
    }
}

/// Tests compare the vector kernel with the scalar one by switching it off.
#[cfg(test)]
static SCALAR_ONLY: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);

fn simd_enabled() -> bool {
    #[cfg(test)]
    if SCALAR_ONLY.load(std::sync::atomic::Ordering::Relaxed) {
        return false;
    }
    true
}

/// The AVX2 kernel on an 8-bit RGB batch where the CPU has AVX2; returns how many
/// values (from the start) it did, 0 if it did not apply.
#[allow(clippy::too_many_arguments)]
fn simd_batch<T: Sample, const CC: usize, const CH: usize>(
    plan: &Plan,
    words: &[u32],
    src: &[T],
    lin: &mut [f32],
    out: &mut [T],
    v0: u64,
    fallback_key: u64,
) -> usize {
    #[cfg(target_arch = "x86_64")]
    if CC == 3 && CH == 3 && simd_enabled() && std::arch::is_x86_feature_detected!("avx2") {
        if let (Some(enc), Some(src), Some(out)) = (&plan.rgb8, T::bytes(src), T::bytes_mut(out)) {
            let batch = avx2::Rgb8Batch {
                words,
                src,
                lin,
                out,
                v0,
            };
            // SAFETY: the CPU supports AVX2 (checked above); `plan.table` holds the
            // 3 · 256 entries of an 8-bit RGB plan (`plan.rgb8` exists only for those).
            return unsafe { avx2::rgb8(batch, ziggurat(), &plan.table, enc, fallback_key) };
        }
    }
    let _ = (plan, words, src, lin, out, v0, fallback_key);
    0
}

/// Philox blocks `first ..` of `stream` into `out` (a whole number of `LANES` blocks),
/// with AVX2 where the CPU has it: the same integer arithmetic, so the same words.
fn philox_fill(key: u64, stream: u64, first: u64, out: &mut [u32]) {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU supports AVX2, checked just above.
        unsafe { avx2::philox_fill(key, stream, first, out) };
        return;
    }
    for (i, chunk) in out.chunks_exact_mut(LANES * 4).enumerate() {
        philox_lanes(key, stream, first + (i * LANES) as u64, chunk);
    }
}

pub(super) fn apply_plan(img: &Image, plan: &Plan, key: u64, stream: u64) -> Result<Noisy> {
    let lc = if img.has_alpha() { 4 } else { 3 };
    let samples = match &img.samples {
        Samples::U8(s) => {
            let (linear, p) = apply(s, img, plan, key, stream);
            return Ok(Noisy {
                linear,
                linear_channels: lc,
                processed: Image::new(img.width, img.height, img.channels, Samples::U8(p))?,
            });
        }
        Samples::U16(s) => apply(s, img, plan, key, stream),
    };
    Ok(Noisy {
        linear: samples.0,
        linear_channels: lc,
        processed: Image::new(img.width, img.height, img.channels, Samples::U16(samples.1))?,
    })
}

/// Add noise to one image (one frame of one view).
pub fn add_noise(img: &Image, model: &NoiseModel, key: u64, stream: u64) -> Result<Noisy> {
    model.validate()?;
    let plan = Plan::new(model, img.samples.max_code(), img.color_channels());
    apply_plan(img, &plan, key, stream)
}

/// The clean linear values `y` the noise is added to (colour channels only, H·W·C).
pub fn clean_linear(img: &Image, model: &NoiseModel) -> Result<Vec<f32>> {
    model.validate()?;
    let (ch, cc) = (img.channels, img.color_channels());
    let max = img.samples.max_code() as f64;
    let code = |i: usize| match &img.samples {
        Samples::U8(s) => s[i] as f64,
        Samples::U16(s) => s[i] as f64,
    };
    let n = img.samples.len() / ch;
    Ok((0..n * cc)
        .map(|v| {
            let (p, c) = (v / cc, v % cc);
            (model.channel_scale(c, cc) * model.gamma.decode(code(p * ch + c) / max)) as f32
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::error::Error;
    use crate::noise::model::{
        sample_white_balance, stream_id, NoiseLevels, WhiteBalance, MIN_WHITE_LEVEL,
    };

    fn model(sr: f64, ss: f64) -> NoiseModel {
        NoiseModel {
            sigma_read: sr,
            sigma_shot: ss,
            gamma: Gamma::Power22,
            white_balance: None,
            white_level: 1.0,
        }
    }

    fn flat(w: u32, h: u32, channels: usize, value: u8) -> Result<Image> {
        let n = (w * h) as usize * channels;
        Image::new(w, h, channels, Samples::U8(vec![value; n]))
    }

    fn moments(v: &[f32]) -> (f64, f64) {
        let n = v.len() as f64;
        let m = v.iter().map(|&x| x as f64).sum::<f64>() / n;
        let var = v.iter().map(|&x| (x as f64 - m).powi(2)).sum::<f64>() / n;
        (m, var)
    }

    #[test]
    fn vector_kernel_matches_scalar_kernel() -> Result<()> {
        // Odd sizes leave batch tails; bright, dark and mid codes; both curves; white
        // balance on and off; a tiny white level pushes values below every threshold.
        let mut s = rng::Stream::new(3, 3);
        let src: Vec<u8> = (0..301 * 7 * 3).map(|_| s.next_u64() as u8).collect();
        let img = Image::new(301, 7, 3, Samples::U8(src))?;
        for (gamma, wb, wl, gain) in [
            (Gamma::Power22, Some(sample_white_balance(2)), 1.0, 20.0),
            (Gamma::Srgb, None, 1.0, 1.0),
            (Gamma::Power22, None, 1e-3, 4.0),
        ] {
            let (sr, ss) = NoiseLevels::DEFAULT.sigmas(gain)?;
            let m = NoiseModel {
                gamma,
                white_balance: wb,
                white_level: wl,
                ..model(sr, ss)
            };
            let fast = add_noise(&img, &m, 5, stream_id(1, 2))?;
            SCALAR_ONLY.store(true, std::sync::atomic::Ordering::Relaxed);
            let slow = add_noise(&img, &m, 5, stream_id(1, 2));
            SCALAR_ONLY.store(false, std::sync::atomic::Ordering::Relaxed);
            assert_eq!(fast, slow?, "{gamma:?} {wb:?} {wl}");
        }
        Ok(())
    }

    #[test]
    fn philox_fill_matches_rng() {
        let mut out = vec![0u32; 3 * LANES * 4];
        for (key, stream, first) in [(0, 0, 0), (u64::MAX, 0x1234_0000_0007, (1u64 << 32) - 21)] {
            philox_fill(key, stream, first, &mut out);
            for (j, w) in out.chunks_exact(4).enumerate() {
                let b = first + j as u64;
                let c = [
                    b as u32,
                    (b >> 32) as u32,
                    stream as u32,
                    (stream >> 32) as u32,
                ];
                assert_eq!(w, rng::philox4x32(key, c));
            }
        }
    }

    #[test]
    fn lane_philox_matches_rng() {
        let mut out = vec![0u32; LANES * 4];
        for (key, stream, first) in [(0, 0, 0), (u64::MAX, 0x1234_0000_0007, (1u64 << 32) - 5)] {
            philox_lanes(key, stream, first, &mut out);
            for j in 0..LANES {
                let b = first + j as u64;
                let c = [
                    b as u32,
                    (b >> 32) as u32,
                    stream as u32,
                    (stream >> 32) as u32,
                ];
                assert_eq!(out[j * 4..j * 4 + 4], rng::philox4x32(key, c));
            }
        }
    }

    #[test]
    fn encoder_rounds_the_forward_curve() {
        for gamma in [Gamma::Power22, Gamma::Srgb] {
            for max in [255u32, 65535] {
                let scale = 0.37;
                let enc = Encoder::new(gamma, max, scale);
                let mut s = rng::Stream::new(17, max as u64);
                for i in 0..200_000 {
                    let v = if i % 4 == 0 {
                        s.uniform_in(-0.05, 0.01) as f32
                    } else {
                        s.uniform_in(-0.1, 1.2 * scale) as f32
                    };
                    let exact = max as f64 * gamma.encode(v as f64 / scale);
                    let got = enc.code(v) as f64;
                    // Thresholds are f32: near a half code, 16-bit codes may round
                    // either way within f32 precision (~0.002 codes).
                    let tol = if max > 255 { 0.01 } else { 1e-3 };
                    let tie = (exact - exact.floor() - 0.5).abs() < tol;
                    assert!(got == (exact + 0.5).floor() || tie, "{v}: {got} vs {exact}");
                }
            }
        }
    }

    #[test]
    fn no_noise_gives_the_input_back() -> Result<()> {
        let wb = Some(sample_white_balance(5));
        for gamma in [Gamma::Power22, Gamma::Srgb] {
            for wl in [1.0, 0.3, 1e-3] {
                let m = NoiseModel {
                    gamma,
                    white_balance: wb,
                    white_level: wl,
                    ..model(0.0, 0.0)
                };
                let img8 = Image::new(
                    256,
                    1,
                    3,
                    Samples::U8((0..768).map(|i| (i / 3) as u8).collect()),
                )?;
                assert_eq!(add_noise(&img8, &m, 1, 0)?.processed, img8);
                let s16: Vec<u16> = (0..65536u32 * 2).map(|i| (i / 2) as u16).collect();
                let img16 = Image::new(65536, 1, 2, Samples::U16(s16))?;
                assert_eq!(add_noise(&img16, &m, 1, 0)?.processed, img16);
            }
        }
        Ok(())
    }

    #[test]
    fn black_has_read_noise_only_and_stays_signed() -> Result<()> {
        let img = flat(300, 200, 3, 0)?;
        let noisy = add_noise(&img, &model(0.02, 0.1), 3, stream_id(0, 0))?;
        let (m, var) = moments(&noisy.linear);
        assert!(m.abs() < 3.0 * 0.02 / (180_000f64).sqrt(), "mean {m}");
        assert!((var.sqrt() / 0.02 - 1.0).abs() < 0.01, "std {}", var.sqrt());
        assert!(noisy.linear.iter().any(|&v| v < 0.0));
        Ok(())
    }

    #[test]
    fn white_and_heteroscedastic_variance() -> Result<()> {
        let wb = WhiteBalance {
            red: 2.0,
            blue: 1.6,
        };
        let m = NoiseModel {
            white_balance: Some(wb),
            ..model(0.01, 0.05)
        };
        let img = flat(300, 200, 3, 255)?;
        let noisy = add_noise(&img, &m, 4, 0)?;
        for (c, g) in [1.0 / wb.red, 1.0, 1.0 / wb.blue].iter().enumerate() {
            let ch: Vec<f32> = noisy.linear.iter().skip(c).step_by(3).copied().collect();
            let (mean, var) = moments(&ch);
            assert!((mean - g).abs() < 0.001, "channel {c} mean {mean}");
            let want = 0.01f64.powi(2) + 0.05f64.powi(2) * g;
            assert!(
                (var / want - 1.0).abs() < 0.02,
                "channel {c} var {var} vs {want}"
            );
        }
        Ok(())
    }

    #[test]
    fn extremes_stay_finite() -> Result<()> {
        let (sr, ss) = NoiseLevels::DEFAULT.sigmas(20.0)?;
        for wl in [1.0, MIN_WHITE_LEVEL] {
            for value in [0u8, 128, 255] {
                let m = NoiseModel {
                    white_level: wl,
                    white_balance: Some(sample_white_balance(1)),
                    ..model(sr, ss)
                };
                let noisy = add_noise(&flat(64, 64, 4, value)?, &m, 9, 1)?;
                assert!(noisy.linear.iter().all(|v| v.is_finite()));
            }
        }
        let bad = NoiseModel {
            white_level: 0.0,
            ..model(sr, ss)
        };
        assert!(add_noise(&flat(2, 2, 3, 0)?, &bad, 0, 0).is_err());
        Ok(())
    }

    #[test]
    fn identical_for_any_thread_count_and_keyed() -> Result<()> {
        let s: Vec<u8> = (0..97 * 61 * 3).map(|i| (i * 7 % 256) as u8).collect();
        let img = Image::new(97, 61, 3, Samples::U8(s))?;
        let m = model(0.05, 0.1);
        let run = |threads: usize, key: u64| -> Result<Noisy> {
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .map_err(|e| Error::Value(e.to_string()))?
                .install(|| add_noise(&img, &m, key, stream_id(2, 1)))
        };
        let a = run(1, 11)?;
        assert_eq!(a, run(3, 11)?);
        assert_ne!(a.linear, run(1, 12)?.linear);
        Ok(())
    }

    #[test]
    fn gray_and_alpha_layouts() -> Result<()> {
        let img = Image::new(4, 4, 2, Samples::U8((0..32).map(|i| i as u8 * 8).collect()))?;
        let noisy = add_noise(&img, &model(0.01, 0.01), 1, 0)?;
        assert_eq!(noisy.linear_channels, 4);
        let Samples::U8(out) = &noisy.processed.samples else {
            panic!("depth changed")
        };
        let Samples::U8(src) = &img.samples else {
            panic!()
        };
        for p in 0..16 {
            assert_eq!(out[p * 2 + 1], src[p * 2 + 1], "alpha must be copied");
            let l = &noisy.linear[p * 4..p * 4 + 4];
            assert!(l[0] == l[1] && l[1] == l[2]);
            assert_eq!(l[3], src[p * 2 + 1] as f32 / 255.0);
        }
        Ok(())
    }
}
