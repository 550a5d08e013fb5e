//! Rendering each image to a render-noise target (`--target-psnr`, DESIGN §8): an image is
//! rendered as two halves on independent Cycles sequences, in rounds; after each round its
//! own render noise is estimated from the two halves (the noise of their mean is
//! MSE(h₁, h₂) / 4, on its object pixels: `metrics::half_noise`) and the samples still
//! needed are extrapolated from it, so each image renders what it needs and no more.
//!
//! Every round of an image renders each of its m frames (1 for a sharp image) once per
//! half, the same number of samples each, as the next block of that half's sequence: a
//! half is always the first samples of one sequence split over its frames, so at zero
//! motion a blurry image's half is the sharp image's half with as many samples, and
//! the pair lands on one sample count by construction. Nothing depends on timing: the
//! rounds follow from rendered pixels, which Cycles makes the same on every run.
use super::renders::Render;
use crate::rng::derive_seed;
use serde::{Deserialize, Serialize};

/// Extrapolated samples aim this far above the target (dB): the estimate of a round is
/// itself noisy, and one more round costs a render call per frame and half.
pub const AIM_ABOVE_DB: f64 = 0.2;

/// A final estimate this far under the target (dB) is accepted: the next round would buy
/// less than the estimate's own scatter.
pub const ACCEPT_BELOW_DB: f64 = 0.25;

/// Rounds of one image at most (pilot included); the record says when the target was
/// not reached within them or within the sample cap.
pub const MAX_ROUNDS: u32 = 6;

/// The most one round multiplies an image's samples by before the noise has been seen to
/// fall (a pilot estimate far off, e.g. on an image whose pilot saw almost no object
/// pixel, must not commit the image to its cap in one step).
pub const FIRST_STEP_MAX: f64 = 8.0;

/// The range the fitted exponent of noise against samples (MSE ∝ samples^-α) is held in:
/// 1 is plain Monte Carlo, 2 a smooth integrand under a good stratification.
pub const ALPHA_RANGE: (f64, f64) = (1.0, 2.0);

/// The rule of a target-driven build.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct TargetRule {
    /// Render PSNR (dB, peak 1, on the object's pixels) each image is rendered to.
    pub target_psnr_db: f64,
    /// Samples of an image's first round, both halves together (at least one per frame
    /// and half).
    pub pilot_samples: u32,
    /// Most samples of one image, both halves together (the Cycles sequence of every
    /// render is half of it).
    pub max_samples: u32,
}

/// Where one image stands: its frames m ([`layers`]), the samples each has rendered per
/// half so far, the rounds so far, and the last estimate of its render noise (the MSE of the
/// mean of its halves, on object pixels; None before the first round), with the one
/// before it (samples per frame and half then, and its MSE) once there are two.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ImageState {
    pub frames: u32,
    pub spent_per_frame: u32,
    pub rounds: u32,
    pub mse: Option<f64>,
    pub previous: Option<(u32, f64)>,
}

impl TargetRule {
    /// The MSE the target is.
    pub fn target_mse(&self) -> f64 {
        10f64.powf(-self.target_psnr_db / 10.0)
    }

    /// Whether an image whose render noise is `mse` is at the target: within
    /// [`ACCEPT_BELOW_DB`] under it (its record's `reached`, and where its rounds stop).
    pub fn reached(&self, mse: f64) -> bool {
        mse <= self.target_mse() * 10f64.powf(ACCEPT_BELOW_DB / 10.0)
    }

    /// The Cycles sequence every render of a target-driven build takes its blocks of.
    pub fn sequence(&self) -> u32 {
        (self.max_samples / 2).max(1)
    }

    /// The fewest `max_samples` an image of `frames` latent frames can render under: one
    /// sample per frame and half, its frames' blocks inside the [`Self::sequence`] of
    /// half of it (fewer would put a frame's block past the end of the sequence).
    pub fn least_max_samples(frames: usize) -> u64 {
        2 * frames.max(1) as u64
    }

    /// Samples per frame and half of the pilot round of an image of `frames` frames.
    pub fn pilot_per_frame(&self, frames: u32) -> u32 {
        let per_half = (self.pilot_samples / 2).max(1);
        per_half
            .div_ceil(frames.max(1))
            .min(self.cap_per_frame(frames))
    }

    /// The most samples a frame may render per half: the sequence split over the frames.
    fn cap_per_frame(&self, frames: u32) -> u32 {
        (self.sequence() / frames.max(1)).max(1)
    }

