//! Area downsampling in linear light: the `images_<f>/` copies that LLFF loaders read
//! (IBRNet and NAN hard-code factor 4). Each output pixel is the mean of an f × f block
//! of linear values, so a blurry image stays the mean of its latent frames at every
//! size; the caller encodes the result with the same sRGB curve as a full-size image.
//! Sizes must divide: LLFF keeps hwf at full size and loaders scale the focal length
//! by exactly 1/f, so a rounded size would shift every ray.
use crate::error::{Error, Result};
use rayon::prelude::*;

/// Refuse a factor that is 0 or does not divide both sides.
pub fn check_factor(width: u32, height: u32, factor: u32) -> Result<()> {
    if factor == 0 || !width.is_multiple_of(factor) || !height.is_multiple_of(factor) {
        return Err(Error::Value(format!(
            "downsample factor {factor} does not divide the image size {width} x {height}"
        )));
    }
    Ok(())
}

/// The mean of every `factor × factor` block of a row-major image of `channels` f64
/// values per pixel: (width / factor) × (height / factor) pixels, in f64.
pub fn area_mean(
    width: u32,
    height: u32,
    channels: usize,
    data: &[f64],
    factor: u32,
) -> Result<Vec<f64>> {
    check_factor(width, height, factor)?;
    let (w, f) = (width as usize, factor as usize);
    if data.len() != w * height as usize * channels || channels == 0 {
        return Err(Error::Shape(format!(
            "{} values for a {width} x {height} image of {channels} channels",
            data.len()
        )));
    }
    let (ow, inv) = (w / f, 1.0 / (f * f) as f64);
    let mut out = vec![0.0; ow * (height as usize / f) * channels];
    out.par_chunks_mut(ow * channels)
        .enumerate()
        .for_each(|(oy, row)| {
            for dy in 0..f {
                let src = &data[(oy * f + dy) * w * channels..][..w * channels];
                for (ox, px) in row.chunks_exact_mut(channels).enumerate() {
                    for dx in 0..f {
                        let s = &src[(ox * f + dx) * channels..][..channels];
                        for (o, v) in px.iter_mut().zip(s) {
                            *o += v;
                        }
                    }
                }
            }
            for v in row.iter_mut() {
                *v *= inv;
            }
        });
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn blocks_average_and_factor_one_is_identity() -> Result<()> {
        // 4 x 2 pixels, 1 channel: two 2 x 2 blocks.
        let d = [1.0, 3.0, 10.0, 20.0, 5.0, 7.0, 30.0, 40.0];
        assert_eq!(area_mean(4, 2, 1, &d, 2)?, vec![4.0, 25.0]);
        assert_eq!(area_mean(4, 2, 1, &d, 1)?, d.to_vec());
        // Channels stay apart.
        let rgb: Vec<f64> = (0..4 * 4 * 3).map(|i| (i % 3) as f64).collect();
        assert_eq!(area_mean(4, 4, 3, &rgb, 4)?, vec![0.0, 1.0, 2.0]);
        Ok(())
    }

    #[test]
    fn sizes_that_do_not_divide_are_refused() {
        let e = area_mean(6, 4, 1, &[0.0; 24], 4)
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
        assert!(e.contains("factor 4") && e.contains("6 x 4"), "{e}");
        assert!(check_factor(8, 8, 0).is_err());
        assert!(area_mean(4, 4, 1, &[0.0; 15], 2).is_err());
    }

    #[test]
    fn the_mean_is_kept_exactly_enough() -> Result<()> {
        let mut s = crate::rng::Stream::new(7, 0);
        let d: Vec<f64> = (0..64 * 48 * 3).map(|_| s.uniform()).collect();
        let small = area_mean(64, 48, 3, &d, 8)?;
        let a: f64 = d.iter().sum::<f64>() / d.len() as f64;
        let b: f64 = small.iter().sum::<f64>() / small.len() as f64;
        assert!((a - b).abs() < 1e-12);
        Ok(())
    }
}
