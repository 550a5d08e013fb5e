//! `meta.json` of one setting (DESIGN §4): every sampled number of its plan, how it was
//! rendered, the object, the QA of each sharp view. The writer and the reader
//! (`blurset stats`) share these structs; the reader's subset skips the rest unparsed.
use super::splits::test_views;
use crate::error::{Error, Result};
use crate::ground::atomic::write_atomic;
use crate::ground::names;
use crate::image::denoise::DenoiserRecord;
use crate::image::qa::FrameQa;
use crate::metrics::NOISE_BOUND_Z;
use crate::plan::camera::orbit_c2w;
use crate::plan::camera::rows;
use crate::plan::choices::{BlurBudget, BlurMethod, Denoise, LatentSampling, LightPaths, Preset};
use crate::plan::config::BuildConfig;
use crate::plan::cost::BlurChoice;
use crate::plan::degradation::Degradation;
use crate::plan::kind::ImageKind;
use crate::plan::motion::{MetaLevel, Motion, MotionStat};
use crate::plan::sampling::{SettingPlan, ViewPlan};
use crate::plan::sampling_config::{SamplingConfig, NEED_SATURATION_PX, PARITY_EXPONENT};
use crate::plan::target::{
    TargetRule, ACCEPT_BELOW_DB, AIM_ABOVE_DB, ALPHA_RANGE, FIRST_STEP_MAX, MAX_ROUNDS,
};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::Path;

/// Where the object came from, who made it and under which licence (issue 19: no path
/// of the build machine), and what the worker reported about it (null where it did not
/// say).
#[derive(Clone, Debug, Default, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct ObjectRecord {
    /// The model file, relative to the folder or list it was found in (or
    /// `objaverse:<uid>`).
    pub path: String,
    /// SHA-256 of that file: a rerun reuses a setting made from the same bytes.
    pub sha256: Option<String>,
    /// Attribution (dataset::license, blurset.attribution): `unknown` where the model
    /// and its annotations say nothing; `license` is the SPDX id (or `other`) of
    /// `license_text`, kept as given.
    pub title: String,
    pub author: String,
    pub author_url: Option<String>,
    pub license: String,
    pub license_text: String,
    pub source_url: String,
    /// The glTF `asset.copyright`, when the file has one.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub copyright: Option<String>,
    pub bbox_dims: Option<Vec<f64>>,
    pub scale: Option<f64>,
    pub center: Option<Vec<f64>>,
    pub n_vertices: Option<u64>,
    pub n_triangles: Option<u64>,
    pub unlit_fixed: Option<bool>,
    pub blender_version: Option<String>,
    pub warnings: Vec<String>,
}

/// Wall-clock seconds of a setting's stages (not part of the data: they vary per run).
#[derive(Clone, Debug, Default, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct Timings {
    pub plan_s: Option<f64>,
    pub sharp_s: Option<f64>,
    pub blur_s: Option<f64>,
    /// The geometry renders of `--passes depth,normal` (absent without them).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub geometry_s: Option<f64>,
    pub load_s: Option<f64>,
    pub total_s: Option<f64>,
    pub frames: usize,
}

