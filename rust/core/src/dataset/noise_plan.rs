//! The plan of `blurset noise` (DESIGN §5) and the writers of its units.
//!
//! A unit is one LLFF scene to noise: the scene itself (`blurset noise SCENE`, one unit)
//! or one level of one complete setting of a build (`blurset noise BUILD`). Its plan
//! says what it reads, its seed and white balance, its pose rows, the views left clean,
//! and per gain the folder, Philox key, σ and the whole `noise.json`; every input is
//! checked here before a pixel is touched. Python only schedules: it picks the folders a
//! unit's gains are written into, calls [`NoiseUnit::write_images`] and
//! [`NoiseUnit::write_gain_files`], and publishes each gain whole.
use super::layout::is_complete;
use super::llff::{read_poses_bounds, write_poses_bounds, write_scene_transforms};
use super::llff::{PoseRow, SceneFields};
use super::read::{read_record, Record};
use super::records::{write_noise, BuildNoiseRecord, NoiseDoc, NoiseFile, NoiseTableRecord};
use super::records::{NoiseParams, NoiseTableParams};
use super::records::{NoiseSource as SourceRecord, WhiteBalanceRecord};
use crate::error::{Error, Result};
use crate::ground::names::{files, gain_name, images_dir, linear_dir, test_views};
use crate::image::io::image_info;
use crate::noise::config::NoiseConfig;
use crate::noise::model::{noise_key, sample_white_balance, scene_seed, Gamma};
use crate::noise::model::{NoiseLevels, NoiseModel, WhiteBalance};
use crate::noise::raw_model::{Display, ModelKind, RawModel};
use crate::noise::variants::{write_variants, write_variants_linear, Variant, VariantOptions};
use crate::plan::choices::{Choice, NoiseGamma, NoiseProfile, NoiseSource};
use crate::plan::spec::config_error;
use std::path::{Path, PathBuf};

/// How every draw is addressed (noise.json `rng`), in both modes: `seed` is the scene's
/// (a build's unit: its scene seed), and `noise_key(seed, gain)` is this derive_seed.
pub const RNG: &str = "philox4x32-10, key derive_seed(seed, [fnv1a64('noise'), gain bits]), \
    stream view<<32|frame, word = pixel*colour_channels + c; ziggurat normals";

/// How a build's unit gets its seed (noise.json `build_noise`, noise_dataset.json).
pub const SEED_DERIVATION: &str = "noise_scene_seed(seed, setting, level) = \
    derive_seed(seed, [fnv1a64('build_noise'), fnv1a64(setting), fnv1a64(level)]); per gain \
    key noise_key(scene seed, gain) and white balance noise_white_balance(scene seed), as \
    `blurset noise SCENE --seed <scene seed>`";

const MODEL: &str = "y' = y + sqrt(sigma_read^2 + sigma_shot^2 * y) * N(0, 1)";
/// noise.json `model` of the camera models (their parameters are in `raw_model`).
const RAW_MODEL: &str = "raw pipeline: linear RGB -> camera RGB (inverse colour matrix) -> \
    inverse white balance -> RGGB mosaic -> DN (black level) -> noise per photosite -> \
    quantization, clip -> demosaic of the noise -> white balance -> colour matrix -> linear \
    RGB (linear/*.exr) -> transfer -> 8-bit codes; sigma_read, sigma_shot are the \
    equivalent sigmas in raw signal units";
/// noise.json `rng` of the camera models.
const RAW_RNG: &str = "philox4x32-10, key derive_seed(noise_key(seed, gain), \
    [fnv1a64('raw_noise'), view<<32|frame]), sensor row r: photosites stream 2r, row noise \
    stream 2r+1; unprocess scene draws derive_seed(seed, [fnv1a64('unprocess')])";
const SCENE_CLEAN: &str = "y = white_level * decode(x) / wb";
const CLEAN_LINEAR: &str = "y = white_level * clip(composite(L, background), 0, 1) / wb, L the \
    build's linear premultiplied RGBA (linear/*.exr)";
const CLEAN_PNG: &str = "y = white_level * decode(x) / wb, x the build's 8-bit sRGB PNG \
    (images/*.png)";
/// The clean image a camera model starts from (build mode), by source.
const RAW_CLEAN_LINEAR: &str = "L = clip(composite(L, background), 0, 1), L the build's \
    linear premultiplied RGBA (linear/*.exr), into the raw pipeline of raw_model";
const RAW_CLEAN_PNG: &str = "L = decode(x), x the build's 8-bit sRGB PNG (images/*.png), \
    into the raw pipeline of raw_model";

/// One gain of a unit: its folder, key, σ and record.
#[derive(Clone, Debug)]
pub struct NoiseGain {
    pub gain: f64,
    /// `gain_<g>`.
    pub dir: String,
    pub key: u64,
    pub sigma_read: f64,
    pub sigma_shot: f64,
    /// The gain's noise.json.
    pub record: NoiseDoc,
    /// The camera model of `--model` (None: the paper's).
    pub raw: Option<RawModel>,
}

/// One scene to noise and what each of its gains writes.
#[derive(Clone, Debug)]
pub struct NoiseUnit {
    /// The setting and level of a build's unit (None for a scene).
    pub setting: Option<String>,
    pub level: Option<String>,
    /// Where its gain folders go: `OUT/<setting>/<level>` of a build, `OUT` of a scene.
    pub dst: PathBuf,
    pub seed: u64,
    /// The clean images the noise reads (a build's EXRs under `--source linear`).
    pub sources: Vec<PathBuf>,
    /// The scene's own images, copied as the clean views' files.
    pub images: Vec<PathBuf>,
    /// `sources.len() * frames` output stems, view-major.
    pub names: Vec<String>,
    pub frames: u32,
    /// A gain scene's pose rows (one per written image, hwf of the written size).
    pub rows: Vec<PoseRow>,
    /// The background a build's linear EXRs are composited over (linear source only).
    pub background: Option<[f64; 3]>,
    pub gamma: Gamma,
    pub white_balance: Option<WhiteBalance>,
    pub white_level: f64,
    pub downsample: Vec<u32>,
    /// The scene's own `images_<f>/` folders, whose files are the clean views' copies.
    pub small: Vec<(u32, PathBuf)>,
    pub test_views: Vec<usize>,
    pub clean_views: Vec<usize>,
    /// The factor of the folder read and written (a scene's images_<F>/; a build's 1).
    pub factor: u32,
    pub no_linear: bool,
    /// A build's setting transforms.json, from which each gain's is made.
    pub transforms: Option<PathBuf>,
    pub gains: Vec<NoiseGain>,
}

