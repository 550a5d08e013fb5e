//! The noise kernel of 8-bit RGB images with AVX2: eight values per step, bit for bit
//! the scalar kernel of `noise.rs` (the same IEEE f32 operations in the same order, no
//! fused multiply-add; table look-ups become gathers).
//!
//! Values are taken in memory order, so a vector's lanes cycle through the R, G, B
//! channels; per-lane channel constants come from a permutation of three-entry
//! vectors. The rare ziggurat rejections (≈1.2 % of values) leave the vector path:
//! their lanes are redone by the scalar `zig_slow`, which keeps the exact stream.
use crate::noise::ziggurat::{zig_slow, Ziggurat};
use crate::rng::{PHILOX_M0, PHILOX_M1, PHILOX_W0, PHILOX_W1};
use std::arch::x86_64::*;

/// The three colour channels' encoders of an 8-bit plan in one gather-friendly form:
/// every bin holds at most two thresholds (true of any 8-bit curve), so a code is the
/// bin's start plus two comparisons.
pub(super) struct Rgb8Encoders {
    /// `start` tables of the three channels, concatenated, widened to u32 for gathers.
    start: Vec<u32>,
    /// Thresholds (with their two +inf sentinels) of the three channels, concatenated.
    thresholds: Vec<f32>,
    first_bin: [i32; 3],
    span: [i32; 3],
    start_base: [i32; 3],
    threshold_base: [i32; 3],
}

impl Rgb8Encoders {
    /// `None` unless there are three 8-bit encoders with at most two thresholds a bin.
    pub(super) fn new(encoders: &[super::Encoder]) -> Option<Self> {
        if encoders.len() != 3 {
            return None;
        }
        let mut e = Rgb8Encoders {
            start: Vec::new(),
            thresholds: Vec::new(),
            first_bin: [0; 3],
            span: [0; 3],
            start_base: [0; 3],
            threshold_base: [0; 3],
        };
        for (c, enc) in encoders.iter().enumerate() {
            let sparse = enc.start.windows(2).all(|w| w[1] - w[0] <= 2);
            if enc.thresholds.len() != 257 || !sparse {
                return None;
            }
            e.first_bin[c] = i32::try_from(enc.first_bin).ok()?;
            e.span[c] = i32::try_from(enc.last_bin - enc.first_bin).ok()?;
            e.start_base[c] = i32::try_from(e.start.len()).ok()?;
            e.threshold_base[c] = i32::try_from(e.thresholds.len()).ok()?;
            e.start.extend(enc.start.iter().map(|&s| u32::from(s)));
            e.thresholds.extend_from_slice(&enc.thresholds);
        }
        Some(e)
    }
}

/// Per-lane value of a three-entry table for the lanes' channels.
#[inline]
#[target_feature(enable = "avx2")]
unsafe fn per_lane(v: [i32; 3], channels: __m256i) -> __m256i {
    _mm256_permutevar8x32_epi32(_mm256_setr_epi32(v[0], v[1], v[2], 0, 0, 0, 0, 0), channels)
}

/// Gather an (a, b) f32 pair per lane (8 bytes at `base + index · SCALE`), returned
/// as the vector of the a's and the vector of the b's, in lane order.
#[inline]
#[target_feature(enable = "avx2")]
unsafe fn gather_pairs<const SCALE: i32>(base: *const i64, index: __m256i) -> (__m256, __m256) {
    let lo = _mm256_i32gather_epi64::<SCALE>(base, _mm256_castsi256_si128(index));
    let hi = _mm256_i32gather_epi64::<SCALE>(base, _mm256_extracti128_si256::<1>(index));
    let (lo, hi) = (_mm256_castsi256_ps(lo), _mm256_castsi256_ps(hi));
    // [a0 b0 a1 b1 | a2 b2 a3 b3] and [a4 b4 a5 b5 | a6 b6 a7 b7] → lane order.
    let a = _mm256_castps_pd(_mm256_shuffle_ps::<0b10_00_10_00>(lo, hi));
    let b = _mm256_castps_pd(_mm256_shuffle_ps::<0b11_01_11_01>(lo, hi));
    (
        _mm256_castpd_ps(_mm256_permute4x64_pd::<0b11_01_10_00>(a)),
        _mm256_castpd_ps(_mm256_permute4x64_pd::<0b11_01_10_00>(b)),
    )
}

