//! What a view shows besides colour (issue 35): the depth of its first surface along the
//! camera's viewing axis (the meaning of `poses_bounds.npy`'s near and far), that
//! surface's normal in world space, and the object's mask from the sharp image's
//! coverage. Depth and normals come from one Cycles data-pass render per view (one
//! sample at the pixel centre, so a pixel's depth is the surface its centre sees, never
//! a blend of an edge's two sides); the mask from the sharp image itself.
use super::exr::passes::{decode_named, PassSpec};
use super::exr::write::write_encoded;
use super::io::{read_image, Samples};
use super::resample::check_factor;
use super::{covers, CH};
use crate::error::{Error, Result};
use crate::ground::atomic::write_atomic;
use crate::plan::choices::BlurMethod;
use std::io::Cursor;
use std::path::Path;

/// The passes of a geometry render (Cycles' names in Blender's multi-layer EXR).
const GEOMETRY: [PassSpec; 2] = [("Depth", "Z"), ("Normal", "XYZ")];

/// Cycles writes 1e10 as the depth of a ray that hits nothing; anything this far is a miss.
const MISS: f32 = 1e9;

/// The channel a depth EXR stores its one value in: `Y`, the one-channel (luminance)
/// name every reader takes as a grey float image (OpenCV reads a lone `Z` as zeros).
pub const DEPTH_CHANNEL: &str = "Y";

/// Where no surface is seen (the background): depth 0, normal (0, 0, 0), mask 0.
pub const NO_SURFACE: f32 = 0.0;

/// One view's geometry: per pixel, rows from the top, depth (1 value) and the unit
/// world-space normal (3 values); both [`NO_SURFACE`] where the pixel sees no surface.
#[derive(Clone, Debug, PartialEq)]
pub struct Geometry {
    pub width: usize,
    pub height: usize,
    pub depth: Vec<f32>,
    pub normal: Vec<f32>,
}

/// Decode a geometry render (a multi-layer EXR with Cycles' Depth and Normal passes).
pub fn read_geometry(path: &Path) -> Result<Geometry> {
    let bytes = std::fs::read(path).map_err(|e| Error::io("cannot read", path, e))?;
    let d = decode_named(&bytes, path, &GEOMETRY)?;
    for ((_, seen), (name, _)) in d.passes.iter().zip(GEOMETRY) {
        if !seen.iter().all(|&s| s) {
            return Err(Error::Image {
                reason: format!("no {name} pass: not a geometry render"),
                path: path.to_path_buf(),
            });
        }
    }
    let mut passes = d.passes.into_iter().map(|(b, _)| b);
    let (mut depth, mut normal) = (
        passes.next().unwrap_or_default(),
        passes.next().unwrap_or_default(),
    );
    for (z, n) in depth.iter_mut().zip(normal.chunks_exact_mut(3)) {
        if !(z.is_finite() && *z > 0.0 && *z < MISS) {
            *z = NO_SURFACE;
            n.fill(NO_SURFACE);
        }
    }
    Ok(Geometry {
        width: d.width,
        height: d.height,
        depth,
        normal,
    })
}

/// A float EXR of `channels` (names, in the order `data` interleaves them), ZIP
/// compressed and written block by block in order (the same bytes every time).
fn float_exr(path: &Path, width: usize, height: usize, names: &[&str], data: &[f32]) -> Result<()> {
    use exr::prelude::{AnyChannel, AnyChannels, Encoding, FlatSamples, Image, Layer};
    use exr::prelude::{LayerAttributes, WritableImage};
    let n = names.len();
    if width == 0 || height == 0 || data.len() != width * height * n {
        return Err(Error::Shape(format!(
            "{} floats for a {width} x {height} image of {n} channels",
            data.len()
        )));
    }
    let channels = names
        .iter()
        .enumerate()
        .map(|(c, name)| {
            let plane: Vec<f32> = data.iter().skip(c).step_by(n).copied().collect();
            AnyChannel::new(*name, FlatSamples::F32(plane))
        })
        .collect();
    let layer = Layer::new(
        (width, height),
        LayerAttributes::default(),
        Encoding::SMALL_LOSSLESS,
        AnyChannels::sort(channels),
    );
    write_encoded(path, |buf| {
        Image::from_layer(layer)
            .write()
            .non_parallel()
            .to_buffered(buf)
    })
}

