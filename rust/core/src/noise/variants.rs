//! The files of a scene's noise variants: per gain and frame, the processed PNG and
//! the linear EXR, from 8/16-bit images or from a build's linear EXRs.
use super::kernel::{apply_plan, Noisy, Plan};
use super::linear::{add_noise_linear, linear_from_codes, read_linear, LinearRgb};
use super::model::{factor_key, stream_id, NoiseModel};
use super::raw::raw_frame;
use super::raw_model::RawModel;
use crate::error::{Error, Result};
use crate::ground::names::{images_dir, linear_dir};
use crate::image::exr::read::{check_exr_size, exr_size};
use crate::image::exr::write::exr_bytes;
use crate::image::io as image_io;
use crate::image::resample::check_factor;
use rayon::prelude::*;
use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

/// One noise variant of a scene (one gain): where it goes and how it is made.
#[derive(Clone, Debug)]
pub struct Variant {
    pub out_dir: PathBuf,
    pub model: NoiseModel,
    pub key: u64,
    /// A camera model of `--model` (issue 61) in place of `model`'s noise; `model`
    /// still holds the transfer, white balance and white level.
    pub raw: Option<RawModel>,
}

/// What every variant of a scene writes besides full-size noisy images.
#[derive(Clone, Debug, Default)]
pub struct VariantOptions {
    /// `images_<f>/` and `linear_<f>/` per factor: the clean image area-averaged in linear
    /// light, then noised at that size (key [`factor_key`]), so σ(gain) holds there too.
    pub downsample: Vec<u32>,
    /// Views that stay clean (σ = 0) in every variant: the held-out targets of NAN's
    /// protocol (noisy sources, clean target).
    pub clean_views: BTreeSet<usize>,
    /// The factor of the folder read (a scene's images_<F>/; 0, 1: images/): full-size
    /// files go to images_<F>/ and a downsample f's to images_<F·f>/, the folders LLFF
    /// loaders read at those factors with hwf unchanged.
    pub factor: u32,
    /// No linear EXRs (`--no-linear`).
    pub no_linear: bool,
}

impl VariantOptions {
    /// A variant's images folder at downsample `f` (1: the size read) and its linear
    /// folder, unless `no_linear`.
    fn dirs(&self, v: &Variant, f: u32) -> (PathBuf, Option<PathBuf>) {
        let at = self.factor.max(1) * f;
        let exr = (!self.no_linear).then(|| v.out_dir.join(linear_dir(at)));
        (v.out_dir.join(images_dir(at)), exr)
    }

    fn model(&self, v: &Variant, view: usize) -> NoiseModel {
        if self.clean_views.contains(&view) {
            NoiseModel {
                sigma_read: 0.0,
                sigma_shot: 0.0,
                ..v.model
            }
        } else {
            v.model
        }
    }

    /// One frame of variant `v` from the clean linear image of view `view`: its raw
    /// model's (the clean pipeline for a clean view), else the paper's linear path.
    fn linear_frame(
        &self,
        v: &Variant,
        view: usize,
        img: &LinearRgb,
        key: u64,
        stream: u64,
    ) -> Result<Noisy> {
        match &v.raw {
            Some(raw) if self.clean_views.contains(&view) => {
                raw_frame(img, &raw.clean(), key, stream)
            }
            Some(raw) => raw_frame(img, raw, key, stream),
            None => add_noise_linear(img, &self.model(v, view), key, stream),
        }
    }
}

