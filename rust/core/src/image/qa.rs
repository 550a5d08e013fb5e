//! Render QA of a sharp view (DESIGN §10): an all-black, empty (object out of frame) or
//! saturated image is a failure of its setting with a reason, never silent bad data.
//!
//! The numbers come from the premultiplied linear RGBA mean the accumulator already
//! holds, so QA costs one pass over one frame and sees exactly what gets encoded.
//! A contact sheet's thumbnails (8-bit RGB over the background) get the same kind of
//! numbers from their codes ([`thumbnail_qa`]).
use super::color::{luma, srgb_encode_u8};
use super::exr::read::read_exr;
use super::CH;
use crate::error::{Error, Result};
use serde::{Deserialize, Serialize};

/// A pixel counts as covered by the object from this alpha on.
const COVERED_ALPHA: f32 = 0.5;

/// What one view looks like, in numbers.
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
pub struct FrameQa {
    /// Mean alpha: the fraction of the image the object covers.
    pub coverage: f64,
    /// Mean unpremultiplied luminance of the object (Σ premultiplied Y / Σ alpha).
    pub luminance: f64,
    /// Fraction of covered pixels with a colour channel at or above 1 (clipped in sRGB).
    pub saturated: f64,
    /// Fraction of the image's border pixels the object covers (0 when it is framed).
    pub border_coverage: f64,
}

/// When a view fails (the object QA at load time uses the same numbers).
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct QaThresholds {
    pub min_coverage: f64,
    pub min_luminance: f64,
    pub max_saturated: f64,
}

impl Default for QaThresholds {
    fn default() -> Self {
        QaThresholds {
            min_coverage: 0.002,
            min_luminance: 0.003,
            max_saturated: 0.5,
        }
    }
}

impl QaThresholds {
    /// The reason a view fails, or None when it passes.
    pub fn verdict(&self, qa: &FrameQa) -> Option<String> {
        if qa.coverage.is_nan() || qa.coverage < self.min_coverage {
            return Some(format!(
                "empty: the object covers {:.4} of the image (object out of frame or invisible; minimum {})",
                qa.coverage, self.min_coverage
            ));
        }
        if qa.luminance.is_nan() || qa.luminance < self.min_luminance {
            return Some(format!(
                "black: mean luminance of the object {:.5} (minimum {})",
                qa.luminance, self.min_luminance
            ));
        }
        if qa.saturated.is_nan() || qa.saturated > self.max_saturated {
            return Some(format!(
                "saturated: {:.0}% of the object's pixels are clipped (maximum {:.0}%)",
                100.0 * qa.saturated,
                100.0 * self.max_saturated
            ));
        }
        None
    }
}

/// [`frame_qa`] of an EXR (a load-time QA view): read and judged in the core.
pub fn exr_qa(path: &std::path::Path) -> Result<FrameQa> {
    let f = read_exr(path)?;
    frame_qa(f.width, f.height, &f.rgba)
}

/// QA numbers of a premultiplied linear RGBA image (row-major, 4 f32 per pixel).
pub fn frame_qa(width: u32, height: u32, rgba: &[f32]) -> Result<FrameQa> {
    let (w, h) = (width as usize, height as usize);
    if w == 0 || h == 0 || rgba.len() != w * h * CH {
        return Err(Error::Shape(format!(
            "QA needs a {width}x{height} RGBA image ({} values), got {}",
            w * h * CH,
            rgba.len()
        )));
    }
    let (mut alpha, mut y, mut covered, mut clipped) = (0.0f64, 0.0f64, 0u64, 0u64);
    for p in rgba.chunks_exact(CH) {
        let a = f64::from(p[3]);
        alpha += a;
        y += luma([p[0], p[1], p[2]].map(f64::from));
        if p[3] >= COVERED_ALPHA {
            covered += 1;
            // Unpremultiplied colour ≥ 1 ⇔ premultiplied ≥ alpha.
            if p[..3].iter().any(|&c| c >= p[3]) {
                clipped += 1;
            }
        }
    }
    let mut border = 0u64;
    let mut border_px = 0u64;
    for y in 0..h {
        for x in 0..w {
            if y == 0 || y == h - 1 || x == 0 || x == w - 1 {
                border_px += 1;
                if rgba[(y * w + x) * CH + 3] >= COVERED_ALPHA {
                    border += 1;
                }
            }
        }
    }
    let n = (w * h) as f64;
    Ok(FrameQa {
        coverage: alpha / n,
        luminance: if alpha > 0.0 { y / alpha } else { 0.0 },
        saturated: if covered > 0 {
            clipped as f64 / covered as f64
        } else {
            0.0
        },
        border_coverage: border as f64 / border_px as f64,
    })
}

/// Load-time QA of an object (a black or invisible object must not ship): the worker
/// renders these tiny, cheap views from opposite sides; the driver judges them here.
pub mod object {
    use super::{FrameQa, QaThresholds};
    use crate::plan::camera::bounding_radius;
    use crate::plan::camera::orbit_c2w;