/// How the images were rendered and encoded.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
pub struct RenderRecord {
    pub engine: String,
    /// Per level in views[].levels[].samples_per_frame; null when it differs between
    /// images (a budget split over m frames, or parity under `--latents auto`).
    pub samples_per_latent: Option<u32>,
    pub samples_total: Option<u32>,
    pub blur_method: BlurMethod,
    /// A number, or "auto".
    pub latents: serde_json::Value,
    /// Cycles samples of every sharp image; null under a render target, where each
    /// image renders its own (`views[].images`), never a count that was not rendered.
    pub sharp_samples: Option<u64>,
    /// How a blurry image's latent frames share Cycles samples (issue 15): `subsets` or
    /// `independent`, in words in `latent_sampling_is`. Per level: `sample_sequence`;
    /// per latent frame: `seed` and `sample_offset`.
    pub latent_sampling: LatentSampling,
    pub latent_sampling_is: String,
    /// `parity`, `need` or `flat`, in words in `blur_budget_is`; per level the result is
    /// `samples_per_frame`. A record without it is of a build before the option: flat.
    #[serde(default = "flat_budget")]
    pub blur_budget: BlurBudget,
    #[serde(default)]
    pub blur_budget_is: String,
    /// `oidn` (issue 28): every image denoised once by Open Image Denoise, in words in
    /// `denoise_is`, with the library and device in `denoiser`; absent (as in builds before
    /// it) when the images are as rendered.
    #[serde(default = "no_denoise", skip_serializing_if = "is_no_denoise")]
    pub denoise: Denoise,
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub denoise_is: String,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub denoiser: Option<DenoiserRecord>,
    /// The Cycles `samples` of every render under subsets (`BuildConfig::cycles_samples`).
    pub cycles_samples: Option<u32>,
    /// Cycles adaptive sampling stays off: with it the sharp image stops early while the
    /// sample blocks do not, and the pair loses its noise parity (issue 15).
    pub adaptive_sampling: bool,
    /// Light-path bounces the worker chose from the object's materials (or fixed).
    pub light_paths: Option<LightPathsRecord>,
    /// What the worker rendered on: backend, device names, Cycles kernel.
    pub device: Option<DeviceRecord>,
    pub exr_codec: String,
    pub background: [f64; 3],
    pub alpha: String,
    pub encoding: String,
    /// `<level>/linear/<view>.exr` beside images/ (`--keep-linear`), which `blurset
    /// verify` then expects; written only when true (a default build's meta.json is
    /// unchanged).
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub linear: bool,
    /// `--passes` (issue 35): the per-view outputs besides colour the sharp level holds
    /// (`depth`, `normal`, `mask`), each described in `passes_are`; absent (as in a
    /// default build and every build before them) when none.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub passes: Vec<String>,
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub passes_are: BTreeMap<String, String>,
    /// Each level whose camera moves during the exposure (`ImageKind::own_masks`) holds
    /// masks of its own coverage (`blur_<l>/masks/` …): true in a setting with the
    /// mask pass made since issue 48; absent before, where every level takes the sharp
    /// level's masks.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub level_masks: bool,
    /// The `--preset` the build was asked for (the options it set are recorded as options).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub preset: Option<Preset>,
    /// `--target-psnr`: every image rendered until its render PSNR, estimated from two
    /// halves of its samples on independent sequences, reached this on its object's
    /// pixels (in words in `target_is`); per image in `views[].images`. Absent: fixed
    /// sample counts.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub target_psnr_db: Option<f64>,
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub target_is: String,
    /// `blur_method auto` (the accuracy presets): how each blurry image's method was
    /// chosen from the device's costs (`plan/cost.rs`), each level's `method` being the
    /// result; absent under a method given.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub blur_choice: Option<BlurChoice>,
}

/// How one image of a target-driven build was rendered (`views[].images[<level dir>]`).
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ImageRender {
    /// Cycles samples the image rendered: every latent frame, both halves.
    pub samples: u64,
    /// Render rounds, the pilot included.
    pub rounds: u32,
    /// Its render PSNR (dB, peak 1, sRGB over the background, on its object's pixels),
    /// estimated from its two halves after the last round.
    pub render_psnr_db: f64,
    /// The PSNR it reaches at least (`metrics::half_noise_bound`: the estimate less its
    /// own scatter, wide where a few fireflies carry the noise): what the rounds stop on
    /// and `reached` judges. Absent in builds before it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub render_psnr_bound_db: Option<f64>,
    /// The estimate after the pilot round, from which the samples it needed were
    /// extrapolated (its bound, in builds that record `render_psnr_bound_db`).
    pub pilot_psnr_db: f64,
    /// Fraction of the frame that is object pixels (alpha over 1e-6, Cycles' rounding, in
    /// either half).
    pub coverage: f64,
    /// The bound is at the target (within 0.25 dB); false: the sample cap or the round
    /// limit stopped it first.
    pub reached: bool,
}

// The records below list their fields in alphabetical order: the worker's reports they
// type were written as JSON objects, whose keys serde_json sorts.

/// The Cycles bounce limits a worker set (`blender_scene.FIXED_BOUNCES`'s keys).
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq, Eq, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Bounces {
    pub diffuse_bounces: u32,
    pub glossy_bounces: u32,
    pub max_bounces: u32,
    pub transmission_bounces: u32,
    pub transparent_max_bounces: u32,
    pub volume_bounces: u32,
}

/// The light paths of an object's renders, as its worker reported them: the bounce
/// limits and what the materials can do that decided them under `auto`.
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq, Eq, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct LightPathsRecord {
    pub bounces: Bounces,
    pub mode: LightPaths,
    /// A rendered material transmits light (transmission, diffuse transmission, volume).
    pub transmission: bool,
    /// A rendered material is alpha-blended or alpha-masked.
    pub transparency: bool,
    /// Every rendered primitive is unlit (camera-only emission): no bounce changes it.
    pub unlit_only: bool,
}

/// The COLMAP verdict of a setting's sharp level (`--check-poses`, DESIGN §6), as
/// meta.json and dataset.json keep it: blurset.check_poses's report, compact.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct PoseCheck {
    /// The verdict's name (pass, fail, degenerate, …), or `error: <why>` when the check
    /// could not run (it never costs the setting itself).
    pub verdict: String,
    /// What the verdict means, in words.
    #[serde(default)]
    pub meaning: Option<String>,
    /// Whether the poses were recovered within the bar.
    pub pass: bool,
    /// Views COLMAP registered, of `total`.
    #[serde(default)]
    pub registered: Option<u32>,
    #[serde(default)]
    pub total: Option<u32>,
    /// Median rotation error of the registered views (degrees).
    #[serde(default)]
    pub median_rot_err_deg: Option<f64>,
    /// Median camera-centre error, relative to the camera's distance.
    #[serde(default)]
    pub median_center_err_rel: Option<f64>,
}

