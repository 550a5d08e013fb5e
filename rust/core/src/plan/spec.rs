//! What one option accepts ([`Spec`]), a value as the user gave it ([`Raw`]) and the
//! conversion between them: the ranges every check of an option uses, the build
//! config's ([`super::config`]) and a plan's ([`super::sampling`]) alike. Below both,
//! so neither imports the other for its ranges.
use crate::error::{Error, Result};
use crate::ground::license;
use crate::ground::names::{self, MAX_LEVEL};
use serde::Serialize;
use std::fmt;

/// Largest number of views per setting and of latent frames per blurry image.
pub const MAX_COUNT: usize = 4096;

/// The smallest image Blender renders (its `resolution_x` / `resolution_y` start at 4):
/// a render asked smaller comes back this size.
pub const MIN_RENDER_PX: u32 = 4;

/// Largest Cycles sample count of one render, and of a `samples_total` budget.
pub const MAX_SAMPLES: u32 = 1 << 20;

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
    /// Licence ids (ground::license::canonical), comma-separated or a list, at least one.
    Licenses,
    /// Per-view outputs besides colour (ground::names::PASSES), comma-separated or a
    /// list, or none.
    Passes,
}

impl Spec {
    pub(crate) const fn int(min: i128, max: i128) -> Spec {
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
            Spec::Passes => format!(
                "must be {}, comma-separated or a list (or none)",
                names::PASSES.join(", ")
            ),
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

/// How an option reads on the command line and in a TOML file.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Kind {
    /// A flag without a value: given means true.
    Switch,
    Int,
    Float,
    Text,
    /// One of [`OptionInfo::choices`].
    Choice,
    /// One or more words (`--objects a.glb models/`).
    Words,
    /// Blur levels: `1,2,3,4`, or `none` (sharp only).
    Levels,
    /// Downsampling factors: `4 8`, `4,8`, or `none`.
    Factors,
    /// Device indices: `0,2`, or `all` (None).
    Indices,
    /// Three numbers in [0, 1] (TOML only).
    Rgb,
    /// A count, or `auto`, which sets the option declared `via` this one instead.
    CountOrAuto,
    /// A fraction of the objects, which sets the option declared `via` this one, or
    /// object ids.
    FractionOrIds,
}

/// A value of one option, converted from [`Raw`] under its [`Spec`] and back.
pub trait OptionValue: Sized {
    fn from_raw(raw: &Raw, spec: &Spec) -> Option<Self>;
    fn to_raw(&self) -> Raw;
    /// How a value of this type under `spec` reads on the command line.
    fn kind(spec: &Spec) -> Kind;
    /// Whether None is a value (an `Option`).
    fn optional() -> bool {
        false
    }
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
            fn kind(_: &Spec) -> Kind {
                Kind::Int
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
    fn kind(_: &Spec) -> Kind {
        Kind::Int
    }
}

impl OptionValue for f64 {
    fn from_raw(raw: &Raw, spec: &Spec) -> Option<Self> {
        Spec::num_of(raw).filter(|x| spec.check_num(*x))
    }
    fn to_raw(&self) -> Raw {
        Raw::Float(*self)
    }
    fn kind(_: &Spec) -> Kind {
        Kind::Float
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
    fn kind(_: &Spec) -> Kind {
        Kind::Switch
    }
}

impl OptionValue for String {
    fn from_raw(raw: &Raw, spec: &Spec) -> Option<Self> {
        match (raw, spec) {
            (Raw::Str(s), Spec::Choice(c)) => choice_index(c, s).map(|i| c[i].to_string()),
            (Raw::Str(s), _) => Some(s.clone()),
            _ => None,
        }
    }
    fn to_raw(&self) -> Raw {
        Raw::Str(self.clone())
    }
    fn kind(spec: &Spec) -> Kind {
        match spec {
            Spec::Choice(_) => Kind::Choice,
            _ => Kind::Text,
        }
    }
}

/// The index of the name `text` among `names`, in any case and without surrounding
/// blanks (`CUDA`, ` Cuda` name `cuda`): how every choice is read.
pub fn choice_index(names: &[&str], text: &str) -> Option<usize> {
    let text = text.trim();
    names.iter().position(|n| n.eq_ignore_ascii_case(text))
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
    fn kind(spec: &Spec) -> Kind {
        T::kind(spec)
    }
    fn optional() -> bool {
        true
    }
}

impl OptionValue for Vec<String> {
    fn from_raw(raw: &Raw, spec: &Spec) -> Option<Self> {
        if *spec == Spec::Licenses {
            return licenses_from_raw(raw);
        }
        if *spec == Spec::Passes {
            return passes_from_raw(raw);
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
    fn kind(spec: &Spec) -> Kind {
        match spec {
            Spec::Licenses | Spec::Passes => Kind::Text,
            _ => Kind::Words,
        }
    }
}

/// Items of a comma-separated string or a list of strings (None: another shape).
fn text_items(raw: &Raw) -> Option<Vec<&str>> {
    match raw {
        Raw::Str(s) => Some(s.split(',').collect()),
        Raw::List(v) => v
            .iter()
            .map(|x| match x {
                Raw::Str(s) => Some(s.as_str()),
                _ => None,
            })
            .collect(),
        _ => None,
    }
}

/// `depth,mask`, `none` or a list of pass names → the passes in their canonical order
/// (names::PASSES), once each; None when a name is unknown.
fn passes_from_raw(raw: &Raw) -> Option<Vec<String>> {
    let items: Vec<&str> = text_items(raw)?
        .into_iter()
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .collect();
    if items.len() == 1 && items[0].eq_ignore_ascii_case("none") {
        return Some(Vec::new());
    }
    let picked: Vec<usize> = items
        .iter()
        .map(|item| choice_index(&names::PASSES, item))
        .collect::<Option<_>>()?;
    Some(
        (0..names::PASSES.len())
            .filter(|i| picked.contains(i))
            .map(|i| names::PASSES[i].to_string())
            .collect(),
    )
}

/// `cc-by-4.0, CC0-1.0` or a list of ids → their canonical spellings, once each, in the
/// order given; None when an id is unknown or none is given.
fn licenses_from_raw(raw: &Raw) -> Option<Vec<String>> {
    let items = text_items(raw)?;
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
    fn kind(spec: &Spec) -> Kind {
        match spec {
            Spec::Factors => Kind::Factors,
            Spec::Indices => Kind::Indices,
            _ => Kind::Levels,
        }
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
    fn kind(_: &Spec) -> Kind {
        Kind::Rgb
    }
}

pub(crate) fn config_error(option: &str, detail: String) -> Error {
    Error::Config {
        option: option.to_string(),
        detail,
    }
}

pub(crate) fn convert<T: OptionValue>(option: &str, raw: &Raw, spec: &Spec) -> Result<T> {
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
    /// A render PSNR an image is rendered to (dB, peak 1, on its object's pixels).
    pub const TARGET_PSNR: Spec = Spec::closed(10.0, 120.0);
    /// Two halves of at least one sample.
    pub const TARGET_MAX_SAMPLES: Spec = Spec::int(2, MAX_SAMPLES as i128);
    pub const RADIUS_MARGIN: Spec = Spec::closed(1.0, 100.0);
    pub const LEVEL_SPREAD: Spec = Spec::num(0.0, false, 1.0, true);
    pub const MAX_GHOST_PX: Spec = Spec::num(0.01, false, f64::INFINITY, false);
    pub const ORIENTATION_MAX: Spec = Spec::num(1.0, false, f64::INFINITY, false);
    pub const NEAR_FLOOR: Spec = Spec::num(0.0, true, f64::INFINITY, false);
    pub const GPUS_PER_TASK: Spec = Spec::closed(0.0, 64.0);
    pub const SEED: Spec = Spec::int(0, u64::MAX as i128);
    pub const FRACTION: Spec = Spec::closed(0.0, 1.0);
    /// At most a year: every wait of the build (a thread's, a pipe's) can hold it.
    pub const SECONDS: Spec = Spec::num(0.0, true, MAX_SECONDS, false);
    pub const BUDGET_SECONDS: Spec = Spec::num(0.0, false, MAX_SECONDS, false);
    pub const THREADS: Spec = Spec::int(0, 4096);
    pub const WORKERS: Spec = Spec::int(1, 1024);
    pub const WORKERS_PER_GPU: Spec = Spec::int(1, 64);
}

/// The longest timeout or time budget, s (a year; a wait of 1e308 s cannot be made).
pub const MAX_SECONDS: f64 = 365.0 * 24.0 * 3600.0;

/// Check an already typed value against its spec (the error as from_values gives it).
pub fn check<T: OptionValue>(option: &str, value: &T, spec: &Spec) -> Result<()> {
    let raw = value.to_raw();
    T::from_raw(&raw, spec)
        .map(|_| ())
        .ok_or_else(|| config_error(option, format!("{raw}: {}", spec.expected())))
}

/// A command's own option (no config declares it) checked against `lo`..=`hi` (above
/// `lo` when `lo_open`), integers or numbers, in the words of every declared option's
/// range: a limit reads one way, exactly, in every command (issue 72).
pub fn check_range(
    option: &str,
    raw: &Raw,
    (lo, hi): (f64, f64),
    lo_open: bool,
    int: bool,
) -> Result<()> {
    let spec = match int {
        true => Spec::int(lo as i128, hi as i128),
        false => Spec::num(lo, lo_open, hi, false),
    };
    let ok = match spec {
        Spec::Int { min, max } => Spec::int_of(raw).is_some_and(|i| (min..=max).contains(&i)),
        _ => f64::from_raw(raw, &spec).is_some(),
    };
    ok.then_some(())
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
