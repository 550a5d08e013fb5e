//! The target loop of a `--target-psnr` build (DESIGN §8): the images of one render phase,
//! each held as its two halves, rendered in rounds until [`TargetRule::next_round`] says
//! it is done. The rules are `plan/target.rs`'s and the estimate `metrics`'s; this is
//! where they meet the pixels, so no image leaves the core between rounds: the builder
//! asks for the next renders, hands back the EXRs the worker wrote, and takes each
//! finished image (its halves merged) with its record.
//!
//! A few images are in flight at once ([`GROUP`]) so memory stays bounded at any
//! resolution; the next group starts when every image of the last one is done, so the
//! rounds, their render calls and their EXR names follow from rendered pixels alone.
use super::meta::{round_to, ImageRender};
use crate::error::{Error, Result};
use crate::image::accumulate::Accumulator;
use crate::metrics::{half_noise_bound, HalfNoise};
use crate::plan::renders::Render;
use crate::plan::target::{layers, round_renders, ImageRound, ImageState, TargetRule};
use std::collections::VecDeque;
use std::path::Path;

/// Images whose halves are in flight at once (two accumulators each): 8 MB a half at
/// 512 px.
pub const GROUP: usize = 8;

/// One image of a target-driven build: (view, level).
pub type ImageKey = (usize, String);

/// One image in flight: both halves, where its rounds stand, and its last estimate.
struct Image {
    key: ImageKey,
    /// Its renders per half and round, and those each pixel gets ([`layers`]).
    frames: u32,
    layers: u32,
    halves: [Accumulator; 2],
    spent: u32,
    rounds: u32,
    /// [`half_noise_bound`] of the last round: the estimate and the bound the rounds
    /// stop on (a few fireflies on a specular surface make one round's estimate scatter).
    estimate: Option<HalfNoise>,
    /// (samples per frame and half, MSE bound) of the round before the last.
    previous: Option<(u32, f64)>,
    /// The bound after the pilot round: what the rest was extrapolated from.
    pilot_db: f64,
    /// EXRs each half received in the round in flight (each frame once per half).
    got: [u32; 2],
}

impl Image {
    fn state(&self) -> ImageState {
        ImageState {
            frames: self.layers,
            spent_per_frame: self.spent,
            rounds: self.rounds,
            mse: self.estimate.map(|e| e.mse_bound),
            previous: self.previous,
        }
    }

    /// A round of `add` samples per frame and half is in both halves: estimate anew.
    fn rendered(&mut self, add: u32, background: [f64; 3]) -> Result<()> {
        if self.got != [self.frames; 2] {
            return Err(Error::Value(format!(
                "view {} {}: a round needs {} EXRs per half, the worker delivered {:?}",
                self.key.0, self.key.1, self.frames, self.got
            )));
        }
        self.got = [0; 2];
        if let Some(e) = self.estimate {
            self.previous = Some((self.spent, e.mse_bound));
        }
        self.spent += add;
        self.rounds += 1;
        let [a, b] = &self.halves;
        let e = half_noise_bound(&a.mean()?, &b.mean()?, background)?;
        if self.rounds == 1 {
            self.pilot_db = e.psnr_bound;
        }
        self.estimate = Some(e);
        Ok(())
    }

    fn record(&self, rule: &TargetRule) -> Result<ImageRender> {
        let h = self.estimate.ok_or_else(|| {
            Error::Value(format!(
                "view {} {}: no round rendered",
                self.key.0, self.key.1
            ))
        })?;
        Ok(ImageRender {
            samples: 2 * u64::from(self.layers) * u64::from(self.spent),
            rounds: self.rounds,
            render_psnr_db: round_to(h.estimate.psnr, 3),
            render_psnr_bound_db: Some(round_to(h.psnr_bound, 3)),
            pilot_psnr_db: round_to(self.pilot_db, 3),
            coverage: round_to(h.estimate.coverage, 6),
            reached: rule.reached(h.mse_bound),
        })
    }
}

/// A finished image: the mean of both halves (every frame weighted by its samples) and
/// its record in meta.json.
pub struct Finished {
    pub key: ImageKey,
    pub image: Accumulator,
    pub record: ImageRender,
}