/// The depth EXR of a view: one float channel ([`DEPTH_CHANNEL`]) in world units.
pub fn write_depth_exr(path: &Path, g: &Geometry) -> Result<()> {
    float_exr(path, g.width, g.height, &[DEPTH_CHANNEL], &g.depth)
}

/// The normal EXR of a view: the world-space normal's x, y, z in R, G, B (the channel
/// names every EXR reader shows as an image).
pub fn write_normal_exr(path: &Path, g: &Geometry) -> Result<()> {
    float_exr(path, g.width, g.height, &["R", "G", "B"], &g.normal)
}

/// A geometry render's depth and normal files (either may be skipped): the one step
/// from a render of Cycles' data passes to what a build keeps.
pub fn write_geometry(render: &Path, depth: Option<&Path>, normal: Option<&Path>) -> Result<()> {
    let g = read_geometry(render)?;
    if let Some(p) = depth {
        write_depth_exr(p, &g)?;
    }
    if let Some(p) = normal {
        write_normal_exr(p, &g)?;
    }
    Ok(())
}

/// Read a depth EXR back: (width, height, depth); a file that must be `want` (width,
/// height) when given, of another size, is refused from its header before any decode.
pub fn read_depth_exr_sized(
    path: &Path,
    want: Option<(u32, u32)>,
) -> Result<(usize, usize, Vec<f32>)> {
    if let Some(want) = want {
        crate::image::exr::read::check_exr_size(path, want)?;
    }
    let bytes = std::fs::read(path).map_err(|e| Error::io("cannot read", path, e))?;
    decode_depth_exr(&bytes, path)
}

/// A depth EXR held in memory (`path` names it in errors): (width, height, depth).
pub fn decode_depth_exr(bytes: &[u8], path: &Path) -> Result<(usize, usize, Vec<f32>)> {
    // A one-layer file's plain channel names count as the combined pass's.
    let spec: [PassSpec; 1] = [("Combined", DEPTH_CHANNEL)];
    let d = decode_named(bytes, path, &spec)?;
    let (depth, seen) = d.passes.into_iter().next().unwrap_or_default();
    if !seen.first().copied().unwrap_or(false) {
        return Err(Error::Image {
            reason: format!("no {DEPTH_CHANNEL} channel: not a depth EXR"),
            path: path.to_path_buf(),
        });
    }
    Ok((d.width, d.height, depth))
}

/// The object mask of an image from its coverage (premultiplied RGBA, `width` wide),
/// area-averaged over `factor` × `factor` blocks (1: none): 255 where at least half of a
/// pixel is covered, else 0. A binary mask is what the loaders that read masks take
/// (nerfstudio reads any non-zero value as "use this pixel").
pub fn mask_from_coverage(rgba: &[f32], width: u32, height: u32, factor: u32) -> Result<Vec<u8>> {
    super::check_rgba_len(width, height, rgba.len())?;
    half_covered(width, height, factor, |i| f64::from(rgba[i * CH + 3]))
}

/// The mask of a blurry image from `covered`, per pixel the largest alpha any render of
/// it had (`Accumulator` keeps it beside the mean), area-averaged over `factor` blocks
/// as [`mask_from_coverage`] does. What one render is decides which pixels the exposure
/// covered (issue 48):
/// - `Average`: one latent frame, so a pixel is in when at least one frame covers at
///   least half of it (the union of the frames' alpha ≥ 0.5, the sharp image's rule
///   applied to each instant rendered);
/// - `MotionBlur`: the whole exposure, averaged over time by Cycles: the union of its
///   instants is not observable from that mean (a thin part crossing a pixel for a
///   moment leaves a small alpha), so every pixel the render saw the object in at all
///   (alpha above Cycles' rounding, [`super::COVERAGE_EPS`]) is in, the smallest rule
///   that never drops a pixel an instant covered.
pub fn exposure_mask(
    covered: &[f32],
    width: u32,
    height: u32,
    factor: u32,
    method: BlurMethod,
) -> Result<Vec<u8>> {
    if covered.len() != width as usize * height as usize {
        return Err(Error::Shape(format!(
            "{} coverage values for a {width}x{height} image",
            covered.len()
        )));
    }
    match method {
        BlurMethod::Average => half_covered(width, height, factor, |i| f64::from(covered[i])),
        BlurMethod::MotionBlur => half_covered(width, height, factor, |i| {
            if covers(covered[i]) {
                1.0
            } else {
                0.0
            }
        }),
        BlurMethod::Auto => Err(Error::Value(
            "an exposure mask is made by the method its image was rendered by (its level's \
             `method`), not auto"
                .into(),
        )),
    }
}