    /// Samples per frame and half of the image's next round, or None when it is done: the
    /// estimate reached the target (within [`ACCEPT_BELOW_DB`]), or the cap or
    /// [`MAX_ROUNDS`] stops it. Render noise falls as samples^-α: from two estimates α is
    /// fitted (within [`ALPHA_RANGE`]); from the pilot alone it is taken at the top of
    /// that range (the fewest samples) and the step held to [`FIRST_STEP_MAX`]. Samples
    /// a first step buys too few cost one more round, which then knows α; samples it
    /// buys too many are spent for good (1 / N from the pilot made the smooth demo
    /// objects land 3–6 dB above a 45 dB target, about twice the samples they needed).
    /// The samples that reach the target, aimed [`AIM_ABOVE_DB`] above it, are the spent
    /// ones times (estimate / target)^(1/α).
    pub fn next_round(&self, s: &ImageState) -> Option<u32> {
        let Some(mse) = s.mse else {
            return Some(self.pilot_per_frame(s.frames));
        };
        let target = self.target_mse();
        let cap = self.cap_per_frame(s.frames);
        if s.rounds >= MAX_ROUNDS || s.spent_per_frame >= cap || !mse.is_finite() {
            return None;
        }
        if self.reached(mse) {
            return None;
        }
        let aim = target * 10f64.powf(-AIM_ABOVE_DB / 10.0);
        let spent = f64::from(s.spent_per_frame);
        let fitted = s.previous.and_then(|(n0, mse0)| {
            let (n0, n1) = (f64::from(n0), spent);
            (n0 > 0.0 && n1 > n0 && mse0 > 0.0 && mse > 0.0)
                .then(|| ((mse0 / mse).ln() / (n1 / n0).ln()).clamp(ALPHA_RANGE.0, ALPHA_RANGE.1))
        });
        let need = match fitted {
            Some(alpha) => (spent * (mse / aim).powf(1.0 / alpha)).ceil(),
            None => (spent * (mse / aim).powf(1.0 / ALPHA_RANGE.1))
                .min(spent * FIRST_STEP_MAX)
                .ceil(),
        };
        let total = if need >= f64::from(cap) {
            cap
        } else {
            need as u32
        };
        let add = total.saturating_sub(s.spent_per_frame).max(1);
        Some(add.min(cap - s.spent_per_frame))
    }
}

/// The Cycles seed of half `half` (0 or 1) of an image whose plan gives it `seed`: half 0
/// keeps the plan's seed (the sequence an untargeted build renders), half 1 takes an
/// independent one derived from it.
pub fn half_seed(seed: u32, half: u32) -> u32 {
    if half == 0 {
        seed
    } else {
        (derive_seed(u64::from(seed), &[0x6861_6c66, u64::from(half)]) & 0x7fff_ffff) as u32
    }
}

/// One round of one image: its view and level, how many samples per frame and half
/// it adds and how many each frame rendered before, and which round it is (EXR names).
#[derive(Clone, Debug, PartialEq)]
pub struct ImageRound {
    pub view: usize,
    pub level: String,
    pub spent_per_frame: u32,
    pub add_per_frame: u32,
    pub round: u32,
}

/// The renders each pixel of an image of `frames` gets per half and round, which its
/// pilot, cap and record count: every frame, or one of n bands that tile the image (a
/// rolling shutter's, each rendering only its rows, as the sharp image does).
pub fn layers(frames: &[&Render]) -> u32 {
    let bands = frames.first().and_then(|f| f.band);
    bands.map_or(frames.len() as u32, |_| 1)
}

