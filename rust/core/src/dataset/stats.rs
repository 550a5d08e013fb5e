//! The statistics of a build (DESIGN §7): the numbers behind `blurset stats`.
//!
//! Every complete setting's `meta.json` is read in parallel (rayon) and reduced to the
//! quantities a dataset paper shows. The definitions live here and nowhere else:
//!
//! - scene range = far / near of a view: the camera-space depth range of the object's
//!   vertices at p (near floored at the sampling guard, as recorded in meta.json). It
//!   is, by construction, the depth-range factor R of the blur weight.
//! - scene dimension = geometric mean of the three bounding-box dimensions of a
//!   setting, cbrt(dx · dy · dz) correctly rounded, in object units (the normalized object's largest
//!   side is 1).
//! - blur weight w_l, latent frames m and the largest screen motion (px) of a
//!   bounding-box corner, per level and blurry view; flatness F, depth range R,
//!   orientation O and w_u = (F · R · O)^(1/3) per view, as sampled.
//!
//! A blur level's numbers are those of its blurry images only: a held-out view whose
//! blur-level images are copies of its sharp image (meta.json `test_view_images`
//! `sharp`, Deblur-NeRF's convention, the default) has no blur at any level, so its
//! per-level entries are null although meta.json records what was sampled for it.
//!
//! What counts (see [`Counts`]): a setting is complete when its directory has the
//! `.complete` marker and is not a `*.partial` directory; any other directory that looks
//! like a setting (`*.partial`, or holding `meta.json` or `sharp/`) is skipped and
//! counted as incomplete, so a build still running can be read. A complete setting the
//! cheap check of a rerun finds damaged (a file missing or cut short: a rerun redoes it)
//! is counted from its meta.json all the same, and named in `damaged`. Hidden directories
//! (`.work-*`, `.demo_objects`) and anything else are ignored.
use super::failures;
#[cfg(test)]
use super::layout::MARKER;
use super::layout::{self, Scan};
use super::meta::{ReadMeta as Meta, ReadView as MetaView};
use crate::error::{Error, Result};
use crate::plan::degradation::Degradation;
use crate::plan::kind::ImageKind;
use crate::plan::kinds::KIND_STATS;
use crate::plan::motion::{Motion, MotionStat as MetaLevel};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// Schema name of the stats document (`stats.json`).
pub const SCHEMA: &str = "blurset-stats/1";

/// Per-quantity unit and definition, in the order summaries are listed. A per-level
/// quantity `q` is summarized as `q_<level>`.
pub const QUANTITIES: &[(&str, &str, &str)] = &[
    (
        "scene_range",
        "ratio",
        "far / near: camera-space depth range of the object at the view (one per view)",
    ),
    (
        "scene_dimension",
        "object units",
        "geometric mean of the 3 bounding-box dimensions, cbrt(dx·dy·dz); largest side = 1 (one per setting)",
    ),
    (
        "flatness",
        "ratio",
        "F = (far − near) / max(d) (one per view)",
    ),
    (
        "depth_range",
        "ratio",
        "R = far / near, as sampled (one per view)",
    ),
    (
        "orientation",
        "ratio",
        "O = max(d) / min(d), capped by the sampling guard (one per view)",
    ),
    (
        "w_u",
        "1",
        "scene weight w_u = (F·R·O)^(1/3) (one per view)",
    ),
    (
        "blur_weight",
        "1",
        "w_l ~ U[0.9, 1.1]·w_u·l: multiplier of the trajectory δ at level l (one per blurry view)",
    ),
    (
        "latent_frames",
        "frames",
        "m, latent frames averaged into the blurry image at level l (one per blurry view)",
    ),
    // Motion blur's statistic (its w_l and m above are motion blur's too).
    Motion::STAT,
    (
        "render_psnr",
        "dB",
        "render PSNR of an image on its object's pixels, estimated from its two halves \
         (--target-psnr builds; per level directory, every kind's; one per rendered image)",
    ),
    (
        "image_samples",
        "samples",
        "Cycles samples an image rendered, every latent frame and both halves \
         (--target-psnr builds; per level directory, every kind's; one per rendered image)",
    ),
];

// -- what is read besides meta.json (other fields are skipped unparsed) ------------------

#[derive(Debug, Deserialize)]
struct SplitsDoc {
    #[serde(default)]
    train: Vec<String>,
    #[serde(default)]
    test: Vec<String>,
    #[serde(default)]
    test_views: BTreeMap<String, Vec<u64>>,
}

#[derive(Debug, Deserialize)]
struct DatasetDoc {
    #[serde(default)]
    config: DatasetConfig,
}

#[derive(Debug, Default, Deserialize)]
struct DatasetConfig {
    settings_per_object: Option<usize>,
}

// -- the stats document ---------------------------------------------------------------

/// One complete setting.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
pub struct SettingInfo {
    /// Directory name, `<uid>_<theta0>`.
    pub name: String,
    pub uid: String,
    pub theta0_deg: f64,
    pub views: usize,
    pub bbox_dims: [f64; 3],
    /// Level directories (`sharp`, `blur_1`, …); images = views × levels.
    pub level_dirs: Vec<String>,
    pub images: usize,
    pub test_views: Vec<u64>,
    /// Whether the blur levels hold the sharp image at the test views.
    pub test_views_sharp: bool,
}

/// Minimum, median (mean of the two middle values for an even count), maximum and
/// mean (left-to-right sum in document order / n) of one quantity.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
pub struct Summary {
    pub quantity: String,
    pub unit: String,
    pub n: usize,
    pub min: Option<f64>,
    pub median: Option<f64>,
    pub max: Option<f64>,
    pub mean: Option<f64>,
}