    pub const RESOLUTION: u32 = 48;
    pub const SAMPLES: u32 = 4;
    pub const FOV_DEG: f64 = 40.0;
    /// Camera distance = margin · bounding-sphere radius / sin(fov / 2).
    const MARGIN: f64 = 1.05;
    /// (φ, θ) of the views, degrees: from above, on opposite sides.
    const VIEWS: [(f64, f64); 2] = [(60.0, 45.0), (60.0, 225.0)];

    /// OpenGL camera-to-world (row-major) of each QA view of an object of this box.
    pub fn cameras(bbox_dims: [f64; 3]) -> Vec<[[f64; 4]; 4]> {
        let r = MARGIN * bounding_radius(bbox_dims) / libm::sin(0.5 * FOV_DEG.to_radians());
        VIEWS
            .iter()
            .map(|&(phi, theta)| orbit_c2w(r, phi, theta).transpose().to_cols_array_2d())
            .collect()
    }

    /// The reason an object fails, or None: it fails when no view sees it (coverage) or
    /// when it is black in every view (luminance), under the frame thresholds.
    pub fn verdict(views: &[FrameQa], t: &QaThresholds) -> Option<String> {
        let best = |f: fn(&FrameQa) -> f64| {
            views
                .iter()
                .map(f)
                .filter(|x| !x.is_nan())
                .fold(0.0, f64::max)
        };
        let (cov, lum) = (best(|q| q.coverage), best(|q| q.luminance));
        if cov < t.min_coverage {
            return Some(format!(
                "render QA: object is invisible (alpha coverage {cov:.4} of the image)"
            ));
        }
        if lum < t.min_luminance {
            return Some(format!(
                "render QA: object renders black (mean luminance {lum:.5})"
            ));
        }
        None
    }
}

/// What a contact sheet says about one sharp thumbnail (8-bit RGB over a background).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ThumbnailQa {
    /// Fraction of pixels that differ from the background by more than `tolerance` codes.
    pub coverage: f64,
    /// Mean Rec. 709 luma (codes / 255) of those object pixels; 0 when there are none.
    pub object_luma: f64,
    /// Fraction of the one-pixel frame border covered by the object.
    pub border: f64,
}

/// Codes an object pixel must differ from the background by (any channel).
pub const QA_TOLERANCE: u8 = 8;

