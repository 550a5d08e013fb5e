//! What a degradation is (issue 49): one file per kind (`motion.rs`, the motion blur of
//! Algorithm 1, and each kind beside it), each a [`Degradation`] holding its per-view
//! draw, the renders of a level with the fields it adds to them, its record in meta.json
//! (`views[i].<NAME>["<l>"]`, its `Record`), its statistic and the constants that set
//! its images apart (prefix, highest level, written pose, own masks). The plan, the
//! render list, the config and the statistics call each kind through this interface
//! only; the registry ([`super::kinds`]) lists the kinds.
use super::camera::Trajectory;
use super::choices::BlurMethod;
use super::cost::{ImagePrice, Pricing};
use super::render::Render;
use super::sampling_config::SamplingConfig;
use crate::error::Result;
use crate::plan::kind::{ImageKind, MAX_LEVEL};
use crate::plan::spec::config_error;
use crate::rng::Stream;
use serde::de::{Deserialize, DeserializeOwned};
use serde::Serialize;
use std::cell::RefCell;
use std::collections::BTreeMap;
use std::path::Path;

/// Motion blur keys: Cycles interpolates the camera between its motion steps (position
/// linearly, rotation by slerp); the steps are doubled until that interpolation stays
/// within this many pixels of the true path everywhere over the exposure.
pub const MOTION_KEY_TOLERANCE_PX: f64 = 0.02;
/// Cycles' `motion_steps` range (2^steps + 1 camera positions over the shutter).
pub const MOTION_STEPS_RANGE: (u32, u32) = (1, 7);

/// What a kind's per-view draw knows of its view and of the build's exposure.
pub struct ViewCx<'a> {
    /// The object's depth range along the viewing axis (its vertices, floored by the
    /// near guard), not the LLFF bounds.
    pub near: f64,
    pub far: f64,
    pub resolution: u32,
    pub fov_deg: f64,
    /// The focal length in pixels.
    pub focal_px: f64,
    /// The view's random stream of one purpose (a kind draws from its own, so adding
    /// or dropping a kind moves no other number of the plan).
    pub stream: &'a dyn Fn(u64) -> Stream,
    /// The Cycles seed of frame k of a render of one purpose (a kind's purpose plus
    /// its level).
    pub seed: &'a dyn Fn(u64, usize) -> u32,
    /// Cycles seed of the view's sharp render, which sample subsets share.
    pub sharp_seed: u32,
    /// The exposure a kind rendered as latent frames takes: the build's `latents`
    /// frames of `samples_per_frame` each, under sample subsets the blocks `offsets` of
    /// a `sequence`-sample sequence on the sharp seed (None: independent frames).
    pub latents: usize,
    pub samples_per_frame: u32,
    pub blocks: Option<(u32, Vec<u32>)>,
    /// Whether the build renders an exposure as one Cycles motion blur render.
    pub motion_blur: bool,
    /// The build's sampling, whose latents, positions, anchor and sample budget shape
    /// each blurry image of motion blur (`blur_method auto` included).
    pub cfg: &'a SamplingConfig,
    /// The view's camera p on its orbit (φ and θ in degrees), and δ, the trajectory drawn
    /// with it: motion blur's segments run from p along δ.
    pub r: f64,
    pub phi_deg: f64,
    pub theta_deg: f64,
    pub trajectory: Trajectory,
    /// The view's scene weight w_u (flatness, depth_range, orientation), which scales
    /// each motion blur level's w_l.
    pub w_u: f64,
    /// The object's box, whose corners' screen motion measures a blurry image.
    pub bbox_dims: [f64; 3],
    /// Under `blur_method auto`: the device's prices, and the price of every blurry
    /// image planned so far (the setting's record of the choice).
    pub pricing: Option<(&'a Pricing, &'a RefCell<Vec<ImagePrice>>)>,
}

impl ViewCx<'_> {
    /// Whether an image this kind would otherwise render as `frames` averaged renders
    /// is one motion-blur render instead: `--blur-method motion_blur`, or under `auto`
    /// where the device prices it lower (the price joins the setting's record). For a
    /// kind whose motion Cycles' keys follow exactly; the others keep `motion_blur`.
    pub fn motion_blur_for(&self, frames: usize) -> bool {
        match self.pricing {
            Some((pricing, prices)) if self.cfg.blur_method == BlurMethod::Auto => {
                let price = pricing.price(frames);
                prices.borrow_mut().push(price);
                price.cheaper() == BlurMethod::MotionBlur
            }
            _ => self.motion_blur,
        }
    }
}

/// The latent frames of the fewest count m in `first..=max` whose largest gap is within
/// `bound` (`latents auto`): `draw(m)` gives m frames and their largest gap (px). Each m
/// has its fixed draw, so the choice is reproducible; at `max` the gap may exceed the
/// bound (the caller records it).
pub fn fewest_frames(
    first: usize,
    max: usize,
    bound: f64,
    draw: impl Fn(usize) -> (Vec<f64>, f64),
) -> (Vec<f64>, f64) {
    let mut best = (Vec::new(), f64::INFINITY);
    for m in first..=max.max(first) {
        best = draw(m);
        if best.1 <= bound {
            break;
        }
    }
    best
}

/// The fewest frames a kind whose averaged frames (or bands) are centred on the written
/// pose takes: one would be the sharp image, not the level its record states.
pub const MIN_FRAMES: usize = 2;