#[derive(Clone, Debug, Default, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
pub struct Counts {
    /// Distinct uids among complete settings.
    pub objects: usize,
    /// Complete settings.
    pub settings: usize,
    /// Views of complete settings.
    pub views: usize,
    /// Image files of complete settings: views × level directories (sharp + blur levels).
    pub images: usize,
    /// Held-out views whose blur levels hold copies of the sharp image
    /// (`test_view_images` sharp): left out of every per-level quantity.
    pub sharp_copy_views: usize,
    /// Complete settings listed as test in splits.json (None without splits.json).
    pub test_settings: Option<usize>,
    /// Held-out target views of the test settings: Σ |test_views[s]| over complete
    /// test settings (the paper's "52 settings → 156 test images" counts these).
    pub test_views: Option<usize>,
    /// Image files of those target views at every level: Σ |test_views[s]| × levels(s).
    pub test_images: Option<usize>,
    /// Complete settings splits.json does not list yet (written at the end of a build).
    pub unsplit_settings: Option<usize>,
    /// Objects failing now: distinct uids among the current failures.jsonl records
    /// (latest per object or setting, work not complete since; see `failures`).
    pub failures: usize,
    /// Settings failing render QA now (records naming a setting).
    pub settings_failed: usize,
    /// failures.jsonl lines that do not parse (torn by a kill), skipped.
    pub failure_lines_skipped: usize,
    /// Objects `--licenses` leaves out now (records of stage `license`): skipped by
    /// request, not counted in `failures`.
    #[serde(default)]
    pub licence_skipped: usize,
    /// Setting directories skipped as incomplete (`*.partial`, or no `.complete`).
    pub incomplete_settings: usize,
    /// Complete settings the cheap check of a rerun finds damaged (counted all the
    /// same, named in `damaged`).
    #[serde(default)]
    pub damaged_settings: usize,
}

/// A complete setting the cheap check of a rerun finds damaged: what a rerun redoes it
/// for (the first problem).
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
pub struct Damaged {
    pub setting: String,
    pub problem: String,
}

#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
pub struct Failure {
    pub uid: String,
    pub setting: Option<String>,
    pub stage: Option<String>,
    pub reason: Option<String>,
}

#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
pub struct Quantity {
    pub name: String,
    pub unit: String,
    pub definition: String,
}

/// Everything `blurset stats` reports. Per-view arrays are aligned: entry k belongs to
/// view `view_index[k]` of setting `settings[view_setting[k]]`, settings sorted by
/// name, views in meta.json order. Per-level maps are keyed by level ("1" … "4") and
/// hold one entry per view, `null` where a view has no such level.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
pub struct BuildStats {
    pub schema: String,
    pub build: PathBuf,
    pub counts: Counts,
    pub quantities: Vec<Quantity>,
    pub summary: Vec<Summary>,
    pub settings: Vec<SettingInfo>,
    pub incomplete: Vec<String>,
    /// Complete settings a rerun would redo (a file missing or damaged), by name.
    #[serde(default)]
    pub damaged: Vec<Damaged>,
    pub failures: Vec<Failure>,
    /// Objects `--licenses` leaves out (their failures.jsonl records): not failures.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub licence_skipped: Vec<Failure>,
    pub view_setting: Vec<usize>,
    pub view_index: Vec<u64>,
    pub scene_range: Vec<f64>,
    /// One per setting, aligned with `settings`.
    pub scene_dimension: Vec<f64>,
    pub flatness: Vec<f64>,
    pub depth_range: Vec<f64>,
    pub orientation: Vec<f64>,
    pub w_u: Vec<f64>,
    pub blur_weight: BTreeMap<u32, Vec<Option<f64>>>,
    pub latent_frames: BTreeMap<u32, Vec<Option<u64>>>,
    pub motion_px: BTreeMap<u32, Vec<Option<f64>>>,
    /// Each degradation kind's statistic, by its name (`defocus_coc_px` of `--defocus`
    /// builds: per defocus level, the largest circle of confusion on the object), per
    /// level, null where the view holds the sharp image; absent without the kind.
    #[serde(flatten)]
    pub kinds: BTreeMap<String, BTreeMap<u32, Vec<Option<f64>>>>,
    /// `--target-psnr` builds (absent otherwise): per level directory (`sharp`,
    /// `blur_1`, `defocus_2`, …: every kind's images are certified).
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub render_psnr: BTreeMap<String, Vec<Option<f64>>>,
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub image_samples: BTreeMap<String, Vec<Option<u64>>>,
}

// -- the formulas ----------------------------------------------------------------------

/// Scene range of a view: far / near.
pub fn scene_range(near: f64, far: f64) -> f64 {
    far / near
}

/// Scene dimension of a setting: cbrt((dx · dy) · dz), the cube root correctly
/// rounded (CORE-MATH's, through the libm crate), so the value does not depend on the
/// toolchain (std's `cbrt` changed with Rust versions; glibc's can be 1 ulp off) and
/// anyone can recompute it exactly.
pub fn scene_dimension(bbox_dims: [f64; 3]) -> f64 {
    libm::cbrt(bbox_dims[0] * bbox_dims[1] * bbox_dims[2])
}

/// Median of finite values (None when empty): the middle value, or the mean of the
/// two middle values for an even count.
pub fn median(values: &[f64]) -> Option<f64> {
    let n = values.len();
    if n == 0 {
        return None;
    }
    let mut v = values.to_vec();
    let (_, hi, _) = v.select_nth_unstable_by(n / 2, f64::total_cmp);
    let hi = *hi;
    if n % 2 == 1 {
        return Some(hi);
    }
    let lo = v[..n / 2].iter().copied().fold(f64::NEG_INFINITY, f64::max);
    Some((lo + hi) / 2.0)
}

/// min / median / max / mean of `values`.
pub fn summarize(quantity: &str, unit: &str, values: &[f64]) -> Summary {
    let n = values.len();
    let some = |x: f64| (n > 0).then_some(x);
    Summary {
        quantity: quantity.to_string(),
        unit: unit.to_string(),
        n,
        min: some(values.iter().copied().fold(f64::INFINITY, f64::min)),
        median: median(values),
        max: some(values.iter().copied().fold(f64::NEG_INFINITY, f64::max)),
        mean: some(values.iter().sum::<f64>() / n as f64),
    }
}

// -- reading a build -------------------------------------------------------------------

