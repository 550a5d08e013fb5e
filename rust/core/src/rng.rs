//! Portable, counter-based randomness.
//!
//! Every random number blurset writes comes from Philox4x32-10 (Salmon et al., SC'11):
//! a pure function of (key, counter), so a draw depends only on *which* number it is,
//! never on thread count, platform or library version. Uniforms are built from integer
//! bits with exact IEEE arithmetic (the noise kernel's normals use `libm`, a pure-Rust
//! libm, so that transcendental functions give the same bits on every machine).

// The Philox4x32-10 multipliers and Weyl key increments; the noise kernel's lane-wise
// versions of `philox4x32` use them too.
pub(crate) const PHILOX_M0: u32 = 0xD251_1F53;
pub(crate) const PHILOX_M1: u32 = 0xCD9E_8D57;
pub(crate) const PHILOX_W0: u32 = 0x9E37_79B9;
pub(crate) const PHILOX_W1: u32 = 0xBB67_AE85;

/// One Philox4x32-10 block: 128 random bits for a 128-bit counter under a 64-bit key.
pub fn philox4x32(key: u64, counter: [u32; 4]) -> [u32; 4] {
    let mut k0 = key as u32;
    let mut k1 = (key >> 32) as u32;
    let mut c = counter;
    for _ in 0..10 {
        let p0 = (PHILOX_M0 as u64) * (c[0] as u64);
        let p1 = (PHILOX_M1 as u64) * (c[2] as u64);
        c = [
            ((p1 >> 32) as u32) ^ c[1] ^ k0,
            p1 as u32,
            ((p0 >> 32) as u32) ^ c[3] ^ k1,
            p0 as u32,
        ];
        k0 = k0.wrapping_add(PHILOX_W0);
        k1 = k1.wrapping_add(PHILOX_W1);
    }
    c
}

/// SplitMix64 finaliser: a bijective 64-bit mix used to derive keys from ids.
pub fn mix64(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// FNV-1a over bytes: a stable string hash (std's hasher is not stable across releases).
pub fn fnv1a64(bytes: &[u8]) -> u64 {
    let mut h: u64 = 0xCBF2_9CE4_8422_2325;
    for &b in bytes {
        h ^= b as u64;
        h = h.wrapping_mul(0x0000_0100_0000_01B3);
    }
    h
}

/// Derive a child seed from a parent seed and a path of labels (e.g. [setting, view]).
pub fn derive_seed(parent: u64, labels: &[u64]) -> u64 {
    labels
        .iter()
        .fold(mix64(parent), |acc, &l| mix64(acc ^ mix64(l)))
}

/// Seed for one object/setting from the build seed and the object's uid.
pub fn seed_for(seed: u64, uid: &str, index: u64) -> u64 {
    derive_seed(seed, &[fnv1a64(uid.as_bytes()), index])
}

/// A sequential stream of draws over Philox: stream `stream` under key `key`.
/// Draw k of the stream is block (k / 2) word pair (k % 2): reproducible by position.
#[derive(Clone, Debug)]
pub struct Stream {
    key: u64,
    stream: u64,
    block: u64,
    buf: [u32; 4],
    used: usize,
}

impl Stream {
    pub fn new(key: u64, stream: u64) -> Self {
        Stream {
            key,
            stream,
            block: 0,
            buf: [0; 4],
            used: 4,
        }
    }

    fn refill(&mut self) {
        let b = self.block;
        self.buf = philox4x32(
            self.key,
            [
                b as u32,
                (b >> 32) as u32,
                self.stream as u32,
                (self.stream >> 32) as u32,
            ],
        );
        self.block = self.block.wrapping_add(1);
        self.used = 0;
    }

    #[inline]
    pub fn next_u64(&mut self) -> u64 {
        if self.used >= 4 {
            self.refill();
        }
        let v = ((self.buf[self.used] as u64) << 32) | self.buf[self.used + 1] as u64;
        self.used += 2;
        v
    }

    /// Uniform in [0, 1) with 53 random bits (exact in f64).
    #[inline]
    pub fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }

    /// Uniform in [lo, hi).
    pub fn uniform_in(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.uniform()
    }

    /// A random sign, +1 or -1.
    pub fn sign(&mut self) -> f64 {
        if self.next_u64() >> 63 == 1 {
            1.0
        } else {
            -1.0
        }
    }
}

/// A uniform in (0, 1), never 0 or 1 (the midpoint of a 53-bit cell).
pub fn open_uniform(s: &mut Stream) -> f64 {
    ((s.next_u64() >> 11) as f64 + 0.5) * (1.0 / (1u64 << 53) as f64)
}

/// A standard normal (one Box–Muller draw per call; the sine half is discarded).
pub fn normal(s: &mut Stream) -> f64 {
    let u1 = open_uniform(s);
    let u2 = s.uniform();
    libm::sqrt(-2.0 * libm::log(u1)) * libm::cos(std::f64::consts::TAU * u2)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn philox_known_answer() {
        // Random123 kat_vectors: philox4x32_10, counter = key = 0.
        assert_eq!(
            philox4x32(0, [0, 0, 0, 0]),
            [0x6627_e8d5, 0xe169_c58d, 0xbc57_ac4c, 0x9b00_dbd8]
        );
        // counter = key = all ones.
        assert_eq!(
            philox4x32(u64::MAX, [u32::MAX; 4]),
            [0x408f_276d, 0x41c8_3b0e, 0xa20b_c7c6, 0x6d54_51fd]
        );
    }

    #[test]
    fn draw_k_is_word_pair_k_mod_2_of_block_k_div_2() {
        let (key, stream) = (42u64, (9u64 << 32) | 7);
        let mut s = Stream::new(key, stream);
        for k in 0..9u64 {
            let b = k / 2;
            let c = [
                b as u32,
                (b >> 32) as u32,
                stream as u32,
                (stream >> 32) as u32,
            ];
            let w = philox4x32(key, c);
            let i = (k % 2) as usize * 2;
            assert_eq!(s.next_u64(), (u64::from(w[i]) << 32) | u64::from(w[i + 1]));
        }
    }

    #[test]
    fn uniforms_in_range_and_streams_differ() {
        let mut a = Stream::new(1, 0);
        let mut b = Stream::new(1, 1);
        let mut same = 0;
        for _ in 0..10_000 {
            let (x, y) = (a.uniform(), b.uniform());
            assert!((0.0..1.0).contains(&x));
            if x == y {
                same += 1;
            }
        }
        assert_eq!(same, 0);
    }
}