/// What a worker rendered on.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, Eq, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct DeviceRecord {
    /// The Cycles backend: CPU, OPTIX, CUDA, HIP, ONEAPI or METAL.
    pub backend: String,
    /// The names of the devices it used.
    pub devices: Vec<String>,
    /// The CPU's instruction set Cycles runs, or the GPU backend.
    pub kernel: String,
}

fn no_denoise() -> Denoise {
    Denoise::None
}

fn is_no_denoise(d: &Denoise) -> bool {
    *d == Denoise::None
}

fn flat_budget() -> BlurBudget {
    BlurBudget::Flat
}

impl RenderRecord {
    pub fn of(cfg: &BuildConfig) -> Self {
        RenderRecord {
            engine: "CYCLES".into(),
            samples_per_latent: samples_per_latent(cfg),
            samples_total: cfg.samples_total,
            blur_method: cfg.blur_method,
            latents: if cfg.latents_auto {
                "auto".into()
            } else {
                cfg.latents.into()
            },
            sharp_samples: cfg.fixed_sharp_samples(),
            latent_sampling: cfg.latent_sampling,
            latent_sampling_is: latent_sampling_is(cfg.latent_sampling).into(),
            blur_budget: cfg.blur_budget,
            blur_budget_is: blur_budget_is(cfg.blur_budget),
            denoise: cfg.denoise,
            denoise_is: if cfg.denoise == Denoise::Oidn {
                "Open Image Denoise (RT filter, quality high, hdr, albedo and normal guides \
                 prefiltered, cleanAux; Cycles' defaults) applied once to every finished \
                 image: the sharp render, and the mean of a blurry image's latent frames \
                 with the means of their albedo and normal passes; alpha as rendered"
                    .into()
            } else {
                String::new()
            },
            denoiser: None,
            cycles_samples: cfg.cycles_samples(),
            preset: cfg.preset,
            target_psnr_db: cfg.target_psnr,
            target_is: cfg.target().map(|t| target_is(&t)).unwrap_or_default(),
            blur_choice: None,
            adaptive_sampling: false,
            light_paths: None,
            device: None,
            exr_codec: "NONE (intermediate frames, deleted after accumulation)".into(),
            background: cfg.background,
            alpha: "premultiplied, averaged with colour, composited over background".into(),
            encoding: "sRGB (IEC 61966-2-1) of linear radiance, 8-bit PNG".into(),
            linear: cfg.write_linear,
            passes: cfg.passes.clone(),
            passes_are: cfg
                .passes
                .iter()
                .map(|p| (p.clone(), pass_is(p, &own_mask_kinds(&cfg.level_dirs()))))
                .collect(),
            level_masks: cfg.passes.iter().any(|p| p == "mask"),
        }
    }
}

/// What one `--passes` output holds, in words (meta.json's `render.passes_are`).
/// The level directory patterns (`<prefix><l>`) of the kinds among `levels`, beside motion
/// blur, whose levels hold masks of their own.
fn own_mask_kinds(levels: &[String]) -> Vec<String> {
    let mut out: Vec<String> = levels
        .iter()
        .filter_map(|d| ImageKind::parse(d))
        .filter(|k| k.own_masks() && !matches!(k, ImageKind::Blur(_)))
        .map(|k| k.dir_pattern())
        .collect();
    out.dedup();
    out
}

/// What a pass's files are, for meta.json; `own`: the level patterns beside blur_<l> whose
/// masks are their own (a build without such levels says what it said before they existed).
fn pass_is(pass: &str, own: &[String]) -> String {
    let at = "per view in sharp/{dir}/ (and {dir}_<f>/ per --downsample factor, rendered \
              at that size), named as its image";
    let dir = |p: &str| names::pass_dir(p, 1);
    match pass {
        "depth" => format!(
            "{}: float32 EXR, one channel Y: the distance, along the camera's viewing axis, \
             of the surface the pixel's centre sees (the meaning of poses_bounds.npy's near \
             and far), in world units; 0 where the pixel sees no surface",
            at.replace("{dir}", &dir(pass))
        ),
        "normal" => format!(
            "{}: float32 EXR, the unit normal (Cycles' shading normal) of the surface the \
             pixel's centre sees, in the world frame, x y z in channels R G B; 0 where the \
             pixel sees no surface",
            at.replace("{dir}", &dir(pass))
        ),
        _ => format!(
            "{}: 8-bit PNG, 255 where the sharp image covers at least half the pixel (its \
             alpha, area-averaged to the size), else 0; each blur level holds its own in \
             blur_<l>/{}/{}: 255 where the exposure covered the pixel (a latent frame's alpha \
             at least one half, or with blur_method motion_blur the render's alpha above \
             0, area-averaged to the size) or the sharp mask is 255; a held-out view's is \
             the sharp mask",
            at.replace("{dir}", &dir(pass))
                .replace(", rendered at that size", ""),
            dir(pass),
            own.iter()
                .map(|d| format!(", each {d} in {d}/{}/", dir(pass)))
                .collect::<String>()
        ),
    }
}

