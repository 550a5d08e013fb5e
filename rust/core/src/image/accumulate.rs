//! Streaming accumulation of linear latent frames and their display encoding.
//!
//! A blurry image is the mean of its m latent frames *in linear light* (DESIGN §2).
//! Frames arrive one at a time (from EXR files or from memory) and are summed into one
//! f64 accumulator, so memory is one frame plus the accumulator whatever m is. The
//! sharp image goes through the same path with one frame, so sharp and blurry images
//! share a single encoding: composite over a background (premultiplied alpha, §3),
//! sRGB-encode (IEC 61966-2-1), quantize to 8 bits.
use super::color::{composite_over, srgb_encode_u8};
use super::denoise::Denoiser;
use super::exr::passes::decode_passes;
use super::exr::read::{decode_rgba, first_non_finite, read_into};
use super::exr::write::write_exr;
use super::geometry::{add_mask_file, exposure_mask, mask_from_coverage, write_gray8_png};
use super::io::write_png_rgb8;
use super::qa::{frame_qa, FrameQa};
use super::resample::area_mean;
use super::{check_rgba_len, CH};
use crate::error::{Error, Result};
use crate::plan::choices::BlurMethod;
use rayon::prelude::*;
use std::path::Path;

fn encode_run(out: &mut [u8], pixels: impl Iterator<Item = [f64; 4]>, bg: [f64; 3]) {
    // Renders are mostly flat background: a value equal to the one before reuses its
    // code instead of another `pow` (same function, same result).
    let mut last = (f64::NAN.to_bits(), 0u8);
    let mut encode = |x: f64| {
        if x.to_bits() != last.0 {
            last = (x.to_bits(), srgb_encode_u8(x));
        }
        last.1
    };
    for (o, p) in out.chunks_exact_mut(3).zip(pixels) {
        let c = composite_over(p, bg);
        o[0] = encode(c[0]);
        o[1] = encode(c[1]);
        o[2] = encode(c[2]);
    }
}

/// `sum += frame · weight`; a weight of 1 adds the frame as it is (the same bits).
fn add_scaled(sum: &mut [f64], frame: &[f32], weight: f64) {
    if weight == 1.0 {
        for (s, &f) in sum.iter_mut().zip(frame) {
            *s += f64::from(f);
        }
    } else {
        for (s, &f) in sum.iter_mut().zip(frame) {
            *s += f64::from(f) * weight;
        }
    }
}

/// `covered[i] = max(covered[i], alpha of pixel i)` for the RGBA pixels of `rgba`.
fn cover(covered: &mut [f32], rgba: &[f32]) {
    for (c, p) in covered.iter_mut().zip(rgba.chunks_exact(CH)) {
        *c = c.max(p[3]);
    }
}

/// Running sum of linear RGBA frames of one size; the mean is the blurry image.
#[derive(Clone, Debug)]
pub struct Accumulator {
    width: u32,
    height: u32,
    // f64: the sum of hundreds of f32 frames keeps every f32 bit of their mean.
    sum: Vec<f64>,
    /// Per pixel, the largest alpha of any frame added: what the mean alone cannot say,
    /// whether some frame covered the pixel (a blurry image's mask, issue 48).
    covered: Vec<f32>,
    count: u32,
    /// The frames' weights summed (each frame 1 unless added with a weight: its samples,
    /// when rounds of one image render different counts per frame, `plan/target.rs`).
    weight: f64,
    /// The frame being added by `add_exr`, kept so its memory is reused.
    staging: Vec<f32>,
    /// The bytes of the EXR file being added, kept for the same reason.
    file: Vec<u8>,
    /// Sums of the denoising guides (albedo RGB, normal XYZ: 6 per pixel) when the image
    /// will be denoised (issue 28): averaged exactly as the colour is.
    guides: Option<Vec<f64>>,
    /// The mean was replaced by its denoised version: nothing more may be added.
    denoised: bool,
    /// The share of a whole image each frame is in the weight (its weight × share):
    /// 1, or 1/n for frames that are n bands tiling the image (a rolling shutter's,
    /// each pixel in one band), whose sum is then the image.
    share: f64,
}

/// Values per pixel of the guide sums: albedo RGB, then normal XYZ.
const GUIDES: usize = 6;

impl Accumulator {
    pub fn new(width: u32, height: u32) -> Self {
        Accumulator {
            width,
            height,
            sum: vec![0.0; width as usize * height as usize * CH],
            covered: vec![0.0; width as usize * height as usize],
            count: 0,
            weight: 0.0,
            staging: Vec::new(),
            file: Vec::new(),
            guides: None,
            denoised: false,
            share: 1.0,
        }
    }

    /// An accumulator that also averages the frames' denoising guides (Cycles' albedo and
    /// normal passes), for an image that [`Self::denoise`] finishes: its EXRs must hold
    /// them (multi-layer, see `exr::passes`).
    pub fn with_guides(width: u32, height: u32) -> Self {
        Accumulator {
            guides: Some(vec![0.0; width as usize * height as usize * GUIDES]),
            ..Accumulator::new(width, height)
        }
    }

    /// Whether this accumulator averages denoising guides.
    pub fn has_guides(&self) -> bool {
        self.guides.is_some()
    }

    /// Whether the mean has been denoised.
    pub fn is_denoised(&self) -> bool {
        self.denoised
    }

    pub fn width(&self) -> u32 {
        self.width
    }

    pub fn height(&self) -> u32 {
        self.height
    }

    /// Number of frames added so far.
    pub fn count(&self) -> u32 {
        self.count
    }