fn input_error(reason: impl Into<String>, path: impl Into<PathBuf>) -> Error {
    Error::Input {
        reason: reason.into(),
        path: path.into(),
    }
}

/// The setting directories of `out` (layout's scan); refuse a path that is not a build.
pub fn scan(out: &Path) -> Result<Scan> {
    let s = layout::scan(out)?;
    if !s.is_build {
        return Err(input_error(
            "not a blurset build (no dataset.json, failures.jsonl or setting directories)",
            out,
        ));
    }
    Ok(s)
}

struct ViewRecord {
    index: u64,
    scene_range: f64,
    flatness: f64,
    depth_range: f64,
    orientation: f64,
    w_u: f64,
    levels: BTreeMap<u32, MetaLevel>,
    /// Under a target: (samples, estimated render PSNR) per level directory.
    images: BTreeMap<String, (u64, f64)>,
    /// Each degradation kind's statistic per level, by the statistic's name; none where
    /// the view holds the sharp image.
    kinds: BTreeMap<&'static str, BTreeMap<u32, f64>>,
}

struct SettingRecord {
    info: SettingInfo,
    scene_dimension: f64,
    views: Vec<ViewRecord>,
    /// Blur levels meta.json records (also those only sharp copies have).
    levels: BTreeSet<u32>,
    /// Views whose blur levels hold the sharp image.
    sharp_copies: usize,
}

fn check(ok: bool, path: &Path, what: impl FnOnce() -> String) -> Result<()> {
    if ok {
        Ok(())
    } else {
        Err(input_error(format!("bad meta.json ({})", what()), path))
    }
}

/// Read one complete setting's meta.json and reduce it to its statistics.
fn read_setting(dir: &Path, name: &str) -> Result<SettingRecord> {
    let path = dir.join(name).join("meta.json");
    let bytes = std::fs::read(&path).map_err(|e| {
        input_error(
            format!("cannot read meta.json of a complete setting ({e})"),
            &path,
        )
    })?;
    let meta: Meta = serde_json::from_slice(&bytes)
        .map_err(|e| input_error(format!("corrupt meta.json ({e})"), &path))?;
    check(
        meta.bbox_dims.iter().all(|d| d.is_finite() && *d >= 0.0),
        &path,
        || format!("bbox_dims {:?} must be finite and ≥ 0", meta.bbox_dims),
    )?;
    check(!meta.views.is_empty(), &path, || "no views".into())?;
    let test_views = meta.test_views.unwrap_or_default();
    let test_views_sharp = meta.test_view_images.as_deref() == Some("sharp");
    let mut level_keys = BTreeSet::new();
    let mut sharp_copies = 0;
    let mut views = Vec::with_capacity(meta.views.len());
    for v in &meta.views {
        // A held-out view holding the sharp image at every blur level has no blur.
        let sharp_copy = test_views_sharp && test_views.contains(&v.index);
        sharp_copies += usize::from(sharp_copy);
        views.push(read_view(v, sharp_copy, &mut level_keys, &path)?);
    }
    // Older metas lack `levels`: sharp plus the blur levels the views record.
    let level_dirs = meta.levels.unwrap_or_else(|| {
        std::iter::once("sharp".to_string())
            .chain(level_keys.iter().map(|l| format!("blur_{l}")))
            .collect()
    });
    let n = views.len();
    let dim = scene_dimension(meta.bbox_dims);
    check(dim.is_finite(), &path, || {
        format!("bbox_dims {:?} overflow", meta.bbox_dims)
    })?;
    Ok(SettingRecord {
        scene_dimension: dim,
        sharp_copies,
        info: SettingInfo {
            name: name.to_string(),
            uid: meta.uid,
            theta0_deg: meta.theta0_deg,
            views: n,
            bbox_dims: meta.bbox_dims,
            images: n * level_dirs.len(),
            level_dirs,
            test_views,
            test_views_sharp,
        },
        views,
        levels: level_keys,
    })
}

/// One view of a meta.json at `path`, checked: its numbers, then its blur levels
/// (their keys added to `level_keys`; none kept for a `sharp_copy`), its scene range,
/// its images, each degradation kind's levels.
fn read_view(
    v: &MetaView,
    sharp_copy: bool,
    level_keys: &mut BTreeSet<u32>,
    path: &Path,
) -> Result<ViewRecord> {
    let i = v.index;
    check(v.near > 0.0, path, || {
        format!("view {i}: near {} must be > 0", v.near)
    })?;
    check(v.far >= v.near, path, || {
        format!("view {i}: far {} is below near {}", v.far, v.near)
    })?;
    for (what, x) in [
        ("flatness", v.flatness),
        ("depth_range", v.depth_range),
        ("orientation", v.orientation),
        ("w_u", v.w_u),
    ] {
        check(x >= 0.0, path, || {
            format!("view {i}: {what} {x} is negative")
        })?;
    }
    let levels = read_view_levels(v, sharp_copy, level_keys, path)?;
    let sr = scene_range(v.near, v.far);
    check(sr.is_finite(), path, || {
        format!(
            "view {i}: far / near = {} / {} is not finite",
            v.far, v.near
        )
    })?;
    let images = read_view_images(v, path)?;
    let kinds = read_view_kinds(v, sharp_copy, path)?;
    Ok(ViewRecord {
        index: i,
        scene_range: sr,
        flatness: v.flatness,
        depth_range: v.depth_range,
        orientation: v.orientation,
        w_u: v.w_u,
        levels,
        images,
        kinds,
    })
}

/// The images a view records, by level directory: (samples, render PSNR).
fn read_view_images(v: &MetaView, path: &Path) -> Result<BTreeMap<String, (u64, f64)>> {
    let i = v.index;
    let mut images = BTreeMap::new();
    for (dir, im) in &v.images {
        let kind = ImageKind::parse(dir).ok_or_else(|| {
            input_error(
                format!("bad meta.json (view {i}: image of {dir:?}, not a level directory)"),
                path,
            )
        })?;
        images.insert(kind.dir(), (im.samples, im.render_psnr_db));
    }
    Ok(images)
}

