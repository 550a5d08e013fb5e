//! The build configuration: every option of `blurset build`, its default, its range and
//! the one validator (DESIGN §2, §10). Python maps flags and TOML keys onto these fields
//! ([`BuildConfig::from_values`]) and only formats the errors.
//!
//! A value is checked against its field's [`Spec`]; an error names the option, the value
//! and the range (`views -1: must be an integer in 1..=4096`), never a parser position.
//! The sampling options form the [`SamplingConfig`] of every setting's plan.
use super::sampling::{
    BlurBudget, BlurMethod, LatentPositions, LatentSampling, SamplingConfig, TrajectoryAnchor,
    MAX_COUNT, MAX_SAMPLES,
};
use super::weights::Guards;
use crate::dataset::layout::{self, MAX_LEVEL};
use crate::dataset::license;
use crate::dataset::splits::test_views;
use crate::error::{Error, Result};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::fmt;

/// A value as a user gave it (a flag after argparse, a TOML value), before its type is
/// checked against the field it goes to.
#[derive(Clone, Debug, PartialEq)]
pub enum Raw {
    Null,
    Bool(bool),
    Int(i128),
    /// An integer beyond i128, as its decimal text.
    BigInt(String),
    Float(f64),
    Str(String),
    List(Vec<Raw>),
    /// A table (TOML) or a dict: never a valid option value.
    Table,
}

impl fmt::Display for Raw {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Raw::Null => write!(f, "none"),
            Raw::Bool(b) => write!(f, "{b}"),
            Raw::Int(i) => write!(f, "{i}"),
            Raw::BigInt(s) => write!(f, "{s}"),
            Raw::Float(x) if x.is_nan() => write!(f, "nan"),
            Raw::Float(x) if x.is_infinite() => {
                write!(f, "{}", if *x > 0.0 { "inf" } else { "-inf" })
            }
            Raw::Float(x) => write!(f, "{x:?}"),
            Raw::Str(s) => write!(f, "{s:?}"),
            Raw::List(v) => {
                write!(f, "[")?;
                for (i, x) in v.iter().enumerate() {
                    write!(f, "{}{x}", if i > 0 { ", " } else { "" })?;
                }
                write!(f, "]")
            }
            Raw::Table => write!(f, "a table"),
        }
    }
}

/// What one option accepts; its text is the range an error states.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Spec {
    /// An integer in min..=max (a float with an integral value counts).
    Int {
        min: i128,
        max: i128,
    },
    /// A finite number; `lo`/`hi` bounds, open or closed (an infinite bound is no bound).
    Num {
        lo: f64,
        lo_open: bool,
        hi: f64,
        hi_open: bool,
    },
    Bool,
    Str,
    Choice(&'static [&'static str]),
    /// Distinct blur levels, integers in 1..=MAX_LEVEL.
    Levels,
    /// Distinct downsampling factors, integers in 2..=MAX_FACTOR (none: no copies).
    Factors,
    /// Distinct device indices, integers in 0..=1023 (GPUs of a Cycles backend).
    Indices,
    /// Three numbers in [0, 1] (a linear RGB colour).
    Rgb,
    /// A string or a list of strings.
    StrList,
    /// Licence ids (dataset::license::canonical), comma-separated or a list, at least one.
    Licenses,
}

impl Spec {
    const fn int(min: i128, max: i128) -> Spec {
        Spec::Int { min, max }
    }
    const fn closed(lo: f64, hi: f64) -> Spec {
        Spec::Num {
            lo,
            lo_open: false,
            hi,
            hi_open: false,
        }
    }
    const fn num(lo: f64, lo_open: bool, hi: f64, hi_open: bool) -> Spec {
        Spec::Num {
            lo,
            lo_open,
            hi,
            hi_open,
        }
    }