/// The count every latent frame renders, where one count holds for all of them (never
/// under a render target: each image renders what its own noise needs).
fn samples_per_latent(cfg: &BuildConfig) -> Option<u32> {
    let average = cfg.blur_method == BlurMethod::Average;
    if cfg.target_psnr.is_some() {
        return None;
    }
    match cfg.samples_total {
        Some(_) => None,
        None if cfg.blur_budget == BlurBudget::Need && average => None,
        None if cfg.blur_budget == BlurBudget::Parity && average => {
            (!cfg.latents_auto).then(|| cfg.sampling().samples_per_frame(cfg.latents))
        }
        None => Some(cfg.samples),
    }
}

fn latent_sampling_is(sampling: LatentSampling) -> &'static str {
    if sampling == LatentSampling::Subsets {
        "latent frame k of a level renders the Cycles samples [sample_offset, \
         sample_offset + samples_per_frame) of one sequence on the view's sharp_seed; \
         the sharp image renders its first sharp_samples; every render is a block of \
         a cycles_samples-sample Cycles sequence"
    } else {
        "every latent frame renders the first samples_per_frame samples of its own seed"
    }
}

fn blur_budget_is(budget: BlurBudget) -> String {
    match budget {
        BlurBudget::Need => format!(
            "a blurry image of m >= 2 latent frames renders the sample budget times \
             1 + (m^{PARITY_EXPONENT} - 1) * min(1, motion_px / m / \
             {NEED_SATURATION_PX}) (rounded up per frame): the parity factor bought \
             by its screen motion between frames; sharp_samples is the budget itself"
        ),
        BlurBudget::Parity => format!(
            "a blurry image of m >= 2 latent frames renders the sample budget times \
             m^{PARITY_EXPONENT} (rounded up per frame), so it carries no more render \
             noise than its sharp image; sharp_samples is the budget itself"
        ),
        _ => "a blurry image of m latent frames renders the sample budget split over them".into(),
    }
}

/// The rule of a target build in words, its numbers from the rule's own constants.
fn target_is(t: &TargetRule) -> String {
    let (alpha_lo, alpha_hi) = ALPHA_RANGE;
    format!(
        "each image (the sharp one and each blurry one) renders in rounds as two halves, \
         half 0 on the plan's seed and half 1 on an independent one, each half's frames \
         taking consecutive blocks of one {}-sample Cycles sequence; after each round its \
         render noise on its object pixels is estimated from each half's sRGB distance \
         from their merged image, with a bound: that MSE plus {NOISE_BOUND_Z:.2} standard \
         deviations of the estimate's own scatter (wide where a few pixels carry the \
         noise); after a pilot of \
         {} samples the samples it still needs are extrapolated from the bound as \
         samples^-alpha (alpha {alpha_hi} and at most {FIRST_STEP_MAX}x the samples from \
         the pilot alone, alpha fitted in [{alpha_lo}, {alpha_hi}] from two rounds, aimed \
         {AIM_ABOVE_DB} dB above the target), and it stops once the bound is within \
         {ACCEPT_BELOW_DB} dB of the target (at most {} samples, {MAX_ROUNDS} rounds); the \
         image is the mean of its halves. Its samples, rounds, estimate and bound are \
         views[].images[level]; a level record's samples_per_frame and sample blocks are \
         the plan's fixed counts, which half 0's seed shares, not the samples rendered",
        t.sequence(),
        t.pilot_samples,
        t.max_samples
    )
}

/// A view as meta.json records it: the plan's view with its levels' records and the
/// render QA of its sharp image.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
pub struct MetaView {
    #[serde(flatten)]
    pub view: ViewPlan<MetaLevel>,
    /// Render QA of the sharp view.
    pub qa: FrameQa,
    /// Under `--target-psnr`: how each image of the view was rendered, by level directory
    /// (`sharp`, `blur_1`, …; a held-out view's blur levels hold its sharp image).
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub images: BTreeMap<String, ImageRender>,
}

impl MetaView {
    fn of(v: &ViewPlan, qa: FrameQa) -> Self {
        MetaView {
            view: v.map_levels(Motion::record),
            qa,
            images: BTreeMap::new(),
        }
    }
}

/// What a setting made before `test_view_images` existed held at its test views.
fn blurry() -> String {
    "blurry".into()
}