/// The plan of one `blurset noise` run.
#[derive(Clone, Debug)]
pub struct NoisePlan {
    /// `linear` or `png` (a build; a scene reads its images).
    pub source: String,
    /// `2.2` or `srgb`.
    pub gamma: String,
    pub downsample: Vec<u32>,
    /// The levels of a build noised (none for a scene).
    pub levels: Vec<String>,
    pub units: Vec<NoiseUnit>,
    /// The scene or build noised, by its folder's name (no builder paths in outputs).
    pub input: String,
    /// The options the run is made with: noise_dataset.json's `params`, which a rerun
    /// into the same output must match.
    pub params: NoiseParams,
    /// A build's levels and seed as its dataset.json has them (empty for a scene):
    /// noise_dataset.json orders its levels by them and names the seed.
    pub build_levels: Vec<String>,
    pub build_seed: Option<u64>,
    /// A scene's clean views are those i with i % llffhold == 0 (None: a build, or none).
    pub llffhold: Option<u32>,
}

/// The options of a run as noise_dataset.json records them; `clean` when some views
/// stay clean (a build's test views, a scene's `--clean-views`).
fn params(
    cfg: &NoiseConfig,
    table: &NoiseLevels,
    plan: (&str, NoiseGamma, &[u32], bool),
) -> NoiseParams {
    let (source, gamma, downsample, clean) = plan;
    let kpn = cfg.kpn_levels.is_some();
    NoiseParams {
        seed: cfg.seed,
        source: source.into(),
        profile: cfg.profile.name().into(),
        gamma: gamma.name().into(),
        white_level: cfg.white_level,
        frames: cfg.frames as usize,
        levels_table: NoiseTableParams {
            log10_sigma_read_1: table.log10_read,
            log10_sigma_shot_1: table.log10_shot,
            read_step_per_log2_gain: table.read_step,
            shot_step_per_log2_gain: table.shot_step,
            source: if kpn { "kpn" } else { "blurset-default" }.into(),
        },
        downsample: downsample.to_vec(),
        clean_views: if clean { "test_views" } else { "none" }.into(),
        no_linear: cfg.no_linear,
        model: cfg
            .model_kind()
            .map_or_else(|_| cfg.model.clone(), |k| k.name()),
    }
}

/// What every unit of a run shares: the gains with their σ, and the record's common part.
struct Common {
    gains: Vec<(f64, String, f64, f64)>,
    gamma: Gamma,
    base: NoiseDoc,
    kind: ModelKind,
}

impl Common {
    fn of(cfg: &NoiseConfig, table: &NoiseLevels, gamma: NoiseGamma) -> Result<Common> {
        let gamma_value = match gamma {
            NoiseGamma::Power22 => serde_json::json!(2.2),
            NoiseGamma::Srgb => serde_json::json!("srgb"),
        };
        let base = NoiseDoc {
            gain: serde_json::Number::from(0),
            seed: cfg.seed,
            sigma_read: 0.0,
            sigma_shot: 0.0,
            gamma: gamma_value,
            white_balance: None,
            white_level: cfg.white_level,
            frames: cfg.frames as usize,
            profile: cfg.profile.name().into(),
            model: MODEL.into(),
            clean: None,
            levels: table_record(table, cfg.kpn_levels.as_deref()),
            source: SourceRecord::Scene {
                scene: String::new(),
                images: String::new(),
                factor: 1,
                resolution: [0, 0],
            },
            build_noise: None,
            downsample: Vec::new(),
            clean_views: Vec::new(),
            rng: RNG.into(),
            raw_model: None,
            blurset_version: env!("CARGO_PKG_VERSION").into(),
            files: Vec::new(),
        };
        Ok(Common {
            gains: gain_sigmas(cfg, table)?,
            gamma: Gamma::parse(gamma.name())?,
            base,
            kind: cfg.model_kind()?,
        })
    }

    /// The gains of a unit of seed `seed` and white balance `wb`, each with its record
    /// made from `doc` (a camera model's σ are its equivalents, its parameters in
    /// `raw_model`).
    fn gains(&self, seed: u64, wb: Option<WhiteBalance>, doc: &NoiseDoc) -> Result<Vec<NoiseGain>> {
        let display = Display {
            gamma: self.gamma,
            white_balance: wb,
            white_level: doc.white_level,
        };
        let one = |(g, dir, sr, ss): &(f64, String, f64, f64)| {
            let raw = RawModel::of(self.kind, seed, *g, display)?;
            let (sr, ss) = raw.as_ref().map_or((*sr, *ss), RawModel::sigma_equivalents);
            let mut record = NoiseDoc {
                gain: gain_number(*g),
                sigma_read: sr,
                sigma_shot: ss,
                ..doc.clone()
            };
            if let Some(r) = &raw {
                record.clean = record.clean.as_deref().map(|c| {
                    if c == CLEAN_LINEAR {
                        RAW_CLEAN_LINEAR
                    } else {
                        RAW_CLEAN_PNG
                    }
                    .into()
                });
                record.model = RAW_MODEL.into();
                record.rng = RAW_RNG.into();
                record.raw_model = Some(r.record.clone());
            }
            Ok(NoiseGain {
                gain: *g,
                dir: dir.clone(),
                key: noise_key(seed, *g),
                sigma_read: sr,
                sigma_shot: ss,
                record,
                raw,
            })
        };
        self.gains.iter().map(one).collect()
    }
}

/// The σ table as noise.json records it (`kpn` when read from KPN's file).
fn table_record(t: &NoiseLevels, kpn: Option<&str>) -> NoiseTableRecord {
    NoiseTableRecord {
        source: if kpn.is_some() {
            "kpn"
        } else {
            "blurset-default"
        }
        .into(),
        log10_sigma_read_1: t.log10_read,
        read_step_per_log2_gain: t.read_step,
        log10_sigma_shot_1: t.log10_shot,
        shot_step_per_log2_gain: t.shot_step,
        file: kpn.map(|k| file_name(Path::new(k))),
    }
}

/// A gain as JSON: an integer when it is one (`4`, not `4.0`), as its folder's name.
fn gain_number(g: f64) -> serde_json::Number {
    if g.fract() == 0.0 && g.abs() < 9.0e15 {
        serde_json::Number::from(g as i64)
    } else {
        serde_json::Number::from_f64(g).unwrap_or_else(|| serde_json::Number::from(0))
    }
}

