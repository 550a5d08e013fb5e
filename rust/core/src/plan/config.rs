//! The build configuration: every option of `blurset build`, its default, its range and
//! the one validator (DESIGN §2, §10). Python maps flags and TOML keys onto these fields
//! ([`BuildConfig::from_values`]) and only formats the errors.
//!
//! A value is checked against its field's [`Spec`]; an error names the option, the value
//! and the range (`views -1: must be an integer in 1..=4096`), never a parser position.
//! The sampling options form the [`SamplingConfig`] of every setting's plan.
use super::choices::{
    choice, BlurBudget, BlurMethod, Denoise, Device, Executor, LatentPositions, LatentSampling,
    LightPaths, Preset, TrajectoryAnchor,
};
use super::cost::Pricing;
use super::kind_levels::KindLevels;
use super::options::{config_struct, shapes_outputs, Meta, OptionInfo};
use super::presets::preset_values;
use super::sampling_config::SamplingConfig;
use super::spec::{check, specs, Kind, OptionValue, Raw, Spec, MIN_RENDER_PX};
use super::spec::{config_error, convert};
use super::target::TargetRule;
use super::weights::Guards;
use crate::error::Result;
use crate::ground::names::{self, test_views};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

const SAMPLING: fn() -> SamplingConfig = SamplingConfig::default;

