//! What shapes the sampling of a setting (DESIGN §2): `SamplingConfig`, and the sample
//! budget of a blurry image (the parity and need factors, the sample blocks of its latent
//! frames, the one sequence every render is pinned to). Below the plan and every
//! degradation kind, which all read it; the plan checks a kind's levels against the
//! kind's own range (`sampling.rs`'s `validate`).
use super::camera::bounding_radius;
use super::kind_levels::KindLevels;
use super::spec::MAX_SAMPLES;
use super::weights::Guards;
use serde::{Deserialize, Serialize};

pub use super::choices::{
    BlurBudget, BlurMethod, LatentPositions, LatentSampling, TrajectoryAnchor,
};

/// The parity factor is m^PARITY_EXPONENT: measured on the demo box
/// (bench/bench_render_parity.py), m = 34 frames at S/m samples need ≈ 4 S to carry the
/// render noise of one S-sample frame once the camera moves ≳ 0.5 px per frame (their
/// blocks then sample unrelated content), and fewer frames need less (m = 1 needs none).
pub const PARITY_EXPONENT: f64 = 0.4;

/// How many times the budget an average of m latent frames gets under
/// [`BlurBudget::Parity`]: 1 for one frame, m^[`PARITY_EXPONENT`] (≈ 4.1 at the paper's 34).
pub fn parity_factor(m: usize) -> f64 {
    libm::pow(m.max(1) as f64, PARITY_EXPONENT)
}

/// Screen motion between consecutive latent frames (px) from which their sample blocks
/// stop sharing content and the parity penalty is whole: measured on the demo box at 96
/// px (bench/bench_render_parity.py, m = 34, flat budget): the factor a level needs is
/// 1.55 at 0.15 px per frame, ≈ 2.2 at 0.29 px, ≈ 2.8 at 0.42 px and ≈ 4 (m^0.4) at
/// 0.56 px.
pub const NEED_SATURATION_PX: f64 = 0.5;

/// How many times the budget an average of m latent frames gets under
/// [`BlurBudget::Need`] when a bounding-box corner moves `motion_px` over its segment:
/// 1 + (m^0.4 − 1) · min(1, g / [`NEED_SATURATION_PX`]) with g = motion_px / m, the mean
/// screen step between frames. It rises linearly from 1 (no motion: the frames' blocks
/// add up to one stratified sequence, DESIGN §3) to [`parity_factor`] (saturated), and it
/// lies on or above every measured need (the line through the measurements' ends).
pub fn need_factor(m: usize, motion_px: f64) -> f64 {
    let m = m.max(1);
    let full = parity_factor(m);
    let g = if motion_px.is_finite() {
        motion_px.max(0.0) / m as f64
    } else {
        f64::INFINITY
    };
    1.0 + (full - 1.0) * (g / NEED_SATURATION_PX).min(1.0)
}

/// Longest Cycles sample sequence (`scene.cycles.samples` tops out at 2^24).
pub const MAX_SEQUENCE: u64 = 1 << 24;

/// Everything that shapes the sampling of a setting. Units: degrees, Δr in percent of r.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
// Not deny_unknown_fields: the kinds' levels are flattened in, which serde cannot check.
#[serde(default)]
pub struct SamplingConfig {
    pub views: usize,
    pub phi0_deg: f64,
    pub window_deg: f64,
    pub fov_deg: f64,
    /// Camera distance = margin · (bounding-sphere radius) / sin(fov / 2).
    pub radius_margin: f64,
    pub delta0: f64,
    pub levels: Vec<u32>,
    /// w_l ~ U[(1 − s), (1 + s)] · w_u · l; the paper's s is 0.1.
    pub level_spread: f64,
    /// m of every blurry image (the paper's 34), unless `latents_auto`.
    pub latents: usize,
    pub latent_positions: LatentPositions,
    /// Where p sits on the segment: its start (the paper) or its middle.
    pub trajectory: TrajectoryAnchor,
    pub resolution: u32,
    pub guards: Guards,
    /// Choose m per view and level: the smallest m whose latent frames leave no gap
    /// larger than `max_ghost_px` on screen (see `plan_setting`), capped at `latents_max`.
    pub latents_auto: bool,
    pub latents_max: usize,
    pub max_ghost_px: f64,
    pub blur_method: BlurMethod,
    /// Cycles samples of each rendered frame, unless `samples_total` splits a budget.
    pub samples: u32,
    /// Sample budget of one blurry image: its m frames get ⌈S / m⌉ samples each (the
    /// motion blur method renders one frame with S).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub samples_total: Option<u32>,
    pub latent_sampling: LatentSampling,
    pub blur_budget: BlurBudget,
    /// Each registered kind's levels beside motion blur ([`super::kinds`]).
    #[serde(flatten)]
    pub kinds: KindLevels,
}