/// The inputs of one batch of an 8-bit RGB row.
pub(super) struct Rgb8Batch<'a> {
    pub words: &'a [u32],
    pub src: &'a [u8],
    pub lin: &'a mut [f32],
    pub out: &'a mut [u8],
    /// Index of the batch's first value (a multiple of 3: batches start at a pixel).
    pub v0: u64,
}

/// The inputs of the vector loops for the lanes' channels: one set per phase of a
/// 24-value (8-pixel) cycle.
struct Lanes {
    table_base: __m256i,
    first: __m256i,
    span: __m256i,
    start_base: __m256i,
    thr_base: __m256i,
}

/// Noise the values of a batch, 8 at a time; returns how many were done (a multiple of
/// 8: the caller does the rest with the scalar kernel).
///
/// # Safety
/// The CPU must support AVX2. `table` holds 3 · 256 (clean, std) pairs, channel-major.
#[target_feature(enable = "avx2")]
pub(super) unsafe fn rgb8(
    mut b: Rgb8Batch<'_>,
    z: &Ziggurat,
    table: &[[f32; 2]],
    enc: &Rgb8Encoders,
    fallback_key: u64,
) -> usize {
    let n = b
        .words
        .len()
        .min(b.src.len())
        .min(b.lin.len())
        .min(b.out.len());
    if table.len() < 3 * 256 {
        return 0;
    }
    let lanes = lanes_of(enc);
    noise_pass(&mut b, z, table, &lanes, fallback_key, n);
    encode_pass(&mut b, enc, &lanes, n)
}

/// The lanes' constants for the three vector phases of a 24-value (8-pixel) cycle.
#[inline]
#[target_feature(enable = "avx2")]
unsafe fn lanes_of(enc: &Rgb8Encoders) -> [Lanes; 3] {
    // Lane channels of each phase.
    let phases = [
        _mm256_setr_epi32(0, 1, 2, 0, 1, 2, 0, 1),
        _mm256_setr_epi32(2, 0, 1, 2, 0, 1, 2, 0),
        _mm256_setr_epi32(1, 2, 0, 1, 2, 0, 1, 2),
    ];
    phases.map(|ch| {
        // SAFETY: the caller runs on AVX2; this closure only forwards to `lane`.
        unsafe { lane(enc, ch) }
    })
}

/// The lanes' constants for lanes whose channels are `ch`.
#[inline]
#[target_feature(enable = "avx2")]
unsafe fn lane(enc: &Rgb8Encoders, ch: __m256i) -> Lanes {
    Lanes {
        table_base: _mm256_slli_epi32(ch, 8), // 256 (clean, std) pairs per channel
        first: per_lane(enc.first_bin, ch),
        span: per_lane(enc.span, ch),
        start_base: per_lane(enc.start_base, ch),
        thr_base: per_lane(enc.threshold_base, ch),
    }
}