/// The options of `blurset build`, declared once (DESIGN §10): `name: Type = default,
/// range, shapes|run { flags, help, … }` ([`super::options::Meta`]). `shapes`: the
/// option shapes the files a build writes, so a rerun into the same output must keep
/// it; `run`: it decides only where and how the build runs. The table is a macro so
/// that one list makes the struct here ([`config_struct!`]) and the binding's getters
/// (`rust/py/src/config.rs`); Python makes the flags, the TOML keys and the CLI
/// reference from [`BuildConfig::declarations`].
#[macro_export]
macro_rules! build_options {
    ($then:ident $({ $($extra:tt)* })?) => { $crate::kinds! { [$crate::kind_rows] { $then { $({ $($extra)* })?
    /// Every option of `blurset build` (see the module docs).
    BuildConfig, "blurset build";
    /// GLB files, folders of them, list files, objaverse ids (resolved by Python).
    objects: Vec<String> = Vec::new(), Spec::StrList, run {
        help: "GLB files, folders of GLBs, or text files listing them (required, unless --demo)",
    };
    /// The output directory.
    out: Option<String> = None, Spec::Str, run {
        help: "output directory (required)",
    };
    /// Built-in procedural objects (and smaller defaults: the `demo` of each option).
    demo: bool = false, Spec::Bool, run {
        help: "built-in procedural objects",
    };
    settings_per_object: usize = 4, Spec::int(1, 360), shapes {
        help: "azimuth settings per object",
        demo: Some(1),
    };
    views: usize = SAMPLING().views, specs::COUNT, shapes {
        help: "views per setting",
        demo: Some(17),
    };
    levels: Vec<u32> = SAMPLING().levels, Spec::Levels, shapes {
        help: "blur levels, e.g. 1,2,3,4 or none (sharp only)",
    };
    latents: usize = SAMPLING().latents, specs::COUNT, shapes {
        kind: Some(Kind::CountOrAuto),
        help: "latent frames averaged per blurry image, or auto: per view and level, the \
            fewest that leave no gap over --max-ghost-px on screen",
        demo: Some(6),
    };
    /// m per view and level from the screen motion (DESIGN §8), at most latents_max.
    latents_auto: bool = SAMPLING().latents_auto, Spec::Bool, shapes {
        via: Some("latents"),
    };
    latents_max: usize = SAMPLING().latents_max, specs::COUNT, shapes {
        help: "cap of --latents auto",
    };
    max_ghost_px: f64 = SAMPLING().max_ghost_px, specs::MAX_GHOST_PX, shapes {
        help: "--latents auto: largest screen gap between latent frames, px",
    };
    /// `auto`: per blurry image the method the rendering device makes for less
    /// (`plan/cost.rs`), under a render target.
    blur_method: BlurMethod = BlurMethod::Average, choice::<BlurMethod>(), shapes {
        help: "average of latent renders (the paper), one Cycles motion blur render, or \
            auto: per blurry image whichever costs the rendering device less (motion blur \
            where render calls are dear, a GPU; averaged frames on a CPU), under \
            --target-psnr; meta.json's render.blur_choice says why",
    };
    /// Cycles samples per rendered latent frame.
    samples: u32 = SAMPLING().samples, specs::SAMPLES, shapes {
        help: "Cycles samples per latent frame of the flat split (budget S = this × m)",
        demo: Some(4),
    };
    /// Sample budget S of one blurry image: ⌈S / m⌉ samples per latent frame.
    samples_total: Option<u32> = None, specs::SAMPLES, shapes {
        help: "sample budget S of one blurry image: its m latent frames render \
            ceil(S·m^0.4/m) samples each under --blur-budget parity, ceil(S/m) under flat",
        unset: Some("--samples × the most latent frames of an image"),
    };
    /// Samples of the sharp render; None = the blurry image's budget.
    sharp_samples: Option<u32> = None, specs::SAMPLES, shapes {
        help: "Cycles samples of the sharp image",
        unset: Some("the blurry image's budget S"),
    };
    /// `subsets`: a blurry image's latent frames render the blocks of one sample sequence
    /// on the view's seed, which the sharp image renders too (issue 15); `independent`:
    /// a seed per frame (builds before it).
    latent_sampling: LatentSampling = LatentSampling::Subsets, choice::<LatentSampling>(), shapes {
        help: "subsets: a blurry image's latent frames render the blocks of one sample \
            sequence on the view's seed, which the sharp image renders too; independent: \
            a seed per frame",
        before: Some(LatentSampling::Independent),
    };
    /// `parity`: a blurry image gets the budget times a factor of its m and motion, so
    /// it carries no more render noise than its sharp image (issue 15); `flat`: the
    /// budget as given (builds before it).
    blur_budget: BlurBudget = BlurBudget::Parity, choice::<BlurBudget>(), shapes {
        help: "parity: a blurry image of m >= 2 latent frames renders the sample budget S \
            times m^0.4, so it is no noisier than its sharp image; need: that factor bought \
            by the image's measured motion between frames (less for small motion); flat: \
            the budget as given, ceil(S/m) samples a frame",
        before: Some(BlurBudget::Flat),
    };
    /// `none`: images as rendered; `oidn`: every image (the sharp one and the mean of a
    /// blurry image's latent frames, with their averaged albedo and normal guides)
    /// denoised once by Open Image Denoise.
    denoise: Denoise = Denoise::None, choice::<Denoise>(), shapes {
        help: "none: images as rendered; oidn: every image denoised once by Open Image \
            Denoise, a blurry image after averaging (its frames' albedo and normal averaged \
            the same way), the sharp image the same way",
    };
    /// A named set of options (`plan/presets.rs`), applied under the options given.
    preset: Option<Preset> = None, choice::<Preset>(), run {
        help: "a named set of options, under those given beside it: paper (the paper's \
            construction), balanced, floor, fast (latent frames by motion, every image \
            rendered to 50 dB, the 8-bit floor 58.9 dB, 40 dB on its object's pixels)",
        unset: Some("none: the options as given (the paper's defaults)"),
    };
    /// Render every image to this render PSNR on its object's pixels (`plan/target.rs`).
    target_psnr: Option<f64> = None, specs::TARGET_PSNR, shapes {
        help: "render every image (sharp and blurry, each view and level) until its own \
            render noise, estimated from two independent halves of its samples, reaches \
            this PSNR (dB) on its object's pixels; replaces the fixed sample counts",
        unset: Some("none: fixed sample counts (--samples, --samples-total, --sharp-samples)"),
    };
    /// Samples of an image's first round under a target, both halves together.
    target_pilot_samples: u32 = 32, specs::SAMPLES, shapes {
        help: "--target-psnr: samples of each image's first round, from which the rest \
            it needs is estimated (at least one per latent frame and half)",
    };
    /// Most samples of one image under a target, both halves together.
    target_max_samples: u32 = 16384, specs::TARGET_MAX_SAMPLES, shapes {
        help: "--target-psnr: most samples of one image, at least 2 per latent frame (an \
            image that would need more stops there, and meta.json says it did not reach \
            the target)",
    };
    /// `auto`: light-path bounces from the object's materials; `fixed`: the same for all.
    light_paths: LightPaths = LightPaths::Auto, choice::<LightPaths>(), shapes {
        help: "light-path bounces from the object's materials (auto) or the same for every \
            object",
        before: Some(LightPaths::Fixed),
    };
    /// Cycles device (run-only: the pixels are the plan's on any device, within noise).
    device: Device = Device::Auto, choice::<Device>(), run {
        help: "Cycles device; auto: the best backend Cycles reports \
            (OptiX > CUDA > HIP > oneAPI > Metal > CPU)",
    };
    /// GPU indices of the backend; None = all of them.
    gpus: Option<Vec<u32>> = None, Spec::Indices, run {
        help: "GPU indices of the backend, e.g. 0,2, or all",
        unset: Some("all"),
    };
    /// GPUs each Ray task reserves; None = 1 with a GPU device, else 0.
    gpus_per_task: Option<f64> = None, specs::GPUS_PER_TASK, run {
        help: "GPUs each Ray task reserves (--executor ray)",
        unset: Some("1 with a GPU device, else 0"),
    };
    resolution: u32 = SAMPLING().resolution, specs::RESOLUTION, shapes {
        help: "image side in pixels, square",
        demo: Some(96),
    };
    seed: u64 = 0, specs::SEED, shapes {
        help: "build seed",
    };
    fov_deg: f64 = SAMPLING().fov_deg, specs::FOV_DEG, shapes {
        help: "field of view in degrees",
    };
    phi0_deg: f64 = SAMPLING().phi0_deg, specs::PHI0_DEG, shapes {
        toml_only: true,
        help: "polar angle φ0 of the views, degrees: each view's φ is drawn in φ0 ± window_deg",
    };
    window_deg: f64 = SAMPLING().window_deg, specs::WINDOW_DEG, shapes {
        toml_only: true,
        help: "half-width of the windows a view's polar angle and azimuth are drawn in \
            (φ0 ± w, θ0 ± w), degrees",
    };
    delta0: f64 = SAMPLING().delta0, specs::DELTA0, shapes {
        toml_only: true,
        help: "largest trajectory step of a blurry image per component (Δr %, Δφ, Δθ in \
            degrees), each drawn in ±[δ0/2, δ0]",
    };
    radius_margin: f64 = SAMPLING().radius_margin, specs::RADIUS_MARGIN, shapes {
        toml_only: true,
        help: "camera distance = this × the bounding sphere's radius / sin(fov / 2)",
    };
    level_spread: f64 = SAMPLING().level_spread, specs::LEVEL_SPREAD, shapes {
        toml_only: true,
        help: "spread s of a level's blur weight: w_l ~ U[1 − s, 1 + s] · w_u · l",
    };
    latent_positions: LatentPositions = SAMPLING().latent_positions, choice::<LatentPositions>(), shapes {
        help: "latent positions on the segment: uniform random or stratified",
    };
    /// Where the written pose p sits on a blurry image's segment: `start` (the paper's
    /// U(p, p + w_l·δ)) or `centered` (U(p − w_l·δ/2, p + w_l·δ/2)).
    trajectory: TrajectoryAnchor = SAMPLING().trajectory, choice::<TrajectoryAnchor>(), shapes {
        help: "where the written pose p sits on each blurry image's camera path: its start \
            (the paper) or its middle, so sharp image, pose and exposure coincide",
    };
    orientation_max: f64 = SAMPLING().guards.orientation_max, specs::ORIENTATION_MAX, shapes {
        toml_only: true,
        help: "cap of the orientation term O = max(d) / min(d) of the blur weight (a sheet \
            would blur without bound)",
    };
    near_floor: f64 = SAMPLING().guards.near_floor, specs::NEAR_FLOOR, shapes {
        toml_only: true,
        help: "floor of a view's near depth (object units) in the depth range f / n of the \
            blur weight",
    };
    /// Linear RGB the transparent film is composited over.
    background: [f64; 3] = [1.0, 1.0, 1.0], Spec::Rgb, shapes {
        toml_only: true,
        help: "linear RGB the transparent film is composited over",
    };
    /// linear/<view>.exr beside images/ per level (`--keep-linear`).
    write_linear: bool = false, Spec::Bool, shapes {
        flags: &["--keep-linear", "--write-linear"],
        help: "also store the linear float image (EXR) of every view and level; \
            `blurset noise BUILD` then starts from it",
    };
    /// <setting>/preview.png, written before the marker.
    previews: bool = false, Spec::Bool, run {
        help: "write <setting>/preview.png",
    };
    /// Every k-th view of a setting is held out (`--test-view-stride`, LLFF's llffhold).
    view_stride: usize = 16, specs::COUNT, shapes {
        flags: &["--test-view-stride"],
        help: "every k-th view of a setting is held out (LLFF's llffhold)",
    };
    /// Test settings: a seeded fraction of the objects, or the objects listed
    /// (`--test-objects`), or N random settings (`test_settings`), not both.
    test_fraction: f64 = 0.2, specs::FRACTION, run {
        via: Some("test_objects"),
    };
    test_objects: Option<Vec<String>> = None, Spec::StrList, run {
        kind: Some(Kind::FractionOrIds),
        help: "test settings: a seeded fraction F of the objects, or object ids a,b",
        group: Some("test split"),
    };
    /// N seeded random test settings (the paper's 52).
    test_settings: Option<usize> = None, Spec::int(1, u32::MAX as i128), run {
        help: "test settings: N seeded random settings (the paper: 52)",
        unset: Some("none, --test-objects decides"),
        group: Some("test split"),
    };
    /// Render the held-out views blurry too; by default the blur levels hold the sharp
    /// image there (Deblur-NeRF's convention; those blur renders are skipped).
    blurry_test_views: bool = false, Spec::Bool, shapes {
        help: "render the held-out views blurry too (off: Deblur-NeRF's convention, the \
            blur levels hold the sharp image there)",
        before: Some(true),
    };
    /// `images_<f>/` beside `images/` in every level: area mean in linear light, sRGB.
    downsample: Vec<u32> = vec![4], Spec::Factors, shapes {
        help: "images_<f>/ beside images/ in every level, area-averaged in linear light \
            (e.g. 4 8, or none)",
        before: Some(Vec::new()),
    };
    // Here each registered kind's option (`defocus`, `shake`, …), made by `kind_rows!`.
    } {
    /// Depth, normals and masks of every view, in the sharp level (issue 35): depth and
    /// normals from one extra one-sample render per view and size, masks from coverage.
    passes: Vec<String> = Vec::new(), Spec::Passes, shapes {
        help: "per-view outputs besides colour: depth (EXR, along the viewing axis, world \
            units) and normal (EXR, world frame) in the sharp level, mask (PNG, from \
            coverage) in the sharp level and, their own, in each blur, shake and rolling \
            shutter level; comma-separated, or none",
        before: Some(Vec::new()),
    };
    workers: usize = 1, specs::WORKERS, run {
        help: "objects rendered in parallel",
    };
    /// Workers rendering on each GPU at once; None = one worker per GPU (or --workers).
    workers_per_gpu: Option<usize> = None, specs::WORKERS_PER_GPU, run {
        help: "workers rendering on each GPU at once, to overlap the fixed cost of a \
            render call (a GPU device; local: every chosen GPU gets N pinned workers, \
            Ray: each task reserves 1/N of a GPU)",
        unset: Some("one per GPU, or --workers"),
    };
    /// Cycles threads per worker (0 = all cores).
    threads: usize = 0, specs::THREADS, run {
        help: "Cycles threads per worker (0: all cores)",
    };
    executor: Executor = Executor::Local, choice::<Executor>(), run {
        help: "local process pool or Ray",
    };
    /// Ray cluster address; None starts a local Ray.
    ray_address: Option<String> = None, Spec::Str, run {
        help: "Ray cluster to join (ray://host:10001 or auto; --executor ray)",
        unset: Some("a local Ray"),
    };
    /// `i/N`: this job's share of the objects.
    shard: Option<String> = None, Spec::Str, run {
        help: "i/N: this job's share of the objects (0 ≤ i < N), for job arrays",
        unset: Some("every object"),
    };
    objaverse_dir: Option<String> = None, Spec::Str, run {
        help: "the objaverse package's cache directory",
        unset: Some("the objaverse package's, ~/.objaverse"),
    };
    objaverse_offline: bool = false, Spec::Bool, run {
        help: "never download: objects missing from the cache fail",
    };
    objaverse_count: Option<usize> = None, Spec::int(1, u32::MAX as i128), run {
        help: "a seeded random subset of N objaverse objects",
        unset: Some("every object listed"),
    };
    /// Seconds without a reply from the worker before it counts as hung.
    timeout: f64 = 600.0, specs::SECONDS, run {
        help: "seconds without a worker reply before it is killed",
    };
    /// Wall-clock budget of one object, s (0 = none).
    object_timeout: f64 = 0.0, specs::BUDGET_SECONDS, run {
        help: "wall-clock budget of one object, s (0: none)",
    };
    /// Extra attempts after a transient failure (worker crash or hang).
    retries: u32 = 1, Spec::int(0, 100), run {
        help: "extra attempts after a worker crash or hang",
    };
    /// Exit 1 when more than this fraction of the objects failed.
    max_failure_rate: f64 = 1.0, specs::FRACTION, run {
        help: "exit 1 when more than this fraction of objects failed",
    };
    max_triangles: u64 = 5_000_000, Spec::int(1, u64::MAX as i128), run {
        help: "pre-flight triangle budget",
    };
    max_texture_pixels: u64 = 256 << 20, Spec::int(0, u64::MAX as i128), run {
        help: "pre-flight texture budget, pixels",
    };
    /// A Blender binary instead of the bpy module.
    blender: Option<String> = None, Spec::Str, run {
        help: "a Blender binary instead of the bpy module",
        unset: Some("the bpy module"),
    };
    check_poses: bool = false, Spec::Bool, run {
        help: "COLMAP check per setting",
    };
    /// Build into an OUT made with other output-shaping options (mixes settings).
    allow_mixed: bool = false, Spec::Bool, run {
        help: "build into an OUT made with other output-shaping options (mixes settings)",
    };
    /// Only objects under these licences (SPDX ids, `other`, `unknown`); the rest are
    /// skipped before rendering (failures.jsonl stage `license`). None = every licence.
    licenses: Option<Vec<String>> = None, Spec::Licenses, shapes {
        help: "only objects under these licences, e.g. cc-by-4.0,cc0-1.0 (SPDX ids; add \
            unknown for objects that name none, other for unmapped ones); the rest are \
            skipped before rendering and recorded in failures.jsonl (stage license)",
        unset: Some("every licence"),
    };
    } } } };
}