    /// The accepted values, as an error states them.
    pub fn expected(&self) -> String {
        match *self {
            Spec::Int { min, max } => format!("must be an integer in {min}..={max}"),
            Spec::Num {
                lo,
                lo_open,
                hi,
                hi_open,
            } => match (lo.is_finite(), hi.is_finite()) {
                (true, true) => format!(
                    "must be a number in {}{lo}, {hi}{}",
                    if lo_open { "(" } else { "[" },
                    if hi_open { ")" } else { "]" }
                ),
                (true, false) => {
                    format!(
                        "must be a finite number {} {lo}",
                        if lo_open { ">" } else { "≥" }
                    )
                }
                _ => "must be a finite number".into(),
            },
            Spec::Bool => "must be true or false".into(),
            Spec::Str => "must be a string".into(),
            Spec::Choice(c) => format!("must be one of {}", c.join(", ")),
            Spec::Levels => {
                format!("must be distinct integers in 1..={MAX_LEVEL} (or none: sharp only)")
            }
            Spec::Factors => {
                format!("must be distinct integers in 2..={MAX_FACTOR} (or none)")
            }
            Spec::Indices => "must be distinct integers in 0..=1023 (GPU indices)".into(),
            Spec::Rgb => "must be 3 numbers in [0, 1] (linear RGB)".into(),
            Spec::StrList => "must be a string or a list of strings".into(),
            Spec::Licenses => "must be licence ids, comma-separated or a list: SPDX ids such as \
                cc-by-4.0, cc-by-sa-4.0, cc-by-nc-4.0, cc0-1.0, or other / unknown"
                .into(),
        }
    }

    fn int_of(raw: &Raw) -> Option<i128> {
        match raw {
            Raw::Int(i) => Some(*i),
            Raw::Float(x) if x.is_finite() && x.fract() == 0.0 && x.abs() < 1e38 => {
                Some(*x as i128)
            }
            _ => None,
        }
    }

    fn num_of(raw: &Raw) -> Option<f64> {
        match raw {
            Raw::Int(i) => Some(*i as f64),
            Raw::Float(x) => Some(*x),
            _ => None,
        }
    }

    fn check_num(&self, x: f64) -> bool {
        let Spec::Num {
            lo,
            lo_open,
            hi,
            hi_open,
        } = *self
        else {
            return false;
        };
        x.is_finite()
            && (if lo_open { x > lo } else { x >= lo })
            && (if hi_open { x < hi } else { x <= hi })
    }
}

/// A value of one option, converted from [`Raw`] under its [`Spec`] and back.
pub trait OptionValue: Sized {
    fn from_raw(raw: &Raw, spec: &Spec) -> Option<Self>;
    fn to_raw(&self) -> Raw;
}

macro_rules! int_value {
    ($($t:ty),*) => {$(
        impl OptionValue for $t {
            fn from_raw(raw: &Raw, spec: &Spec) -> Option<Self> {
                let Spec::Int { min, max } = *spec else { return None };
                Spec::int_of(raw)
                    .filter(|i| (min..=max).contains(i))
                    .and_then(|i| <$t>::try_from(i).ok())
            }
            fn to_raw(&self) -> Raw {
                Raw::Int(i128::from(*self))
            }
        }
    )*};
}
int_value!(u32, u64);

impl OptionValue for usize {
    fn from_raw(raw: &Raw, spec: &Spec) -> Option<Self> {
        u64::from_raw(raw, spec).and_then(|v| usize::try_from(v).ok())
    }
    fn to_raw(&self) -> Raw {
        Raw::Int(*self as i128)
    }
}

impl OptionValue for f64 {
    fn from_raw(raw: &Raw, spec: &Spec) -> Option<Self> {
        Spec::num_of(raw).filter(|x| spec.check_num(*x))
    }
    fn to_raw(&self) -> Raw {
        Raw::Float(*self)
    }
}

impl OptionValue for bool {
    fn from_raw(raw: &Raw, _: &Spec) -> Option<Self> {
        match raw {
            Raw::Bool(b) => Some(*b),
            _ => None,
        }
    }
    fn to_raw(&self) -> Raw {
        Raw::Bool(*self)
    }
}

impl OptionValue for String {
    fn from_raw(raw: &Raw, spec: &Spec) -> Option<Self> {
        match (raw, spec) {
            (Raw::Str(s), Spec::Choice(c)) => c.contains(&s.as_str()).then(|| s.clone()),
            (Raw::Str(s), _) => Some(s.clone()),
            _ => None,
        }
    }
    fn to_raw(&self) -> Raw {
        Raw::Str(self.clone())
    }
}