    /// Add one premultiplied linear RGBA frame (row-major, 4 f32 per pixel).
    ///
    /// A frame with a NaN or inf is refused whole, so the sum is never poisoned.
    pub fn add_frame(&mut self, rgba: &[f32]) -> Result<()> {
        self.check_open(false)?;
        check_rgba_len(self.width, self.height, rgba.len())?;
        if let Some((x, y, c, v)) = first_non_finite(self.width as usize, rgba) {
            return Err(Error::Value(format!(
                "frame has a non-finite value {v} at pixel ({x}, {y}) channel {}",
                "RGBA".as_bytes()[c] as char
            )));
        }
        self.add_unchecked(rgba);
        Ok(())
    }

    /// Read an RGBA f32 EXR (alpha 1 when absent) and add it; the file must match the
    /// accumulator size and hold only finite values.
    pub fn add_exr(&mut self, path: &Path) -> Result<()> {
        self.add_exr_at(path, None)
    }

    /// [`Self::add_exr`] for a render cropped to its region: with `origin` = (x0, y0), the
    /// file's pixel (0, 0) is the accumulator's pixel (x0, y0) (rows from the top), and
    /// it must fit inside; every pixel outside adds 0, which is what a full render holds
    /// there (plan/region.rs), so the sum is the same bit for bit. `None`: the file
    /// must be the accumulator's size.
    pub fn add_exr_at(&mut self, path: &Path, origin: Option<(u32, u32)>) -> Result<()> {
        self.add_exr_weighted(path, origin, 1.0)
    }

    /// [`Self::add_exr_at`] of a frame that counts `weight` times in the mean (a positive,
    /// finite number: the samples it rendered, where the frames of one image render
    /// different counts and each is weighted by its own).
    pub fn add_exr_weighted(
        &mut self,
        path: &Path,
        origin: Option<(u32, u32)>,
        weight: f64,
    ) -> Result<()> {
        if !(weight.is_finite() && weight > 0.0) {
            return Err(Error::Value(format!(
                "frame weight {weight}: must be a positive, finite number"
            )));
        }
        if self.guides.is_some() {
            return self.add_passes_at(path, origin, weight);
        }
        self.check_open(false)?;
        let mut file = std::mem::take(&mut self.file);
        let mut staging = std::mem::take(&mut self.staging);
        let res = read_into(path, &mut file).and_then(|()| {
            let d = decode_rgba(&file, path, &mut staging)?;
            let (w, h) = (self.width as usize, self.height as usize);
            let (x0, y0) = origin.map_or((0, 0), |(x, y)| (x as usize, y as usize));
            let fits = match origin {
                None => (d.width, d.height) == (w, h),
                Some(_) => x0 + d.width <= w && y0 + d.height <= h,
            };
            if !fits {
                let at = origin.map_or(String::new(), |o| format!(" at {o:?}"));
                return Err(Error::Shape(format!(
                    "EXR is {}x{}{at} but the accumulator is {}x{}: {path:?}",
                    d.width, d.height, self.width, self.height
                )));
            }
            if let Some((x, y, c, v)) = d.non_finite {
                return Err(Error::Image {
                    reason: format!(
                        "non-finite value {v} at pixel ({}, {}) channel {}; a render must not poison the average",
                        x0 + x,
                        y0 + y,
                        "RGBA".as_bytes()[c] as char
                    ),
                    path: path.to_path_buf(),
                });
            }
            self.add_tile_unchecked(&staging, d.width, x0, y0, weight);
            Ok(())
        });
        self.file = file;
        self.staging = staging;
        res
    }

    /// Refuse a frame once the mean is denoised, and one without guides when they are
    /// averaged (`with_guides`).
    fn check_open(&self, guides_given: bool) -> Result<()> {
        if self.denoised {
            return Err(Error::Value(
                "the image is already denoised; a frame can no longer be added".into(),
            ));
        }
        if self.guides.is_some() && !guides_given {
            return Err(Error::Value(
                "this accumulator averages denoising guides: add frames with their albedo \
                 and normal"
                    .into(),
            ));
        }
        Ok(())
    }

    /// Add one frame with its guides: RGBA (4 f32 per pixel), albedo and normal (3 f32
    /// per pixel each), all finite (an accumulator made `with_guides`).
    pub fn add_frame_with_guides(
        &mut self,
        rgba: &[f32],
        albedo: &[f32],
        normal: &[f32],
    ) -> Result<()> {
        self.check_open(true)?;
        if self.guides.is_none() {
            return Err(Error::Value(
                "this accumulator does not average guides (make it with guides)".into(),
            ));
        }
        check_rgba_len(self.width, self.height, rgba.len())?;
        let n = self.width as usize * self.height as usize * 3;
        for (what, v) in [("albedo", albedo), ("normal", normal)] {
            if v.len() != n {
                return Err(Error::Shape(format!(
                    "{what} has {} values, a {}x{} image needs {n}",
                    v.len(),
                    self.width,
                    self.height
                )));
            }
        }
        if let Some(v) = rgba
            .iter()
            .chain(albedo)
            .chain(normal)
            .find(|v| !v.is_finite())
        {
            return Err(Error::Value(format!(
                "frame or guide has a non-finite value {v}"
            )));
        }
        self.add_guides_tile(albedo, normal, self.width as usize, 0, 0, 1.0);
        self.add_unchecked(rgba);
        Ok(())
    }