/// The images of one render phase rendered to the target (see the module).
pub struct TargetImages {
    rule: TargetRule,
    background: [f64; 3],
    size: (u32, u32),
    /// The Cycles sequence every block is taken of.
    sequence: u32,
    /// The plan's renders of these images (cameras, motion, regions, seeds).
    base: Vec<Render>,
    waiting: VecDeque<ImageKey>,
    group: Vec<Image>,
    /// The renders asked for last: (image in `group`, half), in their order.
    asked: Vec<(usize, usize)>,
    /// Samples per frame and half of the round in flight, per image in `group`.
    adds: Vec<Option<u32>>,
    finished: Vec<Finished>,
    records: Vec<(ImageKey, ImageRender)>,
}

impl TargetImages {
    /// The images `keys` of the plan's renders `base` (`renders_except` at the rule's
    /// sequence), rendered to `rule` at `size`, noise judged over `background`.
    pub fn new(
        rule: TargetRule,
        base: Vec<Render>,
        keys: &[ImageKey],
        size: (u32, u32),
        background: [f64; 3],
        sequence: u32,
    ) -> Result<Self> {
        let mut waiting = VecDeque::new();
        for k in keys {
            if !base.iter().any(|r| r.view == k.0 && r.level == k.1) {
                return Err(Error::Value(format!(
                    "the plan has no render of view {} at {}",
                    k.0, k.1
                )));
            }
            if !waiting.contains(k) {
                waiting.push_back(k.clone());
            }
        }
        Ok(TargetImages {
            rule,
            background,
            size,
            sequence,
            base,
            waiting,
            group: Vec::new(),
            asked: Vec::new(),
            adds: Vec::new(),
            finished: Vec::new(),
            records: Vec::new(),
        })
    }

    /// The renders of the next round of every image in flight that needs one, after the
    /// round the worker just delivered is estimated; an image that is done leaves (for
    /// [`Self::take_finished`]). The next group starts when one is all done. Empty: every
    /// image is done.
    pub fn next_renders(&mut self) -> Result<Vec<Render>> {
        for (im, add) in self.group.iter_mut().zip(&self.adds) {
            if let Some(add) = add {
                im.rendered(*add, self.background)?;
            }
        }
        self.adds.clear();
        self.asked.clear();
        loop {
            let rounds = self.rounds()?;
            if !rounds.is_empty() {
                return Ok(self.ask(&rounds));
            }
            if self.waiting.is_empty() {
                return Ok(Vec::new());
            }
            let n = GROUP.min(self.waiting.len());
            let keys: Vec<ImageKey> = self.waiting.drain(..n).collect();
            for key in keys {
                let frames: Vec<&Render> = self
                    .base
                    .iter()
                    .filter(|r| r.view == key.0 && r.level == key.1)
                    .collect();
                let share = frames.first().map_or(1.0, |r| r.share());
                let (w, h) = self.size;
                let half = || Accumulator::new(w, h).with_share(share);
                self.group.push(Image {
                    frames: frames.len() as u32,
                    layers: layers(&frames),
                    key,
                    halves: [half(), half()],
                    spent: 0,
                    rounds: 0,
                    estimate: None,
                    previous: None,
                    pilot_db: 0.0,
                    got: [0; 2],
                });
            }
        }
    }

    /// The next round of every image of the group that needs one; an image that is done
    /// leaves the group, its halves merged.
    fn rounds(&mut self) -> Result<Vec<ImageRound>> {
        let mut rounds = Vec::new();
        let mut kept = Vec::new();
        for mut im in std::mem::take(&mut self.group) {
            match self.rule.next_round(&im.state()) {
                None => {
                    let record = im.record(&self.rule)?;
                    let [mut a, b] = im.halves;
                    a.merge(&b)?;
                    self.records.push((im.key.clone(), record));
                    self.finished.push(Finished {
                        key: im.key,
                        image: a,
                        record,
                    });
                }
                Some(add) => {
                    rounds.push(ImageRound {
                        view: im.key.0,
                        level: im.key.1.clone(),
                        spent_per_frame: im.spent,
                        add_per_frame: add,
                        round: im.rounds + 1,
                    });
                    im.got = [0; 2];
                    kept.push(im);
                }
            }
        }
        self.group = kept;
        Ok(rounds)
    }

    /// The renders of `rounds` (one per image of the group, in its order), remembered so
    /// each EXR the worker delivers finds its image and half.
    fn ask(&mut self, rounds: &[ImageRound]) -> Vec<Render> {
        let renders = round_renders(&self.base, rounds, self.sequence);
        self.adds = rounds.iter().map(|r| Some(r.add_per_frame)).collect();
        self.asked = renders
            .iter()
            .map(|r| {
                let i = rounds
                    .iter()
                    .position(|x| x.view == r.view && x.level == r.level)
                    .unwrap_or_default();
                (i, r.half.unwrap_or_default() as usize)
            })
            .collect();
        renders
    }