impl<T: OptionValue> OptionValue for Option<T> {
    fn from_raw(raw: &Raw, spec: &Spec) -> Option<Self> {
        match raw {
            Raw::Null => Some(None),
            r => T::from_raw(r, spec).map(Some),
        }
    }
    fn to_raw(&self) -> Raw {
        self.as_ref().map_or(Raw::Null, T::to_raw)
    }
}

impl OptionValue for Vec<String> {
    fn from_raw(raw: &Raw, spec: &Spec) -> Option<Self> {
        if *spec == Spec::Licenses {
            return licenses_from_raw(raw);
        }
        match raw {
            Raw::Str(s) => Some(vec![s.clone()]),
            Raw::List(v) => v
                .iter()
                .map(|x| match x {
                    Raw::Str(s) => Some(s.clone()),
                    _ => None,
                })
                .collect(),
            _ => None,
        }
    }
    fn to_raw(&self) -> Raw {
        Raw::List(self.iter().cloned().map(Raw::Str).collect())
    }
}

/// `cc-by-4.0, CC0-1.0` or a list of ids → their canonical spellings, once each, in the
/// order given; None when an id is unknown or none is given.
fn licenses_from_raw(raw: &Raw) -> Option<Vec<String>> {
    let items: Vec<&str> = match raw {
        Raw::Str(s) => s.split(',').collect(),
        Raw::List(v) => v
            .iter()
            .map(|x| match x {
                Raw::Str(s) => Some(s.as_str()),
                _ => None,
            })
            .collect::<Option<_>>()?,
        _ => return None,
    };
    let mut out: Vec<String> = Vec::new();
    for item in items.iter().filter(|s| !s.trim().is_empty()) {
        let id = license::canonical(item)?;
        if !out.contains(&id) {
            out.push(id);
        }
    }
    (!out.is_empty()).then_some(out)
}

impl OptionValue for Vec<u32> {
    fn from_raw(raw: &Raw, spec: &Spec) -> Option<Self> {
        let items: Vec<Raw> = match raw {
            Raw::List(v) => v.clone(),
            Raw::Int(_) => vec![raw.clone()],
            _ => return None,
        };
        let level = match spec {
            Spec::Factors => Spec::int(2, MAX_FACTOR as i128),
            Spec::Indices => Spec::int(0, 1023),
            _ => Spec::int(1, MAX_LEVEL as i128),
        };
        let mut levels: Vec<u32> = items
            .iter()
            .map(|x| match x {
                Raw::Int(_) => u32::from_raw(x, &level),
                _ => None,
            })
            .collect::<Option<_>>()?;
        levels.sort_unstable();
        let n = levels.len();
        levels.dedup();
        (levels.len() == n).then_some(levels)
    }
    fn to_raw(&self) -> Raw {
        Raw::List(self.iter().map(|l| Raw::Int(i128::from(*l))).collect())
    }
}

impl OptionValue for [f64; 3] {
    fn from_raw(raw: &Raw, _: &Spec) -> Option<Self> {
        let Raw::List(v) = raw else { return None };
        let unit = Spec::closed(0.0, 1.0);
        match v.as_slice() {
            [r, g, b] => Some([
                f64::from_raw(r, &unit)?,
                f64::from_raw(g, &unit)?,
                f64::from_raw(b, &unit)?,
            ]),
            _ => None,
        }
    }
    fn to_raw(&self) -> Raw {
        Raw::List(self.iter().map(|x| Raw::Float(*x)).collect())
    }
}

fn config_error(option: &str, detail: String) -> Error {
    Error::Config {
        option: option.to_string(),
        detail,
    }
}

fn convert<T: OptionValue>(option: &str, raw: &Raw, spec: &Spec) -> Result<T> {
    T::from_raw(raw, spec)
        .ok_or_else(|| config_error(option, format!("{raw}: {}", spec.expected())))
}