build_options!(config_struct);

/// The registered kinds' levels of a build, from their options.
macro_rules! kind_levels_of {
    ({} $($module:ident :: $Kind:ident),* $(,)?) => {
        impl BuildConfig {
            /// The registered kinds' levels of this build (their options).
            pub fn kind_levels(&self) -> KindLevels {
                KindLevels { $($module: self.$module.clone(),)* }
            }
        }
    };
}

crate::kinds!([kind_levels_of] {});

impl BuildConfig {
    /// Defaults overridden by `values` (option name → value), then validated.
    pub fn from_values(values: &BTreeMap<String, Raw>) -> Result<BuildConfig> {
        BuildConfig::default().with_values(values)
    }

    /// This config with `values` replaced, validated: every field, what holds between
    /// fields ([`Self::validate`]) and what holds of the options given here
    /// ([`Self::check_given`]).
    pub fn with_values(&self, values: &BTreeMap<String, Raw>) -> Result<BuildConfig> {
        let mut cfg = self.clone();
        // A preset first, then every option given (beside it, they override it).
        if let Some(p) = values.get("preset") {
            cfg.set("preset", p)?;
            if let Some(preset) = cfg.preset {
                for (k, v) in preset_values(preset) {
                    cfg.set(k, &v)?;
                }
            }
        }
        for (k, v) in values {
            cfg.set(k, v)?;
        }
        // A method given beside an accuracy preset is kept: the preset's frames by motion
        // mean nothing to one motion-blur render, so they go unless given too.
        let given = |k: &str| values.get(k).is_some_and(|v| *v != Raw::Null);
        if cfg.preset.is_some()
            && cfg.blur_method == BlurMethod::MotionBlur
            && !given("latents")
            && !given("latents_auto")
        {
            cfg.latents_auto = false;
        }
        cfg.validate()?;
        cfg.check_given(values)?;
        Ok(cfg)
    }

    /// An option given that means nothing under the others is refused, not ignored:
    /// `latents_max` and `max_ghost_px` without latents auto, `latent_positions` under
    /// the motion_blur method, test settings together with test objects or a fraction.
    pub fn check_given(&self, given: &BTreeMap<String, Raw>) -> Result<()> {
        let value = |k: &str| given.get(k).filter(|v| **v != Raw::Null);
        if let Some(n) = value("test_settings") {
            if value("test_objects").is_some() || value("test_fraction").is_some() {
                return Err(config_error(
                    "test_settings",
                    format!("{n}: give either N random test settings or test objects, not both"),
                ));
            }
        }
        for option in ["latents_max", "max_ghost_px"] {
            if let Some(v) = value(option) {
                if !self.latents_auto {
                    return Err(config_error(
                        option,
                        format!("{v}: only used with latents auto"),
                    ));
                }
            }
        }
        if let Some(t) = self.target_psnr {
            // Under a target each image renders what its own noise needs: a count of
            // samples beside it would mean nothing.
            for option in ["samples", "samples_total", "sharp_samples", "blur_budget"] {
                if let Some(v) = value(option) {
                    return Err(config_error(
                        option,
                        format!(
                            "{v}: a fixed sample count, but every image renders to \
                             target_psnr {t} dB; give one or the other"
                        ),
                    ));
                }
            }
        } else {
            for option in ["target_pilot_samples", "target_max_samples"] {
                if let Some(v) = value(option) {
                    return Err(config_error(
                        option,
                        format!("{v}: only used with target_psnr"),
                    ));
                }
            }
        }
        if self.blur_method == BlurMethod::MotionBlur {
            if let Some(v) = value("latent_positions") {
                return Err(config_error(
                    "latent_positions",
                    format!(
                        "{v}: the motion_blur method has no latent frames (one render per \
                         blurry image); use blur_method average"
                    ),
                ));
            }
        }
        Ok(())
    }

    /// The one validator: every field in its range, then what holds between fields.
    pub fn validate(&self) -> Result<()> {
        self.check_fields()?;
        self.sampling().validate()?;
        self.check_executor()?;
        self.check_outputs()?;
        if let Some(t) = self.target_psnr {
            self.check_target(t)?;
        }
        if self.latents_auto && self.blur_method == BlurMethod::MotionBlur {
            return Err(config_error(
                "latents",
                "auto: the motion_blur method has no latent frames (one render per blurry image)"
                    .into(),
            ));
        }
        if self.blur_method == BlurMethod::Auto && self.target_psnr.is_none() {
            // Priced at equal samples, the methods are compared at equal accuracy only
            // where a target renders each image until its own noise reaches it.
            return Err(config_error(
                "blur_method",
                "auto: the methods are priced at the accuracy a render target sets; give \
                 target_psnr (a preset sets one) or blur_method average or motion_blur"
                    .into(),
            ));
        }
        Ok(())
    }