/// The whole meta.json of a setting.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
pub struct Meta {
    pub uid: String,
    pub theta0_deg: f64,
    pub seed: u64,
    pub resolution: [u32; 2],
    pub fov_deg: f64,
    pub focal_px: f64,
    pub bbox_dims: [f64; 3],
    pub radius: f64,
    pub views: Vec<MetaView>,
    pub test_views: Vec<usize>,
    /// What the blur levels hold at the test views: `sharp` (copies of the sharp image,
    /// Deblur-NeRF's convention) or `blurry` (`--blurry-test-views`).
    #[serde(default = "blurry")]
    pub test_view_images: String,
    /// Level directories written (`sharp`, `blur_1`, …).
    pub levels: Vec<String>,
    /// Factors of the `images_<f>/` copies in every level (LLFF's downsampled images).
    #[serde(default)]
    pub downsample: Vec<u32>,
    pub sampling: SamplingConfig,
    pub render: RenderRecord,
    pub object: ObjectRecord,
    pub timings: Timings,
    pub blurset_version: String,
    /// The COLMAP verdict of the sharp level (`--check-poses`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pose_check: Option<PoseCheck>,
}

impl Meta {
    /// The record of a planned and rendered setting; `qa` holds one entry per view.
    pub fn new(
        plan: &SettingPlan,
        cfg: &BuildConfig,
        object: ObjectRecord,
        timings: Timings,
        qa: &[FrameQa],
    ) -> Result<Meta> {
        if qa.len() != plan.views.len() {
            return Err(Error::Shape(format!(
                "{} QA records for {} views",
                qa.len(),
                plan.views.len()
            )));
        }
        Ok(Meta {
            uid: plan.uid.clone(),
            theta0_deg: plan.theta0_deg,
            seed: plan.seed,
            resolution: plan.resolution,
            fov_deg: plan.fov_deg,
            focal_px: plan.focal_px,
            bbox_dims: plan.bbox_dims,
            radius: plan.radius,
            views: plan
                .views
                .iter()
                .zip(qa)
                .map(|(v, q)| MetaView::of(v, *q))
                .collect(),
            test_views: test_views(plan.views.len(), cfg.view_stride),
            test_view_images: cfg.test_view_images().into(),
            levels: cfg.level_dirs(),
            downsample: cfg.downsample.clone(),
            sampling: plan.config.clone(),
            render: RenderRecord {
                blur_choice: plan.blur_choice.clone(),
                ..RenderRecord::of(cfg)
            },
            object,
            timings,
            blurset_version: env!("CARGO_PKG_VERSION").into(),
            pose_check: None,
        })
    }

    /// Record how each image was rendered under a target: (view, level dir, record).
    pub fn set_images(&mut self, images: Vec<(usize, String, ImageRender)>) -> Result<()> {
        let n = self.views.len();
        for (view, level, record) in images {
            let v = self.views.get_mut(view).ok_or_else(|| {
                Error::Shape(format!(
                    "image record of view {view}: the setting has {n} views"
                ))
            })?;
            v.images.insert(level, record);
        }
        Ok(())
    }

    /// Write meta.json atomically (one-space indent, like the build's other JSON).
    pub fn write(&self, path: &Path) -> Result<()> {
        write_json(path, self)
    }
}

/// `x` rounded to `digits` decimals, correctly (the nearest decimal, ties to even, as
/// Python's `round`): the figures the records keep.
pub fn round_to(x: f64, digits: usize) -> f64 {
    format!("{x:.digits$}").parse().unwrap_or(x)
}

/// Serialize `value` as JSON (indent 1, newline at the end) and write it atomically.
pub fn write_json<T: Serialize>(path: &Path, value: &T) -> Result<()> {
    let mut buf = Vec::new();
    let fmt = serde_json::ser::PrettyFormatter::with_indent(b" ");
    let mut ser = serde_json::Serializer::with_formatter(&mut buf, fmt);
    value
        .serialize(&mut ser)
        .map_err(|e| Error::Value(format!("cannot write JSON ({e}): {}", path.display())))?;
    buf.push(b'\n');
    write_atomic(path, &buf)
}

// -- what `blurset stats` reads of a meta.json (a subset of the above) -----------------

/// How an image of a target-driven build was rendered, as the statistics read it.
#[derive(Debug, Deserialize)]
pub struct ReadImage {
    pub samples: u64,
    pub render_psnr_db: f64,
}

#[derive(Debug, Deserialize)]
pub struct ReadView {
    pub index: u64,
    pub near: f64,
    pub far: f64,
    pub flatness: f64,
    pub depth_range: f64,
    pub orientation: f64,
    pub w_u: f64,
    #[serde(default)]
    pub levels: BTreeMap<String, MotionStat>,
    /// `--target-psnr` builds: per level directory.
    #[serde(default)]
    pub images: BTreeMap<String, ReadImage>,
    /// The view's other fields, among them each degradation kind's levels (`defocus`
    /// …), which the statistics read through the kind ([`crate::plan::kinds::KIND_STATS`]).
    #[serde(flatten)]
    pub rest: BTreeMap<String, serde_json::Value>,
}