/// The ranges every check of these options uses (the build's and the plan's alike).
pub mod specs {
    use super::*;
    pub const COUNT: Spec = Spec::int(1, MAX_COUNT as i128);
    pub const SAMPLES: Spec = Spec::int(1, MAX_SAMPLES as i128);
    pub const RESOLUTION: Spec = Spec::int(8, 16384);
    pub const FOV_DEG: Spec = Spec::num(1.0, true, 150.0, true);
    pub const WINDOW_DEG: Spec = Spec::num(0.0, false, 90.0, true);
    pub const PHI0_DEG: Spec = Spec::num(0.0, true, 180.0, true);
    pub const DELTA0: Spec = Spec::closed(0.0, 45.0);
    pub const RADIUS_MARGIN: Spec = Spec::closed(1.0, 100.0);
    pub const LEVEL_SPREAD: Spec = Spec::num(0.0, false, 1.0, true);
    pub const MAX_GHOST_PX: Spec = Spec::num(0.01, false, f64::INFINITY, false);
    pub const ORIENTATION_MAX: Spec = Spec::num(1.0, false, f64::INFINITY, false);
    pub const NEAR_FLOOR: Spec = Spec::num(0.0, true, f64::INFINITY, false);
    pub const LATENT_POSITIONS: Spec = Spec::Choice(&["random", "stratified"]);
    pub const TRAJECTORY: Spec = Spec::Choice(&["start", "centered"]);
    pub const BLUR_METHOD: Spec = Spec::Choice(&["average", "motion_blur"]);
    pub const EXECUTOR: Spec = Spec::Choice(&["local", "ray"]);
    pub const LATENT_SAMPLING: Spec = Spec::Choice(&["subsets", "independent"]);
    pub const LIGHT_PATHS: Spec = Spec::Choice(&["auto", "fixed"]);
    pub const BLUR_BUDGET: Spec = Spec::Choice(&["parity", "flat", "need"]);
    pub const DENOISE: Spec = Spec::Choice(&["none", "oidn"]);
    /// `auto`: the best backend Cycles reports (OptiX > CUDA > HIP > oneAPI > Metal > CPU).
    pub const DEVICE: Spec =
        Spec::Choice(&["auto", "cpu", "optix", "cuda", "hip", "oneapi", "metal"]);
    pub const GPUS_PER_TASK: Spec = Spec::closed(0.0, 64.0);
    pub const SEED: Spec = Spec::int(0, u64::MAX as i128);
    pub const FRACTION: Spec = Spec::closed(0.0, 1.0);
    pub const SECONDS: Spec = Spec::num(0.0, true, f64::INFINITY, false);
    pub const BUDGET_SECONDS: Spec = Spec::num(0.0, false, f64::INFINITY, false);
    pub const THREADS: Spec = Spec::int(0, 4096);
    pub const WORKERS: Spec = Spec::int(1, 1024);
}

/// Check an already typed value against its spec (the error as from_values gives it).
pub fn check<T: OptionValue>(option: &str, value: &T, spec: &Spec) -> Result<()> {
    let raw = value.to_raw();
    T::from_raw(&raw, spec)
        .map(|_| ())
        .ok_or_else(|| config_error(option, format!("{raw}: {}", spec.expected())))
}

/// The largest factor of an `images_<f>/` copy.
pub const MAX_FACTOR: u32 = 64;

/// Refuse downsampling factors outside 2..=MAX_FACTOR or repeated (`blurset noise
/// --downsample`, whose image size is the scene's own; the build checks them as a field).
pub fn check_downsample(factors: &[u32]) -> Result<()> {
    let raw = factors.to_vec().to_raw();
    Vec::<u32>::from_raw(&raw, &Spec::Factors)
        .map(|_| ())
        .ok_or_else(|| config_error("downsample", format!("{raw}: {}", Spec::Factors.expected())))
}

/// θ0 of a setting: any finite azimuth in degrees.
pub const THETA0_DEG: Spec = Spec::num(f64::NEG_INFINITY, false, f64::INFINITY, false);