    /// The prices `blur_method auto` chooses by on the Cycles `backend` the worker reported
    /// (`plan/cost.rs`); None under a method given.
    pub fn pricing(&self, backend: &str) -> Result<Option<Pricing>> {
        match (self.blur_method, self.target()) {
            (BlurMethod::Auto, Some(rule)) => {
                Pricing::new(backend, rule.pilot_samples, self.resolution).map(Some)
            }
            _ => Ok(None),
        }
    }

    /// Where the build runs: the options of one executor are refused under the other.
    fn check_executor(&self) -> Result<()> {
        self.check_ray_address()?;
        self.check_shard()?;
        self.check_ray_placement()?;
        self.check_workers_per_gpu()?;
        self.check_gpus_per_task()
    }

    /// `ray_address` only with executor ray.
    fn check_ray_address(&self) -> Result<()> {
        if self.ray_address.is_some() && self.executor != Executor::Ray {
            return Err(config_error(
                "ray_address",
                format!(
                    "{}: only with executor ray",
                    Raw::Str(self.ray_address.clone().unwrap_or_default())
                ),
            ));
        }
        Ok(())
    }

    /// `shard` is i/N with 0 ≤ i < N.
    fn check_shard(&self) -> Result<()> {
        if let Some(s) = &self.shard {
            if parse_shard(s).is_none() {
                return Err(config_error(
                    "shard",
                    format!("{s:?}: must be i/N with 0 ≤ i < N"),
                ));
            }
        }
        Ok(())
    }

    /// Under Ray, which places the tasks, no `gpus` and one worker.
    fn check_ray_placement(&self) -> Result<()> {
        if self.executor == Executor::Ray {
            // Ray places the tasks: it hands each its GPUs and runs as many as fit.
            if let Some(g) = &self.gpus {
                return Err(config_error(
                    "gpus",
                    format!(
                        "{}: only with executor local (Ray gives each task its GPUs: \
                         gpus_per_task)",
                        g.to_raw()
                    ),
                ));
            }
            if self.workers != 1 {
                return Err(config_error(
                    "workers",
                    format!(
                        "{}: only with executor local (Ray runs as many tasks as the \
                         cluster holds)",
                        self.workers
                    ),
                ));
            }
        }
        Ok(())
    }

    /// `workers_per_gpu` only on a GPU device, and neither with `workers` nor
    /// `gpus_per_task`.
    fn check_workers_per_gpu(&self) -> Result<()> {
        if let Some(k) = self.workers_per_gpu {
            if self.device == Device::Cpu {
                return Err(config_error(
                    "workers_per_gpu",
                    format!("{k}: only with a GPU device (the CPU takes --workers)"),
                ));
            }
            if self.workers != 1 {
                return Err(config_error(
                    "workers_per_gpu",
                    format!("{k}: with workers {}: give one of them", self.workers),
                ));
            }
            if self.gpus_per_task.is_some() {
                return Err(config_error(
                    "workers_per_gpu",
                    format!("{k}: with gpus_per_task: give one of them (it is 1/{k})"),
                ));
            }
        }
        Ok(())
    }

    /// `gpus_per_task` only with executor ray.
    fn check_gpus_per_task(&self) -> Result<()> {
        if let Some(g) = self.gpus_per_task {
            if self.executor != Executor::Ray {
                return Err(config_error(
                    "gpus_per_task",
                    format!(
                        "{}: only with executor ray (a local build takes --gpus)",
                        Raw::Float(g)
                    ),
                ));
            }
        }
        Ok(())
    }

    /// What the build writes: image copies that divide the resolution, one way to choose
    /// the test settings.
    fn check_outputs(&self) -> Result<()> {
        if let Some(f) = self
            .downsample
            .iter()
            .find(|f| !self.resolution.is_multiple_of(**f))
        {
            return Err(config_error(
                "downsample",
                format!(
                    "{f}: does not divide resolution {} (LLFF loaders scale the focal \
                     length by exactly 1/factor)",
                    self.resolution
                ),
            ));
        }
        if self.test_settings.is_some() && self.test_objects.is_some() {
            return Err(config_error(
                "test_settings",
                "and test_objects: give either N random test settings or test objects".into(),
            ));
        }
        self.check_rendered_passes()
    }

    /// Depth and normals are rendered at every size the build writes (a depth cannot be
    /// area-averaged across an edge), and Blender renders no image under
    /// [`MIN_RENDER_PX`]: a smaller size would come back as a 4 x 4 file that `verify`
    /// refuses. Masks come from coverage and take any size.
    fn check_rendered_passes(&self) -> Result<()> {
        let rendered: Vec<&str> = self
            .passes
            .iter()
            .map(String::as_str)
            .filter(|p| names::RENDERED_PASSES.contains(p))
            .collect();
        let Some(f) = self
            .downsample
            .iter()
            .find(|&&f| self.resolution / f < MIN_RENDER_PX)
        else {
            return Ok(());
        };
        if rendered.is_empty() {
            return Ok(());
        }
        Err(config_error(
            "passes",
            format!(
                "{}: {} is rendered at every size, and {}_{f} of resolution {} would be \
                 {} px, under the {MIN_RENDER_PX} px Blender renders: drop {f} from \
                 downsample or raise resolution to at least {}",
                rendered.join(","),
                rendered.join(" and "),
                names::pass_dir(rendered[0], 1),
                self.resolution,
                self.resolution / f,
                MIN_RENDER_PX * f
            ),
        ))
    }

    /// A render target `t` (dB) needs the images' own samples, in subsets, pilot ≤ cap.
    fn check_target(&self, t: f64) -> Result<()> {
        if self.denoise != Denoise::None {
            return Err(config_error(
                "denoise",
                format!(
                    "{}: target_psnr {t} dB is an estimate of an image's render noise \
                     from its own samples, which a denoiser's output is not",
                    self.denoise
                ),
            ));
        }
        if self.latent_sampling != LatentSampling::Subsets {
            return Err(config_error(
                "latent_sampling",
                format!(
                    "{}: target_psnr renders each image as blocks of one sequence per \
                     half (subsets)",
                    self.latent_sampling
                ),
            ));
        }
        if self.target_pilot_samples > self.target_max_samples {
            return Err(config_error(
                "target_pilot_samples",
                format!(
                    "{}: more than target_max_samples {}",
                    self.target_pilot_samples, self.target_max_samples
                ),
            ));
        }
        self.check_target_max_samples()
    }

    /// An image cannot stop below one sample per latent frame and half: a cap under
    /// that is refused here, naming the least that works, rather than failing every
    /// object at its first render.
    fn check_target_max_samples(&self) -> Result<()> {
        let m = self.max_latents();
        let least = TargetRule::least_max_samples(m);
        if u64::from(self.target_max_samples) >= least {
            return Ok(());
        }
        let (frames, fewer) = if self.latents_auto && self.blur_method.averages() {
            (format!("up to latents_max {m}"), "a lower latents_max")
        } else {
            (m.to_string(), "fewer latents")
        };
        Err(config_error(
            "target_max_samples",
            format!(
                "{}: an image of {frames} latent frames renders at least one sample per \
                 frame and half, {least} in all: give at least {least} (or {fewer})",
                self.target_max_samples
            ),
        ))
    }

    /// This job's share of the objects, `(i, N)` of `shard` (None: every object).
    pub fn shard_index(&self) -> Option<(u64, u64)> {
        self.shard.as_deref().and_then(parse_shard)
    }