/// (gain, folder, σ_read, σ_shot) of every gain, in the order given; two gains that
/// would share a folder, or a σ out of range (a huge `--any-gain`), name `gains`.
fn gain_sigmas(cfg: &NoiseConfig, table: &NoiseLevels) -> Result<Vec<(f64, String, f64, f64)>> {
    let mut out: Vec<(f64, String, f64, f64)> = Vec::new();
    for (given, g) in cfg.gains.iter().zip(cfg.gain_values()?) {
        let dir = gain_name(g);
        if let Some(i) = out.iter().position(|o| o.1 == dir) {
            let first = &cfg.gains[i];
            let why = format!("{first} and {given}: both would be written to {dir}/");
            return Err(config_error("gains", why));
        }
        let (sr, ss) = table
            .sigmas(g)
            .map_err(|e| config_error("gains", format!("{given}: {e}")))?;
        if !(sr.is_finite() && ss.is_finite()) {
            let why =
                format!("{given}: its noise sigma is not a finite number (read {sr}, shot {ss})");
            return Err(config_error("gains", why));
        }
        out.push((g, dir, sr, ss));
    }
    Ok(out)
}

fn file_name(p: &Path) -> String {
    p.file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default()
}

/// A folder by its own name (`.` and symlinks resolved): no builder paths in outputs.
fn resolved_name(p: &Path) -> Result<String> {
    let full = std::fs::canonicalize(p).map_err(|e| Error::io("cannot resolve", p, e))?;
    Ok(file_name(&full))
}

/// Image files in the order LLFF loaders use: sorted by file name, hidden files skipped.
pub fn list_images(dir: &Path) -> Result<Vec<PathBuf>> {
    let entries = std::fs::read_dir(dir).map_err(|e| Error::io("cannot list", dir, e))?;
    let mut out = Vec::new();
    for entry in entries {
        let p = entry.map_err(|e| Error::io("cannot list", dir, e))?.path();
        let name = file_name(&p);
        let ext = p
            .extension()
            .map(|e| e.to_string_lossy().to_ascii_lowercase());
        let image = matches!(ext.as_deref(), Some("png" | "jpg" | "jpeg"));
        if image && !name.starts_with('.') && p.is_file() {
            out.push(p);
        }
    }
    out.sort_by_key(|p| file_name(p));
    Ok(out)
}

/// Stems per (view, frame), view-major, whose sorted order is that order: the sources'
/// own stems when that holds, else index names.
pub fn output_names(sources: &[PathBuf], frames: u32) -> Vec<String> {
    let stems: Vec<String> = sources
        .iter()
        .map(|p| {
            p.file_stem()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_default()
        })
        .collect();
    let fw = (frames.saturating_sub(1)).to_string().len().max(2);
    let names: Vec<String> = if frames == 1 {
        stems
    } else {
        let frame = |s: String| (0..frames).map(move |k| format!("{s}_f{k:0fw$}"));
        stems.into_iter().flat_map(frame).collect()
    };
    let unique = names
        .iter()
        .collect::<std::collections::BTreeSet<_>>()
        .len()
        == names.len();
    if unique && names.windows(2).all(|w| w[0] <= w[1]) {
        return names;
    }
    let vw = sources.len().saturating_sub(1).to_string().len().max(3);
    let view = |i: usize| format!("view{i:0vw$}");
    if frames == 1 {
        return (0..sources.len()).map(view).collect();
    }
    let frame = |i: usize| (0..frames).map(move |k| format!("{}_f{k:0fw$}", view(i)));
    (0..sources.len()).flat_map(frame).collect()
}

/// Every image's header read and the same size as the first's: (width, height).
fn one_size(images: &[PathBuf]) -> Result<(u32, u32)> {
    let (w0, h0, _, _) = image_info(&images[0])?;
    for p in &images[1..] {
        let (w, h, _, _) = image_info(p)?;
        if (w, h) != (w0, h0) {
            let first = file_name(&images[0]);
            return Err(Error::Input {
                reason: format!("image size {w}x{h} differs from {w0}x{h0} of {first}"),
                path: p.clone(),
            });
        }
    }
    Ok((w0, h0))
}

/// The pose rows of `poses` when there is one per image in `dir`.
fn pose_rows(poses: &Path, images: &[PathBuf], dir: &Path) -> Result<Vec<PoseRow>> {
    if !poses.is_file() {
        let (reason, path) = ("poses_bounds.npy not found".into(), poses.into());
        return Err(Error::Input { reason, path });
    }
    let rows = read_poses_bounds(poses)?;
    if rows.len() != images.len() {
        let n = images.len();
        return Err(Error::Input {
            reason: format!(
                "{n} images in {} but {} pose rows",
                dir.display(),
                rows.len()
            ),
            path: poses.into(),
        });
    }
    Ok(rows)
}

/// Refuses a `--downsample` factor that does not divide the image size.
fn check_divides(downsample: &[u32], (w, h): (u32, u32), at: &str) -> Result<()> {
    match downsample.iter().find(|f| w % **f != 0 || h % **f != 0) {
        Some(f) => Err(config_error(
            "downsample",
            format!("{f}: does not divide the image size {w}x{h}{at}"),
        )),
        None => Ok(()),
    }
}

/// Per written image: its view, frame, clean source, files, and whether it stayed clean.
fn files_record(
    sources: &[String],
    names: &[String],
    cfg: &NoiseConfig,
    (clean, factor): (&[usize], u32),
) -> Vec<NoiseFile> {
    let f = cfg.frames as usize;
    let exr = |n: &str| format!("{}/{n}.exr", linear_dir(factor));
    let file = |(i, k): (usize, usize)| NoiseFile {
        view: i,
        frame: k,
        source: sources[i].clone(),
        image: format!("{}/{}.png", images_dir(factor), names[i * f + k]),
        linear: (!cfg.no_linear).then(|| exr(&names[i * f + k])),
        clean: clean.contains(&i),
    };
    let pairs = (0..sources.len()).flat_map(|i| (0..f).map(move |k| (i, k)));
    pairs.map(file).collect()
}

fn white_balance(cfg: &NoiseConfig, seed: u64) -> Option<WhiteBalance> {
    (cfg.profile == NoiseProfile::Paper).then(|| sample_white_balance(seed))
}

