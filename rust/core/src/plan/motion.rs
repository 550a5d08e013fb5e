//! Motion blur, the paper's Algorithm 1 (DESIGN §2), as a [`Degradation`]: a view's
//! trajectory δ, each level's weight w_l ~ U[(1 − s), (1 + s)] · w_u · l and its segment
//! p + t · w_l · δ, and the latent positions on it whose frames are averaged, or the keys
//! of one Cycles motion blur render (`--blur-method motion_blur`, or where `auto` finds
//! it cheaper). meta.json records a level as `views[i].levels["<l>"]`, without its
//! camera matrices.
//!
//! δ comes from the view's own stream, after φ and θ ([`super::sampling::sample_view`]);
//! level l draws w_l and then its latent positions from purpose l, so changing the number
//! of latents moves no viewpoint and dropping a level changes no other.
use super::camera::{bounding_radius, clamp_polar, corners, orbit_c2w, rows, Trajectory};
use super::choices::{LatentPositions, LatentSampling};
use super::degradation::{
    fewest_frames, Degradation, RenderCx, ViewCx, MOTION_KEY_TOLERANCE_PX, MOTION_STEPS_RANGE,
};
use super::render::{Motion as MotionPath, Render};
use super::sampling_config::{BlurMethod, SamplingConfig};
use super::weights::level_interval;
use crate::plan::kind::ImageKind;
use crate::rng::Stream;
use glam::{DMat4, DVec3};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// Motion blur as a [`Degradation`]: each level's latent frames along its segment of the
/// view's trajectory, or one render along its motion keys.
pub struct Motion;

/// A view's blur level, as the statistics read it from meta.json.
#[derive(Debug, Deserialize)]
pub struct MotionStat {
    pub w_l: f64,
    pub latents: u64,
    /// Absent from metas written before it was recorded.
    #[serde(default)]
    pub motion_px: Option<f64>,
}

impl Degradation for Motion {
    type Level = LevelPlan;
    type Record = MetaLevel;
    type Read = MotionStat;
    /// The paper's blur levels, `views[i].levels`: the name predates the other kinds.
    const NAME: &'static str = "levels";
    /// Level l draws from purpose l and seeds its frames as level l; purpose 0 is the
    /// view's own draw, which ends with δ.
    const PURPOSE: u64 = 0;
    const STAT: (&'static str, &'static str, &'static str) = (
        "motion_px",
        "px",
        "largest screen motion of a bounding-box corner over the trajectory at level l (one per blurry view)",
    );
    const FIGURE: (&'static str, &'static str) = (
        "Blur extent per level",
        "largest bounding-box corner motion  (px at build resolution)",
    );
    const MEANS: &'static str = "the same views blurred at level l";
    /// A blurry image is the mean over a moving camera; meta.json records its mean pose.
    const WRITTEN_POSE: bool = false;
    const OWN_MASKS: bool = true;

    fn kind(level: u32) -> ImageKind {
        ImageKind::Blur(level)
    }

    fn plan_view(cx: &ViewCx, levels: &[u32]) -> BTreeMap<String, LevelPlan> {
        let view = View {
            cx,
            screen: Screen {
                corners: corners(cx.bbox_dims),
                focal: cx.focal_px,
                size: f64::from(cx.resolution),
            },
            r_min: 1.05 * bounding_radius(cx.bbox_dims),
        };
        levels
            .iter()
            .map(|&level| (level.to_string(), view.level(level)))
            .collect()
    }

    fn renders(cx: &RenderCx, level: u32, lp: &LevelPlan) -> Vec<Render> {
        let prefix = cx.exr_dir.join(format!("{:04}_{level}", cx.view));
        level_renders(cx.view, level, lp, &prefix.display().to_string(), cx.pin)
    }

    fn record(lp: &LevelPlan) -> MetaLevel {
        lp.map_frames(
            |f| MetaLatent {
                t: f.t,
                r: f.r,
                phi_deg: f.phi_deg,
                theta_deg: f.theta_deg,
                seed: f.seed,
                sample_offset: f.sample_offset,
            },
            |k| MetaKey {
                t: k.t,
                r: k.r,
                phi_deg: k.phi_deg,
                theta_deg: k.theta_deg,
            },
        )
    }

    fn stat(s: &MotionStat) -> Option<f64> {
        s.motion_px
    }
}

#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
pub struct LatentFrame {
    /// Position on the segment: the camera at p + t · w_l · δ, with t ∈ [0, 1] when the
    /// trajectory starts at p and t ∈ [−½, ½] when it is centred on p.
    pub t: f64,
    pub r: f64,
    pub phi_deg: f64,
    pub theta_deg: f64,
    /// Cycles seed of this frame's render (the view's `sharp_seed` under subsets).
    pub seed: u32,
    /// First sample of this frame's block in its level's `sample_sequence` (0 when
    /// the frames are independent).
    #[serde(default)]
    pub sample_offset: u32,
    /// OpenGL camera-to-world, row-major.
    pub c2w: [[f64; 4]; 4],
}