/// Each degradation kind's statistic per level (none for a `sharp_copy`).
fn read_view_kinds(
    v: &MetaView,
    sharp_copy: bool,
    path: &Path,
) -> Result<BTreeMap<&'static str, BTreeMap<u32, f64>>> {
    let i = v.index;
    let mut kinds = BTreeMap::new();
    for kind in KIND_STATS.iter().filter(|_| !sharp_copy) {
        let Some(levels) = v.rest.get(kind.name).and_then(|x| x.as_object()) else {
            continue;
        };
        let mut stat = BTreeMap::new();
        for (key, rec) in levels {
            let l = level_key(key, i, kind.name, path)?;
            let read = (kind.read)(rec).ok_or_else(|| {
                input_error(
                    format!(
                        "bad meta.json (view {i}: {} level {key} unreadable)",
                        kind.name
                    ),
                    path,
                )
            })?;
            if let Some(x) = read {
                stat.insert(l, x);
            }
        }
        kinds.insert(kind.stat.0, stat);
    }
    Ok(kinds)
}

/// A view's blur levels by number, each w_l checked; every key goes into `level_keys`
/// (the levels the setting has), but a `sharp_copy` keeps none of its own.
fn read_view_levels(
    v: &MetaView,
    sharp_copy: bool,
    level_keys: &mut BTreeSet<u32>,
    path: &Path,
) -> Result<BTreeMap<u32, MetaLevel>> {
    let i = v.index;
    let mut levels = BTreeMap::new();
    for (key, lp) in &v.levels {
        let l = level_key(key, i, "level", path)?;
        check(lp.w_l >= 0.0, path, || {
            format!("view {i} level {l}: w_l {} is negative", lp.w_l)
        })?;
        level_keys.insert(l);
        if !sharp_copy {
            levels.insert(
                l,
                MetaLevel {
                    w_l: lp.w_l,
                    latents: lp.latents,
                    motion_px: lp.motion_px,
                },
            );
        }
    }
    Ok(levels)
}

/// A level's number from its key in view `i`'s `what` map (`level`, `defocus`).
fn level_key(key: &str, i: u64, what: &str, path: &Path) -> Result<u32> {
    key.parse().map_err(|_| {
        input_error(
            format!("bad meta.json (view {i}: {what} key {key:?} is not a number)"),
            path,
        )
    })
}

fn read_json_file<T: serde::de::DeserializeOwned>(path: &Path, what: &str) -> Result<Option<T>> {
    let bytes = match std::fs::read(path) {
        Ok(b) => b,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(input_error(format!("cannot read {what} ({e})"), path)),
    };
    serde_json::from_slice(&bytes)
        .map(Some)
        .map_err(|e| input_error(format!("corrupt {what} ({e})"), path))
}

/// A build's folder name (`.` and relative paths resolved), or the path as given.
fn build_name(out: &Path) -> PathBuf {
    out.canonicalize()
        .ok()
        .and_then(|p| p.file_name().map(PathBuf::from))
        .unwrap_or_else(|| out.to_path_buf())
}

/// Read every complete setting of the build at `out` (in parallel) and compute its
/// statistics. Errors name the file: a missing or non-build directory, an unreadable
/// or corrupt meta.json of a complete setting, a corrupt splits.json.
pub fn build_stats(out: &Path) -> Result<BuildStats> {
    let scan = scan(out)?;
    let records: Vec<Result<SettingRecord>> = scan
        .complete
        .par_iter()
        .map(|name| read_setting(out, name))
        .collect();
    let records = records.into_iter().collect::<Result<Vec<_>>>()?;
    let splits: Option<SplitsDoc> = read_json_file(&out.join("splits.json"), "splits.json")?;
    let dataset: Option<DatasetDoc> = read_json_file(&out.join("dataset.json"), "dataset.json")?;
    let theta0s = dataset
        .and_then(|d| d.config.settings_per_object)
        .map(crate::ground::names::theta0s);
    let (lines, skipped) = failures::read_records(&out.join("failures.jsonl"))?;
    let complete: BTreeSet<String> = scan.complete.iter().cloned().collect();
    let text =
        |r: &serde_json::Value, k: &str| r.get(k).and_then(|v| v.as_str()).map(str::to_owned);
    let (licence, failing): (Vec<Failure>, Vec<Failure>) =
        failures::current(&lines, &complete, theta0s.as_deref())
            .iter()
            .map(|r| Failure {
                uid: text(r, "uid").unwrap_or_default(),
                setting: text(r, "setting"),
                stage: text(r, "stage"),
                reason: text(r, "reason"),
            })
            .partition(|f| failures::is_license_skip(f.stage.as_deref()));
    let mut st = assemble(out, scan, records, splits, failing);
    st.counts.failure_lines_skipped = skipped;
    st.counts.licence_skipped = licence.len();
    st.licence_skipped = licence;
    st.damaged = damaged(out, &st.settings);
    st.counts.damaged_settings = st.damaged.len();
    Ok(st)
}

/// The complete settings the cheap check of a rerun finds damaged (checked in
/// parallel), with their first problem: statistics of a damaged build say so.
fn damaged(out: &Path, settings: &[SettingInfo]) -> Vec<Damaged> {
    settings
        .par_iter()
        .filter_map(|s| {
            layout::setting_problem(&out.join(&s.name)).map(|problem| Damaged {
                setting: s.name.clone(),
                problem,
            })
        })
        .collect()
}