fn wb_record(wb: Option<WhiteBalance>) -> Option<WhiteBalanceRecord> {
    wb.map(|w| WhiteBalanceRecord {
        red: w.red,
        blue: w.blue,
    })
}

/// Every frame of a view shares its pose (a burst stays a valid LLFF scene).
fn repeat_rows(rows: &[PoseRow], frames: u32) -> Vec<PoseRow> {
    let each = |r: &PoseRow| std::iter::repeat_n(*r, frames as usize);
    rows.iter().flat_map(each).collect()
}

/// The plan of `blurset noise SCENE`: one unit, the scene, its gain folders in `out`.
/// The scene is refused whole before any pixel work: a missing folder or file, a count
/// that does not match, two images of one stem, a size that differs, a `--downsample`
/// that does not divide it.
pub fn plan_scene(
    scene: &Path,
    out: &Path,
    cfg: &NoiseConfig,
    table: &NoiseLevels,
) -> Result<NoisePlan> {
    let (factor, image_dir) = scene_images(scene, cfg.factor)?;
    let poses = scene.join(files::POSES_BOUNDS);
    let sources = list_images(&image_dir)?;
    if sources.is_empty() {
        return Err(Error::Input {
            reason: "no .png/.jpg images".into(),
            path: image_dir,
        });
    }
    let rows = pose_rows(&poses, &sources, &image_dir)?;
    let stems: std::collections::BTreeSet<_> = sources.iter().map(|p| p.file_stem()).collect();
    if stems.len() != sources.len() {
        return Err(Error::Input {
            reason: "two images share a file stem".into(),
            path: image_dir,
        });
    }
    let size = one_size(&sources)?;
    let downsample = cfg.downsample.clone().unwrap_or_default();
    check_divides(&downsample, size, "")?;
    let gamma = cfg.gamma.unwrap_or(NoiseGamma::Power22);
    let common = Common::of(cfg, table, gamma)?;
    let llffhold = cfg.llffhold();
    let unit = scene_unit(
        scene,
        (factor, &image_dir),
        out,
        cfg,
        &common,
        (sources, rows, size),
    )?;
    let clean = llffhold.is_some();
    Ok(NoisePlan {
        source: "png".into(),
        gamma: gamma.name().into(),
        params: params(cfg, table, ("png", gamma, &downsample, clean)),
        downsample,
        levels: Vec::new(),
        units: vec![unit],
        input: resolved_name(scene)?,
        build_levels: Vec::new(),
        build_seed: None,
        llffhold,
    })
}

/// A scene's image folder and its factor: `--factor`'s, else the one of images/ and
/// images_<f>/ it holds; several are refused, naming them and the option.
fn scene_images(scene: &Path, factor: Option<u32>) -> Result<(u32, PathBuf)> {
    let dir = |f: u32| scene.join(images_dir(f));
    let listed = std::fs::read_dir(scene).map_err(|e| Error::io("cannot list", scene, e))?;
    let factor_of = |n: &str| match n.strip_prefix("images")? {
        "" => Some(1),
        f => f.strip_prefix('_')?.parse().ok().filter(|f| *f > 1),
    };
    let mut found: Vec<u32> = match factor {
        Some(f) => vec![f],
        None => listed
            .filter_map(|e| factor_of(e.ok()?.file_name().to_str()?))
            .collect(),
    };
    found.retain(|f| factor.is_some() || dir(*f).is_dir());
    found.sort_unstable();
    let names: Vec<String> = found.iter().map(|f| images_dir(*f) + "/").collect();
    let names = names.join(", ");
    let reason = match found[..] {
        [f] if dir(f).is_dir() => return Ok((f, dir(f))),
        [_] => format!("image directory {names} not found"),
        [] => "no images/ or images_<f>/ directory".into(),
        _ => format!("the scene holds {names}: pass --factor F to read images_<F>/ (1: images/)"),
    };
    let path = scene.into();
    Err(Error::Input { reason, path })
}

type Read = (Vec<PathBuf>, Vec<PoseRow>, (u32, u32));

fn scene_unit(
    scene: &Path,
    (factor, image_dir): (u32, &Path),
    out: &Path,
    cfg: &NoiseConfig,
    common: &Common,
    (sources, rows, (w, h)): Read,
) -> Result<NoiseUnit> {
    let hold = cfg.llffhold();
    let clean_views = hold.map_or_else(Vec::new, |k| test_views(sources.len(), k as usize));
    let names = output_names(&sources, cfg.frames);
    let downsample = cfg.downsample.clone().unwrap_or_default();
    let wb = white_balance(cfg, cfg.seed);
    let written: Vec<String> = sources.iter().map(|p| file_name(p)).collect();
    let doc = NoiseDoc {
        model: format!("{MODEL}, {SCENE_CLEAN}"),
        white_balance: wb_record(wb),
        source: SourceRecord::Scene {
            scene: resolved_name(scene)?,
            images: file_name(image_dir),
            factor,
            resolution: [w, h],
        },
        downsample: downsample.clone(),
        clean_views: clean_views.clone(),
        files: files_record(&written, &names, cfg, (&clean_views, factor)),
        ..common.base.clone()
    };
    // A scene's own images_<F·f>/ hold its clean images of that size.
    let small = downsample.iter().map(|f| factor * f);
    let small = small.map(|f| (f, scene.join(images_dir(f)))).collect();
    Ok(NoiseUnit {
        setting: None,
        level: None,
        dst: out.into(),
        seed: cfg.seed,
        images: sources.clone(),
        sources,
        names,
        frames: cfg.frames,
        // hwf stays the scene's: LLFF loaders divide it by the factor they read.
        rows: repeat_rows(&rows, cfg.frames),
        background: None,
        gamma: common.gamma,
        white_balance: wb,
        white_level: cfg.white_level,
        downsample,
        small,
        test_views: Vec::new(),
        clean_views,
        factor,
        no_linear: cfg.no_linear,
        transforms: None,
        gains: common.gains(cfg.seed, wb, &doc)?,
    })
}