/// A camera at position t on a blurry image's segment, by its orbit coordinates and its
/// matrix: one field list for [`MotionKey`] and [`MeanPose`], which stay two types (and
/// two schemas) because they mean different things.
macro_rules! camera_on_segment {
    ($(#[$doc:meta])* $name:ident) => {
        $(#[$doc])*
        #[derive(Clone, Debug, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
        pub struct $name {
            pub t: f64,
            pub r: f64,
            pub phi_deg: f64,
            pub theta_deg: f64,
            /// OpenGL camera-to-world, row-major.
            pub c2w: [[f64; 4]; 4],
        }

        impl $name {
            /// The camera at `t`, given as [`Segment::at`] places it.
            fn at(t: f64, ((r, phi_deg, theta_deg), m): ((f64, f64, f64), DMat4)) -> Self {
                $name {
                    t,
                    r,
                    phi_deg,
                    theta_deg,
                    c2w: rows(&m),
                }
            }
        }
    };
}

camera_on_segment! {
    /// One camera keyframe of the motion blur method: position t on the segment (as in
    /// `LatentFrame`).
    MotionKey
}

/// The single render of a blurry image made by Cycles motion blur: the camera is
/// keyframed at t_k = t_open + k / 2^steps (k = 0..=2^steps; t_open = 0, or −½ for a
/// centred trajectory) over a shutter of one frame that opens at the first key, and
/// Cycles gets `motion_steps` = steps on the camera object, so its motion steps fall
/// exactly on the keys.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
pub struct MotionBlurPlan<K = MotionKey> {
    pub seed: u32,
    pub motion_steps: u32,
    /// Largest screen error (px) of Cycles' interpolation between keys, estimated at
    /// the middle of every key interval (≤ MOTION_KEY_TOLERANCE_PX unless capped).
    pub interpolation_error_px: f64,
    pub keys: Vec<K>,
}

camera_on_segment! {
    /// The camera at the mean latent position t̄ of a blurry image: the pose its content is
    /// centred on, which SfM recovers from it (DESIGN §12). The average method's t̄ is the
    /// mean of its drawn t; the motion blur method's exposure is uniform over the segment,
    /// so its t̄ is the segment's middle.
    MeanPose
}

/// One blur level of a view; `F` and `K` are its latent frames and motion keys (the
/// plan's, or meta.json's records of them, which drop the camera matrices).
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
#[serde(bound(deserialize = "F: Deserialize<'de>, K: Deserialize<'de>"))]
pub struct LevelPlan<F = LatentFrame, K = MotionKey> {
    pub w_l: f64,
    /// m, the number of latent frames averaged (1 for the motion blur method: one render).
    pub latents: usize,
    /// Largest screen motion (px) of a bounding-box corner from the segment's start to
    /// its end (p to p + w_l · δ, or p ∓ w_l · δ / 2 when centred).
    pub motion_px: f64,
    /// Largest screen motion (px) between consecutive latent frames, the ends of the
    /// segment counted as one gap (start → t_1 plus t_m → end), so one frame has the
    /// whole motion as its gap; ghosting shows when it exceeds ~1 px. 0 for motion blur.
    pub max_gap_px: f64,
    pub method: BlurMethod,
    /// Cycles samples of each render of this image (the length of a frame's block).
    pub samples_per_frame: u32,
    /// How the frames share samples, and the Cycles `samples` of each frame's render:
    /// the whole sequence m · samples_per_frame under subsets, else samples_per_frame.
    pub latent_sampling: LatentSampling,
    pub sample_sequence: u32,
    pub latent_frames: Vec<F>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub motion_blur: Option<MotionBlurPlan<K>>,
    /// The camera at the mean latent position (kept whole in meta.json: check-poses
    /// compares a blur level's reconstruction with it).
    pub mean_pose: MeanPose,
}

impl<F, K> LevelPlan<F, K> {
    /// The same level with its latent frames and motion keys recorded by `f` and `k`.
    pub fn map_frames<F2, K2>(
        &self,
        f: impl Fn(&F) -> F2,
        k: impl Fn(&K) -> K2,
    ) -> LevelPlan<F2, K2> {
        LevelPlan {
            w_l: self.w_l,
            latents: self.latents,
            motion_px: self.motion_px,
            max_gap_px: self.max_gap_px,
            method: self.method,
            samples_per_frame: self.samples_per_frame,
            latent_sampling: self.latent_sampling,
            sample_sequence: self.sample_sequence,
            latent_frames: self.latent_frames.iter().map(f).collect(),
            motion_blur: self.motion_blur.as_ref().map(|mb| MotionBlurPlan {
                seed: mb.seed,
                motion_steps: mb.motion_steps,
                interpolation_error_px: mb.interpolation_error_px,
                keys: mb.keys.iter().map(k).collect(),
            }),
            mean_pose: self.mean_pose.clone(),
        }
    }
}

/// A latent frame as meta.json records it (its camera matrix follows from r, φ, θ).
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
pub struct MetaLatent {
    pub t: f64,
    pub r: f64,
    pub phi_deg: f64,
    pub theta_deg: f64,
    pub seed: u32,
    /// First sample of the frame's block in its level's sample_sequence (0: independent).
    pub sample_offset: u32,
}

#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
pub struct MetaKey {
    pub t: f64,
    pub r: f64,
    pub phi_deg: f64,
    pub theta_deg: f64,
}

/// A blur level as meta.json records it: the plan's, without camera matrices.
pub type MetaLevel = LevelPlan<MetaLatent, MetaKey>;

/// w_l and m latent positions of one level, sorted, on the anchored segment (t ∈ [0, 1)
/// from p, or shifted by −½ when centred on p). w_l is the stream's first draw, so it
/// does not depend on m, and a given m always gets the same positions under either
/// anchor. `s` is the level's stream (purpose l of its view).
pub fn sample_level_m(
    cfg: &SamplingConfig,
    mut s: Stream,
    level: u32,
    w_u: f64,
    m: usize,
) -> (f64, Vec<f64>) {
    let (lo, hi) = level_interval(w_u, level, cfg.level_spread);
    let w_l = s.uniform_in(lo, hi);
    let open = cfg.trajectory.t_open();
    let mut t: Vec<f64> = match cfg.latent_positions {
        LatentPositions::Random => (0..m).map(|_| open + s.uniform()).collect(),
        LatentPositions::Stratified => (0..m)
            .map(|i| open + (i as f64 + s.uniform()) / m as f64)
            .collect(),
    };
    t.sort_by(|a, b| a.total_cmp(b));
    (w_l, t)
}

/// Position along the trajectory. The radius is kept outside the bounding sphere
/// (≥ 1.05 ρ) and φ off the poles, so no latent camera sits inside the object.
pub fn along(
    r: f64,
    phi_deg: f64,
    theta_deg: f64,
    d: &Trajectory,
    s: f64,
    r_min: f64,
) -> (f64, f64, f64) {
    (
        (r * (1.0 + s * d.dr / 100.0)).max(r_min),
        clamp_polar(phi_deg + s * d.dphi_deg),
        theta_deg + s * d.dtheta_deg,
    )
}

/// The screen positions of the object's bounding-box corners (None behind the camera).
type CornerPoints = [Option<(f64, f64)>; 8];

/// Projects the bounding-box corners of one object for any camera of a setting.
struct Screen {
    corners: [DVec3; 8],
    focal: f64,
    size: f64,
}

impl Screen {
    fn points(&self, c2w: &DMat4) -> CornerPoints {
        let w2c = c2w.inverse();
        self.corners.map(|x| {
            let p = w2c.transform_point3(x);
            (p.z < -1e-9).then(|| {
                (
                    0.5 * self.size + self.focal * p.x / -p.z,
                    0.5 * self.size - self.focal * p.y / -p.z,
                )
            })
        })
    }
}

/// Largest screen distance any box corner moves between two cameras' projections.
fn motion(a: &CornerPoints, b: &CornerPoints) -> f64 {
    a.iter()
        .zip(b)
        .filter_map(|(pa, pb)| {
            let (pa, pb) = ((*pa)?, (*pb)?);
            Some(((pa.0 - pb.0).powi(2) + (pa.1 - pb.1).powi(2)).sqrt())
        })
        .fold(0.0, f64::max)
}

/// Largest gap (px) between consecutive latent frames `pts` (sorted by t) on the path
/// from `start` to `end`, the segment's ends. The two uncovered ends of the segment count
/// together as one more gap, so the gaps always add up to at least the whole motion:
/// one frame has the whole motion as its gap, and m frames leave a gap ≥ motion / m.
fn max_gap(pts: &[CornerPoints], start: &CornerPoints, end: &CornerPoints) -> f64 {
    let (Some(first), Some(last)) = (pts.first(), pts.last()) else {
        return motion(start, end);
    };
    let ends = motion(start, first) + motion(last, end);
    pts.windows(2)
        .map(|w| motion(&w[0], &w[1]))
        .fold(ends, f64::max)
}

/// The camera of position t on one level's segment, p + t · w_l · δ for t from `open`
/// to `open + 1`.
struct Segment<'a> {
    open: f64,
    r: f64,
    phi_deg: f64,
    theta_deg: f64,
    trajectory: &'a Trajectory,
    w_l: f64,
    r_min: f64,
}

impl Segment<'_> {
    fn at(&self, t: f64) -> ((f64, f64, f64), DMat4) {
        let (r, phi, theta) = along(
            self.r,
            self.phi_deg,
            self.theta_deg,
            self.trajectory,
            t * self.w_l,
            self.r_min,
        );
        ((r, phi, theta), orbit_c2w(r, phi, theta))
    }

    /// The cameras where the exposure opens and closes.
    fn ends(&self) -> (DMat4, DMat4) {
        (self.at(self.open).1, self.at(self.open + 1.0).1)
    }

    fn mean_pose(&self, t: f64) -> MeanPose {
        MeanPose::at(t, self.at(t))
    }
}