/// The renders of `rounds`, made from the plan's renders `base` of the same images (their
/// cameras, motion and regions): for each image, half 0's frames then half 1's, frame
/// k of m taking the block `m · spent + k · add` of length `add` of a `sequence`-sample
/// Cycles sequence on its half's seed (m its [`layers`]: every band takes the block a
/// sharp image would). Each (image, round, plan call) is one render call.
pub fn round_renders(base: &[Render], rounds: &[ImageRound], sequence: u32) -> Vec<Render> {
    let mut out = Vec::new();
    let mut call = 0usize;
    for r in rounds {
        let frames: Vec<&Render> = base
            .iter()
            .filter(|f| f.view == r.view && f.level == r.level)
            .collect();
        let m = layers(&frames);
        // The plan's calls of this image, in order (a frame without one is its own): each
        // stays one call per half.
        let mut runs: Vec<Vec<u32>> = Vec::new();
        for (k, f) in frames.iter().enumerate() {
            match runs.last_mut() {
                Some(run) if f.call.is_some() && frames[run[0] as usize].call == f.call => {
                    run.push(k as u32)
                }
                _ => runs.push(vec![k as u32]),
            }
        }
        for run in &runs {
            for half in 0..2u32 {
                for &k in run {
                    let f = frames[k as usize];
                    let stem = f.out.strip_suffix(".exr").unwrap_or(&f.out);
                    out.push(Render {
                        seed: half_seed(f.seed, half),
                        samples: Some(r.add_per_frame),
                        sample_offset: Some(m * r.spent_per_frame + k % m * r.add_per_frame),
                        sample_sequence: Some(sequence),
                        out: format!("{stem}_r{}{}.exr", r.round, ["a", "b"][half as usize]),
                        call: Some(call),
                        half: Some(half),
                        ..f.clone()
                    });
                }
                call += 1;
            }
        }
    }
    out
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // a failing unwrap is a failing test
mod tests {
    use super::*;

    const RULE: TargetRule = TargetRule {
        target_psnr_db: 40.0,
        pilot_samples: 32,
        max_samples: 8192,
    };

    fn state(frames: u32, spent: u32, rounds: u32, mse: Option<f64>) -> ImageState {
        ImageState {
            frames,
            spent_per_frame: spent,
            rounds,
            mse,
            previous: None,
        }
    }

    #[test]
    fn pilot_splits_its_samples_over_the_frames() {
        assert_eq!(RULE.next_round(&state(1, 0, 0, None)), Some(16));
        assert_eq!(RULE.next_round(&state(4, 0, 0, None)), Some(4));
        // At least one sample per frame and half.
        assert_eq!(RULE.next_round(&state(40, 0, 0, None)), Some(1));
    }

    #[test]
    fn the_pilot_fits_the_sequence_its_frames_split() {
        // Every pilot the config accepts (pilot <= max) of every image the config accepts
        // (frames <= the sequence, `BuildConfig::check_target`): its m frames' blocks lie
        // inside the sequence. 32 of 32 over 3 frames: 16 a half, 6 a frame would end at
        // 18, past the 16 samples of the sequence.
        for max in 2..=40 {
            for pilot in 1..=max {
                let rule = TargetRule {
                    pilot_samples: pilot,
                    max_samples: max,
                    ..RULE
                };
                for frames in 1..=rule.sequence() {
                    let n = rule.pilot_per_frame(frames);
                    assert!(n >= 1, "{pilot}/{max}, {frames} frames");
                    assert!(
                        frames * n <= rule.sequence(),
                        "{pilot}/{max}, {frames} frames: {n} a frame"
                    );
                }
            }
        }
    }

    #[test]
    fn extrapolates_from_the_pilot_at_the_fastest_fall_and_stops_at_the_target() {
        // 5x the target's MSE after 16 samples: as samples^-2, 16 * sqrt(5) samples,
        // aimed 0.2 dB above.
        let add = RULE.next_round(&state(1, 16, 1, Some(5e-4))).unwrap();
        let total = 16 + add;
        let expect = 16.0 * (5e-4 / (1e-4 * 10f64.powf(-0.02))).sqrt();
        assert_eq!(total, expect.ceil() as u32);
        // A harder image (more noise at the same samples) gets more.
        let harder = RULE.next_round(&state(1, 16, 1, Some(4e-3))).unwrap();
        assert!(harder > add);
        // At the target, or within the accepted 0.25 dB: done.
        assert_eq!(RULE.next_round(&state(1, 176, 2, Some(1e-4))), None);
        assert_eq!(RULE.next_round(&state(1, 176, 2, Some(1.05e-4))), None);
        assert!(RULE.next_round(&state(1, 176, 2, Some(1.1e-4))).is_some());
        // A flat image (no object pixels: exact) is done after its pilot.
        assert_eq!(RULE.next_round(&state(1, 16, 1, Some(0.0))), None);
    }

    #[test]
    fn the_first_step_is_bounded_and_the_second_fits_the_exponent() {
        // 10^4 x the target after the pilot: at most 8x the samples before the fall is
        // seen (as samples^-2 it would be 100x).
        assert_eq!(
            RULE.next_round(&state(1, 16, 1, Some(1.0))),
            Some(16 * 8 - 16)
        );
        // 25x: as samples^-2, 5x (and a bit for the aim), under the bound.
        let add = RULE.next_round(&state(1, 16, 1, Some(2.5e-3))).unwrap();
        assert_eq!(16 + add, (80.0 * 10f64.powf(0.01)).ceil() as u32);
        // From 16 to 128 samples the MSE fell 8^1.5 times: α = 1.5, so the rest of the
        // way (10^0.5 · 10^0.02 in MSE) needs that to the power 1/1.5.
        let s = ImageState {
            previous: Some((16, 1e-2)),
            ..state(1, 128, 2, Some(1e-2 / 8f64.powf(1.5)))
        };
        let mse = 1e-2 / 8f64.powf(1.5);
        let expect = (128.0 * (mse / (1e-4 * 10f64.powf(-0.02))).powf(1.0 / 1.5)).ceil() as u32;
        assert_eq!(RULE.next_round(&s), Some(expect - 128));
        // The exponent is held in [1, 2]: a noise that did not fall is taken as 1 / N.
        let flat = ImageState {
            previous: Some((16, 1e-3)),
            ..state(1, 32, 2, Some(1e-3))
        };
        let one_over_n = (32.0 * 1e-3 / (1e-4 * 10f64.powf(-0.02))).ceil() as u32;
        assert_eq!(RULE.next_round(&flat), Some(one_over_n - 32));
    }

    #[test]
    fn reached_is_where_the_rounds_stop() {
        let mse_at = |db: f64| 10f64.powf(-db / 10.0);
        let target = RULE.target_psnr_db;
        assert!(RULE.reached(mse_at(target + 3.0)));
        assert!(RULE.reached(mse_at(target - ACCEPT_BELOW_DB + 0.01)));
        assert!(!RULE.reached(mse_at(target - ACCEPT_BELOW_DB - 0.01)));
        for db in [target - 0.26, target - 0.24, target + 1.0] {
            let s = ImageState {
                frames: 2,
                spent_per_frame: 8,
                rounds: 1,
                mse: Some(mse_at(db)),
                previous: None,
            };
            assert_eq!(
                RULE.next_round(&s).is_none(),
                RULE.reached(mse_at(db)),
                "{db}"
            );
        }
    }

    #[test]
    fn cap_and_round_limit_stop_an_image() {
        let cap = RULE.sequence() / 8;
        let far = ImageState {
            previous: Some((1, 1.0)),
            ..state(8, 2, 2, Some(1.0))
        };
        let add = RULE.next_round(&far).unwrap();
        assert_eq!(2 + add, cap);
        assert_eq!(RULE.next_round(&state(8, cap, 2, Some(1.0))), None);
        assert_eq!(RULE.next_round(&state(1, 16, MAX_ROUNDS, Some(1.0))), None);
    }

    #[test]
    fn halves_are_independent_and_stable() {
        assert_eq!(half_seed(17, 0), 17);
        assert_ne!(half_seed(17, 1), 17);
        assert_eq!(half_seed(17, 1), half_seed(17, 1));
        assert!(half_seed(u32::MAX, 1) <= i32::MAX as u32);
    }

    fn frame(view: usize, level: &str, k: usize, call: Option<usize>) -> Render {
        let kind = crate::plan::kind::ImageKind::parse(level).expect("level");
        Render {
            view,
            level: level.into(),
            kind,
            phase: kind.phase(),
            c2w: [[k as f64; 4]; 4],
            seed: 5,
            samples: Some(3),
            sample_offset: Some(0),
            sample_sequence: Some(9),
            out: format!("/x/{view:04}_{level}_{k:04}.exr"),
            motion: None,
            region: None,
            call,
            half: None,
            dof: None,
            band: None,
            rolling_shutter: None,
        }
    }

    #[test]
    fn round_renders_take_consecutive_blocks_per_half() {
        let base = vec![
            frame(0, "sharp", 0, Some(0)),
            frame(0, "blur_1", 0, Some(1)),
            frame(0, "blur_1", 1, Some(1)),
            frame(0, "blur_1", 2, Some(2)),
        ];
        let rounds = [ImageRound {
            view: 0,
            level: "blur_1".into(),
            spent_per_frame: 4,
            add_per_frame: 6,
            round: 2,
        }];
        let r = round_renders(&base, &rounds, 4096);
        assert_eq!(r.len(), 6);
        // Plan call 1 (frames 0, 1) per half, then plan call 2 (frame 2) per half.
        let calls: Vec<_> = r.iter().map(|f| f.call.unwrap()).collect();
        assert_eq!(calls, [0, 0, 1, 1, 2, 3]);
        let offsets: Vec<_> = r.iter().map(|f| f.sample_offset.unwrap()).collect();
        assert_eq!(offsets, [12, 18, 12, 18, 24, 24]);
        assert!(r
            .iter()
            .all(|f| f.samples == Some(6) && f.sample_sequence == Some(4096)));
        assert_eq!((r[0].seed, r[2].seed), (5, half_seed(5, 1)));
        assert_eq!(r[0].out, "/x/0000_blur_1_0000_r2a.exr");
        assert_eq!(r[3].out, "/x/0000_blur_1_0001_r2b.exr");
        assert_eq!(r[1].c2w, base[2].c2w);
        let halves: Vec<_> = r.iter().map(|f| f.half.unwrap()).collect();
        assert_eq!(halves, [0, 0, 1, 1, 0, 1]);
    }
}