    /// Refuse `test_objects` that are not among the build's objects (`uids`: every
    /// object of the build, all shards), before anything renders.
    pub fn check_test_objects(&self, uids: &[String]) -> Result<()> {
        let Some(listed) = &self.test_objects else {
            return Ok(());
        };
        let unknown: Vec<&String> = listed.iter().filter(|o| !uids.contains(o)).collect();
        if unknown.is_empty() {
            return Ok(());
        }
        let mut known: Vec<&str> = uids.iter().map(String::as_str).take(8).collect();
        if uids.len() > known.len() {
            known.push("…");
        }
        let names: Vec<String> = unknown.iter().map(|o| format!("{o:?}")).collect();
        Err(config_error(
            "test_objects",
            format!(
                "{}: not {} of this build (its objects: {})",
                names.join(", "),
                if unknown.len() == 1 {
                    "an object"
                } else {
                    "objects"
                },
                if known.is_empty() {
                    "none".to_string()
                } else {
                    known.join(", ")
                }
            ),
        ))
    }

    /// What a build (not a plan) needs besides valid values: an output and objects.
    pub fn require_target(&self) -> Result<()> {
        if self.out.is_none() {
            return Err(config_error(
                "out",
                "is required: an output directory".into(),
            ));
        }
        if self.objects.is_empty() && !self.demo {
            return Err(config_error(
                "objects",
                "are required: GLB files/folders/lists, or demo".into(),
            ));
        }
        Ok(())
    }

    /// The sampling of every setting's plan under this config.
    pub fn sampling(&self) -> SamplingConfig {
        SamplingConfig {
            views: self.views,
            phi0_deg: self.phi0_deg,
            window_deg: self.window_deg,
            fov_deg: self.fov_deg,
            radius_margin: self.radius_margin,
            delta0: self.delta0,
            levels: self.levels.clone(),
            level_spread: self.level_spread,
            latents: self.latents,
            latent_positions: self.latent_positions,
            trajectory: self.trajectory,
            resolution: self.resolution,
            guards: Guards {
                orientation_max: self.orientation_max,
                near_floor: self.near_floor,
            },
            latents_auto: self.latents_auto,
            latents_max: self.latents_max,
            max_ghost_px: self.max_ghost_px,
            blur_method: self.blur_method,
            samples: self.samples,
            samples_total: self.samples_total,
            latent_sampling: self.latent_sampling,
            blur_budget: self.blur_budget,
            kinds: self.kind_levels(),
        }
    }

    /// The Cycles `samples` every render of a subsets build is pinned to (None: each
    /// render its own): the longest sequence of the config and at least the sharp
    /// budget. Cycles sizes its sample pattern from `samples` and never shrinks it within
    /// a process, so one value for the whole build keeps every pixel independent of what
    /// the worker rendered before it (a resumed object equals an uninterrupted one).
    pub fn cycles_samples(&self) -> Option<u32> {
        if let Some(rule) = self.target() {
            return Some(rule.sequence());
        }
        let s = self.sampling();
        (s.latent_sampling == LatentSampling::Subsets).then(|| {
            let sharp = u32::try_from(self.effective_sharp_samples()).unwrap_or(u32::MAX);
            s.max_sequence().max(sharp)
        })
    }

    /// The rule of a build that renders every image to a target (None: fixed counts).
    pub fn target(&self) -> Option<TargetRule> {
        self.target_psnr.map(|t| TargetRule {
            target_psnr_db: t,
            pilot_samples: self.target_pilot_samples,
            max_samples: self.target_max_samples,
        })
    }

    /// The most renders one blurry image can take.
    pub fn max_latents(&self) -> usize {
        self.sampling().max_latents()
    }

    /// The sample budget S of one blurry image (`samples_total`, or samples × its most
    /// frames); under `blur_budget` parity the image renders S times its parity factor.
    pub fn blur_samples_total(&self) -> u64 {
        if let Some(t) = self.samples_total {
            return u64::from(t);
        }
        let m = if self.blur_method == BlurMethod::MotionBlur {
            self.latents
        } else {
            self.max_latents()
        };
        u64::from(self.samples) * m as u64
    }

    /// Samples of the sharp render: `sharp_samples`, or the budget S (whose render noise
    /// the parity factor gives the blurry images too).
    pub fn effective_sharp_samples(&self) -> u64 {
        self.sharp_samples
            .map_or_else(|| self.blur_samples_total(), u64::from)
    }

    /// The samples every sharp image renders, where one count holds for all of them:
    /// None under a render target, where each image renders what its own noise needs
    /// (its record in meta.json says how many), so no record states a count that was
    /// not rendered.
    pub fn fixed_sharp_samples(&self) -> Option<u64> {
        self.target_psnr
            .is_none()
            .then(|| self.effective_sharp_samples())
    }

    /// Renders of a setting (an upper bound with latents auto).
    pub fn frames_per_setting(&self) -> usize {
        let s = self.sampling();
        self.views
            * (1 + self.levels.len() * self.max_latents() + super::kinds::frames(&s.kinds, &s))
    }

    /// The views whose blur levels hold a copy of the sharp image (the held-out views,
    /// Deblur-NeRF's convention); none with `blurry_test_views`.
    pub fn sharp_views(&self, n_views: usize) -> Vec<usize> {
        if self.blurry_test_views {
            Vec::new()
        } else {
            test_views(n_views, self.view_stride)
        }
    }

    /// What the blur levels hold at the test views (meta.json, splits.json).
    pub fn test_view_images(&self) -> &'static str {
        if self.blurry_test_views {
            "blurry"
        } else {
            "sharp"
        }
    }

    /// `sharp`, the blur levels' and every other kind's level directories.
    pub fn level_dirs(&self) -> Vec<String> {
        let mut dirs = super::kind::level_dirs(&self.levels);
        dirs.extend(self.kind_levels().dirs());
        dirs
    }

    pub fn theta0s(&self) -> Vec<f64> {
        names::theta0s(self.settings_per_object)
    }

    /// The `config` record of dataset.json: every option, `latents` = "auto" under
    /// latents auto, and the effective sharp samples (null under a render target:
    /// [`Self::fixed_sharp_samples`]). It names no path of the build
    /// machine (issue 19: a build is published as is): OUT, the objaverse cache and a
    /// Blender binary by their last component, `--objects` entries by [`public_entry`].
    /// Those are run options, never compared between runs.
    pub fn record(&self) -> serde_json::Value {
        let mut public = self.clone();
        public.out = public.out.as_deref().map(last_component);
        public.objaverse_dir = public.objaverse_dir.as_deref().map(last_component);
        public.blender = public.blender.as_deref().map(last_component);
        public.objects = public.objects.iter().map(|e| public_entry(e)).collect();
        let mut v = serde_json::to_value(&public).unwrap_or_default();
        if let Some(m) = v.as_object_mut() {
            m.insert(
                "effective_sharp_samples".into(),
                self.fixed_sharp_samples().into(),
            );
            if self.latents_auto {
                m.insert("latents".into(), "auto".into());
            }
        }
        v
    }
}

/// `i/N` with 0 ≤ i < N, both plain decimal digits (no sign, no spaces).
fn parse_shard(s: &str) -> Option<(u64, u64)> {
    let (i, n) = s.split_once('/')?;
    let digits = |t: &str| !t.is_empty() && t.bytes().all(|b| b.is_ascii_digit());
    if !digits(i) || !digits(n) {
        return None;
    }
    let (i, n) = (i.parse::<u64>().ok()?, n.parse::<u64>().ok()?);
    (i < n).then_some((i, n))
}

/// A path's last component (`.`/`..`/`/` kept as given).
fn last_component(path: &str) -> String {
    std::path::Path::new(path)
        .file_name()
        .map_or_else(|| path.to_string(), |n| n.to_string_lossy().into_owned())
}

