//! Colour: the sRGB transfer curve, compositing over a background and luma. Every
//! part of blurset that encodes, composites or weighs colour calls these.
use rayon::prelude::*;

/// Linear value at which the sRGB curve switches from the line to the power law.
pub const SRGB_LINEAR_BREAK: f64 = 0.003_130_8;
/// Encoded value at which the inverse curve switches from the line to the power law.
pub const SRGB_ENCODED_BREAK: f64 = 0.040_45;

/// The exact IEC 61966-2-1 encoding of a linear value, clamped to [0, 1]; NaN maps to 0.
///
/// Evaluated in f64 so that the f32 result is correctly rounded and 8-bit quantization
/// never depends on where the accumulation rounded.
pub fn srgb_encode_f64(linear: f64) -> f64 {
    // `clamp` passes NaN through; a NaN must not reach a PNG byte as an arbitrary value.
    let x = if linear.is_nan() {
        0.0
    } else {
        linear.clamp(0.0, 1.0)
    };
    if x <= SRGB_LINEAR_BREAK {
        12.92 * x
    } else {
        1.055 * libm::pow(x, 1.0 / 2.4) - 0.055
    }
}

/// The exact IEC 61966-2-1 decoding of an encoded value, clamped to [0, 1]; NaN maps to 0.
pub fn srgb_decode_f64(encoded: f64) -> f64 {
    let x = if encoded.is_nan() {
        0.0
    } else {
        encoded.clamp(0.0, 1.0)
    };
    if x <= SRGB_ENCODED_BREAK {
        x / 12.92
    } else {
        libm::pow((x + 0.055) / 1.055, 2.4)
    }
}

/// sRGB encoding of one linear value (see [`srgb_encode_f64`]).
pub fn srgb_encode(linear: f32) -> f32 {
    srgb_encode_f64(f64::from(linear)) as f32
}

/// sRGB encoding of many values, in parallel.
pub fn srgb_encode_slice(linear: &[f32]) -> Vec<f32> {
    linear.par_iter().map(|&x| srgb_encode(x)).collect()
}

/// Linear value quantized to an 8-bit sRGB code (round to nearest).
pub fn srgb_encode_u8(linear: f64) -> u8 {
    // The encoding is clamped to [0, 1], so the rounded value fits in a u8.
    (srgb_encode_f64(linear) * 255.0).round() as u8
}

/// A premultiplied RGBA pixel over an opaque background: `rgb + (1 - a) * bg`, in linear light.
///
/// Alpha is film coverage; it is clamped to [0, 1] so that a stray value never
/// subtracts background.
pub fn composite_over(rgba_premul: [f64; 4], background: [f64; 3]) -> [f64; 3] {
    let t = 1.0 - rgba_premul[3].clamp(0.0, 1.0);
    [
        rgba_premul[0] + t * background[0],
        rgba_premul[1] + t * background[1],
        rgba_premul[2] + t * background[2],
    ]
}

/// Rec. 709 / sRGB weights of R, G and B: luminance of linear values, luma of encoded ones.
pub const LUMA: [f64; 3] = [0.2126, 0.7152, 0.0722];

/// `LUMA · rgb`, summed left to right.
pub fn luma(rgb: [f64; 3]) -> f64 {
    LUMA[0] * rgb[0] + LUMA[1] * rgb[1] + LUMA[2] * rgb[2]
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn srgb_breakpoints_are_exact() {
        assert_eq!(srgb_encode_f64(0.0), 0.0);
        // 1.055 - 0.055 is one ulp below 1 in f64; the f32 result and the byte are exact.
        assert!((srgb_encode_f64(1.0) - 1.0).abs() < 1e-15);
        assert_eq!(srgb_encode(1.0), 1.0);
        assert_eq!(srgb_decode_f64(1.0), 1.0);
        // Both pieces meet at the break (continuity to ~1e-8, the standard's rounding).
        let lo = 12.92 * SRGB_LINEAR_BREAK;
        let hi = 1.055 * SRGB_LINEAR_BREAK.powf(1.0 / 2.4) - 0.055;
        assert_eq!(srgb_encode_f64(SRGB_LINEAR_BREAK), lo);
        assert!((lo - hi).abs() < 1e-7, "{lo} vs {hi}");
        assert!((lo - SRGB_ENCODED_BREAK).abs() < 1e-6);
        assert_eq!(
            srgb_decode_f64(SRGB_ENCODED_BREAK),
            SRGB_ENCODED_BREAK / 12.92
        );
        assert!(srgb_encode_f64(SRGB_LINEAR_BREAK + 1e-12) > lo - 1e-7);
        assert_eq!(
            srgb_encode(0.5),
            (1.055 * 0.5f64.powf(1.0 / 2.4) - 0.055) as f32
        );
        // Known code values: linear 0.5 is sRGB 188, 0.2159 (the decode of 128/255) is 128.
        assert_eq!(srgb_encode_u8(0.5), 188);
        assert_eq!(srgb_encode_u8(0.215_860_5), 128);
        assert_eq!(srgb_encode_u8(-3.0), 0);
        assert_eq!(srgb_encode_u8(7.0), 255);
        assert_eq!(srgb_encode_u8(f64::NAN), 0);
    }

    #[test]
    fn composite_alpha_zero_gives_background_alpha_one_gives_colour() {
        let bg = [0.25, 0.5, 1.0];
        assert_eq!(composite_over([0.0, 0.0, 0.0, 0.0], bg), bg);
        assert_eq!(composite_over([0.1, 0.2, 0.3, 1.0], bg), [0.1, 0.2, 0.3]);
        // Half coverage of premultiplied red over white.
        assert_eq!(
            composite_over([0.5, 0.0, 0.0, 0.5], [1.0; 3]),
            [1.0, 0.5, 0.5]
        );
    }

    #[test]
    fn luma_weighs_green_most_and_white_is_one() {
        assert!((luma([1.0; 3]) - 1.0).abs() < 1e-15);
        assert_eq!(luma([0.0, 1.0, 0.0]), LUMA[1]);
        assert!(luma([0.0, 1.0, 0.0]) > luma([1.0, 0.0, 0.0]));
        assert!(luma([1.0, 0.0, 0.0]) > luma([0.0, 0.0, 1.0]));
    }

    proptest! {
        #[test]
        fn srgb_roundtrip(x in 0.0f64..=1.0) {
            prop_assert!((srgb_decode_f64(srgb_encode_f64(x)) - x).abs() < 1e-12);
            prop_assert!((srgb_encode_f64(srgb_decode_f64(x)) - x).abs() < 1e-12);
            let y = x as f32;
            let back = srgb_decode_f64(f64::from(srgb_encode(y))) as f32;
            prop_assert!((back - y).abs() <= 2e-7_f32.max(y * 4e-7));
        }

        #[test]
        fn srgb_is_monotone(a in -0.5f64..1.5, b in -0.5f64..1.5) {
            let (lo, hi) = if a <= b { (a, b) } else { (b, a) };
            prop_assert!(srgb_encode_f64(lo) <= srgb_encode_f64(hi));
            prop_assert!(srgb_encode_u8(lo) <= srgb_encode_u8(hi));
        }
    }
}