    /// The EXR of render `i` of the last [`Self::next_renders`] (`origin`: where a
    /// cropped render lies) into its image's half, weighted by the samples each frame
    /// rendered this round; the file is deleted once read.
    pub fn add_exr(&mut self, i: usize, path: &Path, origin: Option<(u32, u32)>) -> Result<()> {
        let &(im, half) = self.asked.get(i).ok_or_else(|| {
            Error::Value(format!(
                "render {i} was not asked for (the last round has {})",
                self.asked.len()
            ))
        })?;
        let add = self.adds[im].unwrap_or_default();
        let image = &mut self.group[im];
        image.halves[half].add_exr_weighted(path, origin, f64::from(add))?;
        image.got[half] += 1;
        std::fs::remove_file(path).map_err(|e| Error::io("cannot remove", path, e))
    }

    /// The images done since the last call, in the order they finished.
    pub fn take_finished(&mut self) -> Vec<Finished> {
        std::mem::take(&mut self.finished)
    }

    /// The record of every image done so far, in the order they finished.
    pub fn records(&self) -> &[(ImageKey, ImageRender)] {
        &self.records
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // a failing unwrap is a failing test
mod tests {
    use super::*;
    use crate::image::exr::write::write_exr;
    use crate::plan::config::BuildConfig;
    use crate::plan::sampling::plan_setting;
    use crate::rng::derive_seed;
    use std::collections::BTreeMap;

    const SIZE: u32 = 16;
    const RULE: TargetRule = TargetRule {
        target_psnr_db: 30.0,
        pilot_samples: 8,
        max_samples: 4096,
    };

    /// A stand-in render: grey 0.5 everywhere plus noise that falls as 1 / √samples,
    /// drawn from its seed and sample block (independent halves, reproducible); a band's
    /// only over its rows. Returns where it lies.
    fn render(r: &Render) -> Result<Option<(u32, u32)>> {
        let n = f64::from(r.samples.unwrap());
        let key = u64::from(r.seed) << 32 | u64::from(r.sample_offset.unwrap());
        let [top, bottom] = r.band.map_or([0, SIZE], |b| b.rows);
        let px = u64::from(SIZE * (bottom - top));
        let rgba: Vec<f32> = (0..px)
            .flat_map(|i| {
                let u = (derive_seed(key, &[i]) >> 11) as f64 / (1u64 << 53) as f64;
                let v = (0.5 + (u - 0.5) / n.sqrt()) as f32;
                [v, v, v, 1.0]
            })
            .collect();
        write_exr(Path::new(&r.out), SIZE, bottom - top, &rgba)?;
        Ok(r.band.map(|_| (0, top)))
    }

    fn images(dir: &Path, rolling_shutter: Vec<u32>) -> Result<(Vec<Render>, Vec<ImageKey>)> {
        let cfg = BuildConfig {
            views: 2,
            levels: vec![1],
            latents: 2,
            rolling_shutter,
            resolution: SIZE,
            ..Default::default()
        };
        let plan = plan_setting(&cfg.sampling(), "u", 90.0, 5, [1.0, 0.5, 0.5], &[])?;
        let base = plan.renders_except(dir, &[], Some(RULE.sequence()));
        let mut keys: Vec<ImageKey> = Vec::new();
        for r in &base {
            let k = (r.view, r.level.clone());
            if !keys.contains(&k) {
                keys.push(k);
            }
        }
        Ok((base, keys))
    }

    fn scratch(name: &str) -> Result<std::path::PathBuf> {
        let dir = std::env::temp_dir().join(format!("blurset-{name}-{}", std::process::id()));
        std::fs::create_dir_all(&dir).map_err(|e| Error::io("mkdir", &dir, e))?;
        Ok(dir)
    }

    #[test]
    fn every_image_renders_to_the_target_and_leaves_once() -> Result<()> {
        let dir = scratch("target-loop")?;
        let (base, keys) = images(&dir, vec![])?;
        let frames = |k: &ImageKey| {
            base.iter()
                .filter(|r| (r.view, &r.level) == (k.0, &k.1))
                .count()
        };
        let frames: Vec<(ImageKey, u32)> =
            keys.iter().map(|k| (k.clone(), frames(k) as u32)).collect();
        let mut t = TargetImages::new(RULE, base, &keys, (SIZE, SIZE), [1.0; 3], RULE.sequence())?;
        let mut done = Vec::new();
        let mut rounds = 0;
        loop {
            let renders = t.next_renders()?;
            for f in t.take_finished() {
                // Both halves merged: every frame of every round, once per half.
                let m = frames.iter().find(|(k, _)| *k == f.key).unwrap().1;
                assert_eq!(f.image.count(), 2 * m * f.record.rounds, "{:?}", f.key);
                done.push(f.key);
            }
            if renders.is_empty() {
                break;
            }
            rounds += 1;
            for (i, r) in renders.iter().enumerate() {
                let at = render(r)?;
                t.add_exr(i, Path::new(&r.out), at)?;
                assert!(!Path::new(&r.out).exists(), "an EXR is deleted once read");
            }
        }
        // Every image once, in the order their rounds stopped; each reached the target,
        // which its pilot (4 samples a frame and half) was far from.
        let (mut a, mut b) = (done.clone(), keys.clone());
        a.sort();
        b.sort();
        assert_eq!(a, b);
        assert!(rounds >= 2);
        for (key, r) in t.records() {
            assert!(r.reached, "{key:?}: {r:?}");
            assert!(
                r.rounds >= 2 && r.pilot_psnr_db < RULE.target_psnr_db,
                "{key:?}: {r:?}"
            );
            assert!(
                r.render_psnr_db >= RULE.target_psnr_db - 1.0,
                "{key:?}: {r:?}"
            );
        }
        let _ = std::fs::remove_dir_all(&dir);
        Ok(())
    }

    #[test]
    fn a_round_the_worker_did_not_deliver_whole_is_an_error() -> Result<()> {
        let dir = scratch("target-short")?;
        let (base, keys) = images(&dir, vec![])?;
        let mut t = TargetImages::new(RULE, base, &keys, (SIZE, SIZE), [1.0; 3], RULE.sequence())?;
        let renders = t.next_renders()?;
        for (i, r) in renders.iter().enumerate().skip(1) {
            let at = render(r)?;
            t.add_exr(i, Path::new(&r.out), at)?;
        }
        let err = t.next_renders().unwrap_err().to_string();
        assert!(err.contains("the worker delivered"), "{err}");
        assert!(t.add_exr(renders.len(), &dir.join("x.exr"), None).is_err());
        let _ = std::fs::remove_dir_all(&dir);
        Ok(())
    }

    #[test]
    fn records_count_the_samples_each_pixel_got_and_bands_take_the_sharp_budget() -> Result<()> {
        // A target the stand-in cannot reach in the rounds or the cap allowed, and one it
        // reaches: either way each image's record counts the samples its pixels got.
        for rule in [
            RULE,
            TargetRule {
                target_psnr_db: 90.0,
                max_samples: 64,
                ..RULE
            },
        ] {
            let dir = scratch("target-samples")?;
            let (base, keys) = images(&dir, vec![3])?;
            let mut t =
                TargetImages::new(rule, base, &keys, (SIZE, SIZE), [1.0; 3], rule.sequence())?;
            // Per image, the samples of its renders that cover the top-left pixel, and of
            // its first round's renders.
            let mut got: BTreeMap<ImageKey, (u64, Vec<u32>)> = BTreeMap::new();
            let mut first = true;
            loop {
                let renders = t.next_renders()?;
                if renders.is_empty() {
                    break;
                }
                for (i, r) in renders.iter().enumerate() {
                    let e = got.entry((r.view, r.level.clone())).or_default();
                    let n = r.samples.unwrap();
                    if r.band.is_none_or(|b| b.rows[0] == 0) {
                        e.0 += u64::from(n);
                    }
                    if first {
                        e.1.push(n);
                    }
                    let at = render(r)?;
                    t.add_exr(i, Path::new(&r.out), at)?;
                }
                first = false;
            }
            for (key, r) in t.records() {
                assert_eq!(r.samples, got[key].0, "{key:?}: {r:?}");
            }
            for v in 0..2 {
                let sharp = &got[&(v, "sharp".into())].1;
                let rs = &got[&(v, "rolling_shutter_3".into())].1;
                // Each band's pilot is the sharp image's, on its own rows.
                assert_eq!(rs.len(), 2 * sharp.len());
                assert!(rs.iter().all(|n| *n == sharp[0]), "{rs:?} {sharp:?}");
            }
            if rule.max_samples == 64 {
                // At the cap every image holds the cap per pixel, bands and frames alike.
                assert!(
                    t.records().iter().all(|(_, r)| r.samples == 64),
                    "{:?}",
                    t.records()
                );
            }
            let _ = std::fs::remove_dir_all(&dir);
        }
        Ok(())
    }
}