/// Coverage, object brightness and border contact of an RGB8 image whose background is
/// `background` (linear RGB, encoded to sRGB codes as the build's PNGs are).
pub fn thumbnail_qa(
    width: u32,
    height: u32,
    rgb: &[u8],
    background: [f64; 3],
) -> Result<ThumbnailQa> {
    let (w, h) = (width as usize, height as usize);
    if rgb.len() != w * h * 3 || w == 0 || h == 0 {
        return Err(Error::Shape(format!(
            "{} values for a {width} x {height} RGB8 image",
            rgb.len()
        )));
    }
    let bg = background.map(srgb_encode_u8);
    let is_object = |p: usize| (0..3).any(|c| rgb[p * 3 + c].abs_diff(bg[c]) > QA_TOLERANCE);
    let (mut count, mut sum) = (0usize, 0.0f64);
    for p in 0..w * h {
        if is_object(p) {
            count += 1;
            let [r, g, b] = [0, 1, 2].map(|c| f64::from(rgb[p * 3 + c]) / 255.0);
            sum += luma([r, g, b]);
        }
    }
    let border: Vec<usize> = (0..w)
        .flat_map(|x| [x, (h - 1) * w + x])
        .chain((1..h.saturating_sub(1)).flat_map(|y| [y * w, y * w + w - 1]))
        .collect();
    let touching = border.iter().filter(|&&p| is_object(p)).count();
    Ok(ThumbnailQa {
        coverage: count as f64 / (w * h) as f64,
        object_luma: if count > 0 { sum / count as f64 } else { 0.0 },
        border: touching as f64 / border.len().max(1) as f64,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn image(w: usize, h: usize, f: impl Fn(usize, usize) -> [f32; 4]) -> Vec<f32> {
        (0..h)
            .flat_map(|y| (0..w).flat_map(move |x| (0..1).map(move |_| (x, y))))
            .flat_map(|(x, y)| f(x, y))
            .collect()
    }

    /// A grey disc of radius r (pixels) in the middle of a w × w image.
    fn disc(w: usize, r: f64, grey: f32) -> Vec<f32> {
        image(w, w, |x, y| {
            let c = (w as f64 - 1.0) / 2.0;
            let d = ((x as f64 - c).powi(2) + (y as f64 - c).powi(2)).sqrt();
            if d <= r {
                [grey, grey, grey, 1.0]
            } else {
                [0.0; 4]
            }
        })
    }

    #[test]
    fn a_framed_grey_object_passes() -> Result<()> {
        let qa = frame_qa(64, 64, &disc(64, 20.0, 0.3))?;
        assert!((qa.coverage - std::f64::consts::PI * 400.0 / 4096.0).abs() < 0.01);
        assert!((qa.luminance - 0.3).abs() < 1e-6);
        assert_eq!(qa.saturated, 0.0);
        assert_eq!(qa.border_coverage, 0.0);
        assert_eq!(QaThresholds::default().verdict(&qa), None);
        Ok(())
    }

    #[test]
    fn empty_black_and_saturated_fail_with_their_reason() -> Result<()> {
        let t = QaThresholds::default();
        let empty = frame_qa(32, 32, &vec![0.0; 32 * 32 * 4])?;
        assert_eq!((empty.coverage, empty.luminance), (0.0, 0.0));
        assert!(t.verdict(&empty).is_some_and(|r| r.starts_with("empty")));
        let black = frame_qa(32, 32, &disc(32, 10.0, 0.0))?;
        assert!(t.verdict(&black).is_some_and(|r| r.starts_with("black")));
        let white = frame_qa(32, 32, &disc(32, 10.0, 1.5))?;
        assert_eq!(white.saturated, 1.0);
        assert!(t
            .verdict(&white)
            .is_some_and(|r| r.starts_with("saturated")));
        Ok(())
    }

    #[test]
    fn an_object_over_the_whole_frame_touches_the_border() -> Result<()> {
        let qa = frame_qa(16, 8, &image(16, 8, |_, _| [0.2, 0.2, 0.2, 1.0]))?;
        assert_eq!(qa.border_coverage, 1.0);
        assert_eq!(qa.coverage, 1.0);
        Ok(())
    }

    #[test]
    fn nan_never_passes_and_bad_shapes_are_errors() -> Result<()> {
        let mut img = disc(16, 5.0, 0.5);
        img[3] = f32::NAN;
        let qa = frame_qa(16, 16, &img)?;
        assert!(QaThresholds::default().verdict(&qa).is_some());
        assert!(frame_qa(16, 16, &img[..10]).is_err());
        assert!(frame_qa(0, 16, &[]).is_err());
        Ok(())
    }

    #[test]
    fn object_qa_cameras_frame_the_box_and_judge_the_best_view() -> Result<()> {
        let cams = object::cameras([1.0, 0.5, 0.25]);
        assert_eq!(cams.len(), 2);
        for c in &cams {
            let eye = glam::DVec3::new(c[0][3], c[1][3], c[2][3]);
            let fwd = -glam::DVec3::new(c[0][2], c[1][2], c[2][2]);
            assert!(
                (fwd.dot(-eye.normalize()) - 1.0).abs() < 1e-12,
                "looks at the centre"
            );
            assert!(eye.z > 0.0);
        }
        let t = QaThresholds::default();
        let seen = frame_qa(32, 32, &disc(32, 10.0, 0.3))?;
        let empty = frame_qa(32, 32, &vec![0.0; 32 * 32 * 4])?;
        assert_eq!(object::verdict(&[empty, seen], &t), None);
        let invisible = object::verdict(&[empty, empty], &t).unwrap_or_default();
        assert!(invisible.starts_with("render QA: object is invisible"));
        let black = frame_qa(32, 32, &disc(32, 10.0, 0.0))?;
        let v = object::verdict(&[black, empty], &t).unwrap_or_default();
        assert!(v.starts_with("render QA: object renders black"), "{v}");
        Ok(())
    }

    #[test]
    fn qa_sees_empty_black_and_clipped() -> Result<()> {
        let (w, h) = (20u32, 10u32);
        let white = vec![255u8; (w * h * 3) as usize];
        let qa = thumbnail_qa(w, h, &white, [1.0; 3])?;
        assert_eq!((qa.coverage, qa.border), (0.0, 0.0));
        let mut img = white.clone();
        // A black 4 x 4 square inside, then one touching the left edge.
        for y in 3..7 {
            for x in 8..12 {
                img[(y * w as usize + x) * 3..][..3].fill(0);
            }
        }
        let qa = thumbnail_qa(w, h, &img, [1.0; 3])?;
        assert!((qa.coverage - 16.0 / 200.0).abs() < 1e-12);
        assert_eq!((qa.object_luma, qa.border), (0.0, 0.0));
        for y in 0..h as usize {
            img[y * w as usize * 3..][..3].fill(128);
        }
        let qa = thumbnail_qa(w, h, &img, [1.0; 3])?;
        // 10 left-column pixels of the 56 border pixels (2·20 + 2·8).
        assert!((qa.border - 10.0 / 56.0).abs() < 1e-12, "{}", qa.border);
        assert!(thumbnail_qa(w, h, &img[1..], [1.0; 3]).is_err());
        Ok(())
    }
}