/// `sharp,blur_1,…` → level folders, in the build's order; an unknown or repeated one
/// names `levels`.
pub fn parse_levels(value: Option<&str>, available: &[String]) -> Result<Vec<String>> {
    let Some(value) = value else {
        return Ok(available.to_vec());
    };
    let names: Vec<&str> = value
        .split(',')
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .collect();
    if names.is_empty() {
        return Err(config_error(
            "levels",
            format!("{value:?}: give level names like sharp,blur_1"),
        ));
    }
    if let Some(n) = names.iter().find(|n| !available.iter().any(|a| a == *n)) {
        let have = available.join(", ");
        return Err(config_error(
            "levels",
            format!("unknown level '{n}': the build has {have}"),
        ));
    }
    let unique: std::collections::BTreeSet<_> = names.iter().collect();
    if unique.len() != names.len() {
        return Err(config_error(
            "levels",
            format!("{value:?}: a level is given twice"),
        ));
    }
    Ok(available
        .iter()
        .filter(|a| names.contains(&a.as_str()))
        .cloned()
        .collect())
}

/// What a build's plan reads of its dataset.json.
struct BuildRecord {
    /// Its levels as written (none in a build that did not record them).
    levels: Vec<String>,
    seed: Option<u64>,
    /// Its `images_<f>/` factors.
    factors: Vec<u32>,
}

impl BuildRecord {
    /// The levels a plan may choose from: `sharp` alone in a build that did not record them.
    fn available(&self) -> Vec<String> {
        match self.levels.is_empty() {
            true => vec!["sharp".into()],
            false => self.levels.clone(),
        }
    }
}

fn build_record(build: &Path) -> Result<BuildRecord> {
    let doc = read_record(&build.join(files::DATASET), Record::Dataset)?;
    let levels = doc["levels"].as_array().into_iter().flatten();
    let factors = doc["config"]["downsample"].as_array().into_iter().flatten();
    let factors = factors.filter_map(|f| f.as_u64().and_then(|f| u32::try_from(f).ok()));
    Ok(BuildRecord {
        levels: levels
            .filter_map(|x| x.as_str().map(String::from))
            .collect(),
        seed: doc["seed"].as_u64(),
        factors: factors.collect(),
    })
}

/// Whether every image of a level has its linear EXR (`--keep-linear`).
fn has_linear(level_dir: &Path) -> Result<bool> {
    let (lin, images) = (level_dir.join(files::LINEAR), level_dir.join(files::IMAGES));
    if !(lin.is_dir() && images.is_dir()) {
        return Ok(false);
    }
    let stem = |p: &PathBuf| {
        p.file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default()
    };
    Ok(list_images(&images)?
        .iter()
        .all(|p| lin.join(format!("{}.exr", stem(p))).is_file()))
}

/// The plan of `blurset noise BUILD`: a unit per chosen level of each of `settings` (the
/// build's complete settings), its gains under `out/<setting>/<level>/`. Every unit is
/// checked before anything is written: a bad build fails with nothing written.
pub fn plan_build(
    build: &Path,
    out: &Path,
    settings: &[String],
    cfg: &NoiseConfig,
    table: &NoiseLevels,
) -> Result<NoisePlan> {
    let record = build_record(build)?;
    let levels = parse_levels(cfg.levels.as_deref(), &record.available())?;
    let downsample = cfg.downsample.clone().unwrap_or(record.factors);
    if settings.is_empty() {
        return Err(Error::Input {
            reason: format!(
                "no complete setting (<setting>/{}) in build",
                super::layout::MARKER
            ),
            path: build.into(),
        });
    }
    let linear = reads_linear(build, settings, &levels, cfg.source)?;
    let gamma = cfg.gamma.unwrap_or(NoiseGamma::Srgb);
    let mut common = Common::of(cfg, table, gamma)?;
    common.base.clean = Some(if linear { CLEAN_LINEAR } else { CLEAN_PNG }.into());
    common.base.build_noise = Some(BuildNoiseRecord {
        seed: cfg.seed,
        seed_derivation: SEED_DERIVATION.into(),
    });
    common.base.downsample = downsample.clone();
    let at = BuildUnit {
        build,
        name: resolved_name(build)?,
        out,
        linear,
        cfg,
        common: &common,
    };
    let mut units = Vec::new();
    for s in settings {
        for l in &levels {
            units.push(at.unit(s, l)?);
        }
    }
    let source = if linear { "linear" } else { "png" };
    let clean = !cfg.noisy_test_views;
    Ok(NoisePlan {
        source: source.into(),
        gamma: gamma.name().into(),
        params: params(cfg, table, (source, gamma, &downsample, clean)),
        downsample,
        levels,
        units,
        input: at.name,
        build_levels: record.levels,
        build_seed: record.seed,
        llffhold: None,
    })
}

/// Whether the units read the build's linear EXRs: `auto` when every chosen level of
/// every setting has them.
fn reads_linear(
    build: &Path,
    settings: &[String],
    levels: &[String],
    source: NoiseSource,
) -> Result<bool> {
    if source != NoiseSource::Auto {
        return Ok(source == NoiseSource::Linear);
    }
    for s in settings {
        for l in levels {
            if !has_linear(&build.join(s).join(l))? {
                return Ok(false);
            }
        }
    }
    Ok(true)
}

/// What every unit of a build shares.
struct BuildUnit<'a> {
    build: &'a Path,
    /// The build by its folder's name (no builder paths in outputs).
    name: String,
    out: &'a Path,
    linear: bool,
    cfg: &'a NoiseConfig,
    common: &'a Common,
}

/// A setting's meta.json as the noise reads it: the background its PNGs were composited
/// over (white in a build made before it was recorded) and its test views.
fn setting_meta(setting: &Path) -> Result<([f64; 3], Vec<usize>)> {
    let meta = read_record(&setting.join(files::META), Record::Meta)?;
    let bg: Vec<f64> = meta["render"]["background"]
        .as_array()
        .map(|a| a.iter().filter_map(serde_json::Value::as_f64).collect())
        .unwrap_or_default();
    let bg = if bg.len() == 3 {
        [bg[0], bg[1], bg[2]]
    } else {
        [1.0; 3]
    };
    let views = meta["test_views"].as_array().into_iter().flatten();
    let views = views.filter_map(|v| v.as_u64().map(|v| v as usize));
    Ok((bg, views.collect()))
}