fn assemble(
    out: &Path,
    scan: Scan,
    records: Vec<SettingRecord>,
    splits: Option<SplitsDoc>,
    failures: Vec<Failure>,
) -> BuildStats {
    let n_views: usize = records.iter().map(|r| r.views.len()).sum();
    let levels: BTreeSet<u32> = records
        .iter()
        .flat_map(|r| r.levels.iter().copied())
        .collect();
    let sharp_copy_views = records.iter().map(|r| r.sharp_copies).sum();
    let mut st = no_views(out, scan.incomplete, records.len(), n_views, &levels);
    add_views(&mut st, records, &levels);
    // A level nobody recorded motion for (older metas) has no motion column.
    st.motion_px.retain(|_, v| v.iter().any(Option::is_some));
    // Builds without a target record no image renders.
    st.render_psnr.retain(|_, v| v.iter().any(Option::is_some));
    st.image_samples
        .retain(|_, v| v.iter().any(Option::is_some));
    st.failures = failures;
    st.counts = counts(&st, n_views, sharp_copy_views, splits.as_ref());
    st.summary = summaries(&st);
    st
}

/// The statistics of the build at `out` before any view is added: its columns empty,
/// each with room for `n_views` views (`settings` settings), a column per blur level.
fn no_views(
    out: &Path,
    incomplete: Vec<String>,
    settings: usize,
    n_views: usize,
    levels: &BTreeSet<u32>,
) -> BuildStats {
    let col = || Vec::with_capacity(n_views);
    BuildStats {
        schema: SCHEMA.to_string(),
        // The build by its folder's name: a published stats.json names no builder path.
        build: build_name(out),
        counts: Counts::default(),
        quantities: quantities()
            .map(|(n, u, d)| Quantity {
                name: n.to_string(),
                unit: u.to_string(),
                definition: d.to_string(),
            })
            .collect(),
        summary: Vec::new(),
        settings: Vec::with_capacity(settings),
        incomplete,
        damaged: Vec::new(),
        failures: Vec::new(),
        licence_skipped: Vec::new(),
        view_setting: Vec::with_capacity(n_views),
        view_index: Vec::with_capacity(n_views),
        scene_range: col(),
        scene_dimension: Vec::with_capacity(settings),
        flatness: col(),
        depth_range: col(),
        orientation: col(),
        w_u: col(),
        blur_weight: per_level(levels, n_views),
        latent_frames: per_level(levels, n_views),
        motion_px: per_level(levels, n_views),
        kinds: BTreeMap::new(),
        render_psnr: BTreeMap::new(),
        image_samples: BTreeMap::new(),
    }
}

/// An empty column per level, each with room for `n_views` rows.
fn per_level<T>(levels: &BTreeSet<u32>, n_views: usize) -> BTreeMap<u32, Vec<T>> {
    levels
        .iter()
        .map(|&l| (l, Vec::with_capacity(n_views)))
        .collect()
}

/// Every view of every setting, a row of each column; a per-level column has a row of
/// every view (null where the view has no such level).
fn add_views(st: &mut BuildStats, records: Vec<SettingRecord>, levels: &BTreeSet<u32>) {
    // Each kind's levels over every view: (statistic, level).
    let kind_levels: BTreeSet<(&str, u32)> = records
        .iter()
        .flat_map(|r| r.views.iter())
        .flat_map(|v| {
            v.kinds
                .iter()
                .flat_map(|(name, m)| m.keys().map(move |&l| (*name, l)))
        })
        .collect();
    // Every level directory any view recorded an image of.
    let image_dirs: BTreeSet<String> = records
        .iter()
        .flat_map(|r| r.views.iter())
        .flat_map(|v| v.images.keys().cloned())
        .collect();
    for (k, r) in records.into_iter().enumerate() {
        for v in &r.views {
            st.view_setting.push(k);
            st.view_index.push(v.index);
            st.scene_range.push(v.scene_range);
            st.flatness.push(v.flatness);
            st.depth_range.push(v.depth_range);
            st.orientation.push(v.orientation);
            st.w_u.push(v.w_u);
            for &l in levels {
                let lp = v.levels.get(&l);
                st.blur_weight.entry(l).or_default().push(lp.map(|x| x.w_l));
                st.latent_frames
                    .entry(l)
                    .or_default()
                    .push(lp.map(|x| x.latents));
                st.motion_px
                    .entry(l)
                    .or_default()
                    .push(lp.and_then(Motion::stat));
            }
            for &(name, l) in &kind_levels {
                st.kinds
                    .entry(name.to_string())
                    .or_default()
                    .entry(l)
                    .or_default()
                    .push(v.kinds.get(name).and_then(|m| m.get(&l)).copied());
            }
            for dir in &image_dirs {
                let im = v.images.get(dir);
                let psnr = st.render_psnr.entry(dir.clone()).or_default();
                psnr.push(im.map(|x| x.1));
                let samples = st.image_samples.entry(dir.clone()).or_default();
                samples.push(im.map(|x| x.0));
            }
        }
        st.scene_dimension.push(r.scene_dimension);
        st.settings.push(r.info);
    }
}

/// What the build holds and what failed; with a splits.json, what its test split holds
/// and how many settings it does not list.
fn counts(
    st: &BuildStats,
    n_views: usize,
    sharp_copy_views: usize,
    splits: Option<&SplitsDoc>,
) -> Counts {
    let complete_uids: BTreeSet<&str> = st.settings.iter().map(|s| s.uid.as_str()).collect();
    let failed_uids: BTreeSet<&str> = st.failures.iter().map(|f| f.uid.as_str()).collect();
    let mut c = Counts {
        objects: complete_uids.len(),
        settings: st.settings.len(),
        views: n_views,
        images: st.settings.iter().map(|s| s.images).sum(),
        sharp_copy_views,
        failures: failed_uids.len(),
        settings_failed: st.failures.iter().filter(|f| f.setting.is_some()).count(),
        incomplete_settings: st.incomplete.len(),
        ..Counts::default()
    };
    if let Some(sp) = splits {
        let test: BTreeSet<&str> = sp.test.iter().map(String::as_str).collect();
        let listed: BTreeSet<&str> = sp
            .train
            .iter()
            .chain(&sp.test)
            .map(String::as_str)
            .collect();
        let (mut ts, mut tv, mut ti) = (0, 0, 0);
        for s in st
            .settings
            .iter()
            .filter(|s| test.contains(s.name.as_str()))
        {
            let views = sp
                .test_views
                .get(&s.name)
                .map_or(s.test_views.len(), Vec::len);
            ts += 1;
            tv += views;
            ti += views * s.level_dirs.len();
        }
        c.test_settings = Some(ts);
        c.test_views = Some(tv);
        c.test_images = Some(ti);
        c.unsplit_settings = Some(
            st.settings
                .iter()
                .filter(|s| !listed.contains(s.name.as_str()))
                .count(),
        );
    }
    c
}