    /// [`Self::add_exr_at`] of a render with its guide passes (multi-layer EXR).
    fn add_passes_at(
        &mut self,
        path: &Path,
        origin: Option<(u32, u32)>,
        weight: f64,
    ) -> Result<()> {
        self.check_open(true)?;
        let mut file = std::mem::take(&mut self.file);
        let res = read_into(path, &mut file).and_then(|()| decode_passes(&file, path));
        self.file = file;
        let p = res?;
        let (w, h) = (self.width as usize, self.height as usize);
        let (x0, y0) = origin.map_or((0, 0), |(x, y)| (x as usize, y as usize));
        let fits = match origin {
            None => (p.width, p.height) == (w, h),
            Some(_) => x0 + p.width <= w && y0 + p.height <= h,
        };
        if !fits {
            let at = origin.map_or(String::new(), |o| format!(" at {o:?}"));
            return Err(Error::Shape(format!(
                "EXR is {}x{}{at} but the accumulator is {}x{}: {path:?}",
                p.width, p.height, self.width, self.height
            )));
        }
        for (name, v, ch) in [
            ("RGBA", &p.rgba, 4usize),
            ("albedo RGB", &p.albedo, 3),
            ("normal XYZ", &p.normal, 3),
        ] {
            if let Some(i) = v.iter().position(|v| !v.is_finite()) {
                let px = i / ch;
                return Err(Error::Image {
                    reason: format!(
                        "non-finite value {} at pixel ({}, {}) of the {name} pass; a render \
                         must not poison the average",
                        v[i],
                        x0 + px % p.width.max(1),
                        y0 + px / p.width.max(1)
                    ),
                    path: path.to_path_buf(),
                });
            }
        }
        self.add_guides_tile(&p.albedo, &p.normal, p.width, x0, y0, weight);
        self.add_tile_unchecked(&p.rgba, p.width, x0, y0, weight);
        Ok(())
    }

    /// Add guide rows of `tile_width` pixels at (x0, y0); the caller checked that they fit.
    fn add_guides_tile(
        &mut self,
        albedo: &[f32],
        normal: &[f32],
        tile_width: usize,
        x0: usize,
        y0: usize,
        weight: f64,
    ) {
        let w = self.width as usize;
        let Some(g) = self.guides.as_mut() else {
            return;
        };
        if tile_width == 0 {
            return;
        }
        let rows = albedo.len() / (3 * tile_width);
        for y in 0..rows {
            for x in 0..tile_width {
                let (s, d) = (3 * (y * tile_width + x), GUIDES * ((y0 + y) * w + x0 + x));
                for c in 0..3 {
                    g[d + c] += f64::from(albedo[s + c]) * weight;
                    g[d + 3 + c] += f64::from(normal[s + c]) * weight;
                }
            }
        }
    }

    /// The means of the guides: (albedo RGB, normal XYZ), 3 f32 per pixel each.
    pub fn guide_means(&self) -> Result<(Vec<f32>, Vec<f32>)> {
        self.require_frames()?;
        let Some(g) = self.guides.as_ref() else {
            return Err(Error::Value(
                "this accumulator does not average guides (make it with guides)".into(),
            ));
        };
        let inv = 1.0 / self.weight;
        let (mut a, mut n) = (
            Vec::with_capacity(g.len() / 2),
            Vec::with_capacity(g.len() / 2),
        );
        for p in g.chunks_exact(GUIDES) {
            a.extend(p[..3].iter().map(|&v| (v * inv) as f32));
            n.extend(p[3..].iter().map(|&v| (v * inv) as f32));
        }
        Ok((a, n))
    }

    /// Denoise the image once, now that its frames are in: `denoiser` sees the mean
    /// colour (RGB of the premultiplied mean) with the mean albedo and normal, and its
    /// output replaces the mean's RGB; alpha stays the frames' mean (Cycles does not
    /// denoise alpha either). Every writer then writes the denoised image.
    pub fn denoise(&mut self, denoiser: &Denoiser) -> Result<()> {
        if self.denoised {
            return Ok(());
        }
        let (albedo, normal) = self.guide_means()?;
        let mean = self.mean()?;
        let color: Vec<f32> = mean
            .chunks_exact(CH)
            .flat_map(|p| [p[0], p[1], p[2]])
            .collect();
        let out = denoiser.denoise(self.width, self.height, &color, &albedo, &normal)?;
        let count = self.weight;
        // sum = value · count, exact in f64 (a 24-bit mantissa times a count < 2^29), so
        // the mean gives the denoiser's f32 back bit for bit.
        for (s, d) in self.sum.chunks_exact_mut(CH).zip(out.chunks_exact(3)) {
            for c in 0..3 {
                s[c] = f64::from(d[c]) * count;
            }
        }
        self.denoised = true;
        Ok(())
    }

    /// Add rows of `tile_width` pixels at (x0, y0); the caller checked that they fit.
    fn add_tile_unchecked(
        &mut self,
        rgba: &[f32],
        tile_width: usize,
        x0: usize,
        y0: usize,
        weight: f64,
    ) {
        if tile_width == self.width as usize {
            let start = y0 * tile_width * CH;
            return self.add_rows(start, rgba, weight);
        }
        let row = self.width as usize * CH;
        let tile_row = tile_width * CH;
        if tile_row == 0 {
            self.count_frame(weight);
            return;
        }
        self.sum[y0 * row..]
            .par_chunks_mut(row)
            .zip(rgba.par_chunks(tile_row))
            .for_each(|(s, f)| add_scaled(&mut s[x0 * CH..x0 * CH + tile_row], f, weight));
        // Outside the tile the frame's alpha is 0, which changes no maximum.
        self.covered[y0 * self.width as usize..]
            .par_chunks_mut(self.width as usize)
            .zip(rgba.par_chunks(tile_row))
            .for_each(|(c, f)| cover(&mut c[x0..x0 + tile_width], f));
        self.count_frame(weight);
    }

