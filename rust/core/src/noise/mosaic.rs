//! The Bayer colour filter array (RGGB) and its bilinear demosaic.
//!
//! Demosaic: per channel, the weighted mean of that channel's photosites in the 3 × 3
//! neighbourhood under the bilinear kernels (green `[0 1 0; 1 4 1; 0 1 0]`, red and
//! blue `[1 2 1; 2 4 2; 1 2 1]`), which is the standard bilinear interpolation inside
//! the image; at the borders the weights are renormalised over the photosites there.
#[cfg(test)]
use rayon::prelude::*;

/// The demosaic named in noise.json.
pub const DEMOSAIC: &str = "bilinear (3x3 kernels, green [0 1 0;1 4 1;0 1 0]/4, red/blue \
    [1 2 1;2 4 2;1 2 1]/4, renormalised at borders)";

/// The channel (0 R, 1 G, 2 B) of photosite (x, y) of an RGGB mosaic.
pub fn cfa_channel(x: usize, y: usize) -> usize {
    (x & 1) + (y & 1)
}

/// One row of the bilinear kernel of channel `c` at offset `d` ∈ {−1, 0, 1}.
fn weight(c: usize, dx: isize, dy: isize) -> f64 {
    let (ax, ay) = (dx.unsigned_abs(), dy.unsigned_abs());
    if c == 1 {
        match ax + ay {
            0 => 4.0,
            1 => 1.0,
            _ => 0.0,
        }
    } else {
        [4.0, 2.0, 1.0][ax + ay]
    }
}

/// The RGB of pixel (x, y) from the mosaic `m` (`w` × `h`, row-major).
fn pixel(m: &[f64], w: usize, h: usize, x: usize, y: usize) -> [f64; 3] {
    let mut sum = [0.0; 3];
    let mut norm = [0.0; 3];
    for dy in -1isize..=1 {
        let Some(yy) = y.checked_add_signed(dy).filter(|v| *v < h) else {
            continue;
        };
        for dx in -1isize..=1 {
            let Some(xx) = x.checked_add_signed(dx).filter(|v| *v < w) else {
                continue;
            };
            let c = cfa_channel(xx, yy);
            let k = weight(c, dx, dy);
            sum[c] += k * m[yy * w + xx];
            norm[c] += k;
        }
    }
    [0, 1, 2].map(|c| if norm[c] > 0.0 { sum[c] / norm[c] } else { 0.0 })
}

/// [`pixel`] away from the borders, by the kernels' closed forms: at a green site the
/// two horizontal and the two vertical neighbours give the other channels; at a red or
/// blue site the four orthogonal ones give green and the four diagonal ones the other.
fn pixel_inside(m: &[f64], w: usize, x: usize, y: usize) -> [f64; 3] {
    let i = y * w + x;
    let c = cfa_channel(x, y);
    let mut out = [0.0; 3];
    out[c] = m[i];
    if c == 1 {
        out[cfa_channel(x + 1, y)] = 0.5 * (m[i - 1] + m[i + 1]);
        out[cfa_channel(x, y + 1)] = 0.5 * (m[i - w] + m[i + w]);
    } else {
        out[1] = 0.25 * (m[i - 1] + m[i + 1] + m[i - w] + m[i + w]);
        out[2 - c] = 0.25 * (m[i - w - 1] + m[i - w + 1] + m[i + w - 1] + m[i + w + 1]);
    }
    out
}

/// The RGB of pixel (x, y) of the bilinear demosaic of a `w` × `h` RGGB mosaic.
pub fn demosaic_at(m: &[f64], w: usize, h: usize, x: usize, y: usize) -> [f64; 3] {
    if y > 0 && y + 1 < h && x > 0 && x + 1 < w {
        pixel_inside(m, w, x, y)
    } else {
        pixel(m, w, h, x, y)
    }
}