impl BuildUnit<'_> {
    /// The unit of one level of one setting; its inputs are refused here, naming the file.
    fn unit(&self, setting: &str, level: &str) -> Result<NoiseUnit> {
        let src = self.build.join(setting).join(level);
        let (background, test_views) = setting_meta(&self.build.join(setting))?;
        let (pngs, rows, (w, h)) = self.read_level(&src, level)?;
        let sources = self.sources(&src, &pngs)?;
        let seed = scene_seed(self.cfg.seed, setting, level);
        let clean_views = if self.cfg.noisy_test_views {
            Vec::new()
        } else {
            test_views.clone()
        };
        let names = output_names(&pngs, self.cfg.frames);
        let wb = white_balance(self.cfg, seed);
        let doc = NoiseDoc {
            seed,
            white_balance: wb_record(wb),
            source: SourceRecord::Build {
                kind: if self.linear { "linear" } else { "png" }.into(),
                build: self.name.clone(),
                setting: setting.into(),
                level: level.into(),
                background,
                resolution: [w, h],
            },
            clean_views: clean_views.clone(),
            files: files_record(
                &self.read_names(level, &sources),
                &names,
                self.cfg,
                (&clean_views, 1),
            ),
            ..self.common.base.clone()
        };
        let downsample = self.common.base.downsample.clone();
        Ok(NoiseUnit {
            setting: Some(setting.into()),
            level: Some(level.into()),
            dst: self.out.join(setting).join(level),
            seed,
            small: downsample
                .iter()
                .map(|f| (*f, src.join(images_dir(*f))))
                .collect(),
            sources,
            images: pngs,
            names,
            frames: self.cfg.frames,
            // The build's rows already hold the written size and focal length.
            rows: repeat_rows(&rows, self.cfg.frames),
            background: self.linear.then_some(background),
            gamma: self.common.gamma,
            white_balance: wb,
            white_level: self.cfg.white_level,
            downsample,
            test_views,
            clean_views,
            factor: 1,
            no_linear: self.cfg.no_linear,
            transforms: Some(self.build.join(setting).join(files::TRANSFORMS)),
            gains: self.common.gains(seed, wb, &doc)?,
        })
    }

    /// A level's images, pose rows and size; a missing or mismatched file is refused
    /// here, naming it.
    fn read_level(&self, src: &Path, level: &str) -> Result<Read> {
        let image_dir = src.join(files::IMAGES);
        if !image_dir.is_dir() {
            return Err(Error::Input {
                reason: format!("level '{level}' has no images/ directory"),
                path: image_dir,
            });
        }
        let pngs = list_images(&image_dir)?;
        if pngs.is_empty() {
            return Err(Error::Input {
                reason: "no .png/.jpg images".into(),
                path: image_dir,
            });
        }
        let rows = pose_rows(&src.join(files::POSES_BOUNDS), &pngs, &image_dir)?;
        let (w, h, _, _) = image_info(&pngs[0])?;
        check_divides(
            &self.common.base.downsample,
            (w, h),
            &format!(": {}", src.display()),
        )?;
        one_size(&pngs)?;
        Ok((pngs, rows, (w, h)))
    }

    /// The clean files noise.json says each image came from, relative to the setting.
    fn read_names(&self, level: &str, sources: &[PathBuf]) -> Vec<String> {
        let subdir = if self.linear {
            files::LINEAR
        } else {
            files::IMAGES
        };
        let name = |p: &PathBuf| format!("{level}/{subdir}/{}", file_name(p));
        sources.iter().map(name).collect()
    }

    /// The clean images a level's noise reads: its PNGs, or their linear EXRs.
    fn sources(&self, src: &Path, pngs: &[PathBuf]) -> Result<Vec<PathBuf>> {
        if !self.linear {
            return Ok(pngs.to_vec());
        }
        let lin = src.join(files::LINEAR);
        let exr = |p: &PathBuf| {
            lin.join(format!(
                "{}.exr",
                p.file_stem().unwrap_or_default().to_string_lossy()
            ))
        };
        let sources: Vec<PathBuf> = pngs.iter().map(exr).collect();
        match sources.iter().find(|s| !s.is_file()) {
            Some(missing) => Err(Error::Input {
                reason: "--source linear: missing linear image (build with --keep-linear)".into(),
                path: missing.clone(),
            }),
            None => Ok(sources),
        }
    }
}

impl NoiseUnit {
    /// The gains not yet complete in `dst` (indices into `gains`): a rerun skips the rest.
    pub fn pending(&self) -> Vec<usize> {
        let done = |g: &NoiseGain| is_complete(&self.dst.join(&g.dir));
        (0..self.gains.len())
            .filter(|i| !done(&self.gains[*i]))
            .collect()
    }

    fn model(&self, g: &NoiseGain) -> Result<NoiseModel> {
        let m = NoiseModel {
            sigma_read: g.sigma_read,
            sigma_shot: g.sigma_shot,
            gamma: self.gamma,
            white_balance: self.white_balance,
            white_level: self.white_level,
        };
        m.validate()?;
        Ok(m)
    }

    /// The noisy images of the gains `dirs` names (gain index, folder), one pass over
    /// the unit's sources.
    pub fn write_images(&self, dirs: &[(usize, PathBuf)]) -> Result<()> {
        let mut variants = Vec::new();
        for (i, dir) in dirs {
            let g = self
                .gains
                .get(*i)
                .ok_or_else(|| Error::Value(format!("no gain {i} in the unit")))?;
            variants.push(Variant {
                out_dir: dir.clone(),
                model: self.model(g)?,
                key: g.key,
                raw: g.raw.clone(),
            });
        }
        let opts = VariantOptions {
            downsample: self.downsample.clone(),
            clean_views: self.clean_views.iter().copied().collect(),
            factor: self.factor,
            no_linear: self.no_linear,
        };
        let (src, names, frames) = (&self.sources, &self.names, self.frames);
        match self.background {
            Some(bg) => {
                // The level's images are its size: a linear EXR of another is refused
                // from its header before any is decoded.
                let size = self.images.first().map(|p| image_info(p)).transpose()?;
                let size = size.map(|(w, h, _, _)| (w, h));
                write_variants_linear(src, names, frames, &variants, bg, size, &opts)
            }
            None => write_variants(src, names, frames, &variants, &opts),
        }
    }

