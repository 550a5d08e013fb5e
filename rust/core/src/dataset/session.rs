//! One setting's render session (DESIGN §2–4, §8): the one loop that owns a setting's
//! images. It renders them phase by phase as the plan orders them (the sharp images
//! first, then each kind's), gates the rest on the render QA of the first phase, holds
//! every accumulator, writes each image once it is done ([`ImageWriter`]) and keeps its
//! record. Fixed sample counts are one round per phase: the plan's renders. A render
//! target is rounds of two halves per image ([`TargetImages`]). The builder only asks
//! for the next renders, has the worker render them and hands back each EXR:
//! `while renders := session.next_renders(): worker.render(renders, on_frame=add_exr)`.
use super::finished::ImageWriter;
use super::meta::ImageRender;
use super::target_loop::{ImageKey, TargetImages};
use crate::error::{Error, Result};
use crate::image::accumulate::Accumulator;
use crate::image::qa::{FrameQa, QaThresholds};
use crate::plan::renders::Render;
use crate::plan::target::TargetRule;
use std::collections::{BTreeMap, VecDeque};
use std::path::Path;

/// How the images of a phase are rendered.
pub enum Counts {
    /// The plan's renders at their own sample counts, every image in one round.
    Fixed,
    /// Rounds of two halves until each image's estimate reaches `rule` (renders pinned
    /// to a `sequence`-sample Cycles sequence), its noise judged over `background`.
    Target {
        rule: TargetRule,
        sequence: u32,
        background: [f64; 3],
    },
}

/// One phase's images of a fixed-count build: the renders asked for, and each image's
/// frames as they arrive.
struct FixedPhase {
    /// The image of each render asked for, in its order.
    images: Vec<ImageKey>,
    /// The share of a whole image each render's frame is (`Render::share`).
    shares: Vec<f64>,
    guides: bool,
    /// Frames each unfinished image still needs (a finished one leaves).
    need: BTreeMap<ImageKey, u32>,
    open: BTreeMap<ImageKey, Accumulator>,
}

enum Phase {
    Fixed(FixedPhase),
    Target(Box<TargetImages>),
}

/// The images of one setting, rendered phase by phase (see the module).
pub struct Session {
    renders: Vec<Render>,
    counts: Counts,
    size: u32,
    guides: bool,
    writer: ImageWriter,
    /// The phases not started yet, each its images in render order.
    phases: VecDeque<Vec<ImageKey>>,
    current: Option<Phase>,
    /// Phases started so far.
    started: u32,
    qa: BTreeMap<usize, FrameQa>,
    failure: Option<String>,
    records: Vec<(ImageKey, ImageRender)>,
}

impl Session {
    /// The images of the plan's `renders` (in the order the plan gives them), rendered
    /// at `size` px by `counts` and written by `writer`; `guides`: the frames carry
    /// the denoiser's guide passes.
    pub fn new(
        renders: Vec<Render>,
        counts: Counts,
        size: u32,
        guides: bool,
        writer: ImageWriter,
    ) -> Self {
        let mut by_phase: BTreeMap<u32, Vec<ImageKey>> = BTreeMap::new();
        for r in &renders {
            let keys = by_phase.entry(r.phase).or_default();
            let key = (r.view, r.level.clone());
            if !keys.contains(&key) {
                keys.push(key);
            }
        }
        Session {
            renders,
            counts,
            size,
            guides,
            writer,
            phases: by_phase.into_values().collect(),
            current: None,
            started: 0,
            qa: BTreeMap::new(),
            failure: None,
            records: Vec::new(),
        }
    }

    /// The renders to make next; empty when every image is written, or when the first
    /// phase's QA failed ([`Self::failure`]). Each call first takes in what the last one
    /// asked for: an image that is done is written.
    pub fn next_renders(&mut self) -> Result<Vec<Render>> {
        loop {
            if let Some(renders) = self.continue_phase()? {
                return Ok(renders);
            }
            if self.started == 1 {
                self.judge_first_phase();
            }
            if self.failure.is_some() {
                return Ok(Vec::new());
            }
            let Some(keys) = self.phases.pop_front() else {
                return Ok(Vec::new());
            };
            let (phase, renders) = self.start(&keys)?;
            self.current = Some(phase);
            self.started += 1;
            if let Some(renders) = renders {
                return Ok(renders);
            }
        }
    }