/// Refuse a non-finite θ0 (it would make every camera NaN).
pub fn check_theta0(theta0_deg: f64) -> Result<()> {
    check("theta0_deg", &theta0_deg, &THETA0_DEG)
}

/// Declares the fields of BuildConfig once: type, default, spec, doc.
macro_rules! build_config {
    ($( $(#[doc = $doc:expr])* $name:ident : $ty:ty = $default:expr, $spec:expr; )*) => {
        /// Every option of `blurset build` (see the module docs).
        #[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
        #[serde(default, deny_unknown_fields)]
        pub struct BuildConfig {
            $( $(#[doc = $doc])* pub $name: $ty, )*
        }

        impl Default for BuildConfig {
            fn default() -> Self {
                BuildConfig { $( $name: $default, )* }
            }
        }

        impl BuildConfig {
            /// The option names, in declaration order.
            pub const OPTIONS: &'static [&'static str] = &[$(stringify!($name)),*];

            fn set(&mut self, option: &str, raw: &Raw) -> Result<()> {
                match option {
                    $( stringify!($name) => self.$name = convert(option, raw, &$spec)?, )*
                    _ => return Err(config_error(option, "is not an option of blurset build".into())),
                }
                Ok(())
            }

            fn check_fields(&self) -> Result<()> {
                $( check(stringify!($name), &self.$name, &$spec)?; )*
                Ok(())
            }
        }
    };
}

const SAMPLING: fn() -> SamplingConfig = SamplingConfig::default;

build_config! {
    /// GLB files, folders of them, list files, objaverse ids (resolved by Python).
    objects: Vec<String> = Vec::new(), Spec::StrList;
    /// The output directory.
    out: Option<String> = None, Spec::Str;
    /// Built-in procedural objects (and smaller defaults; see Python's DEMO_DEFAULTS).
    demo: bool = false, Spec::Bool;
    settings_per_object: usize = 4, Spec::int(1, 360);
    views: usize = SAMPLING().views, specs::COUNT;
    levels: Vec<u32> = SAMPLING().levels, Spec::Levels;
    latents: usize = SAMPLING().latents, specs::COUNT;
    /// m per view and level from the screen motion (DESIGN §8), at most latents_max.
    latents_auto: bool = SAMPLING().latents_auto, Spec::Bool;
    latents_max: usize = SAMPLING().latents_max, specs::COUNT;
    max_ghost_px: f64 = SAMPLING().max_ghost_px, specs::MAX_GHOST_PX;
    blur_method: String = "average".into(), specs::BLUR_METHOD;
    /// Cycles samples per rendered latent frame.
    samples: u32 = SAMPLING().samples, specs::SAMPLES;
    /// Sample budget S of one blurry image: ⌈S / m⌉ samples per latent frame.
    samples_total: Option<u32> = None, specs::SAMPLES;
    /// Samples of the sharp render; None = the blurry image's budget.
    sharp_samples: Option<u32> = None, specs::SAMPLES;
    /// `subsets`: a blurry image's latent frames render the blocks of one sample sequence
    /// on the view's seed, which the sharp image renders too (issue 15); `independent`:
    /// a seed per frame (builds before it).
    latent_sampling: String = "subsets".into(), specs::LATENT_SAMPLING;
    /// `parity`: a blurry image gets the budget times a factor of its m and motion, so
    /// it carries no more render noise than its sharp image (issue 15); `flat`: the
    /// budget as given (builds before it).
    blur_budget: String = "parity".into(), specs::BLUR_BUDGET;
    /// `none`: images as rendered; `oidn`: every image (the sharp one and the mean of a
    /// blurry image's latent frames, with their averaged albedo and normal guides)
    /// denoised once by Open Image Denoise (issue 28).
    denoise: String = "none".into(), specs::DENOISE;
    /// `auto`: light-path bounces from the object's materials; `fixed`: the same for all.
    light_paths: String = "auto".into(), specs::LIGHT_PATHS;
    /// Cycles device (run-only: the pixels are the plan's on any device, within noise).
    device: String = "auto".into(), specs::DEVICE;
    /// GPU indices of the backend; None = all of them.
    gpus: Option<Vec<u32>> = None, Spec::Indices;
    /// GPUs each Ray task reserves; None = 1 with a GPU device, else 0.
    gpus_per_task: Option<f64> = None, specs::GPUS_PER_TASK;
    resolution: u32 = SAMPLING().resolution, specs::RESOLUTION;
    seed: u64 = 0, specs::SEED;
    fov_deg: f64 = SAMPLING().fov_deg, specs::FOV_DEG;
    phi0_deg: f64 = SAMPLING().phi0_deg, specs::PHI0_DEG;
    window_deg: f64 = SAMPLING().window_deg, specs::WINDOW_DEG;
    delta0: f64 = SAMPLING().delta0, specs::DELTA0;
    radius_margin: f64 = SAMPLING().radius_margin, specs::RADIUS_MARGIN;
    level_spread: f64 = SAMPLING().level_spread, specs::LEVEL_SPREAD;
    latent_positions: String = "random".into(), specs::LATENT_POSITIONS;
    /// Where the written pose p sits on a blurry image's segment: `start` (the paper's
    /// U(p, p + w_l·δ)) or `centered` (U(p − w_l·δ/2, p + w_l·δ/2)).
    trajectory: String = "start".into(), specs::TRAJECTORY;
    orientation_max: f64 = SAMPLING().guards.orientation_max, specs::ORIENTATION_MAX;
    near_floor: f64 = SAMPLING().guards.near_floor, specs::NEAR_FLOOR;
    /// Linear RGB the transparent film is composited over.
    background: [f64; 3] = [1.0, 1.0, 1.0], Spec::Rgb;
    /// linear/<view>.exr beside images/ per level (`--keep-linear`).
    write_linear: bool = false, Spec::Bool;
    /// <setting>/preview.png, written before the marker.
    previews: bool = false, Spec::Bool;
    /// Every k-th view of a setting is held out (`--test-view-stride`, LLFF's llffhold).
    view_stride: usize = 16, specs::COUNT;
    /// Test settings: a seeded fraction of the objects, or the objects listed
    /// (`--test-objects`), or N random settings (`test_settings`), not both.
    test_fraction: f64 = 0.2, specs::FRACTION;
    test_objects: Option<Vec<String>> = None, Spec::StrList;
    /// N seeded random test settings (the paper's 52).
    test_settings: Option<usize> = None, Spec::int(1, u32::MAX as i128);
    /// Render the held-out views blurry too; by default the blur levels hold the sharp
    /// image there (Deblur-NeRF's convention; those blur renders are skipped).
    blurry_test_views: bool = false, Spec::Bool;
    /// `images_<f>/` beside `images/` in every level: area mean in linear light, sRGB.
    downsample: Vec<u32> = vec![4], Spec::Factors;
    workers: usize = 1, specs::WORKERS;
    /// Cycles threads per worker (0 = all cores).
    threads: usize = 0, specs::THREADS;
    executor: String = "local".into(), specs::EXECUTOR;
    /// Ray cluster address; None starts a local Ray.
    ray_address: Option<String> = None, Spec::Str;
    /// `i/N`: this job's share of the objects.
    shard: Option<String> = None, Spec::Str;
    objaverse_dir: Option<String> = None, Spec::Str;
    objaverse_offline: bool = false, Spec::Bool;
    objaverse_count: Option<usize> = None, Spec::int(1, u32::MAX as i128);
    /// Seconds without a reply from the worker before it counts as hung.
    timeout: f64 = 600.0, specs::SECONDS;
    /// Wall-clock budget of one object, s (0 = none).
    object_timeout: f64 = 0.0, specs::BUDGET_SECONDS;
    /// Extra attempts after a transient failure (worker crash or hang).
    retries: u32 = 1, Spec::int(0, 100);
    /// Exit 1 when more than this fraction of the objects failed.
    max_failure_rate: f64 = 1.0, specs::FRACTION;
    max_triangles: u64 = 5_000_000, Spec::int(1, u64::MAX as i128);
    max_texture_pixels: u64 = 256 << 20, Spec::int(0, u64::MAX as i128);
    /// A Blender binary instead of the bpy module.
    blender: Option<String> = None, Spec::Str;
    check_poses: bool = false, Spec::Bool;
    /// Build into an OUT made with other output-shaping options (mixes settings).
    allow_mixed: bool = false, Spec::Bool;
    /// Only objects under these licences (SPDX ids, `other`, `unknown`); the rest are
    /// skipped before rendering (failures.jsonl stage `license`). None = every licence.
    licenses: Option<Vec<String>> = None, Spec::Licenses;
}

impl BuildConfig {
    /// Defaults overridden by `values` (option name → value), then validated.
    pub fn from_values(values: &BTreeMap<String, Raw>) -> Result<BuildConfig> {
        BuildConfig::default().with_values(values)
    }

    /// This config with `values` replaced, validated.
    pub fn with_values(&self, values: &BTreeMap<String, Raw>) -> Result<BuildConfig> {
        let mut cfg = self.clone();
        for (k, v) in values {
            cfg.set(k, v)?;
        }
        cfg.validate()?;
        Ok(cfg)
    }

    /// The one validator: every field in its range, then what holds between fields.
    pub fn validate(&self) -> Result<()> {
        self.check_fields()?;
        self.sampling().validate()?;
        if self.ray_address.is_some() && self.executor != "ray" {
            return Err(config_error(
                "ray_address",
                format!(
                    "{}: only with executor ray",
                    Raw::Str(self.ray_address.clone().unwrap_or_default())
                ),
            ));
        }
        if let Some(s) = &self.shard {
            let ok = s
                .split_once('/')
                .and_then(|(i, n)| {
                    Some((i.trim().parse::<u64>().ok()?, n.trim().parse::<u64>().ok()?))
                })
                .is_some_and(|(i, n)| i < n);
            if !ok {
                return Err(config_error(
                    "shard",
                    format!("{s:?}: must be i/N with 0 ≤ i < N"),
                ));
            }
        }
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
        if self.latents_auto && self.blur_method == "motion_blur" {
            return Err(config_error(
                "latents",
                "auto: the motion_blur method has no latent frames (one render per blurry image)"
                    .into(),
            ));
        }
        Ok(())
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
            latent_positions: if self.latent_positions == "stratified" {
                LatentPositions::Stratified
            } else {
                LatentPositions::Random
            },
            trajectory: if self.trajectory == "centered" {
                TrajectoryAnchor::Centered
            } else {
                TrajectoryAnchor::Start
            },
            resolution: self.resolution,
            guards: Guards {
                orientation_max: self.orientation_max,
                near_floor: self.near_floor,
            },
            latents_auto: self.latents_auto,
            latents_max: self.latents_max,
            max_ghost_px: self.max_ghost_px,
            blur_method: if self.blur_method == "motion_blur" {
                BlurMethod::MotionBlur
            } else {
                BlurMethod::Average
            },
            samples: self.samples,
            samples_total: self.samples_total,
            latent_sampling: if self.latent_sampling == "independent" {
                LatentSampling::Independent
            } else {
                LatentSampling::Subsets
            },
            blur_budget: match self.blur_budget.as_str() {
                "flat" => BlurBudget::Flat,
                "need" => BlurBudget::Need,
                _ => BlurBudget::Parity,
            },
        }
    }

    /// The Cycles `samples` every render of a subsets build is pinned to (None: each
    /// render its own): the longest sequence of the config and at least the sharp
    /// budget. Cycles sizes its sample pattern from `samples` and never shrinks it within
    /// a process, so one value for the whole build keeps every pixel independent of what
    /// the worker rendered before it (a resumed object equals an uninterrupted one).
    pub fn cycles_samples(&self) -> Option<u32> {
        let s = self.sampling();
        (s.latent_sampling == LatentSampling::Subsets).then(|| {
            let sharp = u32::try_from(self.effective_sharp_samples()).unwrap_or(u32::MAX);
            s.max_sequence().max(sharp)
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
        let m = if self.blur_method == "motion_blur" {
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

    /// Renders of a setting (an upper bound with latents auto).
    pub fn frames_per_setting(&self) -> usize {
        self.views * (1 + self.levels.len() * self.max_latents())
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

    pub fn level_dirs(&self) -> Vec<String> {
        layout::level_dirs(&self.levels)
    }

    pub fn theta0s(&self) -> Vec<f64> {
        layout::theta0s(self.settings_per_object)
    }

    /// The `config` record of dataset.json: every option, `latents` = "auto" under
    /// latents auto, and the effective sharp samples. It names no path of the build
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
                self.effective_sharp_samples().into(),
            );
            if self.latents_auto {
                m.insert("latents".into(), "auto".into());
            }
        }
        v
    }
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
            .starts_with("timeout inf: must be a finite number > 0"));
        assert!(err(&[("max_texture_pixels", Raw::Float(f64::INFINITY))])
            .starts_with("max_texture_pixels inf"));
        assert!(
            err(&[("levels", Raw::List(vec![Raw::Int(1), Raw::Float(2.5)]))])
                .starts_with("levels [1, 2.5]: must be distinct")
        );
        assert!(err(&[("levels", Raw::List(vec![Raw::Int(1), Raw::Int(1)]))]).contains("distinct"));
        assert!(err(&[("levels", Raw::List(vec![Raw::Int(65)]))]).contains("1..=64"));
        assert!(err(&[("views", Raw::Bool(true))]).starts_with("views true"));
        assert!(err(&[("views", Raw::Table)]).starts_with("views a table"));
        assert!(err(&[("blur_method", Raw::Str("fast".into()))])
            .contains("one of average, motion_blur"));
        assert!(err(&[("nope", Raw::Int(1))]).starts_with("nope is not an option"));
        assert!(err(&[("samples", Raw::Int(1 << 21))]).contains("1..=1048576"));
        assert!(err(&[("sharp_samples", Raw::Int(1 << 21))]).contains("1..=1048576"));
        assert!(err(&[("shard", Raw::Str("2/2".into()))]).starts_with("shard \"2/2\""));
        assert!(err(&[("phi0_deg", Raw::Float(5.0))]).contains("pole"));
        assert!(err(&[("ray_address", Raw::Str("auto".into()))]).contains("executor ray"));
        assert!(err(&[("background", Raw::List(vec![Raw::Int(1)]))]).starts_with("background [1]"));
        assert!(err(&[("downsample", Raw::List(vec![Raw::Int(1)]))]).contains("2..=64"));
        assert!(
            err(&[("downsample", Raw::List(vec![Raw::Int(4), Raw::Int(4)]))]).contains("distinct")
        );
        assert!(err(&[("downsample", Raw::List(vec![Raw::Int(3)]))])
            .starts_with("downsample 3: does not divide resolution 512"));
        assert!(err(&[("test_settings", Raw::Int(0))]).starts_with("test_settings 0"));
        assert!(check_downsample(&[4, 8]).is_ok() && check_downsample(&[]).is_ok());
        assert!(check_downsample(&[8, 8]).is_err() && check_downsample(&[65]).is_err());
        assert!(err(&[
            ("test_settings", Raw::Int(5)),
            ("test_objects", Raw::Str("a".into()))
        ])
        .starts_with("test_settings and test_objects"));
        assert!(err(&[("licenses", Raw::Str("cc-by-4".into()))])
            .starts_with("licenses \"cc-by-4\": must be licence ids"));
        assert!(err(&[("licenses", Raw::Str(" , ".into()))]).starts_with("licenses"));
        assert!(err(&[("licenses", Raw::List(vec![Raw::Int(1)]))]).starts_with("licenses [1]"));
        assert!(err(&[("latent_sampling", Raw::Str("mixed".into()))])
            .contains("one of subsets, independent"));
        assert!(err(&[("device", Raw::Str("tpu".into()))]).starts_with("device \"tpu\""));
        assert!(err(&[("gpus", Raw::List(vec![Raw::Int(0), Raw::Int(0)]))]).contains("distinct"));
        assert!(err(&[("gpus", Raw::List(vec![Raw::Int(-1)]))]).contains("0..=1023"));
        assert!(err(&[("gpus_per_task", Raw::Float(65.0))]).contains("[0, 64]"));
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