/// The latent positions of one level and their screen gap: `cfg.latents` of them, or
/// with `latents_auto` the smallest m ≤ `latents_max` whose own seeded draw leaves no
/// gap above `max_ghost_px` (the search starts at ⌈motion / max_ghost_px⌉, below which
/// no draw can succeed). Each m has its fixed draw, so the choice is reproducible; with
/// stratified positions gaps never exceed two strata, so m lands between motion / P and
/// 2 · motion / P, while uniformly random positions leave gaps of ~ln(m) / m and need
/// several times more frames. At the cap the gap may exceed the bound (recorded).
/// `draw(m)` gives the m seeded positions of this view and level.
fn latent_positions(
    cfg: &SamplingConfig,
    draw: impl Fn(usize) -> Vec<f64>,
    seg: &Segment,
    screen: &Screen,
    motion_px: f64,
) -> (Vec<f64>, f64) {
    let (open, close) = seg.ends();
    let (start, end) = (screen.points(&open), screen.points(&close));
    let gap_of = |ts: &[f64]| {
        let pts: Vec<CornerPoints> = ts.iter().map(|&t| screen.points(&seg.at(t).1)).collect();
        max_gap(&pts, &start, &end)
    };
    if !cfg.latents_auto {
        let ts = draw(cfg.latents);
        let gap = gap_of(&ts);
        return (ts, gap);
    }
    let lower = (motion_px / cfg.max_ghost_px - 1e-9).ceil().max(1.0);
    let first = (lower as usize).min(cfg.latents_max);
    fewest_frames(first, cfg.latents_max, cfg.max_ghost_px, |m| {
        let ts = draw(m);
        let gap = gap_of(&ts);
        (ts, gap)
    })
}

/// Keys of the motion blur method: 2^n + 1 cameras at t_k = open + k / 2^n, with the smallest
/// n in MOTION_STEPS_RANGE for which Cycles' interpolation between keys (linear in
/// position, slerp in rotation) stays within MOTION_KEY_TOLERANCE_PX of the true
/// camera at the middle of every interval. Returns (n, error px, keys).
fn motion_keys(seg: &Segment, screen: &Screen) -> (u32, f64, Vec<MotionKey>) {
    let (lo, hi) = MOTION_STEPS_RANGE;
    let mut out = (hi, f64::INFINITY, Vec::new());
    for n in lo..=hi {
        let intervals = 1usize << n;
        let t_of = |k: f64| seg.open + k / intervals as f64;
        let cams: Vec<((f64, f64, f64), DMat4)> =
            (0..=intervals).map(|k| seg.at(t_of(k as f64))).collect();
        let err = (0..intervals)
            .map(|k| {
                let (a, b) = (&cams[k].1, &cams[k + 1].1);
                let (_, qa, ta) = a.to_scale_rotation_translation();
                let (_, qb, tb) = b.to_scale_rotation_translation();
                let mid = DMat4::from_rotation_translation(qa.slerp(qb, 0.5), ta.lerp(tb, 0.5));
                let exact = seg.at(t_of(k as f64 + 0.5)).1;
                motion(&screen.points(&mid), &screen.points(&exact))
            })
            .fold(0.0, f64::max);
        let keys = cams
            .iter()
            .enumerate()
            .map(|(k, &cam)| MotionKey::at(t_of(k as f64), cam))
            .collect();
        out = (n, err, keys);
        if err <= MOTION_KEY_TOLERANCE_PX {
            break;
        }
    }
    out
}

/// What every level of one view shares while it is planned: the view, and the screen
/// its segments are measured on.
struct View<'a> {
    cx: &'a ViewCx<'a>,
    screen: Screen,
    r_min: f64,
}