/// 255 where the mean of `alpha(pixel index)` over a `factor` × `factor` block is at
/// least one half, else 0: the one rule of every mask.
fn half_covered(
    width: u32,
    height: u32,
    factor: u32,
    alpha: impl Fn(usize) -> f64,
) -> Result<Vec<u8>> {
    check_factor(width, height, factor)?;
    let (w, f) = (width as usize, factor as usize);
    let (ow, oh) = (w / f, height as usize / f);
    let area = (f * f) as f64;
    Ok((0..oh * ow)
        .map(|i| {
            let (oy, ox) = (i / ow, i % ow);
            let sum: f64 = (0..f * f)
                .map(|k| alpha((oy * f + k / f) * w + ox * f + k % f))
                .sum();
            if sum / area >= 0.5 {
                255
            } else {
                0
            }
        })
        .collect())
}

/// `mask` with every pixel of the mask PNG at `other` added (the sharp image's mask of
/// the same view and size: the object at the written pose p, which is an instant of
/// every exposure, `plan/sampling.rs`); the file must be a mask of the same size.
pub fn add_mask_file(mask: &mut [u8], width: u32, height: u32, other: &Path) -> Result<()> {
    let img = read_image(other)?;
    let bad = |reason: String| Error::Image {
        reason,
        path: other.to_path_buf(),
    };
    if (img.width, img.height) != (width, height) || img.channels != 1 {
        return Err(bad(format!(
            "a {}x{} image of {} channels, not a {width}x{height} mask",
            img.width, img.height, img.channels
        )));
    }
    let Samples::U8(px) = &img.samples else {
        return Err(bad("not an 8-bit mask".into()));
    };
    if px.len() != mask.len() {
        return Err(bad(format!("{} pixels, {} expected", px.len(), mask.len())));
    }
    for (m, &o) in mask.iter_mut().zip(px) {
        if o > 0 {
            *m = 255;
        }
    }
    Ok(())
}

/// An 8-bit single-channel ("L") PNG, written atomically.
pub fn write_gray8_png(path: &Path, width: u32, height: u32, data: &[u8]) -> Result<()> {
    let img = image::GrayImage::from_raw(width, height, data.to_vec())
        .ok_or_else(|| Error::Shape(format!("{} bytes for a {width}x{height} mask", data.len())))?;
    encode_png(path, &image::DynamicImage::ImageLuma8(img))
}

/// Depth in millimetres as 16-bit integers, 0 where no surface is seen: what
/// nerfstudio's depth loader reads by default (`depth_unit_scale_factor` 1e-3). A depth
/// past 65.535 units has no 16-bit millimetre value: refused, not clipped.
pub fn depth_millimetres(depth: &[f32]) -> Result<Vec<u16>> {
    depth
        .iter()
        .map(|&z| {
            let mm = (f64::from(z) * 1000.0).round();
            if !(0.0..=f64::from(u16::MAX)).contains(&mm) {
                return Err(Error::Value(format!(
                    "depth {z} has no 16-bit millimetre value (0 to 65.535 units)"
                )));
            }
            // A surface closer than half a millimetre is not "no surface".
            Ok(if z > 0.0 { (mm as u16).max(1) } else { 0 })
        })
        .collect()
}