    fn add_unchecked(&mut self, rgba: &[f32]) {
        self.add_rows(0, rgba, 1.0);
    }

    /// Add whole rows starting at sum index `start`.
    fn add_rows(&mut self, start: usize, rgba: &[f32], weight: f64) {
        let row = (self.width as usize * CH).max(1);
        self.sum[start..start + rgba.len()]
            .par_chunks_mut(row)
            .zip(rgba.par_chunks(row))
            .for_each(|(s, f)| add_scaled(s, f, weight));
        let px = start / CH;
        cover(&mut self.covered[px..px + rgba.len() / CH], rgba);
        self.count_frame(weight);
    }

    fn count_frame(&mut self, weight: f64) {
        self.count += 1;
        self.weight += weight * self.share;
    }

    /// This accumulator with each frame counting `share` of a whole image in the mean
    /// (`Render::share`: 1/n for each of n bands that tile the image, so their sum is
    /// the image); 1 by default.
    pub fn with_share(mut self, share: f64) -> Self {
        if share.is_finite() && share > 0.0 {
            self.share = share;
        }
        self
    }

    /// Add the frames of `other` (same size, neither denoised nor with guides): the two
    /// halves of an image rendered to a target (`plan/target.rs`) become one image, each
    /// frame keeping its weight.
    pub fn merge(&mut self, other: &Accumulator) -> Result<()> {
        self.check_open(false)?;
        if (other.width, other.height) != (self.width, self.height) {
            return Err(Error::Shape(format!(
                "cannot merge a {}x{} image into a {}x{} one",
                other.width, other.height, self.width, self.height
            )));
        }
        if other.guides.is_some() || other.denoised {
            return Err(Error::Value(
                "only plain, undenoised accumulators merge".into(),
            ));
        }
        self.sum
            .par_iter_mut()
            .zip(other.sum.par_iter())
            .for_each(|(s, o)| *s += o);
        for (c, &o) in self.covered.iter_mut().zip(&other.covered) {
            *c = c.max(o);
        }
        self.count += other.count;
        self.weight += other.weight;
        Ok(())
    }

    fn require_frames(&self) -> Result<()> {
        if self.count == 0 {
            return Err(Error::Value(
                "the accumulator has no frames yet; add at least one before taking the mean".into(),
            ));
        }
        Ok(())
    }

    /// The mean of the frames added, premultiplied linear RGBA f32.
    pub fn mean(&self) -> Result<Vec<f32>> {
        self.require_frames()?;
        let inv = 1.0 / self.weight;
        Ok(self.sum.par_iter().map(|&s| (s * inv) as f32).collect())
    }

    /// Render QA of the mean ([`frame_qa`]): the pixels it judges never leave the core.
    pub fn qa(&self) -> Result<FrameQa> {
        frame_qa(self.width, self.height, &self.mean()?)
    }

    /// The mean composited over `background` (linear RGB), sRGB-encoded, as RGB8.
    pub fn encode_rgb8(&self, background: [f32; 3]) -> Result<Vec<u8>> {
        self.require_frames()?;
        let inv = 1.0 / self.weight;
        let bg = background.map(f64::from);
        let mut out = vec![0u8; self.sum.len() / CH * 3];
        let row = (self.width as usize).max(1);
        // Straight from the f64 sum: the PNG never sees the f32 rounding of the mean.
        out.par_chunks_mut(3 * row)
            .zip(self.sum.par_chunks(CH * row))
            .for_each(|(o, s)| {
                let px = s
                    .chunks_exact(CH)
                    .map(|p| [p[0] * inv, p[1] * inv, p[2] * inv, p[3] * inv]);
                encode_run(o, px, bg);
            });
        Ok(out)
    }

    /// The mean composited over `background` and clipped to the PNG's [0, 1] (as
    /// `images/` shows it), area-averaged over `factor × factor` blocks in linear light,
    /// then sRGB-encoded as RGB8 (LLFF's `images_<f>/`: `images/` downsampled, from the
    /// float image); factor 1 is [`Self::encode_rgb8`]. The factor must divide both sides.
    pub fn encode_rgb8_downsampled(&self, background: [f32; 3], factor: u32) -> Result<Vec<u8>> {
        if factor == 1 {
            return self.encode_rgb8(background);
        }
        self.require_frames()?;
        let inv = 1.0 / self.weight;
        let bg = background.map(f64::from);
        let rgb: Vec<f64> = self
            .sum
            .par_chunks_exact(CH)
            .flat_map_iter(|p| {
                composite_over([p[0] * inv, p[1] * inv, p[2] * inv, p[3] * inv], bg)
                    .map(|v| v.clamp(0.0, 1.0))
            })
            .collect();
        let small = area_mean(self.width, self.height, 3, &rgb, factor)?;
        Ok(small.par_iter().map(|&v| srgb_encode_u8(v)).collect())
    }

    /// Write the mean as an 8-bit sRGB PNG over `background` (linear RGB; white is [1, 1, 1]).
    pub fn write_png(&self, path: &Path, background: [f32; 3]) -> Result<()> {
        self.write_png_downsampled(path, background, 1)
    }

    /// [`Self::write_png`] of the image downsampled `factor` times (area, linear light).
    pub fn write_png_downsampled(
        &self,
        path: &Path,
        background: [f32; 3],
        factor: u32,
    ) -> Result<()> {
        let rgb = self.encode_rgb8_downsampled(background, factor)?;
        write_png_rgb8(path, self.width / factor, self.height / factor, &rgb)
    }