/// An `--objects` entry as a published record shows it: an objaverse reference as it
/// is, a path by its last component (a list's `@` kept).
pub fn public_entry(entry: &str) -> String {
    if entry.starts_with("objaverse:") {
        return entry.to_string();
    }
    match entry.strip_prefix('@') {
        Some(list) => format!("@{}", last_component(list)),
        None => last_component(entry),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::error::Error;
    use crate::plan::options::check_declarations;
    use crate::plan::spec::{check_downsample, MAX_SECONDS};

    fn values(pairs: &[(&str, Raw)]) -> BTreeMap<String, Raw> {
        pairs
            .iter()
            .map(|(k, v)| (k.to_string(), v.clone()))
            .collect()
    }

    fn err(pairs: &[(&str, Raw)]) -> String {
        BuildConfig::from_values(&values(pairs))
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default()
    }

    #[test]
    fn shake_levels_need_more_than_one_frame_whose_mean_is_the_written_pose() -> Result<()> {
        let shake = ("shake", Raw::List(vec![Raw::Int(2)]));
        let e = err(&[shake.clone(), ("latents", Raw::Int(1))]);
        assert!(
            e.starts_with("latents 1: shake levels") && e.contains("2 or more"),
            "{e}"
        );
        let e = err(&[
            shake.clone(),
            ("latents_auto", Raw::Bool(true)),
            ("latents_max", Raw::Int(1)),
        ]);
        assert!(e.starts_with("latents_max 1: shake levels"), "{e}");
        // Two frames (their mean is the written pose at any count), or one motion blur
        // render, or no shake level: accepted.
        for ok in [
            vec![shake.clone(), ("latents", Raw::Int(2))],
            vec![shake.clone(), ("latents", Raw::Int(3))],
            vec![
                shake.clone(),
                ("latents", Raw::Int(1)),
                ("blur_method", Raw::Str("motion_blur".into())),
            ],
            vec![("latents", Raw::Int(1))],
        ] {
            BuildConfig::from_values(&values(&ok))?;
        }
        Ok(())
    }

    #[test]
    fn blur_method_auto_is_the_accuracy_presets_and_needs_a_target() -> Result<()> {
        for p in ["balanced", "floor", "fast"] {
            let cfg = BuildConfig::from_values(&values(&[("preset", Raw::Str(p.into()))]))?;
            assert_eq!(cfg.blur_method, BlurMethod::Auto, "{p}");
            assert!(cfg.pricing("CPU")?.is_some() && cfg.pricing("OPTIX")?.is_some());
            assert!(cfg.pricing("tpu").is_err());
        }
        let paper = BuildConfig::from_values(&values(&[("preset", Raw::Str("paper".into()))]))?;
        assert_eq!(paper.blur_method, BlurMethod::Average);
        assert!(paper.pricing("CUDA")?.is_none());
        // A method given beside a preset is kept.
        let given = BuildConfig::from_values(&values(&[
            ("preset", Raw::Str("balanced".into())),
            ("blur_method", Raw::Str("average".into())),
        ]))?;
        assert_eq!(given.blur_method, BlurMethod::Average);
        assert!(given.pricing("CUDA")?.is_none());
        let mb = BuildConfig::from_values(&values(&[
            ("preset", Raw::Str("fast".into())),
            ("blur_method", Raw::Str("motion_blur".into())),
        ]))?;
        assert_eq!(mb.blur_method, BlurMethod::MotionBlur);
        assert!(!mb.latents_auto && mb.target_psnr == Some(40.0));
        assert!(err(&[("blur_method", Raw::Str("auto".into()))]).contains("target_psnr"));
        // The options of averaged frames stand under auto, which plans them first.
        BuildConfig::from_values(&values(&[
            ("blur_method", Raw::Str("auto".into())),
            ("target_psnr", Raw::Float(45.0)),
            ("latent_positions", Raw::Str("stratified".into())),
            ("latents_auto", Raw::Bool(true)),
        ]))?;
        Ok(())
    }

    #[test]
    fn defaults_are_valid_and_the_papers() -> Result<()> {
        let c = BuildConfig::default();
        c.validate()?;
        assert_eq!(c.sampling(), SamplingConfig::default());
        assert_eq!(
            c.level_dirs(),
            ["sharp", "blur_1", "blur_2", "blur_3", "blur_4"]
        );
        assert_eq!((c.max_latents(), c.blur_samples_total()), (34, 32 * 34));
        assert_eq!(c.frames_per_setting(), 34 * (1 + 4 * 34));
        assert_eq!(c.downsample, [4]);
        assert_eq!(
            (c.sharp_views(34), c.test_view_images()),
            (vec![0, 16, 32], "sharp")
        );
        let blurry = BuildConfig {
            blurry_test_views: true,
            ..c
        };
        assert!(blurry.sharp_views(34).is_empty());
        Ok(())
    }

    #[test]
    fn errors_name_the_option_value_and_range() {
        assert_eq!(
            err(&[("views", Raw::Int(-1))]),
            "views -1: must be an integer in 1..=4096"
        );
        assert_eq!(
            err(&[("fov_deg", Raw::Float(f64::NAN))]),
            "fov_deg nan: must be a number in (1, 150)"
        );
        assert_eq!(
            err(&[("seed", Raw::Int(1 << 64))]),
            "seed 18446744073709551616: must be an integer in 0..=18446744073709551615"
        );
        assert!(err(&[("seed", Raw::Int(-1))]).starts_with("seed -1: must be"));
        assert!(err(&[("seed", Raw::BigInt("1".repeat(50)))]).starts_with("seed 111"));
        assert!(err(&[("timeout", Raw::Float(f64::INFINITY))])
            .starts_with("timeout inf: must be a number in (0, 31536000]"));
        assert!(err(&[("max_texture_pixels", Raw::Float(f64::INFINITY))])
            .starts_with("max_texture_pixels inf"));
        assert!(err(&[("samples", Raw::Int(1 << 21))]).contains("1..=1048576"));
        assert!(err(&[("sharp_samples", Raw::Int(1 << 21))]).contains("1..=1048576"));
        assert!(err(&[("timeout", Raw::Float(1e308))]).starts_with("timeout 1e308: must be"));
        assert!(err(&[("object_timeout", Raw::Float(1e308))]).starts_with("object_timeout"));
        assert!(err(&[("workers_per_gpu", Raw::Int(0))]).starts_with("workers_per_gpu 0"));
        assert!(err(&[("phi0_deg", Raw::Float(5.0))]).contains("pole"));
        assert!(err(&[("test_settings", Raw::Int(0))]).starts_with("test_settings 0"));
        assert!(err(&[("gpus_per_task", Raw::Float(65.0))]).contains("[0, 64]"));
    }

    #[test]
    fn lists_must_hold_distinct_values_in_range() {
        assert!(
            err(&[("levels", Raw::List(vec![Raw::Int(1), Raw::Float(2.5)]))])
                .starts_with("levels [1, 2.5]: must be distinct")
        );
        assert!(err(&[("levels", Raw::List(vec![Raw::Int(1), Raw::Int(1)]))]).contains("distinct"));
        assert!(err(&[("levels", Raw::List(vec![Raw::Int(65)]))]).contains("1..=64"));
        assert!(err(&[("background", Raw::List(vec![Raw::Int(1)]))]).starts_with("background [1]"));
        assert!(err(&[("downsample", Raw::List(vec![Raw::Int(1)]))]).contains("2..=64"));
        assert!(
            err(&[("downsample", Raw::List(vec![Raw::Int(4), Raw::Int(4)]))]).contains("distinct")
        );
        assert!(err(&[("downsample", Raw::List(vec![Raw::Int(3)]))])
            .starts_with("downsample 3: does not divide resolution 512"));
        assert!(check_downsample(&[4, 8]).is_ok() && check_downsample(&[]).is_ok());
        assert!(check_downsample(&[8, 8]).is_err() && check_downsample(&[65]).is_err());
        assert!(err(&[("gpus", Raw::List(vec![Raw::Int(0), Raw::Int(0)]))]).contains("distinct"));
        assert!(err(&[("gpus", Raw::List(vec![Raw::Int(-1)]))]).contains("0..=1023"));
    }

    #[test]
    fn a_value_of_the_wrong_kind_or_an_unknown_name_is_named() {
        assert!(err(&[("views", Raw::Bool(true))]).starts_with("views true"));
        assert!(err(&[("views", Raw::Table)]).starts_with("views a table"));
        assert!(err(&[("blur_method", Raw::Str("fast".into()))])
            .contains("one of average, motion_blur"));
        assert!(err(&[("nope", Raw::Int(1))]).starts_with("nope is not an option"));
        assert!(err(&[("licenses", Raw::Str("cc-by-4".into()))])
            .starts_with("licenses \"cc-by-4\": must be licence ids"));
        assert!(err(&[("licenses", Raw::Str(" , ".into()))]).starts_with("licenses"));
        assert!(err(&[("licenses", Raw::List(vec![Raw::Int(1)]))]).starts_with("licenses [1]"));
        assert!(err(&[("latent_sampling", Raw::Str("mixed".into()))])
            .contains("one of subsets, independent"));
        assert!(err(&[("device", Raw::Str("tpu".into()))]).starts_with("device \"tpu\""));
    }

    #[test]
    fn a_shard_must_be_i_of_n() {
        assert!(err(&[("shard", Raw::Str("2/2".into()))]).starts_with("shard \"2/2\""));
        for bad in ["-1/2", "+1/2", " 1/2", "1/ 2", "1/2/3", "/2", "a/2", "1/0"] {
            assert!(
                err(&[("shard", Raw::Str(bad.into()))]).starts_with("shard"),
                "{bad}"
            );
        }
    }

    #[test]
    fn the_options_of_one_executor_are_refused_under_the_other() {
        assert!(err(&[("gpus_per_task", Raw::Float(1.0))])
            .starts_with("gpus_per_task 1.0: only with executor ray"));
        let k = ("workers_per_gpu", Raw::Int(2));
        assert!(err(&[k.clone(), ("device", Raw::Str("cpu".into()))])
            .starts_with("workers_per_gpu 2: only with a GPU device"));
        assert!(err(&[k.clone(), ("workers", Raw::Int(4))]).contains("give one of them"));
        let ray = ("executor", Raw::Str("ray".into()));
        assert!(err(&[ray.clone(), ("gpus", Raw::List(vec![Raw::Int(0)]))])
            .starts_with("gpus [0]: only with executor local"));
        assert!(err(&[ray, ("workers", Raw::Int(4))]).starts_with("workers 4: only with"));
        assert!(err(&[("ray_address", Raw::Str("auto".into()))]).contains("executor ray"));
    }

    #[test]
    fn options_that_conflict_are_refused_by_name() {
        assert!(err(&[
            ("test_settings", Raw::Int(5)),
            ("test_objects", Raw::Str("a".into()))
        ])
        .starts_with("test_settings and test_objects"));
        // A sequence Cycles cannot hold is named by the scheme that makes it.
        assert!(
            err(&[("latents", Raw::Int(4096)), ("samples", Raw::Int(8192))])
                .starts_with("latent_sampling subsets")
        );
    }

    #[test]
    fn accepted_spellings() -> Result<()> {
        let c = BuildConfig::from_values(&values(&[
            ("views", Raw::Float(4.0)),
            ("levels", Raw::List(vec![Raw::Int(4), Raw::Int(1)])),
            ("objects", Raw::Str("a.glb".into())),
            ("fov_deg", Raw::Int(50)),
            ("seed", Raw::Int(u64::MAX as i128)),
            ("samples_total", Raw::Null),
        ]))?;
        assert_eq!(
            (c.views, c.levels.clone(), c.objects.clone()),
            (4, vec![1, 4], vec!["a.glb".to_string()])
        );
        assert_eq!((c.fov_deg, c.seed), (50.0, u64::MAX));
        // A typed config read back goes through the same validator.
        let text = serde_json::to_string(&c).map_err(|e| Error::Value(e.to_string()))?;
        let back: BuildConfig =
            serde_json::from_str(&text).map_err(|e| Error::Value(e.to_string()))?;
        back.validate()?;
        assert_eq!(back, c);
        assert!(serde_json::from_str::<BuildConfig>("{\"vews\": 3}").is_err());
        let lic = BuildConfig::from_values(&values(&[(
            "licenses",
            Raw::Str("cc-by-4.0, CC0-1.0,unknown,cc-by-4.0".into()),
        )]))?;
        assert_eq!(
            lic.licenses,
            Some(vec!["CC-BY-4.0".into(), "CC0-1.0".into(), "unknown".into()])
        );
        let listed = BuildConfig::from_values(&values(&[(
            "licenses",
            Raw::List(vec![Raw::Str("Other".into())]),
        )]))?;
        assert_eq!(listed.licenses, Some(vec!["other".into()]));
        Ok(())
    }

    #[test]
    fn the_record_names_no_builder_path() -> Result<()> {
        let c = BuildConfig::from_values(&values(&[
            ("out", Raw::Str("/home/u/data/out".into())),
            (
                "objects",
                Raw::List(vec![
                    Raw::Str("/home/u/glb/a.glb".into()),
                    Raw::Str("@/home/u/lists/l.txt".into()),
                    Raw::Str("objaverse:abc".into()),
                ]),
            ),
            ("objaverse_dir", Raw::Str("/home/u/.objaverse".into())),
        ]))?;
        let r = c.record();
        assert_eq!(r["out"], "out");
        assert_eq!(
            r["objects"],
            serde_json::json!(["a.glb", "@l.txt", "objaverse:abc"])
        );
        assert_eq!(r["objaverse_dir"], ".objaverse");
        assert_eq!(r["licenses"], serde_json::Value::Null);
        assert!(!r.to_string().contains("/home/u"));
        Ok(())
    }

    #[test]
    fn options_given_that_mean_nothing_are_refused() -> Result<()> {
        assert_eq!(
            err(&[("latents_max", Raw::Int(5))]),
            "latents_max 5: only used with latents auto"
        );
        assert!(err(&[("max_ghost_px", Raw::Float(2.0))]).starts_with("max_ghost_px 2.0: only"));
        assert!(err(&[
            ("blur_method", Raw::Str("motion_blur".into())),
            ("latent_positions", Raw::Str("stratified".into()))
        ])
        .starts_with("latent_positions \"stratified\": the motion_blur method"));
        assert!(err(&[
            ("test_settings", Raw::Int(5)),
            ("test_fraction", Raw::Float(0.3))
        ])
        .starts_with("test_settings 5: give either"));
        // Given with what gives them meaning, or left as they are: accepted.
        BuildConfig::from_values(&values(&[
            ("latents_auto", Raw::Bool(true)),
            ("latents_max", Raw::Int(5)),
            ("test_settings", Raw::Null),
            ("test_fraction", Raw::Float(0.3)),
        ]))?
        .with_values(&values(&[("views", Raw::Int(3))]))?;
        Ok(())
    }

    #[test]
    fn shards_and_test_objects() -> Result<()> {
        let c = BuildConfig::from_values(&values(&[
            ("shard", Raw::Str("1/3".into())),
            ("test_objects", Raw::List(vec![Raw::Str("a".into())])),
        ]))?;
        assert_eq!(c.shard_index(), Some((1, 3)));
        assert_eq!(BuildConfig::default().shard_index(), None);
        let uids = |v: &[&str]| v.iter().map(|s| s.to_string()).collect::<Vec<_>>();
        c.check_test_objects(&uids(&["a", "b"]))?;
        BuildConfig::default().check_test_objects(&[])?;
        let e = c
            .check_test_objects(&uids(&["b", "c"]))
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
        assert_eq!(
            e,
            "test_objects \"a\": not an object of this build (its objects: b, c)"
        );
        let ray = BuildConfig::from_values(&values(&[
            ("executor", Raw::Str("ray".into())),
            ("gpus_per_task", Raw::Float(0.5)),
            ("timeout", Raw::Float(MAX_SECONDS)),
        ]))?;
        assert_eq!(ray.gpus_per_task, Some(0.5));
        Ok(())
    }

    #[test]
    fn every_option_is_declared_whole() -> Result<()> {
        let decls = BuildConfig::declarations();
        check_declarations(&decls).map_err(Error::Value)?;
        let names: Vec<&str> = decls.iter().map(|d| d.name).collect();
        assert_eq!(names, BuildConfig::OPTIONS);
        // The demo's defaults are values of their options.
        let demo: BTreeMap<String, Raw> = decls
            .iter()
            .filter_map(|d| Some((d.name.to_string(), json_raw(d.demo.as_ref()?))))
            .collect();
        assert_eq!(demo.len(), 5);
        let c = BuildConfig::from_values(&demo)?;
        assert_eq!((c.views, c.latents, c.resolution), (17, 6, 96));
        // Flags, keys and what a record without the option was made with.
        let d = |n: &str| decls.iter().find(|d| d.name == n).cloned();
        let wl = d("write_linear").ok_or(Error::Value("write_linear".into()))?;
        assert_eq!(wl.flags, ["--keep-linear", "--write-linear"]);
        assert_eq!(wl.keys, ["write_linear", "keep_linear"]);
        let ds = d("downsample").ok_or(Error::Value("downsample".into()))?;
        assert_eq!(
            (ds.kind, ds.before.clone()),
            (Kind::Factors, serde_json::json!([]))
        );
        assert_eq!(ds.default, serde_json::json!([4]));
        let la = d("latents_auto").ok_or(Error::Value("latents_auto".into()))?;
        assert!(la.flags.is_empty() && la.via == Some("latents") && la.shapes_outputs);
        let ph = d("phi0_deg").ok_or(Error::Value("phi0_deg".into()))?;
        assert!(ph.flags.is_empty() && ph.keys == ["phi0_deg"]);
        let bm = d("blur_method").ok_or(Error::Value("blur_method".into()))?;
        assert_eq!(
            (bm.kind, bm.choices.clone()),
            (Kind::Choice, vec!["average", "motion_blur", "auto"])
        );
        Ok(())
    }

    fn json_raw(v: &serde_json::Value) -> Raw {
        match v {
            serde_json::Value::Bool(b) => Raw::Bool(*b),
            serde_json::Value::Number(n) => n.as_i64().map_or_else(
                || Raw::Float(n.as_f64().unwrap_or(f64::NAN)),
                |i| Raw::Int(i.into()),
            ),
            serde_json::Value::String(s) => Raw::Str(s.clone()),
            serde_json::Value::Array(a) => Raw::List(a.iter().map(json_raw).collect()),
            serde_json::Value::Null => Raw::Null,
            serde_json::Value::Object(_) => Raw::Table,
        }
    }

    #[test]
    fn a_target_cap_under_one_sample_per_frame_and_half_is_refused_naming_the_least() -> Result<()>
    {
        let target = ("target_psnr", Raw::Float(40.0));
        // 34 latent frames (the default) need 68: one sample per frame and half.
        assert_eq!(
            err(&[target.clone(), ("target_max_samples", Raw::Int(67))]),
            "target_max_samples 67: an image of 34 latent frames renders at least one \
             sample per frame and half, 68 in all: give at least 68 (or fewer latents)"
        );
        BuildConfig::from_values(&values(&[
            target.clone(),
            ("target_max_samples", Raw::Int(68)),
            ("target_pilot_samples", Raw::Int(2)),
        ]))?;
        // Under latents auto an image may take up to latents_max frames.
        let auto = [
            target.clone(),
            ("latents_auto", Raw::Bool(true)),
            ("latents_max", Raw::Int(100)),
            ("target_pilot_samples", Raw::Int(2)),
        ];
        let e = err(&[auto.as_slice(), &[("target_max_samples", Raw::Int(199))]].concat());
        assert!(
            e.starts_with("target_max_samples 199: an image of up to latents_max 100")
                && e.contains("give at least 200 (or a lower latents_max)"),
            "{e}"
        );
        BuildConfig::from_values(&values(
            &[auto.as_slice(), &[("target_max_samples", Raw::Int(200))]].concat(),
        ))?;
        // The fast preset's frame cap with the default max.
        BuildConfig::from_values(&values(&[("preset", Raw::Str("fast".into()))]))?;
        Ok(())
    }

    #[test]
    fn defocus_levels_stop_where_the_circle_is_as_wide_as_the_image() -> Result<()> {
        let defocus = |l: &[i128]| {
            (
                "defocus",
                Raw::List(l.iter().map(|&x| Raw::Int(x)).collect()),
            )
        };
        BuildConfig::from_values(&values(&[defocus(&[1, 9])]))?;
        for bad in [10, 31, 64] {
            let e = err(&[defocus(&[1, bad])]);
            assert!(
                e.starts_with(&format!("defocus {bad}: defocus levels must be in 1..=9")),
                "{e}"
            );
        }
        assert!(err(&[defocus(&[65])]).starts_with("defocus [65]"));
        Ok(())
    }

    #[test]
    fn rendered_passes_need_every_size_blender_renders() -> Result<()> {
        let passes = |p: &str| ("passes", Raw::Str(p.into()));
        let res = |r: i128| ("resolution", Raw::Int(r));
        for r in [8, 12] {
            let e = err(&[res(r), passes("depth,mask")]);
            assert!(
                e.starts_with(
                    "passes depth: depth is rendered at every size, and depth_4 of \
                     resolution"
                ) && e.contains("under the 4 px Blender renders")
                    && e.contains("raise resolution to at least 16"),
                "{e}"
            );
        }
        assert!(err(&[res(8), passes("normal")]).starts_with("passes normal:"));
        // Masks come from coverage; 16 px gives 4 px depth_4 files; no copies, no sizes.
        BuildConfig::from_values(&values(&[res(8), passes("mask")]))?;
        BuildConfig::from_values(&values(&[res(16), passes("depth,normal")]))?;
        BuildConfig::from_values(&values(&[
            res(8),
            passes("depth"),
            ("downsample", Raw::List(Vec::new())),
        ]))?;
        Ok(())
    }

    #[test]
    fn a_target_build_states_no_fixed_sample_count() -> Result<()> {
        let fast = BuildConfig::from_values(&values(&[("preset", Raw::Str("fast".into()))]))?;
        assert_eq!(fast.fixed_sharp_samples(), None);
        assert_eq!(
            fast.record()["effective_sharp_samples"],
            serde_json::Value::Null
        );
        let fixed = BuildConfig::default();
        assert_eq!(fixed.fixed_sharp_samples(), Some(32 * 34));
        assert_eq!(fixed.record()["effective_sharp_samples"], 32 * 34);
        Ok(())
    }

    #[test]
    fn derived_numbers() -> Result<()> {
        let auto = BuildConfig::from_values(&values(&[
            ("latents_auto", Raw::Bool(true)),
            ("latents_max", Raw::Int(50)),
            ("samples", Raw::Int(4)),
        ]))?;
        assert_eq!((auto.max_latents(), auto.blur_samples_total()), (50, 200));
        assert_eq!(auto.record()["latents"], "auto");
        let mb = BuildConfig::from_values(&values(&[
            ("blur_method", Raw::Str("motion_blur".into())),
            ("samples", Raw::Int(4)),
            ("latents", Raw::Int(10)),
        ]))?;
        assert_eq!((mb.max_latents(), mb.blur_samples_total()), (1, 40));
        let budget = BuildConfig::from_values(&values(&[
            ("samples_total", Raw::Int(100)),
            ("sharp_samples", Raw::Int(7)),
        ]))?;
        assert_eq!(
            (
                budget.blur_samples_total(),
                budget.effective_sharp_samples()
            ),
            (100, 7)
        );
        assert_eq!(budget.record()["effective_sharp_samples"], 7);
        Ok(())
    }
}