/// Refuse, naming `latents` (`latents_max` under latents auto), an averaging build that
/// could give a level of kind `D` (its `levels`) fewer than [`MIN_FRAMES`]; `why` says
/// why one frame is the sharp image.
pub fn min_frames<D: Degradation>(cfg: &SamplingConfig, levels: &[u32], why: &str) -> Result<()> {
    let most = cfg.max_latents();
    if cfg.blur_method == BlurMethod::MotionBlur || most >= MIN_FRAMES {
        return Ok(());
    }
    let option = ["latents", "latents_max"][usize::from(cfg.latents_auto)];
    let fix = format!("give {MIN_FRAMES} or more, or blur_method motion_blur");
    let what = format!(
        "{} levels ({levels:?}) {why}, so one alone is the sharp image",
        D::NAME
    );
    Err(config_error(option, format!("{most}: {what}; {fix}")))
}

/// Where a view's renders of a kind go.
pub struct RenderCx<'a> {
    pub view: usize,
    /// OpenGL camera-to-world at p, the view's written pose, row-major.
    pub c2w: [[f64; 4]; 4],
    pub exr_dir: &'a Path,
    /// [`crate::BuildConfig::cycles_samples`]: the sequence every render is pinned to.
    pub pin: Option<u32>,
}

/// One degradation kind: `Level` is what the plan holds of one level of one view,
/// `Record` what meta.json records of it.
pub trait Degradation {
    type Level: Clone + Serialize;
    /// The level as meta.json records it: the `Level` itself, or less of it (motion
    /// blur's leaves out the camera matrices, which follow from r, φ, θ).
    type Record: Clone + Serialize;
    /// What the statistics read of a level's record in a meta.json (the fields its
    /// statistic needs, so an older record with fewer fields is still read).
    type Read: DeserializeOwned;
    /// Its key in a view of meta.json (and of the plan): `views[i].<NAME>`; for a
    /// registered kind its module's name, which is also its option and the prefix of its
    /// level directories ([`super::kind`]).
    const NAME: &'static str;
    /// The purpose of its random stream and render seeds (distinct per kind).
    const PURPOSE: u64;
    /// Its statistic, one value per view and level: (name, unit, help).
    const STAT: (&'static str, &'static str, &'static str);

    /// Its statistic's histogram in `blurset stats`: (title, x axis label with unit).
    const FIGURE: (&'static str, &'static str);
    /// What a level of the kind is, as a dataset card says it ("`defocus_l` the same
    /// views out of focus at level l").
    const MEANS: &'static str;
    /// Whether its images are seen from the view's written pose (a lens, a shake about
    /// the camera's centre) rather than being means over a moving camera whose mean
    /// latent pose meta.json records (motion blur).
    const WRITTEN_POSE: bool = true;
    /// Whether its image integrates a camera that moves during the exposure, so its
    /// level holds masks of its own (the pixels the exposure covered) rather than the
    /// sharp image's.
    const OWN_MASKS: bool = false;
    /// Its highest level, and why no higher level is meaningful (an error says it).
    const MAX_LEVEL: u32 = MAX_LEVEL;
    const LEVEL_RANGE: &'static str = "";
    /// The help of its option of `blurset build` (`--<NAME>`): what a level is.
    const OPTION_HELP: &'static str = "";

    /// The image of level `level` of this kind.
    fn kind(level: u32) -> ImageKind;
    /// The renders one view's level takes at most under `cfg` (one still render; an
    /// exposure of latent frames takes as many as a blurry image can).
    fn frames_per_level(_cfg: &SamplingConfig) -> usize {
        1
    }
    /// What the kind needs of the rest of the config, given its `levels` (not empty):
    /// a config error naming the option to change.
    fn check(_cfg: &SamplingConfig, _levels: &[u32]) -> Result<()> {
        Ok(())
    }
    /// The levels `levels` of one view, keyed by level number.
    fn plan_view(cx: &ViewCx, levels: &[u32]) -> BTreeMap<String, Self::Level>;
    /// The renders of one level of one view.
    fn renders(cx: &RenderCx, level: u32, rec: &Self::Level) -> Vec<Render>;
    /// The level's record in meta.json.
    fn record(level: &Self::Level) -> Self::Record;
    /// The level's statistic ([`Self::STAT`]) from its record in meta.json; None for a
    /// record written before the kind recorded it.
    fn stat(rec: &Self::Read) -> Option<f64>;
}

/// A kind as the statistics see it: its key in a view of meta.json, its statistic
/// (name, unit, help) and that statistic of one level's record.
pub struct KindStat {
    pub name: &'static str,
    pub stat: (&'static str, &'static str, &'static str),
    /// Its histogram's (title, x axis label).
    pub figure: (&'static str, &'static str),
    pub read: fn(&serde_json::Value) -> Option<Option<f64>>,
}

impl KindStat {
    pub const fn of<D: Degradation>() -> KindStat {
        KindStat {
            name: D::NAME,
            stat: D::STAT,
            figure: D::FIGURE,
            read: read_stat::<D>,
        }
    }
}

/// The statistic of one level's record (None: a record the kind cannot read; Some(None):
/// one from before the statistic).
fn read_stat<D: Degradation>(v: &serde_json::Value) -> Option<Option<f64>> {
    D::Read::deserialize(v).ok().map(|r| D::stat(&r))
}

/// The records in meta.json of every level of kind `D` of one view.
pub fn records<D: Degradation>(levels: &BTreeMap<String, D::Level>) -> BTreeMap<String, D::Record> {
    levels
        .iter()
        .map(|(k, l)| (k.clone(), D::record(l)))
        .collect()
}

/// The renders of every level of kind `D` of one view, in level order.
pub fn kind_renders<D: Degradation>(
    cx: &RenderCx,
    levels: &BTreeMap<String, D::Level>,
) -> Vec<Render> {
    levels
        .iter()
        .flat_map(|(key, rec)| D::renders(cx, key.parse().unwrap_or(0), rec))
        .collect()
}