    /// Write the object mask of the mean (its coverage, area-averaged `factor` times:
    /// [`crate::image::geometry::mask_from_coverage`]) as an 8-bit PNG.
    pub fn write_mask(&self, path: &Path, factor: u32) -> Result<()> {
        let mask = mask_from_coverage(&self.mean()?, self.width, self.height, factor)?;
        write_gray8_png(path, self.width / factor, self.height / factor, &mask)
    }

    /// Per pixel, the largest alpha any frame added had (row-major).
    pub fn covered(&self) -> Result<&[f32]> {
        self.require_frames()?;
        Ok(&self.covered)
    }

    /// Write the mask of a blurry image (the pixels its exposure covered, area-averaged
    /// `factor` times: [`crate::image::geometry::exposure_mask`], each frame being one
    /// render of `method`) as an 8-bit PNG, with every pixel of the mask PNG `with`
    /// added (the sharp image's mask of the view at that size: the object at the written
    /// pose, an instant of the exposure).
    pub fn write_exposure_mask(
        &self,
        path: &Path,
        factor: u32,
        method: BlurMethod,
        with: Option<&Path>,
    ) -> Result<()> {
        let mut mask = exposure_mask(self.covered()?, self.width, self.height, factor, method)?;
        let (w, h) = (self.width / factor, self.height / factor);
        if let Some(other) = with {
            add_mask_file(&mut mask, w, h, other)?;
        }
        write_gray8_png(path, w, h, &mask)
    }