/// The fields of [`Meta`] the statistics use (older metas may lack `levels`).
#[derive(Debug, Deserialize)]
pub struct ReadMeta {
    pub uid: String,
    pub theta0_deg: f64,
    pub bbox_dims: [f64; 3],
    pub views: Vec<ReadView>,
    #[serde(default)]
    pub levels: Option<Vec<String>>,
    #[serde(default)]
    pub test_views: Option<Vec<u64>>,
    /// `sharp` when the blur levels hold the sharp image at the test views; absent in
    /// metas from before the field, whose test views were blurry.
    #[serde(default)]
    pub test_view_images: Option<String>,
}

// -- what `blurset check-poses` reads: the mean latent poses of a blur level -----------

#[derive(Deserialize)]
struct PoseRead {
    c2w: [[f64; 4]; 4],
}

/// A latent frame or motion key as meta.json records it: where on the orbit, when.
#[derive(Deserialize)]
struct OrbitRead {
    t: f64,
    r: f64,
    phi_deg: f64,
    theta_deg: f64,
}

#[derive(Deserialize)]
struct MotionRead {
    #[serde(default)]
    keys: Vec<OrbitRead>,
}

#[derive(Deserialize)]
struct LevelPoseRead {
    #[serde(default)]
    mean_pose: Option<PoseRead>,
    #[serde(default)]
    latent_frames: Vec<OrbitRead>,
    #[serde(default)]
    motion_blur: Option<MotionRead>,
}

#[derive(Deserialize)]
struct ViewPoseRead {
    c2w: [[f64; 4]; 4],
    #[serde(default)]
    levels: BTreeMap<String, LevelPoseRead>,
}

#[derive(Deserialize)]
struct MetaPoseRead {
    views: Vec<ViewPoseRead>,
    #[serde(default)]
    test_views: Vec<usize>,
    #[serde(default = "blurry")]
    test_view_images: String,
}

/// The mean latent pose (OpenGL camera-to-world, row-major) of blur level `level` of every
/// view of a setting's meta.json, in view order: the pose a blurry image's content is
/// centred on, which check-poses compares SfM with. A test view whose blur levels hold the
/// sharp image (`test_view_images` sharp) gets its written pose: that image was rendered
/// there. None when the meta.json predates mean poses; an error naming the file when it is unreadable, lacks the level, or a pose
/// is not finite.
pub fn read_mean_poses(path: &Path, level: u32) -> Result<Option<Vec<[[f64; 4]; 4]>>> {
    let bad = |reason: String| Error::Input {
        reason,
        path: path.to_path_buf(),
    };
    let meta = read_pose_meta(path)?;
    let key = level.to_string();
    let mut poses = Vec::with_capacity(meta.views.len());
    for (i, v) in meta.views.iter().enumerate() {
        let lp = v
            .levels
            .get(&key)
            .ok_or_else(|| bad(format!("view {i} of meta.json has no blur level {level}")))?;
        let Some(mp) = &lp.mean_pose else {
            return Ok(None);
        };
        let sharp_copy = meta.test_view_images == "sharp" && meta.test_views.contains(&i);
        let c2w = if sharp_copy { v.c2w } else { mp.c2w };
        if !c2w.iter().flatten().all(|x| x.is_finite()) {
            return Err(bad(format!(
                "view {i}: the mean pose of blur level {level} is not finite"
            )));
        }
        poses.push(c2w);
    }
    Ok(Some(poses))
}

fn read_pose_meta(path: &Path) -> Result<MetaPoseRead> {
    let bytes = std::fs::read(path).map_err(|e| Error::io("cannot read meta.json", path, e))?;
    serde_json::from_slice(&bytes).map_err(|e| Error::Input {
        reason: format!("corrupt meta.json ({e})"),
        path: path.to_path_buf(),
    })
}

/// Where each view's exposure of blur level `level` opens and closes: the OpenGL
/// camera-to-world (row-major) of its first and last latent frame in time (first and last
/// motion key under the motion blur method), the ends of the streaks a blurry image shows.
/// None for a view whose image is a sharp copy (`test_view_images` sharp) or that has
/// fewer than two frames; None overall for a meta.json from before mean poses.
#[allow(clippy::type_complexity)]
pub fn read_exposure_ends(path: &Path, level: u32) -> Result<Option<Vec<Option<[Pose; 2]>>>> {
    let meta = read_pose_meta(path)?;
    let key = level.to_string();
    let mut ends = Vec::with_capacity(meta.views.len());
    for (i, v) in meta.views.iter().enumerate() {
        let Some(lp) = v.levels.get(&key) else {
            return Err(Error::Input {
                reason: format!("view {i} of meta.json has no blur level {level}"),
                path: path.to_path_buf(),
            });
        };
        if lp.mean_pose.is_none() {
            return Ok(None);
        }
        let frames = match &lp.motion_blur {
            Some(m) if lp.latent_frames.is_empty() => &m.keys,
            _ => &lp.latent_frames,
        };
        let sharp_copy = meta.test_view_images == "sharp" && meta.test_views.contains(&i);
        let by_t = |a: &&OrbitRead, b: &&OrbitRead| a.t.total_cmp(&b.t);
        let pose = |f: &OrbitRead| rows(&orbit_c2w(f.r, f.phi_deg, f.theta_deg));
        ends.push(
            match (frames.iter().min_by(by_t), frames.iter().max_by(by_t)) {
                (Some(first), Some(last)) if frames.len() >= 2 && !sharp_copy => {
                    Some([pose(first), pose(last)])
                }
                _ => None,
            },
        );
    }
    Ok(Some(ends))
}