/// Read every source image once and write, for each variant and frame,
/// `out_dir/images/<name>.png` and `out_dir/linear/<name>.exr` (and the
/// `images_<f>/`, `linear_<f>/` copies of `opts.downsample`); `names` holds
/// `sources.len() · frames` stems, view-major. All images must share one size.
/// Files are written in place: callers make the whole tree atomic by writing into a
/// temporary directory and renaming it.
pub fn write_variants(
    sources: &[PathBuf],
    names: &[String],
    frames: u32,
    variants: &[Variant],
    opts: &VariantOptions,
) -> Result<()> {
    prepare(sources, names, frames, variants, opts)?;
    let Some(first) = sources.first() else {
        return Ok(());
    };
    let (w0, h0, _, _) = image_io::image_info(first)?;
    for &f in &opts.downsample {
        check_factor(w0, h0, f).map_err(|e| Error::Image {
            reason: e.to_string(),
            path: first.clone(),
        })?;
    }
    // Plans depend on (variant, clean, depth, colour layout); built once, on first use.
    let plans: Vec<[OnceLock<Plan>; 8]> = variants.iter().map(|_| Default::default()).collect();
    sources.par_iter().enumerate().try_for_each(|(i, path)| {
        let img = image_io::read_image(path)?;
        if (img.width, img.height) != (w0, h0) {
            return Err(Error::Image {
                reason: format!(
                    "size {} x {} differs from {} x {} of {:?}",
                    img.width, img.height, w0, h0, first
                ),
                path: path.clone(),
            });
        }
        let clean = opts.clean_views.contains(&i);
        let slot = usize::from(clean) * 4
            + usize::from(img.samples.max_code() > 255) * 2
            + usize::from(img.channels >= 3);
        let raw_linear = RawLinear::new(&img, variants);
        for (v, plan) in variants.iter().zip(&plans) {
            if v.raw.is_some() {
                let lin = raw_linear.get(path)?;
                for k in 0..frames {
                    let noisy = opts.linear_frame(v, i, lin, v.key, stream_id(i as u32, k))?;
                    let name = &names[i * frames as usize + k as usize];
                    write_frame(v, opts, 1, name, (img.width, img.height), &noisy)?;
                }
                continue;
            }
            let model = opts.model(v, i);
            let plan = plan[slot]
                .get_or_init(|| Plan::new(&model, img.samples.max_code(), img.color_channels()));
            for k in 0..frames {
                let noisy = apply_plan(&img, plan, v.key, stream_id(i as u32, k))?;
                let name = &names[i * frames as usize + k as usize];
                write_frame(v, opts, 1, name, (img.width, img.height), &noisy)?;
            }
        }
        if !opts.downsample.is_empty() {
            let lin =
                linear_from_codes(&img, variants[0].model.gamma).map_err(|e| Error::Image {
                    reason: e.to_string(),
                    path: path.clone(),
                })?;
            write_downsampled(&lin, i, names, frames, variants, opts)?;
        }
        Ok(())
    })
}

/// The linear-path counterpart of [`write_variants`]: read every linear EXR once
/// (composited over `background`) and write, per variant and frame,
/// `out_dir/images/<name>.png` (8-bit RGB) and `out_dir/linear/<name>.exr` (RGB float),
/// and their downsampled copies. Keys and streams are those of the PNG path
/// (`stream_id(view, frame)`). All images must be `size` (width, height; None: the
/// first one's), read from every file's header before any is decoded: a file that
/// claims another size costs its header, not the frame it claims (issue 60). Files
/// are written in place; callers make the tree atomic.
pub fn write_variants_linear(
    sources: &[PathBuf],
    names: &[String],
    frames: u32,
    variants: &[Variant],
    background: [f64; 3],
    size: Option<(u32, u32)>,
    opts: &VariantOptions,
) -> Result<()> {
    prepare(sources, names, frames, variants, opts)?;
    if let Some(first) = sources.first() {
        let want = size.map_or_else(|| exr_size(first), Ok)?;
        sources.iter().try_for_each(|p| check_exr_size(p, want))?;
    }
    let size = std::sync::OnceLock::new();
    sources.par_iter().enumerate().try_for_each(|(i, path)| {
        let img = read_linear(path, background)?;
        let (w0, h0, first) = *size.get_or_init(|| (img.width, img.height, i));
        if (img.width, img.height) != (w0, h0) {
            return Err(Error::Image {
                reason: format!(
                    "size {} x {} differs from {} x {} of {:?}",
                    img.width, img.height, w0, h0, sources[first]
                ),
                path: path.clone(),
            });
        }
        for v in variants {
            for k in 0..frames {
                let noisy = opts.linear_frame(v, i, &img, v.key, stream_id(i as u32, k))?;
                let name = &names[i * frames as usize + k as usize];
                write_frame(v, opts, 1, name, (img.width, img.height), &noisy)?;
            }
        }
        write_downsampled(&img, i, names, frames, variants, opts).map_err(|e| match e {
            Error::Value(reason) => Error::Image {
                reason,
                path: path.clone(),
            },
            e => e,
        })
    })
}