/// A depth EXR as the 16-bit millimetre PNG nerfstudio reads ([`depth_millimetres`]).
pub fn write_depth_millimetres(depth_exr: &Path, png: &Path) -> Result<()> {
    let (w, h, depth) = read_depth_exr_sized(depth_exr, None)?;
    let mm = depth_millimetres(&depth).map_err(|e| Error::Image {
        reason: e.to_string(),
        path: depth_exr.to_path_buf(),
    })?;
    write_gray16_png(png, w as u32, h as u32, &mm)
}

/// A 16-bit single-channel PNG, written atomically.
pub fn write_gray16_png(path: &Path, width: u32, height: u32, data: &[u16]) -> Result<()> {
    let img =
        image::ImageBuffer::<image::Luma<u16>, Vec<u16>>::from_raw(width, height, data.to_vec())
            .ok_or_else(|| {
                Error::Shape(format!(
                    "{} values for a {width}x{height} image",
                    data.len()
                ))
            })?;
    encode_png(path, &image::DynamicImage::ImageLuma16(img))
}

fn encode_png(path: &Path, img: &image::DynamicImage) -> Result<()> {
    let mut buf = Cursor::new(Vec::new());
    img.write_to(&mut buf, image::ImageFormat::Png)
        .map_err(|e| Error::Image {
            reason: format!("cannot encode PNG: {e}"),
            path: path.to_path_buf(),
        })?;
    write_atomic(path, buf.get_ref())
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // a failing unwrap is a failing test
mod tests {
    use super::*;

    fn tmp(name: &str) -> std::path::PathBuf {
        std::env::temp_dir().join(format!("blurset-geom-{}-{name}", std::process::id()))
    }

    #[test]
    fn depth_and_normals_round_trip_through_their_exrs() -> Result<()> {
        let g = Geometry {
            width: 3,
            height: 2,
            depth: vec![1.5, 0.0, 2.25, 3.0, 1e-3, 40.0],
            normal: (0..18).map(|i| i as f32 / 17.0).collect(),
        };
        let (d, n) = (tmp("d.exr"), tmp("n.exr"));
        write_depth_exr(&d, &g)?;
        write_normal_exr(&n, &g)?;
        assert_eq!(read_depth_exr_sized(&d, None)?, (3, 2, g.depth.clone()));
        let first = std::fs::read(&d).map_err(|e| Error::io("read", &d, e))?;
        write_depth_exr(&d, &g)?;
        assert_eq!(
            std::fs::read(&d).map_err(|e| Error::io("read", &d, e))?,
            first
        );
        // The normal file is an RGB image holding x, y, z.
        let bytes = std::fs::read(&n).map_err(|e| Error::io("read", &n, e))?;
        let rgb = decode_named(&bytes, &n, &[("Combined", "RGB")])?;
        assert_eq!(rgb.passes[0].0, g.normal);
        // A depth file is not a colour image, nor a colour image a depth file.
        assert!(read_depth_exr_sized(&n, None).is_err());
        for p in [d, n] {
            let _ = std::fs::remove_file(p);
        }
        Ok(())
    }

    #[test]
    fn a_pixel_that_sees_no_surface_has_depth_and_normal_zero() -> Result<()> {
        // A geometry render as Cycles writes it: the miss depth (1e10), an infinite or
        // NaN depth, and a normal that is not zero on every pixel (Cycles leaves what it
        // likes in a missed pixel's normal).
        let depth = [2.5f32, 1e10, f32::INFINITY, f32::NAN, 0.0, 3.0];
        let normal: Vec<f32> = (0..18).map(|i| 0.1 + i as f32 / 20.0).collect();
        let interleaved: Vec<f32> = depth
            .iter()
            .zip(normal.chunks_exact(3))
            .flat_map(|(z, n)| [*z, n[0], n[1], n[2]])
            .collect();
        let p = tmp("render.exr");
        let names = [
            "ViewLayer.Depth.Z",
            "ViewLayer.Normal.X",
            "ViewLayer.Normal.Y",
            "ViewLayer.Normal.Z",
        ];
        float_exr(&p, 3, 2, &names, &interleaved)?;
        let g = read_geometry(&p)?;
        let _ = std::fs::remove_file(&p);
        assert_eq!(g.depth, [2.5, 0.0, 0.0, 0.0, 0.0, 3.0]);
        for (i, n) in g.normal.chunks_exact(3).enumerate() {
            if g.depth[i] == NO_SURFACE {
                assert_eq!(n, [NO_SURFACE; 3], "pixel {i}");
            } else {
                assert_eq!(n, &normal[i * 3..i * 3 + 3], "pixel {i}");
            }
        }
        Ok(())
    }

    #[test]
    fn a_mask_is_half_coverage_or_more_at_every_size() -> Result<()> {
        // 4 x 2 pixels, alpha 0, 0.49, 0.5, 1 / 1, 1, 0, 0.
        let alpha = [0.0f32, 0.49, 0.5, 1.0, 1.0, 1.0, 0.0, 0.0];
        let rgba: Vec<f32> = alpha.iter().flat_map(|&a| [a, a, a, a]).collect();
        assert_eq!(
            mask_from_coverage(&rgba, 4, 2, 1)?,
            [0, 0, 255, 255, 255, 255, 0, 0]
        );
        // 2 x 2 blocks: (0 + 0.49 + 1 + 1) / 4 = 0.62, (0.5 + 1 + 0 + 0) / 4 = 0.375.
        assert_eq!(mask_from_coverage(&rgba, 4, 2, 2)?, [255, 0]);
        assert!(mask_from_coverage(&rgba, 4, 2, 3).is_err());
        assert!(mask_from_coverage(&rgba[..4], 4, 2, 1).is_err());
        Ok(())
    }

    #[test]
    fn an_exposure_mask_at_a_size_averages_the_largest_alpha_or_any_cover() -> Result<()> {
        // 4 x 2 pixels' largest alpha over the frames: 2 x 2 blocks average 0.6 and 0.25;
        // with motion blur every pixel but two is touched at all (4 and 2 of 4 a block).
        let covered = [0.6f32, 0.8, 0.0, 0.6, 0.2, 0.8, 0.0, 0.4];
        assert_eq!(
            exposure_mask(&covered, 4, 2, 2, BlurMethod::Average)?,
            [255, 0]
        );
        assert_eq!(
            exposure_mask(&covered, 4, 2, 2, BlurMethod::MotionBlur)?,
            [255, 255]
        );
        assert_eq!(
            exposure_mask(&covered, 4, 2, 1, BlurMethod::MotionBlur)?,
            [255, 255, 0, 255, 255, 255, 0, 255]
        );
        assert_eq!(
            exposure_mask(&covered, 4, 2, 1, BlurMethod::Average)?,
            [255, 255, 0, 255, 0, 255, 0, 0]
        );
        // Cycles' rounding over a background (1.6e-8, measured) is no exposure; one
        // sample's hit in 65,536 is.
        let fuzz = [
            1.6e-8f32,
            1.6e-8,
            1.0 / 65_536.0,
            0.0,
            1.6e-8,
            1.6e-8,
            1.6e-8,
            1.6e-8,
        ];
        assert_eq!(
            exposure_mask(&fuzz, 4, 2, 1, BlurMethod::MotionBlur)?,
            [0, 0, 255, 0, 0, 0, 0, 0]
        );
        assert!(exposure_mask(&covered[..7], 4, 2, 1, BlurMethod::Average).is_err());
        assert!(exposure_mask(&covered, 4, 2, 3, BlurMethod::Average).is_err());
        Ok(())
    }

    #[test]
    fn millimetres_keep_zero_for_no_surface_and_refuse_what_does_not_fit() -> Result<()> {
        assert_eq!(
            depth_millimetres(&[0.0, 2.0, 1.23456, 1e-4, 65.535])?,
            [0, 2000, 1235, 1, 65535]
        );
        assert!(depth_millimetres(&[65.6]).is_err());
        assert!(depth_millimetres(&[f32::NAN]).is_err());
        assert!(depth_millimetres(&[-1.0]).is_err());
        let p = tmp("mm.png");
        write_gray16_png(&p, 2, 1, &[0, 2000])?;
        let img = image::open(&p).map_err(|e| Error::Value(e.to_string()))?;
        assert_eq!(
            img.as_luma16().map(|i| i.as_raw().clone()),
            Some(vec![0, 2000])
        );
        let _ = std::fs::remove_file(p);
        Ok(())
    }
}