fn unit_of(q: &str) -> &'static str {
    quantities()
        .find(|(n, _, _)| *n == q)
        .map_or("", |(_, u, _)| u)
}

/// Every quantity: [`QUANTITIES`] with each degradation kind's statistic after the
/// motion blur's.
fn quantities() -> impl Iterator<Item = (&'static str, &'static str, &'static str)> {
    let at = QUANTITIES
        .iter()
        .position(|(n, _, _)| *n == "motion_px")
        .map_or(QUANTITIES.len(), |i| i + 1);
    QUANTITIES[..at]
        .iter()
        .copied()
        .chain(KIND_STATS.iter().map(|k| k.stat))
        .chain(QUANTITIES[at..].iter().copied())
}

fn summaries(st: &BuildStats) -> Vec<Summary> {
    let mut out = vec![
        summarize("scene_range", unit_of("scene_range"), &st.scene_range),
        summarize(
            "scene_dimension",
            unit_of("scene_dimension"),
            &st.scene_dimension,
        ),
        summarize("flatness", unit_of("flatness"), &st.flatness),
        summarize("depth_range", unit_of("depth_range"), &st.depth_range),
        summarize("orientation", unit_of("orientation"), &st.orientation),
        summarize("w_u", unit_of("w_u"), &st.w_u),
    ];
    let present = |v: &[Option<f64>]| v.iter().flatten().copied().collect::<Vec<f64>>();
    for (l, v) in &st.blur_weight {
        out.push(summarize(
            &format!("blur_weight_{l}"),
            unit_of("blur_weight"),
            &present(v),
        ));
    }
    for (l, v) in &st.latent_frames {
        let m: Vec<f64> = v.iter().flatten().map(|&x| x as f64).collect();
        out.push(summarize(
            &format!("latent_frames_{l}"),
            unit_of("latent_frames"),
            &m,
        ));
    }
    for (l, v) in &st.motion_px {
        out.push(summarize(
            &format!("motion_px_{l}"),
            unit_of("motion_px"),
            &present(v),
        ));
    }
    for (name, levels) in &st.kinds {
        for (l, v) in levels {
            out.push(summarize(
                &format!("{name}_{l}"),
                unit_of(name),
                &present(v),
            ));
        }
    }
    for (l, v) in &st.render_psnr {
        out.push(summarize(
            &format!("render_psnr_{l}"),
            unit_of("render_psnr"),
            &present(v),
        ));
    }
    for (l, v) in &st.image_samples {
        let n: Vec<f64> = v.iter().flatten().map(|&x| x as f64).collect();
        out.push(summarize(
            &format!("image_samples_{l}"),
            unit_of("image_samples"),
            &n,
        ));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use serde_json::json;

    struct TempDir(PathBuf);
    impl TempDir {
        fn new(tag: &str) -> Result<Self> {
            let p = std::env::temp_dir().join(format!(
                "blurset-stats-{tag}-{}-{:?}",
                std::process::id(),
                std::thread::current().id()
            ));
            let _ = std::fs::remove_dir_all(&p);
            std::fs::create_dir_all(&p).map_err(|e| Error::io("mkdir", &p, e))?;
            Ok(TempDir(p))
        }
    }
    impl Drop for TempDir {
        fn drop(&mut self) {
            let _ = std::fs::remove_dir_all(&self.0);
        }
    }

    fn write(path: &Path, text: &str) -> Result<()> {
        if let Some(d) = path.parent() {
            std::fs::create_dir_all(d).map_err(|e| Error::io("mkdir", d, e))?;
        }
        std::fs::write(path, text).map_err(|e| Error::io("write", path, e))
    }

    /// A meta.json in the shape `blurset build` writes (extra fields included).
    fn meta(uid: &str, theta0: f64, dims: [f64; 3], nears: &[f64], levels: &[u32]) -> String {
        let views: Vec<_> = nears
            .iter()
            .enumerate()
            .map(|(i, &n)| {
                let f = n + 1.0;
                let lv: serde_json::Map<String, serde_json::Value> = levels
                    .iter()
                    .map(|&l| {
                        (
                            l.to_string(),
                            json!({"w_l": 0.5 * l as f64 + i as f64, "latents": 4 + l,
                                   "motion_px": 10.0 * l as f64, "max_gap_px": 1.0,
                                   "latent_frames": [{"t": 0.1, "r": 3.0, "seed": 7}]}),
                        )
                    })
                    .collect();
                json!({"index": i, "r": 3.0, "phi_deg": 60.0, "theta_deg": theta0,
                       "near": n, "far": f, "flatness": 1.0, "depth_range": f / n.max(1e-3),
                       "orientation": 2.0, "w_u": 1.1, "trajectory": {"dr": 1.0},
                       "sharp_seed": 3, "c2w": [[1.0]], "levels": lv})
            })
            .collect();
        let mut dirs = vec!["sharp".to_string()];
        dirs.extend(levels.iter().map(|l| format!("blur_{l}")));
        json!({"uid": uid, "theta0_deg": theta0, "seed": 1, "resolution": [64, 64],
               "fov_deg": 40.0, "bbox_dims": dims, "views": views,
               "test_views": [0], "levels": dirs})
        .to_string()
    }

    fn setting(out: &Path, name: &str, meta_text: &str, complete: bool) -> Result<()> {
        write(&out.join(name).join("meta.json"), meta_text)?;
        if complete {
            write(&out.join(name).join(MARKER), "done\n")?;
        }
        Ok(())
    }

    /// Three complete settings of two objects, two half-written ones (a copy with its
    /// marker under .partial, one without a marker), a worker's scratch folder, a user's
    /// folder, failures.jsonl with a torn last line, and splits naming a setting gone;
    /// no dataset.json yet. Their statistics.
    fn numbers(tag: &str) -> Result<(TempDir, BuildStats)> {
        let t = TempDir::new(tag)?;
        let out = &t.0;
        setting(
            out,
            "a_0",
            &meta("a", 0.0, [1.0, 0.5, 0.25], &[2.0, 4.0], &[1, 2]),
            true,
        )?;
        setting(
            out,
            "a_90",
            &meta("a", 90.0, [1.0, 0.5, 0.25], &[1.0], &[1, 2]),
            true,
        )?;
        setting(
            out,
            "b_0",
            &meta("b", 0.0, [1.0, 1.0, 1.0], &[3.0], &[2]),
            true,
        )?;
        // half-written: a copy with marker under .partial, and one without marker
        setting(
            out,
            "c_0.partial",
            &meta("c", 0.0, [1.0; 3], &[1.0], &[1]),
            true,
        )?;
        setting(out, "c_90", &meta("c", 90.0, [1.0; 3], &[1.0], &[1]), false)?;
        write(&out.join(".work-c/worker.log"), "")?;
        write(&out.join("stats/report.md"), "")?; // a user directory: ignored
        write(
            &out.join("failures.jsonl"),
            "{\"uid\":\"d\",\"stage\":\"load\",\"reason\":\"old\"}\n\
             {\"uid\":\"a\",\"stage\":\"render\",\"reason\":\"retried ok\"}\n\
             {\"uid\":\"d\",\"stage\":\"load\",\"reason\":\"bad glb\"}\n\
             {\"uid\":\"e\",\"sta",
        )?;
        write(
            &out.join("splits.json"),
            &json!({"train": ["a_0", "a_90"], "test": ["b_0", "gone_0"],
                    "test_views": {"b_0": [0]}})
            .to_string(),
        )?;
        let s = build_stats(out)?;
        Ok((t, s))
    }

    #[test]
    fn complete_settings_are_read_and_half_written_ones_named() -> Result<()> {
        let (_t, s) = numbers("complete")?;
        let names: Vec<&str> = s.settings.iter().map(|x| x.name.as_str()).collect();
        assert_eq!(names, ["a_0", "a_90", "b_0"]);
        assert_eq!(s.incomplete, ["c_0.partial", "c_90"]);
        Ok(())
    }

    #[test]
    fn per_view_numbers_follow_the_settings_in_order() -> Result<()> {
        let (_t, s) = numbers("views")?;
        assert_eq!(s.scene_range, [3.0 / 2.0, 5.0 / 4.0, 2.0 / 1.0, 4.0 / 3.0]);
        assert_eq!(s.view_setting, [0, 0, 1, 2]);
        assert_eq!(s.view_index, [0, 1, 0, 0]);
        assert_eq!(s.scene_dimension, [0.5, 0.5, 1.0]);
        assert_eq!(s.blur_weight[&1], [Some(0.5), Some(1.5), Some(0.5), None]);
        assert_eq!(
            s.blur_weight[&2],
            [Some(1.0), Some(2.0), Some(1.0), Some(1.0)]
        );
        assert_eq!(s.latent_frames[&2], [Some(6); 4]);
        Ok(())
    }

    #[test]
    fn counts_of_objects_views_images_and_the_split() -> Result<()> {
        let (_t, s) = numbers("counts")?;
        let c = &s.counts;
        assert_eq!((c.objects, c.settings, c.views), (2, 3, 4));
        assert_eq!(c.images, 2 * 3 + 3 + 2);
        assert_eq!(
            (c.test_settings, c.test_views, c.test_images),
            (Some(1), Some(1), Some(2))
        );
        assert_eq!(c.unsplit_settings, Some(0));
        Ok(())
    }

    #[test]
    fn failures_are_kept_before_dataset_json_and_a_torn_line_skipped() -> Result<()> {
        let (_t, s) = numbers("failures")?;
        let c = &s.counts;
        // No dataset.json yet (a first build still running): object records stay, even
        // for `a`, whose settings are complete; the torn last line is skipped.
        assert_eq!((c.failures, c.incomplete_settings), (2, 2));
        assert_eq!(c.failure_lines_skipped, 1);
        let reasons: Vec<_> = s.failures.iter().map(|f| f.reason.as_deref()).collect();
        assert_eq!(reasons, [Some("retried ok"), Some("bad glb")]);
        Ok(())
    }

    #[test]
    fn summaries_of_the_numbers_and_a_document_without_nan() -> Result<()> {
        let (_t, s) = numbers("summary")?;
        let sum = |q: &str| s.summary.iter().find(|x| x.quantity == q).cloned();
        let b1 = sum("blur_weight_1").ok_or_else(|| Error::Value("no summary".into()))?;
        assert_eq!(
            (b1.n, b1.min, b1.median, b1.max),
            (3, Some(0.5), Some(0.5), Some(1.5))
        );
        let sr = sum("scene_range").ok_or_else(|| Error::Value("no summary".into()))?;
        assert_eq!(sr.median, Some((4.0 / 3.0 + 1.5) / 2.0));
        assert!(sum("motion_px_2").is_some());
        // the document is valid JSON without NaN
        let text = serde_json::to_string(&s).map_err(|e| Error::Value(e.to_string()))?;
        assert!(text.contains("\"blur_weight\":{\"1\":[0.5,1.5,0.5,null]"));
        Ok(())
    }

    #[test]
    fn an_object_left_out_by_licenses_is_skipped_not_failed() -> Result<()> {
        let t = TempDir::new("licence")?;
        let out = &t.0;
        setting(out, "a_0", &meta("a", 0.0, [1.0; 3], &[2.0], &[1]), true)?;
        write(
            &out.join("failures.jsonl"),
            "{\"uid\":\"nc\",\"stage\":\"license\",\"reason\":\"licence CC-BY-NC-4.0\"}\n\
             {\"uid\":\"d\",\"stage\":\"load\",\"reason\":\"bad glb\"}\n",
        )?;
        let s = build_stats(out)?;
        assert_eq!((s.counts.failures, s.counts.licence_skipped), (1, 1));
        let uids = |v: &[Failure]| v.iter().map(|f| f.uid.clone()).collect::<Vec<_>>();
        assert_eq!(
            (uids(&s.failures), uids(&s.licence_skipped)),
            (vec!["d".to_string()], vec!["nc".to_string()])
        );
        Ok(())
    }

    #[test]
    fn sharp_copies_are_left_out_of_the_blur_levels() -> Result<()> {
        let t = TempDir::new("copies")?;
        let text = meta("a", 0.0, [1.0; 3], &[2.0, 4.0, 3.0], &[1, 2]);
        let mut m: serde_json::Value =
            serde_json::from_str(&text).map_err(|e| Error::Value(e.to_string()))?;
        m["test_view_images"] = "sharp".into(); // view 0 holds the sharp image
        setting(&t.0, "a_0", &m.to_string(), true)?;
        // A meta.json from before the field: its test view was rendered blurry.
        setting(
            &t.0,
            "b_0",
            &meta("b", 0.0, [1.0; 3], &[2.0], &[1, 2]),
            true,
        )?;
        let s = build_stats(&t.0)?;
        assert_eq!(s.blur_weight[&1], [None, Some(1.5), Some(2.5), Some(0.5)]);
        assert_eq!(s.latent_frames[&2], [None, Some(6), Some(6), Some(6)]);
        assert_eq!(s.motion_px[&2], [None, Some(20.0), Some(20.0), Some(20.0)]);
        // The view itself still counts: its scene range, factors and images.
        assert_eq!(s.scene_range.len(), 4);
        assert_eq!((s.counts.views, s.counts.images), (4, 4 * 3));
        assert_eq!(s.counts.sharp_copy_views, 1);
        assert!(s.settings[0].test_views_sharp && !s.settings[1].test_views_sharp);
        let b1 = s
            .summary
            .iter()
            .find(|x| x.quantity == "blur_weight_1")
            .ok_or_else(|| Error::Value("no summary".into()))?;
        assert_eq!((b1.n, b1.min, b1.max), (3, Some(0.5), Some(2.5)));
        Ok(())
    }

    #[test]
    fn running_build_without_splits_and_empty_build() -> Result<()> {
        let t = TempDir::new("running")?;
        setting(&t.0, "x_0.partial", "{\"uid\": \"x\"", false)?;
        let s = build_stats(&t.0)?;
        assert_eq!(s.counts.settings, 0);
        assert_eq!(s.counts.incomplete_settings, 1);
        assert_eq!(s.counts.test_images, None);
        assert!(s.summary.iter().all(|x| x.n == 0 && x.median.is_none()));
        Ok(())
    }

    #[test]
    fn bad_input_names_the_file() -> Result<()> {
        let t = TempDir::new("bad")?;
        let msg = |p: &Path| {
            build_stats(p)
                .err()
                .map(|e| e.to_string())
                .unwrap_or_default()
        };
        assert!(msg(&t.0.join("missing")).contains("no such build directory"));
        write(&t.0.join("empty/readme.txt"), "hi")?;
        assert!(msg(&t.0.join("empty")).contains("not a blurset build"));
        let b = t.0.join("b");
        setting(&b, "a_0", &meta("a", 0.0, [1.0; 3], &[1.0], &[1]), true)?;
        setting(&b, "z_0", "{\"uid\": \"z\", \"views\": [", true)?;
        let m = msg(&b);
        assert!(
            m.contains("corrupt meta.json") && m.contains("z_0/meta.json"),
            "{m}"
        );
        setting(&b, "z_0", &meta("z", 0.0, [1.0; 3], &[0.0], &[1]), true)?;
        let m = msg(&b);
        assert!(m.contains("near 0 must be > 0") && m.contains("z_0"), "{m}");
        std::fs::remove_file(b.join("z_0/meta.json")).map_err(|e| Error::io("rm", &b, e))?;
        assert!(msg(&b).contains("cannot read meta.json"));
        std::fs::remove_dir_all(b.join("z_0")).map_err(|e| Error::io("rm", &b, e))?;
        // A torn record is not bad input: it is skipped and counted.
        write(&b.join("failures.jsonl"), "garbage\n{\"uid\":\"q\"}\n")?;
        let c = build_stats(&b)?.counts;
        assert_eq!((c.failures, c.failure_lines_skipped), (1, 1));
        write(&b.join("failures.jsonl"), "")?;
        write(&b.join("splits.json"), "{")?;
        assert!(msg(&b).contains("corrupt splits.json"));
        Ok(())
    }

    #[test]
    fn formulas() {
        assert_eq!(scene_range(2.0, 3.0), 1.5);
        assert_eq!(scene_dimension([1.0, 0.5, 0.25]), 0.5);
        assert_eq!(scene_dimension([1.0, 1.0, 0.0]), 0.0);
        // correctly rounded: glibc's cbrt gives 0.7874832516804876 here
        let d = 0.6988146305084229;
        assert_eq!(scene_dimension([d, d, 1.0]), 0.7874832516804877);
        assert_eq!(median(&[]), None);
        assert_eq!(median(&[3.0, 1.0, 2.0]), Some(2.0));
        assert_eq!(median(&[4.0, 1.0, 3.0, 2.0]), Some(2.5));
    }

    proptest! {
        #[test]
        fn summary_matches_sorting(mut v in prop::collection::vec(-1e6f64..1e6, 1..200)) {
            let s = summarize("q", "u", &v);
            v.sort_by(f64::total_cmp);
            let n = v.len();
            let med = if n % 2 == 1 { v[n / 2] } else { (v[n / 2 - 1] + v[n / 2]) / 2.0 };
            prop_assert_eq!(s.min, Some(v[0]));
            prop_assert_eq!(s.max, Some(v[n - 1]));
            prop_assert_eq!(s.median, Some(med));
            prop_assert!(s.min <= s.median && s.median <= s.max);
        }
    }
}