/// The clean linear image of a PNG source for the raw models, decoded once on first
/// use with the variants' transfer curve.
struct RawLinear<'a> {
    img: &'a image_io::Image,
    gamma: super::model::Gamma,
    lin: OnceLock<LinearRgb>,
}

impl<'a> RawLinear<'a> {
    fn new(img: &'a image_io::Image, variants: &[Variant]) -> Self {
        let gamma = variants
            .first()
            .map_or(super::model::Gamma::Srgb, |v| v.model.gamma);
        RawLinear {
            img,
            gamma,
            lin: OnceLock::new(),
        }
    }

    fn get(&self, path: &Path) -> Result<&LinearRgb> {
        if let Some(l) = self.lin.get() {
            return Ok(l);
        }
        let l = linear_from_codes(self.img, self.gamma).map_err(|e| Error::Image {
            reason: format!("{e} (the camera models need RGB images)"),
            path: path.to_path_buf(),
        })?;
        Ok(self.lin.get_or_init(|| l))
    }
}

/// The `images_<f>/` and `linear_<f>/` files of view `i` from its clean linear image.
fn write_downsampled(
    img: &LinearRgb,
    i: usize,
    names: &[String],
    frames: u32,
    variants: &[Variant],
    opts: &VariantOptions,
) -> Result<()> {
    for &f in &opts.downsample {
        let small = img.downsample(f)?;
        for v in variants {
            for k in 0..frames {
                let (key, stream) = (factor_key(v.key, f), stream_id(i as u32, k));
                let noisy = opts.linear_frame(v, i, &small, key, stream)?;
                let name = &names[i * frames as usize + k as usize];
                write_frame(v, opts, f, name, (small.width, small.height), &noisy)?;
            }
        }
    }
    Ok(())
}

/// Refuse a call whose names do not match its sources and frames, or whose model is
/// invalid; then create every variant's `images*/` and `linear*/` directories.
fn prepare(
    sources: &[PathBuf],
    names: &[String],
    frames: u32,
    variants: &[Variant],
    opts: &VariantOptions,
) -> Result<()> {
    if frames == 0 {
        return Err(Error::Value("frames must be at least 1".into()));
    }
    if names.len() != sources.len() * frames as usize {
        return Err(Error::Shape(format!(
            "{} output names for {} images x {frames} frames",
            names.len(),
            sources.len()
        )));
    }
    if let Some(f) = opts.downsample.iter().find(|&&f| f < 2) {
        return Err(Error::Value(format!(
            "downsample factor {f}: must be at least 2 (images/ is factor 1)"
        )));
    }
    for v in variants {
        v.model.validate()?;
        for f in std::iter::once(1).chain(opts.downsample.iter().copied()) {
            let (png, exr) = opts.dirs(v, f);
            for d in std::iter::once(png).chain(exr) {
                std::fs::create_dir_all(&d)
                    .map_err(|e| Error::io("cannot create directory", &d, e))?;
            }
        }
    }
    Ok(())
}

/// One noisy frame of a variant at downsample `f`: its PNG and (unless `no_linear`) EXR.
fn write_frame(
    v: &Variant,
    opts: &VariantOptions,
    f: u32,
    name: &str,
    (width, height): (u32, u32),
    noisy: &Noisy,
) -> Result<()> {
    let (png, exr) = opts.dirs(v, f);
    write_file(
        &png.join(format!("{name}.png")),
        &image_io::png_bytes(&noisy.processed)?,
    )?;
    let Some(exr) = exr else {
        return Ok(());
    };
    write_file(
        &exr.join(format!("{name}.exr")),
        &exr_bytes(width, height, noisy.linear_channels, &noisy.linear)?,
    )
}