/// An OpenGL camera-to-world, row-major.
pub type Pose = [[f64; 4]; 4];

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plan::sampling::plan_setting;

    #[test]
    fn the_target_text_names_what_the_rounds_stop_on_and_where_the_samples_are() {
        let rule = TargetRule {
            target_psnr_db: 45.0,
            pilot_samples: 32,
            max_samples: 16384,
        };
        let text = target_is(&rule);
        // The rounds stop on the bound, not the estimate (metrics::half_noise_bound).
        assert!(
            text.contains("it stops once the bound is within 0.25 dB"),
            "{text}"
        );
        assert!(text.contains("plus 2.81 standard deviations"), "{text}");
        assert!(
            text.contains("sRGB distance from their merged image"),
            "{text}"
        );
        assert!(text.contains("a pilot of 32 samples") && text.contains("8192-sample"));
        // A reader of a level's fixed-count blocks is told they are not what rendered.
        assert!(
            text.contains("views[].images[level]") && text.contains("not the samples rendered")
        );
    }

    #[test]
    fn the_mask_pass_names_every_level_kind_that_holds_its_own() {
        let levels = |v: &[&str]| v.iter().map(|s| s.to_string()).collect::<Vec<_>>();
        // Blur and defocus only: the text a build wrote before other kinds had masks.
        let plain = pass_is(
            "mask",
            &own_mask_kinds(&levels(&["sharp", "blur_1", "defocus_2"])),
        );
        assert!(plain.contains("blur_<l>/masks/:") && !plain.contains("defocus_<l>/masks"));
        // Another kind's own masks named: tests/test_blur_masks.py, on its build's meta.json.
        assert_eq!(pass_is("depth", &["x_<l>".into()]), pass_is("depth", &[]));
    }

    #[test]
    fn rounding_is_to_the_nearest_decimal_ties_to_even() {
        assert_eq!(round_to(0.007_812_5, 6), 0.007_812);
        assert_eq!(round_to(3.5, 0), 4.0);
        assert_eq!(round_to(35.123_456, 3), 35.123);
        assert_eq!(round_to(2.5, 0), 2.0);
        assert_eq!(round_to(0.25, 1), 0.2);
    }

    const QA: FrameQa = FrameQa {
        coverage: 0.5,
        luminance: 0.2,
        saturated: 0.0,
        border_coverage: 0.0,
    };

    /// A config of 3 views and levels 1 and 3, its plan of one setting and its meta.json.
    fn planned() -> Result<(BuildConfig, SettingPlan, Meta)> {
        let cfg = BuildConfig {
            views: 3,
            levels: vec![1, 3],
            latents: 2,
            ..Default::default()
        };
        let plan = plan_setting(&cfg.sampling(), "u", 90.0, 5, [1.0, 0.5, 0.5], &[])?;
        let meta = Meta::new(
            &plan,
            &cfg,
            ObjectRecord::default(),
            Timings::default(),
            &[QA; 3],
        )?;
        Ok((cfg, plan, meta))
    }

    fn value(meta: &Meta) -> Result<serde_json::Value> {
        serde_json::to_value(meta).map_err(|e| Error::Value(e.to_string()))
    }

    #[test]
    fn meta_is_the_plan_without_cameras_and_stats_can_read_it() -> Result<()> {
        let (cfg, plan, meta) = planned()?;
        let v = value(&meta)?;
        let frame = &v["views"][1]["levels"]["3"]["latent_frames"][0];
        assert!(frame.get("c2w").is_none() && frame.get("seed").is_some());
        assert_eq!(v["views"][1]["c2w"], serde_json::json!(plan.views[1].c2w));
        assert_eq!(
            v["levels"],
            serde_json::json!(["sharp", "blur_1", "blur_3"])
        );
        assert!(v.get("pose_check").is_none());
        let back: ReadMeta =
            serde_json::from_value(v.clone()).map_err(|e| Error::Value(e.to_string()))?;
        assert_eq!((back.views.len(), back.views[2].levels.len()), (3, 2));
        // One QA record a view.
        let one_qa = Meta::new(
            &plan,
            &cfg,
            ObjectRecord::default(),
            Timings::default(),
            &[QA],
        );
        assert!(one_qa.is_err());
        Ok(())
    }

    #[test]
    fn the_render_record_says_what_every_latent_frame_renders() -> Result<()> {
        let (cfg, _, meta) = planned()?;
        let v = value(&meta)?;
        // What every latent frame renders: 32 × 2^0.4 = 42.2 → 43 under parity.
        assert_eq!(v["render"]["samples_per_latent"], 43);
        assert_eq!(v["render"]["blur_budget"], "parity");
        assert_eq!(v["views"][1]["levels"]["3"]["samples_per_frame"], 43);
        let flat = BuildConfig {
            blur_budget: BlurBudget::Flat,
            ..cfg.clone()
        };
        assert_eq!(RenderRecord::of(&flat).samples_per_latent, Some(32));
        let auto = BuildConfig {
            latents_auto: true,
            ..cfg.clone()
        };
        assert_eq!(RenderRecord::of(&auto).samples_per_latent, None);
        assert_eq!(RenderRecord::of(&cfg).sharp_samples, Some(32 * 2));
        // Under a render target every image renders its own count: none is stated.
        let target = BuildConfig {
            target_psnr: Some(30.0),
            ..cfg.clone()
        };
        let r = RenderRecord::of(&target);
        assert_eq!((r.sharp_samples, r.samples_per_latent), (None, None));
        // A default build's render record is unchanged; --keep-linear says so.
        assert!(v["render"].get("linear").is_none());
        let linear = BuildConfig {
            write_linear: true,
            ..cfg.clone()
        };
        assert_eq!(
            serde_json::to_value(RenderRecord::of(&linear))
                .map_err(|e| Error::Value(e.to_string()))?["linear"],
            true
        );
        Ok(())
    }

    #[test]
    fn the_object_names_no_builder_path() -> Result<()> {
        // Issue 19: `source` is no field.
        let obj: ObjectRecord = serde_json::from_str(r#"{"path": "a.glb", "license": "CC0-1.0"}"#)
            .map_err(|e| Error::Value(e.to_string()))?;
        assert_eq!(
            (obj.path.as_str(), obj.license.as_str()),
            ("a.glb", "CC0-1.0")
        );
        assert!(serde_json::from_str::<ObjectRecord>(r#"{"source": "/home/u/a.glb"}"#).is_err());
        Ok(())
    }

    #[test]
    fn check_poses_reads_the_mean_poses_and_exposure_ends_back() -> Result<()> {
        let (_, plan, meta) = planned()?;
        let v = value(&meta)?;
        // check-poses reads each view's mean latent pose of a level back whole.
        let dir = std::env::temp_dir().join(format!("blurset-meta-{}", std::process::id()));
        std::fs::create_dir_all(&dir).map_err(|e| Error::io("mkdir", &dir, e))?;
        let path = dir.join("meta.json");
        meta.write(&path)?;
        let poses = read_mean_poses(&path, 3)?.expect("mean poses");
        // A test view holds the sharp image in its blur levels: its pose is the written one.
        assert_eq!(
            (meta.test_views.as_slice(), meta.test_view_images.as_str()),
            (&[0][..], "sharp")
        );
        let want: Vec<_> = plan
            .views
            .iter()
            .map(|v| match v.index {
                0 => v.c2w,
                _ => v.levels["3"].mean_pose.c2w,
            })
            .collect();
        assert_eq!(poses, want);
        assert_ne!(plan.views[0].c2w, plan.views[0].levels["3"].mean_pose.c2w);
        // The exposure's ends are its first and last latent camera; none at a sharp copy.
        let ends = read_exposure_ends(&path, 3)?.expect("ends");
        assert!(ends[0].is_none());
        let frames = &plan.views[1].levels["3"].latent_frames;
        assert_eq!(ends[1], Some([frames[0].c2w, frames[frames.len() - 1].c2w]));
        let mut blurry = v.clone();
        blurry["test_view_images"] = "blurry".into();
        write_json(&path, &blurry)?;
        let poses = read_mean_poses(&path, 3)?.expect("mean poses");
        assert_eq!(poses[0], plan.views[0].levels["3"].mean_pose.c2w);
        assert!(read_exposure_ends(&path, 3)?.expect("ends")[0].is_some());
        assert!(matches!(
            read_mean_poses(&path, 2),
            Err(Error::Input { .. })
        ));
        let mut old = v.clone();
        for view in old["views"].as_array_mut().expect("views") {
            for lvl in view["levels"].as_object_mut().expect("levels").values_mut() {
                lvl.as_object_mut().expect("level").remove("mean_pose");
            }
        }
        write_json(&path, &old)?;
        assert_eq!(
            read_mean_poses(&path, 1)?,
            None,
            "a meta.json from before mean poses"
        );
        assert_eq!(read_exposure_ends(&path, 1)?, None);
        std::fs::write(&path, b"{").map_err(|e| Error::io("write", &path, e))?;
        assert!(matches!(
            read_mean_poses(&path, 1),
            Err(Error::Input { .. })
        ));
        std::fs::remove_dir_all(&dir).map_err(|e| Error::io("rm", &dir, e))?;
        Ok(())
    }
}