    /// What makes gain `i`'s images in `dir` an LLFF scene: the clean views' own files,
    /// the poses, a build's transforms.json, and noise.json (written last).
    pub fn write_gain_files(&self, i: usize, dir: &Path) -> Result<()> {
        let g = self
            .gains
            .get(i)
            .ok_or_else(|| Error::Value(format!("no gain {i} in the unit")))?;
        self.copy_clean(dir)?;
        write_poses_bounds(&dir.join(files::POSES_BOUNDS), &self.rows)?;
        if let Some(setting) = &self.transforms {
            let f = self.frames as usize;
            let images = (0..self.images.len()).flat_map(|v| (0..f).map(move |k| (v, k)));
            let images: Vec<(usize, String)> = images
                .map(|(v, k)| (v, format!("images/{}.png", self.names[v * f + k])))
                .collect();
            let fields = SceneFields {
                level: self.level.clone().unwrap_or_default(),
                gain: Some(g.gain),
                test_view_images: Some(
                    if self.clean_views.is_empty() {
                        "noisy"
                    } else {
                        "clean"
                    }
                    .into(),
                ),
            };
            let path = dir.join(files::TRANSFORMS);
            write_scene_transforms(&path, setting, &images, &self.test_views, &fields)?;
        }
        write_noise(&dir.join(files::NOISE), &g.record)
    }