impl View<'_> {
    /// The stream level `level` draws w_l and its latent positions from.
    fn stream(&self, level: u32) -> Stream {
        (self.cx.stream)(Motion::PURPOSE + u64::from(level))
    }

    /// The build's config with each blurry image's method given: under `auto`, what
    /// each method would plan.
    fn as_method(&self, method: BlurMethod) -> SamplingConfig {
        SamplingConfig {
            blur_method: method,
            ..self.cx.cfg.clone()
        }
    }

    /// One blur level of a view: its segment of the trajectory, then its latent frames
    /// (average) or its motion keys (motion blur).
    fn level(&self, level: u32) -> LevelPlan {
        let cx = self.cx;
        let cfg = cx.cfg;
        let (w_l, _) = sample_level_m(cfg, self.stream(level), level, cx.w_u, 0);
        let seg = Segment {
            open: cfg.trajectory.t_open(),
            r: cx.r,
            phi_deg: cx.phi_deg,
            theta_deg: cx.theta_deg,
            trajectory: &cx.trajectory,
            w_l,
            r_min: self.r_min,
        };
        let (open, close) = seg.ends();
        let motion_px = motion(&self.screen.points(&open), &self.screen.points(&close));
        let at = LevelAt { level, motion_px };
        match (cfg.blur_method, cx.pricing) {
            (BlurMethod::Average, _) => self.average(cfg, &seg, &at),
            (BlurMethod::MotionBlur, _) => self.motion_blur(cfg, &seg, &at),
            // The frames the ghost bound plans are what averaging would cost: priced, and
            // kept or replaced by one motion-blur render (the draws are per view and
            // level, so the plan of any other image does not move).
            (BlurMethod::Auto, Some((pricing, prices))) => {
                let averaged = self.average(&self.as_method(BlurMethod::Average), &seg, &at);
                let price = pricing.price(averaged.latents);
                prices.borrow_mut().push(price);
                match price.cheaper() {
                    BlurMethod::MotionBlur => {
                        self.motion_blur(&self.as_method(BlurMethod::MotionBlur), &seg, &at)
                    }
                    _ => averaged,
                }
            }
            // plan_setting_priced refuses auto without a pricing.
            (BlurMethod::Auto, None) => {
                self.average(&self.as_method(BlurMethod::Average), &seg, &at)
            }
        }
    }

    /// Subsets share the view's seed, so every level's frames and the sharp render draw
    /// from one sample sequence.
    fn latent_seed(&self, at: &LevelAt, k: usize) -> u32 {
        match self.cx.cfg.latent_sampling {
            LatentSampling::Subsets => self.cx.sharp_seed,
            LatentSampling::Independent => (self.cx.seed)(Motion::PURPOSE + u64::from(at.level), k),
        }
    }

    /// A level as the mean of latent frames along its segment.
    fn average(&self, cfg: &SamplingConfig, seg: &Segment, at: &LevelAt) -> LevelPlan {
        let draw = |m| sample_level_m(cfg, self.stream(at.level), at.level, self.cx.w_u, m).1;
        let (ts, max_gap_px) = latent_positions(cfg, draw, seg, &self.screen, at.motion_px);
        let (sample_sequence, offsets) = cfg.sample_blocks_at(ts.len(), at.motion_px);
        let latent_frames: Vec<LatentFrame> = ts
            .iter()
            .enumerate()
            .map(|(k, &t)| {
                let ((r, phi, theta), m) = seg.at(t);
                LatentFrame {
                    t,
                    r,
                    phi_deg: phi,
                    theta_deg: theta,
                    seed: self.latent_seed(at, k),
                    sample_offset: offsets[k],
                    c2w: rows(&m),
                }
            })
            .collect();
        let mean_t = ts.iter().sum::<f64>() / ts.len().max(1) as f64;
        LevelPlan {
            w_l: seg.w_l,
            latents: ts.len(),
            motion_px: at.motion_px,
            max_gap_px,
            method: BlurMethod::Average,
            samples_per_frame: cfg.samples_per_frame_at(ts.len(), at.motion_px),
            latent_sampling: cfg.latent_sampling,
            sample_sequence,
            latent_frames,
            motion_blur: None,
            mean_pose: seg.mean_pose(mean_t),
        }
    }

    /// A level as one Cycles motion-blur render along the segment's keys.
    fn motion_blur(&self, cfg: &SamplingConfig, seg: &Segment, at: &LevelAt) -> LevelPlan {
        let (motion_steps, interpolation_error_px, keys) = motion_keys(seg, &self.screen);
        LevelPlan {
            w_l: seg.w_l,
            latents: 1,
            motion_px: at.motion_px,
            max_gap_px: 0.0,
            method: BlurMethod::MotionBlur,
            samples_per_frame: cfg.samples_per_frame(1),
            latent_sampling: cfg.latent_sampling,
            sample_sequence: cfg.samples_per_frame(1),
            latent_frames: Vec::new(),
            motion_blur: Some(MotionBlurPlan {
                seed: self.latent_seed(at, 0),
                motion_steps,
                interpolation_error_px,
                keys,
            }),
            mean_pose: seg.mean_pose(seg.open + 0.5),
        }
    }
}

/// Which level is being planned, and what its segment measured.
struct LevelAt {
    level: u32,
    motion_px: f64,
}