    /// The next renders of the phase in flight (None: it is done, or none is).
    fn continue_phase(&mut self) -> Result<Option<Vec<Render>>> {
        match self.current.take() {
            None => Ok(None),
            Some(Phase::Fixed(p)) => {
                if !p.need.is_empty() {
                    return Err(Error::Value(format!(
                        "{} view/level images incomplete after rendering",
                        p.need.len()
                    )));
                }
                Ok(None)
            }
            Some(Phase::Target(mut t)) => {
                let renders = t.next_renders()?;
                for f in t.take_finished() {
                    let mut image = f.image;
                    self.finish(&f.key, &mut image)?;
                }
                if renders.is_empty() {
                    self.records.extend(t.records().iter().cloned());
                    return Ok(None);
                }
                self.current = Some(Phase::Target(t));
                Ok(Some(renders))
            }
        }
    }

    /// The phase of `keys`, and at fixed counts its renders (a target's come from its
    /// rounds).
    fn start(&self, keys: &[ImageKey]) -> Result<(Phase, Option<Vec<Render>>)> {
        match self.counts {
            Counts::Fixed => {
                let renders: Vec<Render> = self
                    .renders
                    .iter()
                    .filter(|r| keys.contains(&(r.view, r.level.clone())))
                    .cloned()
                    .collect();
                let images: Vec<ImageKey> =
                    renders.iter().map(|r| (r.view, r.level.clone())).collect();
                let mut need = BTreeMap::new();
                for key in &images {
                    *need.entry(key.clone()).or_insert(0) += 1;
                }
                let phase = FixedPhase {
                    images,
                    shares: renders.iter().map(Render::share).collect(),
                    guides: self.guides,
                    need,
                    open: BTreeMap::new(),
                };
                Ok((Phase::Fixed(phase), Some(renders)))
            }
            Counts::Target {
                rule,
                sequence,
                background,
            } => {
                let size = (self.size, self.size);
                let base = self.renders.clone();
                let t = TargetImages::new(rule, base, keys, size, background, sequence)?;
                Ok((Phase::Target(Box::new(t)), None))
            }
        }
    }

    /// The EXR of render `i` of the last [`Self::next_renders`] (`origin`: where a
    /// cropped render lies) into its image; the file is deleted once read, and an image
    /// that holds all its frames is written.
    pub fn add_exr(&mut self, i: usize, path: &Path, origin: Option<(u32, u32)>) -> Result<()> {
        match &mut self.current {
            Some(Phase::Target(t)) => t.add_exr(i, path, origin),
            Some(Phase::Fixed(p)) => {
                let done = p.add_exr(i, path, origin, self.size)?;
                if let Some((key, mut image)) = done {
                    self.finish(&key, &mut image)?;
                }
                Ok(())
            }
            None => Err(Error::Value(format!("render {i}: no phase is in flight"))),
        }
    }

    fn finish(&mut self, key: &ImageKey, image: &mut Accumulator) -> Result<()> {
        if let Some(qa) = self.writer.finish(key, image)? {
            self.qa.insert(key.0, qa);
        }
        Ok(())
    }

    /// After the first phase: the first view whose sharp image fails render QA.
    fn judge_first_phase(&mut self) {
        let t = QaThresholds::default();
        self.failure = self.qa.iter().find_map(|(view, qa)| {
            t.verdict(qa)
                .map(|why| format!("render QA: view {view} is {why}"))
        });
    }

    /// Why the setting failed render QA (the renders stopped after the first phase).
    pub fn failure(&self) -> Option<&str> {
        self.failure.as_deref()
    }

    /// Phases started so far (1 while the sharp images render).
    pub fn phases_started(&self) -> u32 {
        self.started
    }

    /// The render QA of each view's sharp image, by view.
    pub fn qa(&self) -> &BTreeMap<usize, FrameQa> {
        &self.qa
    }

    /// Under a render target, each image's record (meta.json `views[].images`), in the
    /// order the images finished; none at fixed counts.
    pub fn records(&self) -> &[(ImageKey, ImageRender)] {
        &self.records
    }
}