    /// The clean views as the scene's own files, byte for byte: its PNG at images/ and,
    /// where the scene has one, its copy at images_<f>/ (the kernel at σ = 0 wrote the
    /// PNG's pixels, and the area mean of the decoded image where there is no copy).
    fn copy_clean(&self, dir: &Path) -> Result<()> {
        let copy = |from: &Path, to: PathBuf| {
            std::fs::copy(from, &to)
                .map(|_| ())
                .map_err(|e| Error::io("cannot copy", to, e))
        };
        for &v in &self.clean_views {
            let p = &self.images[v];
            let png = p.extension().is_some_and(|e| e.eq_ignore_ascii_case("png"));
            for k in 0..self.frames as usize {
                let name = format!("{}.png", self.names[v * self.frames as usize + k]);
                if png {
                    copy(p, dir.join(images_dir(self.factor)).join(&name))?;
                }
                for (f, small) in &self.small {
                    let from = small.join(file_name(p));
                    if from.is_file() {
                        copy(&from, dir.join(images_dir(*f)).join(&name))?;
                    }
                }
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::image::io::write_png_rgb8;
    use crate::plan::spec::Raw;
    use std::collections::BTreeMap;

    fn cfg(values: &[(&str, Raw)]) -> Result<NoiseConfig> {
        let map = values.iter().map(|(k, v)| (k.to_string(), v.clone()));
        NoiseConfig::from_values(&map.collect::<BTreeMap<_, _>>())
    }

    fn gains(g: &[&str]) -> Raw {
        Raw::List(g.iter().map(|s| Raw::Str(s.to_string())).collect())
    }

    /// An LLFF scene of `n` 8x4 images (`images/` and `images_2/`) and its poses.
    fn scene(tag: &str, n: usize) -> Result<PathBuf> {
        let dir =
            std::env::temp_dir().join(format!("blurset-noise-plan-{tag}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        for (sub, w, h) in [("images", 8, 4), ("images_2", 4, 2)] {
            std::fs::create_dir_all(dir.join(sub)).map_err(|e| Error::io("mkdir", &dir, e))?;
            for i in 0..n {
                let rgb = vec![(40 * i) as u8; (w * h * 3) as usize];
                write_png_rgb8(&dir.join(sub).join(format!("{i:03}.png")), w, h, &rgb)?;
            }
        }
        let row = |i: usize| {
            let mut r = [i as f64 + 1.0; 17];
            (r[15], r[16]) = (1.0, 2.0);
            r
        };
        let rows: Vec<PoseRow> = (0..n).map(row).collect();
        write_poses_bounds(&dir.join(files::POSES_BOUNDS), &rows)?;
        Ok(dir)
    }

    /// The plan of a five-view scene at gains 1, 4 and 20 (seed 7, two frames, every
    /// third view clean, images_2 too), its folder and the default levels.
    fn scene_plan(tag: &str) -> Result<(PathBuf, NoiseLevels, NoisePlan)> {
        let dir = scene(tag, 5)?;
        let c = cfg(&[
            ("gains", gains(&["1", "4", "20"])),
            ("seed", Raw::Int(7)),
            ("frames", Raw::Int(2)),
            ("clean_views", Raw::Int(3)),
            ("downsample", Raw::List(vec![Raw::Int(2)])),
            ("factor", Raw::Int(1)),
        ])?;
        let t = NoiseLevels::DEFAULT;
        let plan = plan_scene(&dir, &dir.join("out"), &c, &t)?;
        Ok((dir, t, plan))
    }

    #[test]
    fn a_scene_plan_records_the_runs_options_and_the_scene_by_name() -> Result<()> {
        let (dir, t, plan) = scene_plan("plan")?;
        assert_eq!((plan.gamma.as_str(), plan.units.len()), ("2.2", 1));
        // The run's options as noise_dataset.json records them; the scene by its name.
        let p = &plan.params;
        assert_eq!((p.seed, p.frames, p.downsample.clone()), (7, 2, vec![2]));
        assert_eq!(
            (p.source.as_str(), p.clean_views.as_str()),
            ("png", "test_views")
        );
        assert_eq!(p.levels_table.read_step_per_log2_gain, t.read_step);
        assert_eq!(
            Some(plan.input.as_str()),
            dir.file_name().and_then(|n| n.to_str())
        );
        let _ = std::fs::remove_dir_all(&dir);
        Ok(())
    }

    #[test]
    fn a_scene_unit_holds_its_clean_views_names_and_rows_per_frame() -> Result<()> {
        let (dir, _, plan) = scene_plan("unit")?;
        let u = &plan.units[0];
        assert_eq!(u.clean_views, vec![0, 3]);
        assert_eq!(u.names[..3], ["000_f00", "000_f01", "001_f00"]);
        assert_eq!(u.white_balance, Some(sample_white_balance(7)));
        assert_eq!(u.small, vec![(2, dir.join("images_2"))]);
        // Rows per frame, hwf the scene's.
        assert_eq!(
            (u.rows.len(), u.rows[1][4], u.rows[1][14], u.rows[2][0]),
            (10, 1.0, 1.0, 2.0)
        );
        let _ = std::fs::remove_dir_all(&dir);
        Ok(())
    }

    #[test]
    fn each_gain_holds_its_key_sigmas_and_record() -> Result<()> {
        let (dir, t, plan) = scene_plan("gains")?;
        let u = &plan.units[0];
        for (g, want) in u.gains.iter().zip([1.0, 4.0, 20.0]) {
            let (sr, ss) = t.sigmas(want)?;
            assert_eq!(
                (g.gain, g.key, g.sigma_read, g.sigma_shot),
                (want, noise_key(7, want), sr, ss)
            );
            assert_eq!(g.dir, gain_name(want));
            let r = &g.record;
            assert_eq!(
                (r.seed, r.sigma_read, r.gain.as_i64()),
                (7, sr, Some(want as i64))
            );
            assert_eq!(
                (r.rng.as_str(), r.frames, r.clean_views.clone()),
                (RNG, 2, vec![0, 3])
            );
            assert_eq!(r.gamma, serde_json::json!(2.2));
            assert_eq!(r.levels.source, "blurset-default");
            assert!(r.build_noise.is_none() && r.clean.is_none());
            assert_eq!(r.files.len(), 10);
            assert!(r.files[1].clean && !r.files[2].clean && r.files[2].source == "001.png");
            assert!(matches!(
                r.source,
                SourceRecord::Scene {
                    factor: 1,
                    resolution: [8, 4],
                    ..
                }
            ));
        }
        let _ = std::fs::remove_dir_all(&dir);
        Ok(())
    }

    #[test]
    fn a_unit_writes_its_record_and_knows_what_is_pending() -> Result<()> {
        let dir = scene("write", 5)?;
        let c = cfg(&[
            ("gains", gains(&["1", "4", "20"])),
            ("frames", Raw::Int(2)),
            ("clean_views", Raw::Int(3)),
            ("downsample", Raw::List(vec![Raw::Int(2)])),
            ("factor", Raw::Int(1)),
        ])?;
        let plan = plan_scene(&dir, &dir.join("out"), &c, &NoiseLevels::DEFAULT)?;
        let u = &plan.units[0];
        assert_eq!(u.pending(), vec![0, 1, 2]);
        let g = dir.join("out").join(&u.gains[1].dir);
        for sub in ["images", "images_2"] {
            std::fs::create_dir_all(g.join(sub)).map_err(|e| Error::io("mkdir", &g, e))?;
        }
        u.write_gain_files(1, &g)?;
        let text = std::fs::read(g.join(files::NOISE)).map_err(|e| Error::io("read", &g, e))?;
        let doc: NoiseDoc =
            serde_json::from_slice(&text).map_err(|e| Error::Value(e.to_string()))?;
        assert_eq!(doc, u.gains[1].record);
        assert_eq!(read_poses_bounds(&g.join(files::POSES_BOUNDS))?, u.rows);
        assert!(g.join("images/003_f01.png").is_file() && g.join("images_2/000_f00.png").is_file());
        std::fs::write(g.join(super::super::layout::MARKER), b"")
            .map_err(|e| Error::io("w", &g, e))?;
        assert_eq!(u.pending(), vec![0, 2]);
        let _ = std::fs::remove_dir_all(&dir);
        Ok(())
    }

    #[test]
    fn a_bad_scene_or_option_is_one_error_naming_it() -> Result<()> {
        let dir = scene("bad", 3)?;
        let t = NoiseLevels::DEFAULT;
        let err = |c: &NoiseConfig| plan_scene(&dir, &dir, c, &t).err().map(|e| e.to_string());
        let e = err(&NoiseConfig::default()).unwrap_or_default();
        assert!(
            e.starts_with("the scene holds images/, images_2/: pass --factor F"),
            "{e}"
        );
        let one = ("factor", Raw::Int(1));
        let e = err(&cfg(&[
            ("downsample", Raw::List(vec![Raw::Int(3)])),
            one.clone(),
        ])?);
        let e = e.unwrap_or_default();
        assert!(
            e.starts_with("downsample 3: does not divide the image size 8x4"),
            "{e}"
        );
        let c = cfg(&[
            ("gains", gains(&["2.0000001", "2.00000012"])),
            ("any_gain", Raw::Bool(true)),
            one.clone(),
        ])?;
        let e = err(&c).unwrap_or_default();
        assert!(
            e.starts_with("gains 2.0000001 and 2.00000012: both would be written to gain_2/"),
            "{e}"
        );
        let e = err(&cfg(&[("factor", Raw::Int(4))])?).unwrap_or_default();
        assert!(e.contains("image directory images_4/ not found"), "{e}");
        std::fs::remove_file(dir.join("images/002.png")).map_err(|e| Error::io("rm", &dir, e))?;
        let e = err(&cfg(&[one])?).unwrap_or_default();
        assert!(
            e.contains("2 images in") && e.contains("3 pose rows"),
            "{e}"
        );
        let _ = std::fs::remove_dir_all(&dir);
        Ok(())
    }

    #[test]
    fn build_units_have_their_own_seed_and_levels_parse() -> Result<()> {
        let have: Vec<String> = ["sharp", "blur_1", "blur_2"].map(String::from).to_vec();
        assert_eq!(parse_levels(None, &have)?, have);
        assert_eq!(
            parse_levels(Some("blur_2, sharp"), &have)?,
            ["sharp", "blur_2"]
        );
        let e = parse_levels(Some("blur_9"), &have)
            .err()
            .map(|e| e.to_string());
        assert_eq!(
            e.as_deref(),
            Some("levels unknown level 'blur_9': the build has sharp, blur_1, blur_2")
        );
        assert!(parse_levels(Some("sharp,sharp"), &have).is_err());
        assert!(parse_levels(Some(" , "), &have).is_err());
        // The scene seed of a unit is the core's one derivation, and RNG names its key.
        assert_eq!(
            scene_seed(3, "a_000", "blur_1"),
            crate::noise::model::scene_seed(3, "a_000", "blur_1")
        );
        let key = crate::rng::derive_seed(9, &[crate::rng::fnv1a64(b"noise"), 4.0f64.to_bits()]);
        assert_eq!(noise_key(9, 4.0), key);
        Ok(())
    }

    #[test]
    fn output_names_keep_sorted_stems_else_index_names() {
        let p = |v: &[&str]| v.iter().map(PathBuf::from).collect::<Vec<_>>();
        assert_eq!(output_names(&p(&["a.png", "b.jpg"]), 1), ["a", "b"]);
        assert_eq!(output_names(&p(&["a.png"]), 3), ["a_f00", "a_f01", "a_f02"]);
        // `a_f..` sorts after `a.` stems' neighbours: index names keep the order.
        assert_eq!(
            output_names(&p(&["a.png", "a_f00.png"]), 2)[0],
            "view000_f00"
        );
        assert_eq!(gain_number(4.0).as_i64(), Some(4));
        assert_eq!(gain_number(2.5).as_f64(), Some(2.5));
    }
}