/// The renders of one blurry image: its latent frames (average method) or its single
/// motion blur render, writing `<prefix>_<k>.exr` / `<prefix>_mb.exr`. Under sample
/// subsets frame k renders the block at its `sample_offset` of a sequence of `pin`
/// samples (the build's [`crate::BuildConfig::cycles_samples`]; None: the level's own
/// `sample_sequence`); independent frames render their own first samples.
pub fn level_renders(
    view: usize,
    level: u32,
    lp: &LevelPlan,
    prefix: &str,
    pin: Option<u32>,
) -> Vec<Render> {
    let kind = ImageKind::Blur(level);
    let subsets = lp.latent_sampling == LatentSampling::Subsets;
    let block = |offset: u32| {
        if subsets {
            (Some(offset), Some(pin.unwrap_or(lp.sample_sequence)))
        } else {
            (None, None)
        }
    };
    if let Some(mb) = &lp.motion_blur {
        let keys: Vec<_> = mb.keys.iter().map(|k| k.c2w).collect();
        let (sample_offset, sample_sequence) = block(0);
        let first = Render::still(view, kind, keys[0], mb.seed, format!("{prefix}_mb.exr"));
        return vec![Render {
            samples: Some(lp.samples_per_frame),
            sample_offset,
            sample_sequence,
            motion: Some(MotionPath {
                steps: mb.motion_steps,
                keys,
            }),
            // The camera moves during the render, between its keys too: whole image.
            region: None,
            ..first
        }];
    }
    lp.latent_frames
        .iter()
        .enumerate()
        .map(|(k, f)| {
            let (sample_offset, sample_sequence) = block(f.sample_offset);
            let out = format!("{prefix}_{k:04}.exr");
            Render {
                samples: Some(lp.samples_per_frame),
                sample_offset,
                sample_sequence,
                ..Render::still(view, kind, f.c2w, f.seed, out)
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plan::choices::{BlurBudget, TrajectoryAnchor};
    use crate::plan::sampling::tests::{cube_vertices, plan};
    use crate::plan::sampling::{
        frame_seed, plan_setting, plan_setting_priced, stream_id, SettingPlan, ViewPlan,
    };
    use crate::plan::spec::MAX_COUNT;

    #[test]
    fn stratified_positions_fill_every_stratum() {
        let cfg = SamplingConfig {
            latent_positions: LatentPositions::Stratified,
            latents: 10,
            ..Default::default()
        };
        let (_, t) = sample_level_m(&cfg, Stream::new(5, stream_id(0, 4)), 4, 1.5, cfg.latents);
        for (i, ti) in t.iter().enumerate() {
            assert!(*ti >= i as f64 / 10.0 && *ti < (i + 1) as f64 / 10.0);
        }
    }

    #[test]
    fn blur_magnitude_matches_the_design_range() {
        // DESIGN §2: at 512 px and 40°, level 1 moves a box corner ~8–27 px, level 4 ~30–90 px.
        let cfg = SamplingConfig::default();
        let p = plan(&cfg, 1, [1.0, 0.8, 0.6]);
        let med = |l: &str| {
            let mut m: Vec<f64> = p.views.iter().map(|v| v.levels[l].motion_px).collect();
            m.sort_by(|a, b| a.total_cmp(b));
            m[m.len() / 2]
        };
        let (m1, m4) = (med("1"), med("4"));
        assert!((6.0..35.0).contains(&m1), "level 1 median motion {m1}");
        assert!((25.0..120.0).contains(&m4), "level 4 median motion {m4}");
        assert!(m4 > 3.0 * m1);
    }

    fn median(mut v: Vec<f64>) -> f64 {
        v.sort_by(|a, b| a.total_cmp(b));
        v[v.len() / 2]
    }

    #[test]
    fn auto_latents_meet_the_ghost_bound_and_follow_the_motion() {
        let cases = [LatentPositions::Stratified, LatentPositions::Random]
            .into_iter()
            .flat_map(|p| ANCHORS.map(|a| (p, a)));
        for (positions, trajectory) in cases {
            let cfg = SamplingConfig {
                latents_auto: true,
                latents_max: MAX_COUNT,
                latent_positions: positions,
                trajectory,
                views: 8,
                ..Default::default()
            };
            let p = plan(&cfg, 2, [1.0, 0.7, 0.5]);
            for v in &p.views {
                for lp in v.levels.values() {
                    assert!(
                        lp.max_gap_px <= cfg.max_ghost_px,
                        "{positions:?} {}",
                        lp.max_gap_px
                    );
                    // No m below motion / P can meet the bound: the gaps add up to the motion.
                    assert!(lp.latents as f64 >= lp.motion_px / cfg.max_ghost_px - 1e-9);
                    assert_eq!(lp.latent_frames.len(), lp.latents);
                }
                assert!(v.levels["1"].latents < v.levels["4"].latents);
            }
            let m = |l: &str| median(p.views.iter().map(|v| v.levels[l].latents as f64).collect());
            let motion = |l: &str| median(p.views.iter().map(|v| v.levels[l].motion_px).collect());
            // Stratified gaps are at most two strata: m within [motion / P, 2 motion / P + 1].
            if positions == LatentPositions::Stratified {
                for l in ["1", "4"] {
                    assert!(
                        m(l) <= 2.0 * motion(l) + 1.0,
                        "level {l}: m {} motion {}",
                        m(l),
                        motion(l)
                    );
                }
            }
        }
    }

    #[test]
    fn stratified_auto_needs_fewer_frames_than_random() {
        let total = |positions| {
            let cfg = SamplingConfig {
                latents_auto: true,
                latents_max: MAX_COUNT,
                latent_positions: positions,
                views: 8,
                ..Default::default()
            };
            let p = plan(&cfg, 4, [1.0, 0.6, 0.4]);
            p.views
                .iter()
                .flat_map(|v| v.levels.values().map(|lp| lp.latents))
                .sum::<usize>()
        };
        let (s, r) = (
            total(LatentPositions::Stratified),
            total(LatentPositions::Random),
        );
        assert!(2 * s < r, "stratified {s} random {r}");
    }

    #[test]
    fn auto_is_the_fixed_plan_at_its_m_and_capped() {
        for trajectory in ANCHORS {
            auto_is_the_fixed_plan(trajectory);
        }
    }

    fn auto_is_the_fixed_plan(trajectory: TrajectoryAnchor) {
        let auto = SamplingConfig {
            latents_auto: true,
            latent_positions: LatentPositions::Stratified,
            trajectory,
            views: 6,
            ..Default::default()
        };
        let p = plan(&auto, 8, [1.0, 0.8, 0.3]);
        for v in &p.views {
            for (l, lp) in &v.levels {
                let fixed = SamplingConfig {
                    latents_auto: false,
                    latents: lp.latents,
                    ..auto.clone()
                };
                let q = plan(&fixed, 8, [1.0, 0.8, 0.3]);
                assert_eq!(&q.views[v.index].levels[l], lp);
                assert!(lp.latents <= 34);
                if lp.max_gap_px > auto.max_ghost_px {
                    assert_eq!(
                        lp.latents, auto.latents_max,
                        "over the bound only at the cap"
                    );
                }
            }
        }
    }

    #[test]
    fn gaps_add_up_to_at_least_the_motion() {
        for trajectory in ANCHORS {
            gaps_add_up(trajectory);
        }
    }

    fn gaps_add_up(trajectory: TrajectoryAnchor) {
        let cfg = SamplingConfig {
            latents: 7,
            trajectory,
            ..Default::default()
        };
        let p = plan(&cfg, 5, [1.0, 0.5, 0.5]);
        for v in &p.views {
            for lp in v.levels.values() {
                assert!(lp.max_gap_px * 7.0 >= lp.motion_px - 1e-9);
            }
        }
        let one = plan(&SamplingConfig { latents: 1, ..cfg }, 5, [1.0, 0.5, 0.5]);
        for v in &one.views {
            for lp in v.levels.values() {
                // One frame: the two uncovered ends add up to (at least) the whole motion.
                assert!(lp.max_gap_px >= lp.motion_px - 1e-9);
            }
        }
    }

    #[test]
    fn motion_blur_keys_follow_the_segment() {
        for trajectory in ANCHORS {
            motion_blur_keys(trajectory);
        }
    }

    fn motion_blur_keys(trajectory: TrajectoryAnchor) {
        let cfg = SamplingConfig {
            blur_method: BlurMethod::MotionBlur,
            trajectory,
            views: 8,
            ..Default::default()
        };
        let avg = SamplingConfig {
            latents: 3,
            trajectory,
            views: 8,
            ..Default::default()
        };
        let (p, q) = (
            plan(&cfg, 6, [1.0, 0.9, 0.2]),
            plan(&avg, 6, [1.0, 0.9, 0.2]),
        );
        for (v, va) in p.views.iter().zip(&q.views) {
            for (l, lp) in &v.levels {
                let mb = lp.motion_blur.as_ref().expect("motion blur plan");
                assert_eq!((lp.latents, lp.latent_frames.len()), (1, 0));
                assert_eq!(mb.keys.len(), (1 << mb.motion_steps) + 1);
                assert!(mb.interpolation_error_px <= MOTION_KEY_TOLERANCE_PX);
                // The shutter opens at p (start), or p is the middle key (centred).
                let (open, at_p) = match trajectory {
                    TrajectoryAnchor::Start => (0.0, 0),
                    TrajectoryAnchor::Centered => (-0.5, mb.keys.len() / 2),
                };
                assert_eq!(mb.keys[0].t, open);
                assert_eq!(mb.keys.last().map(|k| k.t), Some(open + 1.0));
                assert_eq!((mb.keys[at_p].t, &mb.keys[at_p].c2w), (0.0, &v.c2w));
                // A uniform exposure over the segment: its mean pose is the middle key.
                let mid = &mb.keys[mb.keys.len() / 2];
                assert_eq!((lp.mean_pose.t, &lp.mean_pose.c2w), (mid.t, &mid.c2w));
                // Same segment as the average method: the same w_l and motion.
                assert_eq!(lp.w_l, va.levels[l].w_l);
                assert_eq!(lp.motion_px, va.levels[l].motion_px);
                // Every latent frame of the average method lies on the keyed path.
                for f in &va.levels[l].latent_frames {
                    let k = mb.keys.iter().filter(|k| k.t <= f.t).count() - 1;
                    let (a, b) = (&mb.keys[k], &mb.keys[k + 1]);
                    assert!(a.t <= f.t && f.t <= b.t);
                    let between = |x: f64, y: f64, z: f64| (x - z) * (y - z) <= 1e-12;
                    assert!(between(a.theta_deg, b.theta_deg, f.theta_deg));
                }
            }
            // Faster levels need at least as many keys.
            let steps = |l: &str| v.levels[l].motion_blur.as_ref().map(|m| m.motion_steps);
            assert!(steps("1") <= steps("4"));
        }
    }

    #[test]
    fn subsets_split_one_sequence_on_the_view_seed() {
        let cfg = SamplingConfig {
            views: 3,
            latents: 8,
            samples_total: Some(32),
            blur_budget: BlurBudget::Flat,
            ..Default::default()
        };
        let p = plan(&cfg, 3, [1.0, 0.7, 0.4]);
        for v in &p.views {
            for lp in v.levels.values() {
                assert_eq!(lp.latent_sampling, LatentSampling::Subsets);
                assert_eq!((lp.samples_per_frame, lp.sample_sequence), (4, 32));
                let offsets: Vec<u32> = lp.latent_frames.iter().map(|f| f.sample_offset).collect();
                assert_eq!(offsets, [0, 4, 8, 12, 16, 20, 24, 28]);
                assert!(lp.latent_frames.iter().all(|f| f.seed == v.sharp_seed));
            }
        }
        // m ∤ S: every frame keeps ⌈S/m⌉ samples; the blocks tile a longer sequence.
        let odd = SamplingConfig {
            latents: 5,
            ..cfg.clone()
        };
        assert_eq!(odd.sample_blocks(5), (35, vec![0, 7, 14, 21, 28]));
        // Independent: the plans before issue 15, frame by frame.
        let ind = SamplingConfig {
            latent_sampling: LatentSampling::Independent,
            ..cfg.clone()
        };
        let q = plan(&ind, 3, [1.0, 0.7, 0.4]);
        for (v, w) in q.views.iter().zip(&p.views) {
            for (l, lp) in &v.levels {
                assert_eq!(lp.sample_sequence, lp.samples_per_frame);
                let lvl: u32 = l.parse().expect("level");
                for (k, f) in lp.latent_frames.iter().enumerate() {
                    assert_eq!(
                        (f.sample_offset, f.seed),
                        (0, frame_seed(3, v.index, lvl, k))
                    );
                    assert_eq!(f.c2w, w.levels[l].latent_frames[k].c2w);
                }
            }
        }
        // Motion blur under subsets: one render on the view's seed, like the sharp one.
        let mb = SamplingConfig {
            blur_method: BlurMethod::MotionBlur,
            ..cfg.clone()
        };
        for v in &plan(&mb, 3, [1.0, 0.7, 0.4]).views {
            for lp in v.levels.values() {
                let seed = lp.motion_blur.as_ref().map(|m| m.seed);
                assert_eq!(seed, Some(v.sharp_seed));
                assert_eq!(lp.sample_sequence, 32);
            }
        }
    }

    #[test]
    fn auto_latents_get_their_own_sequence_per_level() {
        let cfg = SamplingConfig {
            latents_auto: true,
            latent_positions: LatentPositions::Stratified,
            samples_total: Some(100),
            views: 4,
            blur_budget: BlurBudget::Flat,
            ..Default::default()
        };
        for v in &plan(&cfg, 1, [1.0, 1.0, 1.0]).views {
            for lp in v.levels.values() {
                let m = lp.latents as u32;
                assert_eq!(lp.sample_sequence, m * 100u32.div_ceil(m));
                assert!(lp.sample_sequence >= 100 && lp.sample_sequence < 100 + m);
                let last = lp.latent_frames.last().expect("frames").sample_offset;
                assert_eq!(last + lp.samples_per_frame, lp.sample_sequence);
            }
        }
    }

    const ANCHORS: [TrajectoryAnchor; 2] = [TrajectoryAnchor::Start, TrajectoryAnchor::Centered];

    /// The object the centred plans below are made for.
    const CENTERED_D: [f64; 3] = [1.0, 0.7, 0.4];

    /// The same setting (nine latents, random and stratified) planned from its start and
    /// centred, on the same seeds.
    fn start_and_centered() -> Vec<(LatentPositions, SettingPlan, SettingPlan)> {
        let d = CENTERED_D;
        [LatentPositions::Random, LatentPositions::Stratified]
            .into_iter()
            .map(|positions| {
                let start = SamplingConfig {
                    latents: 9,
                    views: 6,
                    latent_positions: positions,
                    ..Default::default()
                };
                let centered = SamplingConfig {
                    trajectory: TrajectoryAnchor::Centered,
                    ..start.clone()
                };
                (positions, plan(&start, 21, d), plan(&centered, 21, d))
            })
            .collect()
    }

    /// Every level of every view of `start_and_centered`: (positions, start's view and
    /// level, centred's view and level).
    fn each_centered_level(
        mut each: impl FnMut(LatentPositions, (&ViewPlan, &LevelPlan), (&ViewPlan, &LevelPlan)),
    ) {
        for (positions, a, b) in start_and_centered() {
            for (va, vb) in a.views.iter().zip(&b.views) {
                for (l, lb) in &vb.levels {
                    each(positions, (va, &va.levels[l]), (vb, lb));
                }
            }
        }
    }

    #[test]
    fn centering_keeps_the_views_seeds_and_blur_weights() {
        for (_, a, b) in start_and_centered() {
            for (va, vb) in a.views.iter().zip(&b.views) {
                // Same seeds: the same views, δ, sharp image and written pose.
                assert_eq!(
                    (
                        va.phi_deg,
                        va.theta_deg,
                        va.trajectory,
                        va.c2w,
                        va.sharp_seed
                    ),
                    (
                        vb.phi_deg,
                        vb.theta_deg,
                        vb.trajectory,
                        vb.c2w,
                        vb.sharp_seed
                    )
                );
                for (l, lb) in &vb.levels {
                    assert_eq!(lb.w_l, va.levels[l].w_l);
                }
            }
        }
    }

    #[test]
    fn centered_latents_are_the_start_draws_half_a_segment_earlier() {
        each_centered_level(|_, (_, la), (_, lb)| {
            for (fa, fb) in la.latent_frames.iter().zip(&lb.latent_frames) {
                // The same draw, half a segment earlier, with the same Cycles seed.
                assert_eq!((fb.t, fb.seed), (fa.t - 0.5, fa.seed));
                assert!((-0.5..=0.5).contains(&fb.t), "{}", fb.t);
                assert!((0.0..=1.0).contains(&fa.t), "{}", fa.t);
            }
        });
    }

    #[test]
    fn centered_latents_lie_on_p_plus_t_w_delta_around_p() {
        let r_min = 1.05 * bounding_radius(CENTERED_D);
        each_centered_level(|_, (va, la), (vb, lb)| {
            for (fa, fb) in la.latent_frames.iter().zip(&lb.latent_frames) {
                // On p + t · w_l · δ, p the view's own pose.
                for (v, lp, f) in [(va, la, fa), (vb, lb, fb)] {
                    let want = along(
                        v.r,
                        v.phi_deg,
                        v.theta_deg,
                        &v.trajectory,
                        f.t * lp.w_l,
                        r_min,
                    );
                    assert_eq!((f.r, f.phi_deg, f.theta_deg), want);
                    assert_eq!(f.c2w, rows(&orbit_c2w(want.0, want.1, want.2)));
                }
            }
        });
    }

    #[test]
    fn the_mean_latent_pose_is_the_camera_at_the_mean_t() {
        let r_min = 1.05 * bounding_radius(CENTERED_D);
        each_centered_level(|_, (va, la), (vb, lb)| {
            for (v, lp) in [(va, la), (vb, lb)] {
                let ts: Vec<f64> = lp.latent_frames.iter().map(|f| f.t).collect();
                let mean = ts.iter().sum::<f64>() / ts.len() as f64;
                let mp = &lp.mean_pose;
                assert_eq!(mp.t, mean);
                let want = along(
                    v.r,
                    v.phi_deg,
                    v.theta_deg,
                    &v.trajectory,
                    mean * lp.w_l,
                    r_min,
                );
                assert_eq!((mp.r, mp.phi_deg, mp.theta_deg), want);
            }
        });
    }

    #[test]
    fn centred_the_mean_pose_is_about_p() {
        each_centered_level(|positions, (_, la), (_, lb)| {
            // Centred, the mean pose is about p: nine draws of U(−½, ½) average within ±½
            // and, stratified, within ±1/(2·9) of 0.
            let bound = match positions {
                LatentPositions::Random => 0.5,
                LatentPositions::Stratified => 0.5 / 9.0 + 1e-12,
            };
            assert!(lb.mean_pose.t.abs() <= bound, "{}", lb.mean_pose.t);
            assert!((la.mean_pose.t - 0.5).abs() <= bound);
        });
    }

    #[test]
    fn centered_segment_has_p_in_its_middle_and_measures_its_own_ends() {
        let d = [1.0, 0.5, 0.8];
        let r_min = 1.05 * bounding_radius(d);
        let cfg = SamplingConfig {
            trajectory: TrajectoryAnchor::Centered,
            latents: 5,
            views: 6,
            ..Default::default()
        };
        let p = plan(&cfg, 13, d);
        let screen = Screen {
            corners: corners(d),
            focal: p.focal_px,
            size: cfg.resolution as f64,
        };
        for v in &p.views {
            for lp in v.levels.values() {
                let end = |s: f64| {
                    let (r, phi, theta) = along(
                        v.r,
                        v.phi_deg,
                        v.theta_deg,
                        &v.trajectory,
                        s * lp.w_l,
                        r_min,
                    );
                    ((r, phi, theta), orbit_c2w(r, phi, theta))
                };
                let ((r0, phi0, theta0), c0) = end(-0.5);
                let ((r1, phi1, theta1), c1) = end(0.5);
                // p is the middle of the segment in (r, φ, θ).
                let mid = [
                    (r0 + r1) / 2.0,
                    (phi0 + phi1) / 2.0,
                    (theta0 + theta1) / 2.0,
                ];
                for (m, want) in mid.iter().zip([v.r, v.phi_deg, v.theta_deg]) {
                    assert!((m - want).abs() < 1e-9 * want.abs().max(1.0), "{m} {want}");
                }
                // Motion and gaps are measured between the centred segment's own ends.
                let (a, b) = (screen.points(&c0), screen.points(&c1));
                assert_eq!(lp.motion_px, motion(&a, &b));
                let pts: Vec<CornerPoints> = lp
                    .latent_frames
                    .iter()
                    .map(|f| screen.points(&c2w_of(&f.c2w)))
                    .collect();
                let gap = max_gap(&pts, &a, &b);
                assert!(
                    (lp.max_gap_px - gap).abs() < 1e-9,
                    "{} {gap}",
                    lp.max_gap_px
                );
            }
        }
    }

    fn c2w_of(rows: &[[f64; 4]; 4]) -> DMat4 {
        DMat4::from_cols_array_2d(rows).transpose()
    }

    /// `blur_method auto` as the accuracy presets set it, priced on `backend`.
    fn auto_plan(backend: &str, res: u32) -> (SettingPlan, SettingPlan) {
        use crate::plan::cost::Pricing;
        use crate::plan::target::TargetRule;
        let cfg = SamplingConfig {
            views: 6,
            resolution: res,
            latents_auto: true,
            latents_max: MAX_COUNT,
            latent_positions: LatentPositions::Stratified,
            blur_method: BlurMethod::Auto,
            ..SamplingConfig::default()
        };
        let rule = TargetRule {
            target_psnr_db: 50.0,
            pilot_samples: 32,
            max_samples: 16384,
        };
        let pricing = Pricing::new(backend, rule.pilot_samples, res).expect("known backend");
        let d = [1.0, 0.6, 0.3];
        let verts = cube_vertices(d);
        let auto = plan_setting_priced(&cfg, Some(&pricing), "obj", 90.0, 7, d, &verts)
            .expect("valid plan");
        let average = SamplingConfig {
            blur_method: BlurMethod::Average,
            ..cfg
        };
        (auto, plan(&average, 7, d))
    }

    fn levels(p: &SettingPlan) -> Vec<&LevelPlan> {
        p.views.iter().flat_map(|v| v.levels.values()).collect()
    }

    #[test]
    fn auto_on_a_cpu_is_the_average_plan() {
        for res in [16, 512] {
            let (auto, average) = auto_plan("CPU", res);
            assert_eq!(auto.views, average.views, "{res} px");
            let choice = auto.blur_choice.clone().expect("a record under auto");
            assert_eq!(choice.images.get("average"), Some(&levels(&auto).len()));
            assert!(choice.reason.contains("cpu"), "{}", choice.reason);
        }
    }

    #[test]
    fn auto_on_a_gpu_renders_motion_blur_where_frames_are_many() {
        for backend in ["OPTIX", "CUDA"] {
            let (auto, average) = auto_plan(backend, 512);
            for (a, b) in levels(&auto).iter().zip(levels(&average)) {
                let want = if b.latents > 1 {
                    BlurMethod::MotionBlur
                } else {
                    BlurMethod::Average
                };
                assert_eq!(a.method, want, "m = {}", b.latents);
                assert_eq!(a.w_l, b.w_l);
                assert_eq!(a.motion_px, b.motion_px);
                if want == BlurMethod::MotionBlur {
                    assert_eq!(a.latents, 1);
                    assert!(a.motion_blur.is_some());
                }
            }
            let choice = auto.blur_choice.clone().expect("a record under auto");
            assert!(choice.images.get("motion_blur").copied().unwrap_or(0) > 0);
            assert!(choice.cost_s.chosen < choice.cost_s.average);
            // The sharp renders and every camera but the blurry images' are the same.
            for (a, b) in auto.views.iter().zip(&average.views) {
                assert_eq!((a.c2w, a.sharp_seed), (b.c2w, b.sharp_seed));
            }
        }
    }

    #[test]
    fn auto_is_planned_only_with_prices_and_a_given_method_is_kept() {
        let d = [1.0, 0.6, 0.3];
        let cfg = SamplingConfig {
            views: 3,
            blur_method: BlurMethod::Auto,
            ..SamplingConfig::default()
        };
        assert!(plan_setting(&cfg, "obj", 90.0, 7, d, &cube_vertices(d)).is_err());
        use crate::plan::cost::Pricing;
        use crate::plan::target::TargetRule;
        let rule = TargetRule {
            target_psnr_db: 50.0,
            pilot_samples: 32,
            max_samples: 16384,
        };
        let gpu = Pricing::new("cuda", rule.pilot_samples, 512).expect("known backend");
        for method in [BlurMethod::Average, BlurMethod::MotionBlur] {
            let given = SamplingConfig {
                blur_method: method,
                ..cfg.clone()
            };
            let priced =
                plan_setting_priced(&given, Some(&gpu), "obj", 90.0, 7, d, &cube_vertices(d))
                    .expect("valid plan");
            assert!(priced.blur_choice.is_none());
            assert_eq!(priced.views, plan(&given, 7, d).views);
            assert!(levels(&priced).iter().all(|l| l.method == method));
        }
    }
}