impl Default for SamplingConfig {
    fn default() -> Self {
        SamplingConfig {
            views: 34,
            phi0_deg: 60.0,
            window_deg: 7.5,
            fov_deg: 40.0,
            radius_margin: 1.1,
            delta0: 2.5,
            levels: vec![1, 2, 3, 4],
            level_spread: 0.1,
            latents: 34,
            latent_positions: LatentPositions::Random,
            trajectory: TrajectoryAnchor::Start,
            resolution: 512,
            guards: Guards::default(),
            latents_auto: false,
            latents_max: 34,
            max_ghost_px: 1.0,
            blur_method: BlurMethod::Average,
            samples: 32,
            samples_total: None,
            latent_sampling: LatentSampling::Subsets,
            blur_budget: BlurBudget::Parity,
            kinds: KindLevels::default(),
        }
    }
}

impl SamplingConfig {
    /// The most latent frames one blurry image can have under this config.
    pub fn max_latents(&self) -> usize {
        match (self.blur_method, self.latents_auto) {
            (BlurMethod::MotionBlur, _) => 1,
            (_, true) => self.latents_max,
            (_, false) => self.latents,
        }
    }

    /// Cycles samples of each render of a blurry image made of `m` renders.
    /// With a budget S: ⌈S / m⌉ (averaging m frames averages their noise too);
    /// without one, `samples` per latent frame, and for the motion blur method one
    /// render with the budget the average method would spend (`samples · latents`).
    /// Under [`BlurBudget::Parity`] an average of m ≥ 2 frames gets [`parity_factor`]`(m)`
    /// times that, rounded up per frame.
    pub fn samples_per_frame(&self, m: usize) -> u32 {
        self.samples_per_frame_at(m, f64::INFINITY)
    }

    /// [`Self::samples_per_frame`] of an image whose bounding box moves `motion_px` on
    /// screen over its segment: under [`BlurBudget::Need`] the factor is
    /// [`need_factor`]`(m, motion_px)` (an infinite motion gives the parity factor); the
    /// other budgets do not look at the motion.
    pub fn samples_per_frame_at(&self, m: usize, motion_px: f64) -> u32 {
        let m = m.max(1);
        let budget = match (self.blur_method, self.samples_total) {
            (_, Some(total)) => total as f64 / m as f64,
            (BlurMethod::MotionBlur, None) => self.samples as f64 * self.latents as f64,
            (_, None) => self.samples as f64,
        };
        let factor = match (self.blur_method, self.blur_budget) {
            (BlurMethod::MotionBlur, _) => 1.0,
            (_, BlurBudget::Parity) => parity_factor(m),
            (_, BlurBudget::Need) => need_factor(m, motion_px),
            _ => 1.0,
        };
        (budget * factor).ceil().min(MAX_SAMPLES as f64) as u32
    }

    /// The sample blocks of a blurry image's `m` latent frames under this config's
    /// scheme: (Cycles `samples` of each render, sample offset of each frame). Subsets:
    /// a sequence of m·L samples, frame i from i·L, so every frame keeps L =
    /// `samples_per_frame(m)` samples (⌈S / m⌉ with a budget S) and the frames weigh
    /// equally in the mean; when m does not divide S the sequence is m·⌈S / m⌉ > S
    /// samples, never fewer. Independent: each frame renders its own first L samples.
    pub fn sample_blocks(&self, m: usize) -> (u32, Vec<u32>) {
        self.sample_blocks_at(m, f64::INFINITY)
    }

    /// [`Self::sample_blocks`] of an image with `motion_px` of screen motion
    /// ([`Self::samples_per_frame_at`]).
    pub fn sample_blocks_at(&self, m: usize, motion_px: f64) -> (u32, Vec<u32>) {
        let len = self.samples_per_frame_at(m, motion_px);
        match self.latent_sampling {
            LatentSampling::Subsets => (
                (m as u64 * len as u64).min(MAX_SEQUENCE) as u32,
                (0..m as u64)
                    .map(|i| (i * len as u64).min(MAX_SEQUENCE) as u32)
                    .collect(),
            ),
            LatentSampling::Independent => (len, vec![0; m]),
        }
    }

    /// The longest sample sequence a blurry image of this config can render: the
    /// largest `sample_blocks(m).0` over every m the config allows (all of
    /// 1..=latents_max under `latents_auto`). Cycles sizes its sample-pattern table from
    /// the `samples` of a render and never shrinks it within a process, so a pixel
    /// depends on the largest `samples` rendered before it; a build pins every render to
    /// one sequence length at least this long (and the sharp budget) to keep its pixels
    /// independent of render order — a resumed object renders what an uninterrupted one did.
    pub fn max_sequence(&self) -> u32 {
        let ms = match (self.blur_method, self.latents_auto) {
            (BlurMethod::MotionBlur, _) => 1..=1,
            (_, true) => 1..=self.latents_max,
            (_, false) => self.latents..=self.latents,
        };
        ms.map(|m| self.sample_blocks(m).0).max().unwrap_or(1)
    }

    /// Camera distance for an object of the given box.
    pub fn radius(&self, bbox_dims: [f64; 3]) -> f64 {
        self.radius_margin * bounding_radius(bbox_dims) / libm::sin(0.5 * self.fov_deg.to_radians())
    }
}