    /// Write the mean as a linear, premultiplied RGBA f32 EXR.
    pub fn write_exr(&self, path: &Path) -> Result<()> {
        let mean = self.mean()?;
        write_exr(path, self.width, self.height, &mean)
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // a failing unwrap is a failing test
mod tests {
    use super::*;
    use crate::ground::atomic::write_atomic;
    use crate::image::exr::read::read_exr;
    use crate::image::io::{read_image, Samples};
    use image::ImageEncoder;
    use proptest::prelude::*;
    use std::io::Cursor;
    use std::path::PathBuf;

    /// A test's own scratch folder, removed when its thread ends.
    struct Scratch(PathBuf);

    impl Drop for Scratch {
        fn drop(&mut self) {
            let _ = std::fs::remove_dir_all(&self.0);
        }
    }

    thread_local! {
        static SCRATCH: Scratch = {
            let test = std::thread::current().name().unwrap_or("main").replace("::", ".");
            let dir = format!("blurset-accumulate-{}-{test}", std::process::id());
            Scratch(std::env::temp_dir().join(dir))
        };
    }

    fn tmp(name: &str) -> PathBuf {
        SCRATCH.with(|s| s.0.join(name))
    }

    fn as_bytes(v: &[f32]) -> Vec<u8> {
        v.iter().flat_map(|x| x.to_ne_bytes()).collect()
    }

    fn frame(w: u32, h: u32, seed: u64) -> Vec<f32> {
        let mut s = crate::rng::Stream::new(seed, 0);
        (0..w * h * 4).map(|_| s.uniform() as f32).collect()
    }

    /// The encoding of one frame pixel by pixel, without the encoder's reuse of codes.
    fn reference_rgb8(rgba: &[f32], background: [f32; 3]) -> Vec<u8> {
        let bg = background.map(f64::from);
        rgba.chunks_exact(CH)
            .flat_map(|p| composite_over([p[0], p[1], p[2], p[3]].map(f64::from), bg))
            .map(srgb_encode_u8)
            .collect()
    }

    #[test]
    fn bands_that_tile_the_image_sum_to_it_and_a_share_of_one_changes_no_bit() -> Result<()> {
        // A rolling shutter's bands: each frame holds only its rows (0 elsewhere, as a
        // render traced in its band holds), each a 1/n share of the image.
        let (w, h) = (3, 4);
        let img = frame(w, h, 7);
        let row = (w * 4) as usize;
        let mut acc = Accumulator::new(w, h).with_share(0.5);
        for rows in [0..1usize, 1..4] {
            let mut part = vec![0.0f32; img.len()];
            part[rows.start * row..rows.end * row]
                .copy_from_slice(&img[rows.start * row..rows.end * row]);
            acc.add_frame(&part)?;
        }
        assert_eq!(acc.mean()?, img);
        let (mut one, mut plain) = (
            Accumulator::new(w, h).with_share(1.0),
            Accumulator::new(w, h),
        );
        for seed in 1..4 {
            one.add_frame(&frame(w, h, seed))?;
            plain.add_frame(&frame(w, h, seed))?;
        }
        assert_eq!(one.mean()?, plain.mean()?);
        Ok(())
    }

    #[test]
    fn mean_of_known_frames() -> Result<()> {
        let mut acc = Accumulator::new(2, 1);
        acc.add_frame(&[0.0, 1.0, 2.0, 1.0, 4.0, 0.0, 0.0, 0.0])?;
        acc.add_frame(&[1.0, 1.0, 0.0, 0.0, 2.0, 0.0, 0.0, 1.0])?;
        acc.add_frame(&[2.0, 1.0, 1.0, 0.5, 0.0, 0.0, 3.0, 0.5])?;
        assert_eq!(acc.count(), 3);
        assert_eq!(acc.mean()?, vec![1.0, 1.0, 1.0, 0.5, 2.0, 0.0, 1.0, 0.5]);
        Ok(())
    }

    #[test]
    fn weighted_frames_and_merged_halves() -> Result<()> {
        std::fs::create_dir_all(tmp("")).unwrap();
        let (p1, p2) = (tmp("w1.exr"), tmp("w2.exr"));
        write_exr(&p1, 2, 1, &[0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 1.0, 1.0])?;
        write_exr(&p2, 2, 1, &[1.0, 1.0, 1.0, 1.0, 0.0, 0.0, 0.0, 0.0])?;
        // Weights 1 and 3: the second frame counts three times.
        let mut a = Accumulator::new(2, 1);
        a.add_exr_weighted(&p1, None, 1.0)?;
        let mut b = Accumulator::new(2, 1);
        b.add_exr_weighted(&p2, None, 3.0)?;
        a.merge(&b)?;
        assert_eq!(a.count(), 2);
        assert_eq!(
            a.mean()?,
            vec![0.75, 0.75, 0.75, 1.0, 0.25, 0.25, 0.25, 0.25]
        );
        // Weight 1 is the unweighted sum, bit for bit.
        let (mut u, mut w) = (Accumulator::new(2, 1), Accumulator::new(2, 1));
        u.add_exr(&p1)?;
        w.add_exr_weighted(&p1, None, 1.0)?;
        assert_eq!(u.mean()?, w.mean()?);
        for bad in [0.0, -1.0, f64::NAN, f64::INFINITY] {
            assert!(w.add_exr_weighted(&p1, None, bad).is_err());
        }
        assert!(a.merge(&Accumulator::new(1, 1)).is_err());
        Ok(())
    }

    #[test]
    fn empty_accumulator_and_bad_length_are_errors() {
        let acc = Accumulator::new(3, 2);
        assert!(matches!(acc.mean(), Err(Error::Value(_))));
        assert!(acc.write_png(&tmp("never.png"), [1.0; 3]).is_err());
        assert!(!tmp("never.png").exists());
        let mut acc = Accumulator::new(3, 2);
        let e = acc.add_frame(&[0.0; 5]).unwrap_err();
        assert!(e.to_string().contains("3x2"), "{e}");
        assert_eq!(acc.count(), 0);
    }

    #[test]
    fn nan_frame_is_refused_whole() {
        let mut acc = Accumulator::new(2, 2);
        let mut f = vec![0.5f32; 16];
        f[9] = f32::NAN;
        let e = acc.add_frame(&f).unwrap_err().to_string();
        assert!(e.contains("(0, 1)") && e.contains("channel G"), "{e}");
        assert_eq!(acc.count(), 0);
        assert!(acc.sum.iter().all(|&s| s == 0.0));
    }

    #[test]
    fn exr_roundtrip_png_and_errors_name_the_file() -> Result<()> {
        let (w, h) = (7, 5);
        let f = frame(w, h, 3);
        let p = tmp("frame.exr");
        write_exr(&p, w, h, &f)?;
        let back = read_exr(&p)?;
        assert_eq!((back.width, back.height), (w, h));
        assert_eq!(back.rgba, f);

        let mut acc = Accumulator::new(w, h);
        acc.add_exr(&p)?;
        acc.add_exr(&p)?;
        assert_eq!(acc.mean()?, f);
        let out = tmp("out/mean.exr");
        acc.write_exr(&out)?;
        assert_eq!(read_exr(&out)?.rgba, f);
        let png = tmp("out/mean.png");
        acc.write_png(&png, [1.0, 1.0, 1.0])?;
        let img = image::open(&png)
            .map_err(|e| Error::Value(e.to_string()))?
            .into_rgb8();
        assert_eq!(img.dimensions(), (w, h));
        assert_eq!(img.into_raw(), reference_rgb8(&f, [1.0; 3]));

        let mut small = Accumulator::new(w + 1, h);
        let e = small.add_exr(&p).unwrap_err().to_string();
        assert!(
            e.contains("frame.exr") && e.contains("7x5") && e.contains("8x5"),
            "{e}"
        );

        let mut bad = f.clone();
        bad[4 * (2 * w as usize + 3) + 2] = f32::INFINITY;
        let pn = tmp("nan.exr");
        write_exr(&pn, w, h, &bad)?;
        let e = acc.add_exr(&pn).unwrap_err();
        assert!(matches!(e, Error::Image { .. }));
        let e = e.to_string();
        assert!(
            e.contains("nan.exr") && e.contains("(3, 2)") && e.contains("inf"),
            "{e}"
        );
        assert_eq!(acc.count(), 2);

        let missing = tmp("missing.exr");
        let e = acc.add_exr(&missing).unwrap_err().to_string();
        assert!(e.contains("missing.exr"), "{e}");
        let junk = tmp("junk.exr");
        write_atomic(&junk, b"not an exr")?;
        let e = acc.add_exr(&junk).unwrap_err().to_string();
        assert!(e.contains("junk.exr"), "{e}");
        Ok(())
    }

    #[test]
    fn a_cropped_exr_at_its_origin_adds_what_the_full_frame_adds() -> Result<()> {
        // A full render: zeros except the region [2, 1) .. [6, 4) (x, then y from the top).
        let (w, h) = (8, 5);
        let (x0, y0, tw, th) = (2usize, 1usize, 4usize, 3usize);
        let tile = frame(tw as u32, th as u32, 9);
        let mut full = vec![0.0f32; w * h * 4];
        for y in 0..th {
            for x in 0..tw {
                let (d, s) = (4 * ((y0 + y) * w + x0 + x), 4 * (y * tw + x));
                full[d..d + 4].copy_from_slice(&tile[s..s + 4]);
            }
        }
        let (pf, pt) = (tmp("crop_full.exr"), tmp("crop_tile.exr"));
        write_exr(&pf, w as u32, h as u32, &full)?;
        write_exr(&pt, tw as u32, th as u32, &tile)?;
        let other = frame(w as u32, h as u32, 4);
        let (mut a, mut b) = (Accumulator::new(8, 5), Accumulator::new(8, 5));
        for (acc, cropped) in [(&mut a, false), (&mut b, true)] {
            acc.add_frame(&other)?;
            if cropped {
                acc.add_exr_at(&pt, Some((x0 as u32, y0 as u32)))?;
            } else {
                acc.add_exr(&pf)?;
            }
        }
        assert_eq!(a.count(), b.count());
        assert!(a
            .sum
            .iter()
            .zip(&b.sum)
            .all(|(x, y)| x.to_bits() == y.to_bits()));
        // A full-width tile takes the row path.
        let row = frame(8, 2, 5);
        let pr = tmp("crop_rows.exr");
        write_exr(&pr, 8, 2, &row)?;
        let mut c = Accumulator::new(8, 5);
        c.add_exr_at(&pr, Some((0, 3)))?;
        assert_eq!(&c.mean()?[8 * 3 * 4..], &row[..]);
        assert!(c.mean()?[..8 * 3 * 4].iter().all(|&v| v == 0.0));

        // It must fit; an error names the file, its size and the origin.
        for origin in [(5, 1), (2, 3), (9, 0)] {
            let e = b.add_exr_at(&pt, Some(origin)).unwrap_err().to_string();
            assert!(
                e.contains("crop_tile.exr") && e.contains("4x3") && e.contains("8x5"),
                "{e}"
            );
        }
        // Without an origin the file must be the accumulator's size, as before.
        assert!(b.add_exr_at(&pt, None).is_err());
        // A non-finite value is named at its pixel in the whole image.
        let mut bad = tile.clone();
        bad[4 * (tw + 1)] = f32::NAN;
        let pn = tmp("crop_nan.exr");
        write_exr(&pn, tw as u32, th as u32, &bad)?;
        let e = b
            .add_exr_at(&pn, Some((x0 as u32, y0 as u32)))
            .unwrap_err()
            .to_string();
        assert!(e.contains("(3, 2)") && e.contains("crop_nan.exr"), "{e}");
        assert_eq!(b.count(), 2);
        Ok(())
    }

    #[test]
    fn exr_without_alpha_counts_as_opaque() -> Result<()> {
        let (w, h) = (3, 2);
        let rgb: Vec<f32> = (0..w * h * 3).map(|i| i as f32 / 20.0).collect();
        let p = tmp("rgb.exr");
        let mut buf = Cursor::new(Vec::new());
        image::codecs::openexr::OpenExrEncoder::new(&mut buf)
            .write_image(&as_bytes(&rgb), w, h, image::ExtendedColorType::Rgb32F)
            .map_err(|e| Error::Value(e.to_string()))?;
        write_atomic(&p, buf.get_ref())?;
        let mut acc = Accumulator::new(w, h);
        acc.add_exr(&p)?;
        let m = acc.mean()?;
        for (px, c) in m.chunks_exact(4).zip(rgb.chunks_exact(3)) {
            assert_eq!(&px[..3], c);
            assert_eq!(px[3], 1.0);
        }
        Ok(())
    }

    #[test]
    fn downsampled_png_is_the_area_mean_in_linear_light() -> Result<()> {
        let (w, h) = (8, 4);
        let f = frame(w, h, 11);
        let mut acc = Accumulator::new(w, h);
        acc.add_frame(&f)?;
        let bg = [1.0f32, 0.5, 0.0];
        let small = acc.encode_rgb8_downsampled(bg, 4)?;
        assert_eq!(small.len(), 2 * 3);
        // Reference: composite and clip every pixel, average 4 x 4 blocks, encode once.
        for (ox, px) in small.chunks_exact(3).enumerate() {
            let mut sum = [0.0f64; 3];
            for y in 0..4 {
                for x in ox * 4..ox * 4 + 4 {
                    let p = &f[(y * w as usize + x) * 4..][..4];
                    let c =
                        composite_over([p[0], p[1], p[2], p[3]].map(f64::from), bg.map(f64::from));
                    for k in 0..3 {
                        sum[k] += c[k].clamp(0.0, 1.0);
                    }
                }
            }
            let want: Vec<u8> = sum.iter().map(|s| srgb_encode_u8(s / 16.0)).collect();
            assert_eq!(px, &want[..]);
        }
        assert_eq!(acc.encode_rgb8_downsampled(bg, 1)?, acc.encode_rgb8(bg)?);
        assert!(acc.encode_rgb8_downsampled(bg, 3).is_err());
        let p = tmp("small/000.png");
        acc.write_png_downsampled(&p, bg, 2)?;
        let img = image::open(&p).map_err(|e| Error::Value(e.to_string()))?;
        assert_eq!((img.width(), img.height()), (4, 2));
        Ok(())
    }

    #[test]
    fn guides_are_averaged_like_the_colour_and_denoising_ends_the_image() -> Result<()> {
        let (w, h) = (16u32, 8u32);
        let n3 = (w * h * 3) as usize;
        let mut acc = Accumulator::with_guides(w, h);
        assert!(acc.has_guides());
        let e = acc.add_frame(&frame(w, h, 1)).unwrap_err().to_string();
        assert!(e.contains("albedo"), "{e}");
        let (a1, a2) = (vec![0.2f32; n3], vec![0.6f32; n3]);
        let (z1, z2) = (vec![1.0f32; n3], vec![0.0f32; n3]);
        acc.add_frame_with_guides(&frame(w, h, 1), &a1, &z1)?;
        acc.add_frame_with_guides(&frame(w, h, 2), &a2, &z2)?;
        let (ma, mn) = acc.guide_means()?;
        assert!(ma.iter().all(|&v| (v - 0.4).abs() < 1e-6));
        assert!(mn.iter().all(|&v| v == 0.5));
        assert!(Accumulator::new(w, h).guide_means().is_err());
        let Some(lib) = crate::image::denoise::tests::library() else {
            return Ok(());
        };
        let d = Denoiser::open(&lib, crate::image::denoise::DenoiseDevice::Cpu)?;
        let before = acc.mean()?;
        acc.denoise(&d)?;
        assert!(acc.is_denoised());
        assert_eq!(acc.count(), 2);
        let after = acc.mean()?;
        // Alpha is the frames' mean; the colour is the denoiser's.
        for (b, a) in before.chunks_exact(4).zip(after.chunks_exact(4)) {
            assert_eq!(b[3], a[3]);
        }
        assert_ne!(before, after);
        let e = acc
            .add_frame_with_guides(&frame(w, h, 3), &a1, &z1)
            .unwrap_err()
            .to_string();
        assert!(e.contains("already denoised"), "{e}");
        Ok(())
    }

    /// An RGBA frame whose alpha is `alpha` (colour = alpha, premultiplied white).
    fn alpha_frame(alpha: &[f32]) -> Vec<f32> {
        alpha.iter().flat_map(|&a| [a, a, a, a]).collect()
    }

    #[test]
    fn a_blurry_mask_is_every_pixel_some_frame_covered_half() -> Result<()> {
        // Three frames of an object moving right across 6 x 1 pixels: each covers two
        // pixels fully and its edges by 0.6 and 0.3. The mean's alpha reaches 0.5 on
        // two pixels only; the frames cover five of them at least half.
        let frames = [
            [1.0f32, 1.0, 0.6, 0.0, 0.0, 0.0],
            [0.0, 0.3, 1.0, 1.0, 0.0, 0.0],
            [0.0, 0.0, 0.0, 0.3, 1.0, 0.6],
        ];
        let (mut a, mut b) = (Accumulator::new(6, 1), Accumulator::new(6, 1));
        a.add_frame(&alpha_frame(&frames[0]))?;
        // A cropped render adds nothing outside its tile (its alpha there is 0).
        let p = tmp("cover_tile.exr");
        std::fs::create_dir_all(tmp("")).unwrap();
        write_exr(&p, 3, 1, &alpha_frame(&frames[1][1..4]))?;
        a.add_exr_at(&p, Some((1, 0)))?;
        b.add_frame(&alpha_frame(&frames[2]))?;
        a.merge(&b)?;
        assert_eq!(a.covered()?, [1.0, 1.0, 1.0, 1.0, 1.0, 0.6]);
        let of_mean = mask_from_coverage(&a.mean()?, 6, 1, 1)?;
        assert_eq!(of_mean, [0, 0, 255, 0, 0, 0]);
        let m = tmp("cover.png");
        a.write_exposure_mask(&m, 1, BlurMethod::Average, None)?;
        let img = read_image(&m)?;
        assert_eq!(img.samples, Samples::U8(vec![255, 255, 255, 255, 255, 255]));
        // One motion-blurred render: every pixel it saw the object in at all.
        let mut mb = Accumulator::new(6, 1);
        mb.add_frame(&alpha_frame(&[0.0, 0.01, 0.4, 0.9, 0.2, 0.0]))?;
        mb.write_exposure_mask(&m, 1, BlurMethod::MotionBlur, None)?;
        assert_eq!(
            read_image(&m)?.samples,
            Samples::U8(vec![0, 255, 255, 255, 255, 0])
        );
        mb.write_exposure_mask(&m, 1, BlurMethod::Average, None)?;
        assert_eq!(
            read_image(&m)?.samples,
            Samples::U8(vec![0, 0, 0, 255, 0, 0])
        );
        // The sharp mask's pixels are added; a mask of another size is refused by name.
        let sharp = tmp("sharp_mask.png");
        crate::image::geometry::write_gray8_png(&sharp, 6, 1, &[255, 0, 0, 0, 0, 0])?;
        mb.write_exposure_mask(&m, 1, BlurMethod::Average, Some(&sharp))?;
        assert_eq!(
            read_image(&m)?.samples,
            Samples::U8(vec![255, 0, 0, 255, 0, 0])
        );
        let small = tmp("small_mask.png");
        crate::image::geometry::write_gray8_png(&small, 3, 1, &[255, 0, 0])?;
        let e = mb
            .write_exposure_mask(&m, 1, BlurMethod::Average, Some(&small))
            .unwrap_err()
            .to_string();
        assert!(e.contains("small_mask.png") && e.contains("6x1"), "{e}");
        assert!(Accumulator::new(6, 1).covered().is_err());
        Ok(())
    }

    proptest! {
        #[test]
        fn n_copies_of_a_frame_give_the_frame_back(
            w in 1u32..9, h in 1u32..9, n in 1u32..40, seed in any::<u64>(),
            scale in prop::sample::select(vec![1.0f32, 1e-3, 50.0]),
        ) {
            let f: Vec<f32> = frame(w, h, seed).iter().map(|v| v * scale).collect();
            let mut acc = Accumulator::new(w, h);
            for _ in 0..n {
                acc.add_frame(&f).unwrap();
            }
            prop_assert_eq!(acc.count(), n);
            prop_assert_eq!(acc.mean().unwrap(), f.clone());
            prop_assert_eq!(acc.encode_rgb8([1.0, 0.5, 0.0]).unwrap(), reference_rgb8(&f, [1.0, 0.5, 0.0]));
        }

    }
}