/// The bilinear demosaic of a `w` × `h` RGGB mosaic: interleaved RGB, row-major (the
/// tests' whole-image form of [`demosaic_at`]).
#[cfg(test)]
pub fn demosaic_bilinear(m: &[f64], w: usize, h: usize) -> Vec<f64> {
    let mut out = vec![0.0; w * h * 3];
    out.par_chunks_mut((w * 3).max(1))
        .enumerate()
        .for_each(|(y, row)| {
            for x in 0..w {
                row[x * 3..x * 3 + 3].copy_from_slice(&demosaic_at(m, w, h, x, y));
            }
        });
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_closed_forms_inside_are_the_kernels() {
        let (w, h) = (9, 8);
        let m: Vec<f64> = (0..w * h).map(|i| ((i * 37) % 101) as f64 / 7.0).collect();
        for y in 1..h - 1 {
            for x in 1..w - 1 {
                let (a, b) = (pixel_inside(&m, w, x, y), pixel(&m, w, h, x, y));
                for c in 0..3 {
                    assert!((a[c] - b[c]).abs() < 1e-12, "({x}, {y}) {c}: {a:?} {b:?}");
                }
            }
        }
    }

    #[test]
    fn rggb_layout() {
        assert_eq!(
            [
                cfa_channel(0, 0),
                cfa_channel(1, 0),
                cfa_channel(0, 1),
                cfa_channel(1, 1)
            ],
            [0, 1, 1, 2]
        );
    }

    #[test]
    fn a_flat_mosaic_demosaics_to_its_channels_and_sites_keep_their_value() {
        let (w, h) = (7, 5);
        let level = [0.2, 0.5, 0.9];
        let m: Vec<f64> = (0..w * h)
            .map(|i| level[cfa_channel(i % w, i / w)])
            .collect();
        let rgb = demosaic_bilinear(&m, w, h);
        for p in rgb.chunks_exact(3) {
            for c in 0..3 {
                assert!((p[c] - level[c]).abs() < 1e-12);
            }
        }
        // A photosite keeps its own value; a linear ramp is reproduced inside.
        let ramp: Vec<f64> = (0..w * h).map(|i| (i % w) as f64).collect();
        let rgb = demosaic_bilinear(&ramp, w, h);
        for y in 1..h - 1 {
            for x in 1..w - 1 {
                for c in 0..3 {
                    assert!((rgb[(y * w + x) * 3 + c] - x as f64).abs() < 1e-12);
                }
            }
        }
    }

    #[test]
    fn through_the_raw_pipeline_each_photosites_noise_stays_in_its_own_channel() {
        use crate::noise::camera::eld_camera;
        use crate::noise::linear::LinearRgb;
        use crate::noise::matrix::apply;
        use crate::noise::model::{Gamma, WhiteBalance};
        use crate::noise::raw::{clean_raw, noisy_mosaic, raw_frame};
        use crate::noise::raw_model::{Display, RawModel};
        // A coloured flat patch, white balanced: the frame's noise (noisy − clean linear),
        // taken back to camera raw, holds at every photosite in that photosite's channel
        // exactly what the sensor drew there (a demosaic keeps each site's own value), so
        // red's noise is in R, not in B.
        let d = Display {
            gamma: Gamma::Srgb,
            white_balance: Some(WhiteBalance {
                red: 2.1,
                blue: 1.7,
            }),
            white_level: 1.0,
        };
        let m = RawModel::eld(eld_camera("SonyA7S2").expect("camera"), 8.0, d).expect("model");
        let (w, h) = (24usize, 17usize);
        let patch = [0.5f32, 0.25, 0.08];
        let rgb: Vec<f32> = (0..w * h).flat_map(|_| patch).collect();
        let img = LinearRgb::new(w as u32, h as u32, rgb).expect("image");
        let noisy = raw_frame(&img, &m, 5, 6).expect("frame").linear;
        let clean = raw_frame(&img, &m.clean(), 5, 6).expect("frame").linear;
        let raw = clean_raw(&img, &m);
        let drawn = noisy_mosaic(&m, &raw, w, 5, 6);
        let mut worst: f64 = 0.0;
        for y in 0..h {
            for x in 0..w {
                let i = y * w + x;
                let n = [0, 1, 2].map(|c| f64::from(noisy[i * 3 + c] - clean[i * 3 + c]));
                let cam = apply(&m.cam_from_rgb, n.map(|v| v * m.white_level));
                let c = cfa_channel(x, y);
                let want = drawn[i] - raw[i * 3 + c];
                let got = cam[c] / m.wb[c];
                assert!(
                    (got - want).abs() < 2e-5,
                    "({x}, {y}) channel {c}: {got} vs {want}"
                );
                worst = worst.max(want.abs());
            }
        }
        assert!(worst > 1e-3, "the noise is there: {worst}");
    }
}
