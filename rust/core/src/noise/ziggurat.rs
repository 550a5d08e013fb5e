//! Standard normals for the noise kernel, one 32-bit Philox word each.
use crate::rng;
use std::sync::OnceLock;

// Ziggurat after Marsaglia & Tsang (2000) in Doornik's (2005) form, which draws the
// layer and the abscissa from separate bits.
const ZIG_LAYERS: usize = 128;
const ZIG_R: f64 = 3.442_619_855_899;
const ZIG_V: f64 = 9.912_563_035_262_17e-3;

pub(super) struct Ziggurat {
    x: [f64; ZIG_LAYERS + 1],
    ratio: [f64; ZIG_LAYERS],
    x32: [f32; ZIG_LAYERS],
    ratio32: [f32; ZIG_LAYERS],
    /// [ratio32, x32] per layer, for the AVX2 kernel's paired gathers.
    #[cfg_attr(not(target_arch = "x86_64"), allow(dead_code))]
    pub(super) pairs32: [[f32; 2]; ZIG_LAYERS],
}

pub(super) fn ziggurat() -> &'static Ziggurat {
    static Z: OnceLock<Ziggurat> = OnceLock::new();
    Z.get_or_init(|| {
        let f = |x: f64| libm::exp(-0.5 * x * x);
        let mut x = [0.0; ZIG_LAYERS + 1];
        x[0] = ZIG_V / f(ZIG_R);
        x[1] = ZIG_R;
        for i in 2..ZIG_LAYERS {
            x[i] = libm::sqrt(-2.0 * libm::log(ZIG_V / x[i - 1] + f(x[i - 1])));
        }
        let mut ratio = [0.0; ZIG_LAYERS];
        let (mut x32, mut ratio32) = ([0.0f32; ZIG_LAYERS], [0.0f32; ZIG_LAYERS]);
        for i in 0..ZIG_LAYERS {
            ratio[i] = x[i + 1] / x[i];
            x32[i] = x[i] as f32;
            ratio32[i] = ratio[i] as f32;
        }
        Ziggurat {
            x,
            ratio,
            x32,
            ratio32,
            pairs32: std::array::from_fn(|i| [ratio32[i], x32[i]]),
        }
    })
}

/// Standard normal from one 32-bit word: 7 bits layer, 1 bit sign, 24 bits abscissa.
#[inline(always)]
pub(super) fn zig_normal(z: &Ziggurat, word: u32, fallback_key: u64, v: u64) -> f32 {
    let i = (word & 127) as usize;
    let u = ((word >> 8) as f32 + 0.5) * (1.0 / 16_777_216.0);
    if u < z.ratio32[i] {
        // Bit 7 becomes the sign bit without a branch (it is a coin flip).
        return f32::from_bits((u * z.x32[i]).to_bits() ^ ((word & 128) << 24));
    }
    zig_slow(z, word, fallback_key, v) as f32
}

#[cold]
pub(super) fn zig_slow(z: &Ziggurat, mut word: u32, fallback_key: u64, v: u64) -> f64 {
    let mut s = rng::Stream::new(fallback_key, v);
    loop {
        let i = (word & 127) as usize;
        let sign = if word & 128 != 0 { -1.0 } else { 1.0 };
        let u = ((word >> 8) as f64 + 0.5) * (1.0 / 16_777_216.0);
        if u < z.ratio[i] {
            return sign * u * z.x[i];
        }
        if i == 0 {
            // Tail beyond R (Marsaglia 1964); 1 - uniform keeps the logs finite.
            loop {
                let a = libm::log(1.0 - s.uniform()) / ZIG_R;
                let b = libm::log(1.0 - s.uniform());
                if -2.0 * b >= a * a {
                    return sign * (ZIG_R - a);
                }
            }
        }
        let x = u * z.x[i];
        let f0 = libm::exp(-0.5 * (z.x[i] * z.x[i] - x * x));
        let f1 = libm::exp(-0.5 * (z.x[i + 1] * z.x[i + 1] - x * x));
        if f1 + s.uniform() * (f0 - f1) < 1.0 {
            return sign * x;
        }
        word = s.next_u64() as u32;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ziggurat_is_standard_normal() {
        let z = ziggurat();
        let n = 2_000_000u64;
        let (mut s1, mut s2, mut s4, mut tail) = (0.0, 0.0, 0.0, 0u64);
        for v in 0..n {
            let w = rng::philox4x32(7, [(v >> 2) as u32, 0, 0, 0])[(v & 3) as usize];
            let x = zig_normal(z, w, 99, v) as f64;
            assert!(x.is_finite());
            s1 += x;
            s2 += x * x;
            s4 += x * x * x * x;
            if x.abs() > 3.0 {
                tail += 1;
            }
        }
        let nf = n as f64;
        assert!((s1 / nf).abs() < 0.003, "mean {}", s1 / nf);
        assert!((s2 / nf - 1.0).abs() < 0.005, "var {}", s2 / nf);
        assert!((s4 / nf - 3.0).abs() < 0.05, "4th moment {}", s4 / nf);
        // P(|x| > 3) = 0.0026998
        let p = tail as f64 / nf;
        assert!((p - 0.0027).abs() < 0.0003, "tail {p}");
    }
}
