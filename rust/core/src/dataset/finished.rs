//! What a setting writes of one finished image (DESIGN §2–4): the mean of its frames
//! (denoised once under `--denoise oidn`) as the PNG of every image folder, its linear
//! EXR, its masks, and the render QA of a sharp image. The render loop
//! ([`super::session`]) hands each image here as soon as it holds all its frames.
use super::target_loop::ImageKey;
use crate::error::Result;
use crate::ground::names::{
    files, image_name, images_dir, linear_name, pass_dir, pass_file, SHARP,
};
use crate::image::accumulate::Accumulator;
use crate::image::denoise::Denoiser;
use crate::image::qa::FrameQa;
use crate::plan::choices::BlurMethod;
use crate::plan::config::BuildConfig;
use crate::plan::kind::ImageKind;
use crate::plan::renders::Render;
use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// How a setting writes its finished images, under its partial folder.
pub struct ImageWriter {
    partial: PathBuf,
    n_views: usize,
    background: [f32; 3],
    downsample: Vec<u32>,
    linear: bool,
    masks: bool,
    /// Images rendered by one Cycles motion blur render (their exposure masks say so).
    motion_blur: BTreeSet<ImageKey>,
    /// The first phase's images (the sharp images): QA'd, their coverage the mask the
    /// other images of their view share.
    first: BTreeSet<ImageKey>,
    denoiser: Option<Arc<Denoiser>>,
}

impl ImageWriter {
    /// The writer of the images of `renders` (the plan's) under `partial`, whose level
    /// and image folders it makes.
    pub fn new(
        partial: &Path,
        cfg: &BuildConfig,
        n_views: usize,
        renders: &[Render],
        denoiser: Option<Arc<Denoiser>>,
    ) -> Result<Self> {
        let key = |r: &Render| (r.view, r.level.clone());
        let first_phase = renders.iter().map(|r| r.phase).min().unwrap_or_default();
        let w = ImageWriter {
            partial: partial.to_path_buf(),
            n_views,
            background: cfg.background.map(|x| x as f32),
            downsample: cfg.downsample.clone(),
            linear: cfg.write_linear,
            masks: cfg.passes.iter().any(|p| p == "mask"),
            motion_blur: renders
                .iter()
                .filter(|r| r.motion.is_some())
                .map(key)
                .collect(),
            first: renders
                .iter()
                .filter(|r| r.phase == first_phase)
                .map(key)
                .collect(),
            denoiser,
        };
        w.make_dirs(&cfg.level_dirs())?;
        Ok(w)
    }

    /// The image sizes a setting writes: full size, then each `--downsample` factor.
    fn factors(&self) -> impl Iterator<Item = u32> + '_ {
        std::iter::once(1).chain(self.downsample.iter().copied())
    }

    /// Every level's image folders, and the mask folders of the levels that hold masks.
    fn make_dirs(&self, levels: &[String]) -> Result<()> {
        let mkdir = |p: PathBuf| {
            std::fs::create_dir_all(&p).map_err(|e| crate::Error::io("cannot create", &p, e))
        };
        for level in levels {
            for f in self.factors() {
                mkdir(self.partial.join(level).join(images_dir(f)))?;
                if self.masks && (level == SHARP || own_masks(level)) {
                    mkdir(self.partial.join(level).join(pass_dir("mask", f)))?;
                }
            }
        }
        Ok(())
    }

    /// Write a finished image (the mean of its frames) and its masks; the render QA of
    /// a first-phase (sharp) image.
    pub fn finish(&self, key: &ImageKey, a: &mut Accumulator) -> Result<Option<FrameQa>> {
        if let Some(d) = &self.denoiser {
            a.denoise(d)?;
        }
        let (view, level) = key;
        let name = image_name(*view, self.n_views);
        let dir = self.partial.join(level);
        for f in self.factors() {
            a.write_png_downsampled(&dir.join(images_dir(f)).join(&name), self.background, f)?;
        }
        if self.linear {
            a.write_exr(&dir.join(files::LINEAR).join(linear_name(&name)))?;
        }
        if self.masks {
            self.write_masks(key, &name, a)?;
        }
        self.first.contains(key).then(|| a.qa()).transpose()
    }

    /// The image's masks at every size: a sharp image's coverage; a blurry image's own,
    /// the pixels its exposure covered plus the sharp mask of its view (written first:
    /// every sharp image is done before another phase starts).
    fn write_masks(&self, key: &ImageKey, name: &str, a: &Accumulator) -> Result<()> {
        let level = &key.1;
        let first = self.first.contains(key);
        if !first && !own_masks(level) {
            return Ok(());
        }
        let method = if self.motion_blur.contains(key) {
            BlurMethod::MotionBlur
        } else {
            BlurMethod::Average
        };
        for f in self.factors() {
            let (sub, file) = (pass_dir("mask", f), pass_file("mask", name));
            let path = self.partial.join(level).join(&sub).join(&file);
            if first {
                a.write_mask(&path, f)?;
            } else {
                let sharp = self.partial.join(SHARP).join(&sub).join(&file);
                a.write_exposure_mask(&path, f, method, Some(&sharp))?;
            }
        }
        Ok(())
    }
}

/// Whether a level directory holds masks of its own (a moving exposure's coverage).
fn own_masks(level: &str) -> bool {
    ImageKind::parse(level).is_some_and(ImageKind::own_masks)
}