/// First pass, the noise: the linear noisy values of the batch's first `n` values (a
/// multiple of 8 of them) into `b.lin`.
#[inline]
#[target_feature(enable = "avx2")]
unsafe fn noise_pass(
    b: &mut Rgb8Batch<'_>,
    z: &Ziggurat,
    table: &[[f32; 2]],
    lanes: &[Lanes; 3],
    fallback_key: u64,
    n: usize,
) {
    // Pairs are gathered as 64-bit elements: four per gather, half the elements of
    // two 32-bit gathers.
    let table = table.as_ptr() as *const i64;
    let zig = z.pairs32.as_ptr() as *const i64;
    let byte_mask = _mm256_set1_epi32(127);
    let sign_mask = _mm256_set1_epi32(128);
    let half = _mm256_set1_ps(0.5);
    let scale = _mm256_set1_ps(1.0 / 16_777_216.0);
    let mut i = 0;
    while i + 8 <= n {
        let l = &lanes[(i / 8) % 3];
        let w = _mm256_loadu_si256(b.words.as_ptr().add(i) as *const __m256i);
        // Ziggurat: 7 bits layer, 1 bit sign, 24 bits abscissa.
        let layer = _mm256_and_si256(w, byte_mask);
        let u = _mm256_mul_ps(
            _mm256_add_ps(_mm256_cvtepi32_ps(_mm256_srli_epi32(w, 8)), half),
            scale,
        );
        let (ratio, x32) = gather_pairs::<8>(zig, layer);
        let fast = _mm256_cmp_ps(u, ratio, _CMP_LT_OQ);
        let x = _mm256_mul_ps(u, x32);
        let sign = _mm256_slli_epi32(_mm256_and_si256(w, sign_mask), 24);
        let mut normal = _mm256_castsi256_ps(_mm256_xor_si256(_mm256_castps_si256(x), sign));
        let accepted = _mm256_movemask_ps(fast);
        if accepted != 0xFF {
            let mut v = [0f32; 8];
            _mm256_storeu_ps(v.as_mut_ptr(), normal);
            for (j, vj) in v.iter_mut().enumerate() {
                if accepted & (1 << j) == 0 {
                    let word = b.words[i + j];
                    *vj = zig_slow(z, word, fallback_key, b.v0 + (i + j) as u64) as f32;
                }
            }
            normal = _mm256_loadu_ps(v.as_ptr());
        }
        // Clean value and noise std of the source codes.
        let codes = _mm256_cvtepu8_epi32(_mm_loadl_epi64(b.src.as_ptr().add(i) as *const __m128i));
        let (clean, std) = gather_pairs::<8>(table, _mm256_add_epi32(l.table_base, codes));
        let noisy = _mm256_add_ps(clean, _mm256_mul_ps(std, normal));
        _mm256_storeu_ps(b.lin.as_mut_ptr().add(i), noisy);
        i += 8;
    }
}

/// Second pass, the encoding of `b.lin` into `b.out`: split from the noise so that each
/// loop has a short chain of dependent gathers and many iterations can be in flight.
/// Returns how many values were done.
#[inline]
#[target_feature(enable = "avx2")]
unsafe fn encode_pass(
    b: &mut Rgb8Batch<'_>,
    enc: &Rgb8Encoders,
    lanes: &[Lanes; 3],
    n: usize,
) -> usize {
    let start = enc.start.as_ptr() as *const i32;
    let thr = enc.thresholds.as_ptr() as *const i64;
    let zero = _mm256_setzero_si256();
    // Byte 0 of every 32-bit lane, per 128-bit half.
    let pick = _mm256_setr_epi8(
        0, 4, 8, 12, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, 0, 4, 8, 12, -1, -1, -1, -1,
        -1, -1, -1, -1, -1, -1, -1, -1,
    );
    let mut i = 0;
    while i + 8 <= n {
        let l = &lanes[(i / 8) % 3];
        let noisy = _mm256_loadu_ps(b.lin.as_ptr().add(i));
        // Encoder: bin (negative values below every bin), clamped to the table.
        let bin = _mm256_srai_epi32(_mm256_castps_si256(noisy), 16);
        let rel = _mm256_min_epi32(
            _mm256_max_epi32(_mm256_sub_epi32(bin, l.first), zero),
            l.span,
        );
        let lo = _mm256_i32gather_epi32::<4>(start, _mm256_add_epi32(rel, l.start_base));
        // Thresholds lo and lo + 1 are neighbours: one 8-byte element per lane.
        let (t0, t1) = gather_pairs::<4>(thr, _mm256_add_epi32(lo, l.thr_base));
        let ge0 = _mm256_castps_si256(_mm256_cmp_ps(noisy, t0, _CMP_GE_OQ));
        let ge1 = _mm256_castps_si256(_mm256_cmp_ps(noisy, t1, _CMP_GE_OQ));
        // Comparison masks are -1 where true.
        let code = _mm256_sub_epi32(_mm256_sub_epi32(lo, ge0), ge1);
        let bytes = _mm256_shuffle_epi8(code, pick);
        let lo4 = _mm_cvtsi128_si32(_mm256_castsi256_si128(bytes)) as u32;
        let hi4 = _mm_cvtsi128_si32(_mm256_extracti128_si256::<1>(bytes)) as u32;
        let packed = (u64::from(hi4) << 32) | u64::from(lo4);
        b.out[i..i + 8].copy_from_slice(&packed.to_le_bytes());
        i += 8;
    }
    i
}