impl FixedPhase {
    /// Add render `i`'s EXR to its image; the image, when it now holds all its frames.
    fn add_exr(
        &mut self,
        i: usize,
        path: &Path,
        origin: Option<(u32, u32)>,
        size: u32,
    ) -> Result<Option<(ImageKey, Accumulator)>> {
        let key = self.images.get(i).cloned().ok_or_else(|| {
            Error::Value(format!(
                "render {i} was not asked for (the phase has {})",
                self.images.len()
            ))
        })?;
        let (guides, share) = (self.guides, self.shares.get(i).copied().unwrap_or(1.0));
        let a = self.open.entry(key.clone()).or_insert_with(|| {
            if guides {
                Accumulator::with_guides(size, size).with_share(share)
            } else {
                Accumulator::new(size, size).with_share(share)
            }
        });
        a.add_exr_at(path, origin)?;
        std::fs::remove_file(path).map_err(|e| Error::io("cannot remove", path, e))?;
        let need = self.need.get_mut(&key).ok_or_else(|| {
            Error::Value(format!(
                "render {i}: view {} {} is not of this phase",
                key.0, key.1
            ))
        })?;
        *need -= 1;
        if *need > 0 {
            return Ok(None);
        }
        self.need.remove(&key);
        Ok(self.open.remove(&key).map(|a| (key, a)))
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // a failing unwrap is a failing test
mod tests {
    use super::*;
    use crate::image::exr::write::write_exr;
    use crate::plan::config::BuildConfig;
    use crate::plan::renders::with_samples;
    use crate::plan::sampling::plan_setting;
    use std::collections::BTreeSet;

    const SIZE: u32 = 16;

    /// A stand-in render: the object (grey, opaque) over the left `cover` of the image.
    fn render(r: &Render, cover: f32) -> Result<()> {
        let rgba: Vec<f32> = (0..SIZE * SIZE)
            .flat_map(|i| {
                let a = if ((i % SIZE) as f32) < cover * SIZE as f32 {
                    1.0
                } else {
                    0.0
                };
                [0.4 * a, 0.4 * a, 0.4 * a, a]
            })
            .collect();
        write_exr(Path::new(&r.out), SIZE, SIZE, &rgba)
    }

    fn session(dir: &Path) -> Result<Session> {
        let cfg = BuildConfig {
            views: 2,
            levels: vec![1],
            defocus: vec![2],
            latents: 2,
            resolution: SIZE,
            downsample: vec![2],
            passes: vec!["mask".into()],
            ..Default::default()
        };
        let plan = plan_setting(&cfg.sampling(), "u", 90.0, 5, [1.0, 0.5, 0.5], &[])?;
        let exr = dir.join(".frames");
        std::fs::create_dir_all(&exr).map_err(|e| Error::io("mkdir", &exr, e))?;
        let renders = with_samples(plan.renders_except(&exr, &[], None), 4);
        let writer = ImageWriter::new(dir, &cfg, 2, &renders, None)?;
        Ok(Session::new(renders, Counts::Fixed, SIZE, false, writer))
    }

    fn scratch(name: &str) -> std::path::PathBuf {
        std::env::temp_dir().join(format!("blurset-session-{name}-{}", std::process::id()))
    }

    #[test]
    fn phases_render_in_order_and_every_image_is_written() -> Result<()> {
        let dir = scratch("fixed");
        let mut s = session(&dir)?;
        let mut phases = Vec::new();
        loop {
            let renders = s.next_renders()?;
            if renders.is_empty() {
                break;
            }
            // One phase at a time: the sharp images (QA'd) first, then each kind's.
            let kinds: BTreeSet<u32> = renders.iter().map(|r| r.phase).collect();
            assert_eq!(kinds.len(), 1, "{kinds:?}");
            phases.extend(kinds);
            for (i, r) in renders.iter().enumerate() {
                render(r, 0.5)?;
                s.add_exr(i, Path::new(&r.out), None)?;
                assert!(!Path::new(&r.out).exists(), "an EXR is deleted once read");
            }
        }
        assert_eq!(phases, vec![0, 1, 2]);
        assert_eq!((s.failure(), s.qa().len(), s.records().len()), (None, 2, 0));
        for level in ["sharp", "blur_1", "defocus_2"] {
            for view in ["000.png", "001.png"] {
                for sub in ["images", "images_2"] {
                    assert!(
                        dir.join(level).join(sub).join(view).is_file(),
                        "{level} {sub}"
                    );
                }
            }
        }
        // Masks: the sharp image's, and a moving exposure's own; defocus shares the sharp.
        assert!(dir.join("sharp/masks/000.png").is_file());
        assert!(dir.join("blur_1/masks_2/001.png").is_file());
        assert!(!dir.join("defocus_2/masks").exists());
        let _ = std::fs::remove_dir_all(&dir);
        Ok(())
    }

    #[test]
    fn a_failed_render_qa_stops_before_the_next_phase() -> Result<()> {
        let dir = scratch("qa");
        let mut s = session(&dir)?;
        let renders = s.next_renders()?;
        assert!(renders.iter().all(|r| r.phase == 0));
        for (i, r) in renders.iter().enumerate() {
            render(r, 0.0)?; // nothing of the object in frame
            s.add_exr(i, Path::new(&r.out), None)?;
        }
        assert!(
            s.next_renders()?.is_empty(),
            "no blur render after a failed QA"
        );
        let why = s.failure().unwrap();
        assert!(why.starts_with("render QA: view 0 is empty"), "{why}");
        assert!(s.add_exr(0, &dir.join("x.exr"), None).is_err());
        let _ = std::fs::remove_dir_all(&dir);
        Ok(())
    }
}