fn write_file(path: &Path, bytes: &[u8]) -> Result<()> {
    std::fs::write(path, bytes).map_err(|e| Error::io("cannot write", path, e))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::image::exr::read::read_exr;
    use crate::noise::model::Gamma;

    #[test]
    fn clean_views_and_downsampled_copies() -> Result<()> {
        let dir = std::env::temp_dir().join(format!("blurset-noise-opts-{}", std::process::id()));
        let (w, h) = (16u32, 8u32);
        let src = dir.join("src");
        std::fs::create_dir_all(&src).map_err(|e| Error::io("mkdir", &src, e))?;
        let paths: Vec<PathBuf> = (0..2).map(|i| src.join(format!("{i:03}.png"))).collect();
        let codes: Vec<u8> = (0..w * h * 3).map(|i| (i * 11 % 256) as u8).collect();
        let img = image_io::Image::new(w, h, 3, image_io::Samples::U8(codes.clone()))?;
        for p in &paths {
            write_file(p, &image_io::png_bytes(&img)?)?;
        }
        let m = NoiseModel {
            sigma_read: 0.05,
            sigma_shot: 0.05,
            gamma: Gamma::Srgb,
            white_balance: None,
            white_level: 1.0,
        };
        let v = Variant {
            out_dir: dir.join("out"),
            model: m,
            key: 9,
            raw: None,
        };
        let names = vec!["000".to_string(), "001".to_string()];
        let opts = VariantOptions {
            downsample: vec![2, 4],
            clean_views: [0].into(),
            ..Default::default()
        };
        write_variants(&paths, &names, 1, std::slice::from_ref(&v), &opts)?;
        let out = |sub: &str, name: &str| dir.join("out").join(sub).join(name);
        // The clean view keeps its pixels; the other one is noisy.
        assert_eq!(image_io::read_image(&out("images", "000.png"))?, img);
        assert_ne!(image_io::read_image(&out("images", "001.png"))?, img);
        for (f, sub) in [(2, "images_2"), (4, "images_4")] {
            let small = image_io::read_image(&out(sub, "001.png"))?;
            assert_eq!((small.width, small.height), (w / f, h / f));
            let lin = read_exr(&out(&format!("linear_{f}"), "000.exr"))?;
            // A clean view's small linear image is the area mean of the decoded codes.
            let want = linear_from_codes(&img, Gamma::Srgb)?.downsample(f)?;
            let got: Vec<f32> = lin
                .rgba
                .chunks_exact(4)
                .flat_map(|p| [p[0], p[1], p[2]])
                .collect();
            assert_eq!(got, want.rgb);
        }
        // A factor that does not divide the size names the file.
        let bad = VariantOptions {
            downsample: vec![3],
            ..Default::default()
        };
        let e = write_variants(&paths, &names, 1, &[v], &bad)
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
        assert!(e.contains("factor 3") && e.contains("000.png"), "{e}");
        let _ = std::fs::remove_dir_all(&dir);
        Ok(())
    }

    /// Two 8 x 6 linear EXRs, their pixels, a variant and the output names.
    type Sources = (Vec<PathBuf>, Vec<f32>, Variant, Vec<String>);

    /// [`Sources`] under `dir` (the EXRs in src/, the variant writing to out/).
    fn linear_sources(dir: &Path) -> Result<Sources> {
        let rgba: Vec<f32> = (0..8 * 6 * 4).map(|i| (i % 13) as f32 / 13.0).collect();
        let src = dir.join("src");
        let paths: Vec<PathBuf> = (0..2).map(|i| src.join(format!("{i:03}.exr"))).collect();
        for p in &paths {
            crate::image::exr::write::write_exr(p, 8, 6, &rgba)?;
        }
        let model = NoiseModel {
            sigma_read: 0.02,
            sigma_shot: 0.03,
            gamma: Gamma::Srgb,
            white_balance: None,
            white_level: 1.0,
        };
        let v = Variant {
            out_dir: dir.join("out"),
            model,
            key: 4,
            raw: None,
        };
        Ok((paths, rgba, v, vec!["000".to_string(), "001".to_string()]))
    }

    /// `write_variants_linear` of one variant, its error's words (empty when it wrote).
    fn linear_error(
        paths: &[PathBuf],
        names: &[String],
        v: &Variant,
        size: Option<(u32, u32)>,
    ) -> String {
        write_variants_linear(
            paths,
            names,
            1,
            std::slice::from_ref(v),
            [1.0; 3],
            size,
            &VariantOptions::default(),
        )
        .err()
        .map(|e| e.to_string())
        .unwrap_or_default()
    }

    #[test]
    fn exr_files_round_trip_through_the_writer() -> Result<()> {
        let dir = std::env::temp_dir().join(format!("blurset-noise-linear-{}", std::process::id()));
        let (paths, _, v, names) = linear_sources(&dir)?;
        assert_eq!(linear_error(&paths, &names, &v, None), "");
        let back = read_exr(&dir.join("out/linear/001.exr"))?;
        let img = read_linear(&paths[1], [1.0; 3])?;
        let want = add_noise_linear(&img, &v.model, 4, stream_id(1, 0))?;
        let got: Vec<f32> = back
            .rgba
            .chunks_exact(4)
            .flat_map(|p| [p[0], p[1], p[2]])
            .collect();
        assert_eq!(got, want.linear);
        let png = image_io::read_image(&dir.join("out/images/000.png"))?;
        assert_eq!((png.width, png.height, png.channels), (8, 6, 3));
        let _ = std::fs::remove_dir_all(&dir);
        Ok(())
    }

    #[test]
    fn a_camera_model_writes_its_raw_frames_from_linear_sources() -> Result<()> {
        use crate::noise::camera::eld_camera;
        use crate::noise::raw_model::{Display, RawModel};
        let dir = std::env::temp_dir().join(format!("blurset-noise-raw-{}", std::process::id()));
        let (paths, _, mut v, names) = linear_sources(&dir)?;
        let cam = eld_camera("CanonEOS700D").ok_or_else(|| Error::Value("camera".into()))?;
        let display = Display {
            gamma: Gamma::Srgb,
            white_balance: None,
            white_level: 1.0,
        };
        let raw = RawModel::eld(cam, 16.0, display)?;
        v.raw = Some(raw.clone());
        let opts = VariantOptions {
            downsample: vec![2],
            clean_views: [0].into(),
            ..Default::default()
        };
        let one = std::slice::from_ref(&v);
        write_variants_linear(&paths, &names, 1, one, [1.0; 3], None, &opts)?;
        let exr = |sub: &str, name: &str| -> Result<Vec<f32>> {
            let f = read_exr(&dir.join("out").join(sub).join(name))?;
            Ok(f.rgba
                .chunks_exact(4)
                .flat_map(|p| [p[0], p[1], p[2]])
                .collect())
        };
        let img = read_linear(&paths[1], [1.0; 3])?;
        // The noisy view: the raw pipeline's frame under the variant's key and stream.
        let want = raw_frame(&img, &raw, 4, stream_id(1, 0))?;
        assert_eq!(exr("linear", "001.exr")?, want.linear);
        // The clean view: the pipeline without noise, its input back (f32 rounding).
        let clean = exr("linear", "000.exr")?;
        let src = read_linear(&paths[0], [1.0; 3])?;
        let worst = clean
            .iter()
            .zip(&src.rgb)
            .map(|(a, b)| (a - b.clamp(0.0, 1.0)).abs());
        assert!(worst.fold(0.0f32, f32::max) < 1e-5);
        // The half-size copy: drawn afresh under the factor's key.
        let small = raw_frame(&img.downsample(2)?, &raw, factor_key(4, 2), stream_id(1, 0))?;
        assert_eq!(exr("linear_2", "001.exr")?, small.linear);
        let _ = std::fs::remove_dir_all(&dir);
        Ok(())
    }

    #[test]
    fn a_linear_source_with_a_nan_or_of_another_size_is_named() -> Result<()> {
        let dir = std::env::temp_dir().join(format!("blurset-noise-bad-{}", std::process::id()));
        let (paths, rgba, v, names) = linear_sources(&dir)?;
        let mut bad = rgba.clone();
        bad[5] = f32::NAN;
        crate::image::exr::write::write_exr(&paths[0], 8, 6, &bad)?;
        let e = linear_error(&paths, &names, &v, Some((8, 6)));
        assert!(e.contains("000.exr") && e.contains("non-finite"), "{e}");
        // A source of another size than the one given (or the first's) is refused from
        // its header, before any source is decoded: the NaN in the first is not reached.
        crate::image::exr::write::write_exr(&paths[1], 16, 6, &[0.5; 16 * 6 * 4])?;
        for size in [Some((8, 6)), None] {
            let e = linear_error(&paths, &names, &v, size);
            assert!(
                e.contains("001.exr") && e.contains("EXR is 16x6, expected 8x6; refused before"),
                "{e}"
            );
        }
        let _ = std::fs::remove_dir_all(&dir);
        Ok(())
    }
}