/// 32-bit products of one Philox multiplier with 8 lanes: (high halves, low halves).
#[inline]
#[target_feature(enable = "avx2")]
unsafe fn mul_hi_lo(a: __m256i, m: __m256i) -> (__m256i, __m256i) {
    let even = _mm256_mul_epu32(a, m); // lanes 0, 2, 4, 6 as 64-bit products
    let odd = _mm256_mul_epu32(_mm256_srli_epi64::<32>(a), m);
    let hi = _mm256_blend_epi32::<0b1010_1010>(_mm256_srli_epi64::<32>(even), odd);
    let lo = _mm256_blend_epi32::<0b1010_1010>(even, _mm256_slli_epi64::<32>(odd));
    (hi, lo)
}

/// `rng::philox4x32` of blocks `first ..` of `stream` (a multiple of 8 blocks, 4 words
/// each) into `out`, 8 blocks per step.
///
/// # Safety
/// The CPU must support AVX2.
#[target_feature(enable = "avx2")]
pub(super) unsafe fn philox_fill(key: u64, stream: u64, first: u64, out: &mut [u32]) {
    let m0 = _mm256_set1_epi32(PHILOX_M0 as i32);
    let m1 = _mm256_set1_epi32(PHILOX_M1 as i32);
    let s0 = _mm256_set1_epi32(stream as u32 as i32);
    let s1 = _mm256_set1_epi32((stream >> 32) as u32 as i32);
    for (i, o) in out.chunks_exact_mut(32).enumerate() {
        let mut lo = [0u32; 8];
        let mut hi = [0u32; 8];
        for j in 0..8 {
            let b = first + (i * 8 + j) as u64;
            lo[j] = b as u32;
            hi[j] = (b >> 32) as u32;
        }
        let mut c0 = _mm256_loadu_si256(lo.as_ptr() as *const __m256i);
        let mut c1 = _mm256_loadu_si256(hi.as_ptr() as *const __m256i);
        let (mut c2, mut c3) = (s0, s1);
        let (mut k0, mut k1) = (key as u32, (key >> 32) as u32);
        for _ in 0..10 {
            let (hi0, lo0) = mul_hi_lo(c0, m0);
            let (hi1, lo1) = mul_hi_lo(c2, m1);
            let n0 = _mm256_xor_si256(_mm256_xor_si256(hi1, c1), _mm256_set1_epi32(k0 as i32));
            let n2 = _mm256_xor_si256(_mm256_xor_si256(hi0, c3), _mm256_set1_epi32(k1 as i32));
            c0 = n0;
            c1 = lo1;
            c2 = n2;
            c3 = lo0;
            k0 = k0.wrapping_add(PHILOX_W0);
            k1 = k1.wrapping_add(PHILOX_W1);
        }
        // Lane-major (word r of blocks 0..8) to block-major (4 words per block).
        let t0 = _mm256_unpacklo_epi32(c0, c1);
        let t1 = _mm256_unpackhi_epi32(c0, c1);
        let t2 = _mm256_unpacklo_epi32(c2, c3);
        let t3 = _mm256_unpackhi_epi32(c2, c3);
        let u0 = _mm256_unpacklo_epi64(t0, t2); // blocks 0 | 4
        let u1 = _mm256_unpackhi_epi64(t0, t2); // blocks 1 | 5
        let u2 = _mm256_unpacklo_epi64(t1, t3); // blocks 2 | 6
        let u3 = _mm256_unpackhi_epi64(t1, t3); // blocks 3 | 7
        let p = o.as_mut_ptr() as *mut __m256i;
        _mm256_storeu_si256(p, _mm256_permute2x128_si256::<0x20>(u0, u1));
        _mm256_storeu_si256(p.add(1), _mm256_permute2x128_si256::<0x20>(u2, u3));
        _mm256_storeu_si256(p.add(2), _mm256_permute2x128_si256::<0x31>(u0, u1));
        _mm256_storeu_si256(p.add(3), _mm256_permute2x128_si256::<0x31>(u2, u3));
    }
}
