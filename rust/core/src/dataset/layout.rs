//! The names a build (and a noise output) gives its parts on disk, and what "complete"
//! means — the one owner of these rules (DESIGN §4, §10):
//!
//! - a setting directory is `<uid>_<theta0>`; a level directory is `sharp` or
//!   `blur_<l>` (l in 1..=64); a noise gain directory is `gain_<g>`;
//! - a setting (or a noise unit) is written under `<name>.partial/`, gets its `.complete`
//!   marker last and is then renamed into place: it is complete only when its final
//!   directory (never a `*.partial` one) holds the marker;
//! - a build's setting directories are scanned once, here ([`scan`]).
use crate::error::{Error, Result};
use crate::ground::atomic::{replace_dir, write_atomic};
use crate::ground::names::{files, images_dir, pass_dir, SHARP, WORK_PREFIX};
use crate::image::exr::read::header_size_other_than;
use crate::plan::kind::{is_level_dir, sort_level_dirs};
use crate::plan::kinds::pass_level;
use std::path::{Path, PathBuf};

/// The marker a setting directory gets last, when it is complete.
pub const MARKER: &str = ".complete";
/// Suffix of the directory a setting or noise unit is written in before it is published.
pub const PARTIAL_SUFFIX: &str = ".partial";
/// The level directories a setting holds, in level order.
pub fn setting_levels(setting: &Path) -> Result<Vec<String>> {
    let rd = std::fs::read_dir(setting).map_err(|e| Error::io("cannot list", setting, e))?;
    let mut names = Vec::new();
    for entry in rd {
        let entry = entry.map_err(|e| Error::io("cannot list", setting, e))?;
        if entry.path().is_dir() {
            names.push(entry.file_name().to_string_lossy().into_owned());
        }
    }
    Ok(sort_level_dirs(&names))
}

/// Where a setting or noise unit is written before it is published.
pub fn partial_dir(final_dir: &Path) -> PathBuf {
    let name = final_dir
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    final_dir.with_file_name(format!("{name}{PARTIAL_SUFFIX}"))
}

/// A finished setting or noise unit: a final (not `*.partial`) directory with its marker.
pub fn is_complete(dir: &Path) -> bool {
    let partial = dir
        .file_name()
        .is_some_and(|n| n.to_string_lossy().ends_with(PARTIAL_SUFFIX));
    !partial && dir.join(MARKER).is_file()
}

/// Write the marker (holding `stamp`) into `partial`, then put it at `final_dir`,
/// replacing an older one ([`replace_dir`]): the last step of a setting or noise unit.
pub fn publish(partial: &Path, final_dir: &Path, stamp: &str) -> Result<()> {
    write_atomic(&partial.join(MARKER), format!("{stamp}\n").as_bytes())?;
    replace_dir(partial, final_dir)
}

/// A setting's preview image (`--previews`, `blurset preview`).
const PREVIEW: &str = "preview.png";

/// Whether `rel` (relative to a setting folder, '/'-separated) names a file a build
/// writes there: meta.json, transforms.json, preview.png; a level's poses_bounds.npy
/// and transforms.json; the PNGs and EXRs of its images/, linear/, depth/, normals/,
/// masks/ and their `_<f>` sizes. Anything else in a setting is a user's (a note a
/// redone setting keeps): a manifest never certifies it as the build's.
pub fn is_build_file(rel: &str) -> bool {
    let parts: Vec<&str> = rel.split('/').collect();
    match parts.as_slice() {
        [f] => [files::META, files::TRANSFORMS, PREVIEW].contains(f),
        [level, f] => is_level_dir(level) && [files::POSES_BOUNDS, files::TRANSFORMS].contains(f),
        [level, folder, f] => {
            is_level_dir(level)
                && is_image_folder(folder)
                && (f.ends_with(".png") || f.ends_with(".exr"))
                && !f.starts_with('.')
        }
        _ => false,
    }
}

/// Whether `rel`, a path relative to a noise unit's gain folder (`gain_4/…`), is a file
/// `blurset noise` writes there: poses_bounds.npy, transforms.json, noise.json, and the
/// PNGs of images/ and EXRs of linear/ at any size. Anything else is a user's: a
/// manifest never certifies it as the noise output's.
pub fn is_noise_gain_file(rel: &str) -> bool {
    let parts: Vec<&str> = rel.split('/').collect();
    match parts.as_slice() {
        [f] => [files::POSES_BOUNDS, files::TRANSFORMS, files::NOISE].contains(f),
        [folder, f] => {
            let base = match folder.split_once('_') {
                Some((b, n)) if !n.is_empty() && n.bytes().all(|c| c.is_ascii_digit()) => b,
                Some(_) => return false,
                None => folder,
            };
            !f.starts_with('.')
                && ((base == files::IMAGES && f.ends_with(".png"))
                    || (base == files::LINEAR && f.ends_with(".exr")))
        }
        _ => false,
    }
}

/// A noise gain's folder name: `gain_4`, `gain_2.5`.
pub fn is_gain_dir(name: &str) -> bool {
    name.strip_prefix("gain_")
        .and_then(|g| g.parse::<f64>().ok())
        .is_some_and(|g| g.is_finite() && g > 0.0)
}

/// `images`, `linear` or a pass folder (`depth`, `normals`, `masks`), or one of them at
/// a downsampling factor (`images_4`): a folder of a level's per-view files.
pub fn is_image_folder(name: &str) -> bool {
    let base = match name.split_once('_') {
        Some((base, f)) if !f.is_empty() && f.bytes().all(|b| b.is_ascii_digit()) => base,
        Some(_) => return false,
        None => name,
    };
    let passes = crate::ground::names::PASSES.map(|p| pass_dir(p, 1));
    base == files::IMAGES || base == files::LINEAR || passes.iter().any(|p| p == base)
}

const PNG_MAGIC: &[u8; 8] = b"\x89PNG\r\n\x1a\n";
/// Bytes of one `poses_bounds.npy` row (17 float64).
const POSE_ROW_BYTES: u64 = 17 * 8;

/// What is wrong with one file or folder of a complete setting: a kind with its facts;
/// the words are made from it ([`Fault::what`]), so callers match kinds, never text.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Fault {
    /// Not there (a file).
    Missing,
    /// There but not readable as what it should be (the reason).
    Unreadable(String),
    /// A level folder meta.json lists is not there.
    LevelMissing,
    /// A folder holds `have` of the `want` files (`of`: "images", "EXRs").
    Count {
        have: usize,
        want: usize,
        of: &'static str,
    },
    /// A whole PNG, or an EXR by its header, of another size than meta.json's.
    Size { got: (u32, u32), want: (u32, u32) },
    /// Not a PNG at all.
    NotPng,
    /// A PNG without its end chunk (cut short).
    PngTruncated,
    /// An empty file.
    Empty,
    /// A file shorter than what it must hold.
    Truncated,
    /// An EXR that does not decode (cut short, a block that no longer inflates): the
    /// reason.
    Undecodable(String),
}

impl Fault {
    /// The kind's name, as the bindings give it.
    pub fn kind(&self) -> &'static str {
        match self {
            Fault::Missing => "missing",
            Fault::Unreadable(_) => "unreadable",
            Fault::LevelMissing => "level_missing",
            Fault::Count { .. } => "count",
            Fault::Size { .. } => "size",
            Fault::NotPng => "not_png",
            Fault::PngTruncated => "png_truncated",
            Fault::Empty => "empty",
            Fault::Truncated => "truncated",
            Fault::Undecodable(_) => "undecodable",
        }
    }

    /// What is wrong, in words (`blurset verify`'s line after the path).
    pub fn what(&self) -> String {
        match self {
            Fault::Missing => "missing".into(),
            Fault::Unreadable(why) => format!("unreadable ({why})"),
            Fault::LevelMissing => "level folder missing".into(),
            Fault::Count { have, want, of } => format!("holds {have} of {want} {of}"),
            Fault::Size { got, want } => {
                format!("{}x{} px, not {}x{}", got.0, got.1, want.0, want.1)
            }
            Fault::NotPng => "not a whole PNG".into(),
            Fault::PngTruncated => "truncated (no PNG end chunk)".into(),
            Fault::Empty => "empty".into(),
            Fault::Truncated => "truncated".into(),
            Fault::Undecodable(why) => format!("does not decode ({why})"),
        }
    }
}

/// One problem of a complete setting found by the cheap check: the file or folder
/// (relative to the setting, `/`-separated) and what is wrong with it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct SettingProblem {
    pub path: String,
    pub fault: Fault,
}

impl SettingProblem {
    fn new(path: impl Into<String>, fault: Fault) -> Self {
        SettingProblem {
            path: path.into(),
            fault,
        }
    }

    /// The sentence a rerun prints when it redoes the setting.
    pub fn message(&self) -> String {
        let path = &self.path;
        match &self.fault {
            Fault::LevelMissing => format!("level folder {path}/ is missing"),
            Fault::Count { .. } | Fault::Undecodable(_) => format!("{path} {}", self.fault.what()),
            Fault::PngTruncated => format!("{path} is truncated"),
            f => format!("{path} is {}", f.what()),
        }
    }
}

/// What is missing or damaged in a complete setting, checked cheaply (names, sizes, PNG
/// signatures and IEND chunks, the pose file's size; EXRs decoded, as nothing short of
/// inflating their blocks finds a cut or flipped one; `blurset verify` decodes
/// everything): None when it looks whole. A rerun redoes a setting with a problem
/// instead of counting it.
pub fn setting_problem(setting: &Path) -> Option<String> {
    setting_problems(setting)
        .into_iter()
        .next()
        .map(|p| p.message())
}

/// Every problem [`setting_problem`] checks for (it reports the first): `blurset verify`
/// lists them all, then decodes what is there. Linear EXRs are checked (count, each
/// decodes) when meta.json's `render.linear` says they were kept.
pub fn setting_problems(setting: &Path) -> Vec<SettingProblem> {
    let counts = match SettingCounts::read(setting) {
        Ok(c) => c,
        Err(p) => return vec![p],
    };
    let mut out = Vec::new();
    if !setting.join("transforms.json").is_file() {
        out.push(SettingProblem::new("transforms.json", Fault::Missing));
    }
    for lvl in &counts.levels {
        let d = setting.join(lvl);
        if !d.is_dir() {
            out.push(SettingProblem::new(lvl.clone(), Fault::LevelMissing));
            continue;
        }
        let subdirs = std::iter::once((files::IMAGES.to_string(), 1))
            .chain(counts.downsample.iter().map(|&f| (images_dir(f), f.max(1))));
        for (sub, factor) in subdirs {
            let want = counts.resolution.map(|[w, h]| (w / factor, h / factor));
            out.extend(image_problems(
                &d.join(&sub),
                &format!("{lvl}/{sub}"),
                counts.views,
                want,
                "images",
            ));
        }
        if counts.linear {
            let rel = format!("{lvl}/{}", files::LINEAR);
            let want = counts.resolution.map(|[w, h]| (w, h));
            out.extend(exr_problems(
                &d.join(files::LINEAR),
                &rel,
                counts.views,
                want,
            ));
        }
        out.extend(pass_problems(&d, lvl, &counts));
        let npy = format!("{lvl}/poses_bounds.npy");
        match std::fs::metadata(d.join(files::POSES_BOUNDS)) {
            Ok(m) if m.is_file() => {
                if m.len() < counts.views as u64 * POSE_ROW_BYTES + 16 {
                    out.push(SettingProblem::new(npy, Fault::Truncated));
                }
            }
            _ => out.push(SettingProblem::new(npy, Fault::Missing)),
        }
    }
    out
}

/// The problems of the `--passes` folders level `lvl` holds (`level`: its path; the
/// sharp level's passes, a blur level's own masks: `pass_level`): a count other than the
/// views', an empty file, a damaged mask or one of another size.
fn pass_problems(level: &Path, lvl: &str, counts: &SettingCounts) -> Vec<SettingProblem> {
    let mut out = Vec::new();
    let own = |p: &&String| pass_level(p, lvl, counts.level_masks) == lvl;
    for pass in counts.passes.iter().filter(own) {
        for factor in std::iter::once(1).chain(counts.downsample.iter().copied()) {
            let sub = pass_dir(pass, factor);
            let rel = format!("{lvl}/{sub}");
            let want = counts.resolution.map(|[w, h]| (w / factor, h / factor));
            if pass == "mask" {
                let dir = level.join(&sub);
                out.extend(image_problems(&dir, &rel, counts.views, want, "masks"));
                continue;
            }
            out.extend(exr_problems(&level.join(&sub), &rel, counts.views, want));
        }
    }
    out
}

/// What the cheap check needs of a setting's meta.json.
struct SettingCounts {
    views: usize,
    levels: Vec<String>,
    downsample: Vec<u32>,
    /// Linear EXRs were kept (`render.linear`).
    linear: bool,
    /// The sharp level's per-view outputs besides colour (`render.passes`).
    passes: Vec<String>,
    /// Blur levels hold masks of their own (`render.level_masks`).
    level_masks: bool,
    resolution: Option<[u32; 2]>,
}

impl SettingCounts {
    /// meta.json's counts, or the problem of a meta.json that is missing or unreadable.
    fn read(setting: &Path) -> std::result::Result<Self, SettingProblem> {
        #[derive(serde::Deserialize)]
        struct Render {
            #[serde(default)]
            linear: bool,
            #[serde(default)]
            passes: Vec<String>,
            #[serde(default)]
            level_masks: bool,
        }
        #[derive(serde::Deserialize)]
        struct Counts {
            views: Vec<serde::de::IgnoredAny>,
            levels: Vec<String>,
            /// Factors of the `images_<f>/` copies (none in builds made before them).
            #[serde(default)]
            downsample: Vec<u32>,
            render: Option<Render>,
            /// Width and height of `images/` (`images_<f>/`: each divided by f).
            #[serde(default)]
            resolution: Option<[u32; 2]>,
        }
        let text = match std::fs::read(setting.join(files::META)) {
            Ok(t) => t,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
                return Err(SettingProblem::new(files::META, Fault::Missing))
            }
            Err(e) => {
                let fault = Fault::Unreadable(e.kind().to_string());
                return Err(SettingProblem::new(files::META, fault));
            }
        };
        let c = serde_json::from_slice::<Counts>(&text)
            .map_err(|e| SettingProblem::new(files::META, Fault::Unreadable(e.to_string())))?;
        Ok(SettingCounts {
            views: c.views.len(),
            levels: c.levels,
            downsample: c.downsample,
            linear: c.render.as_ref().is_some_and(|r| r.linear),
            level_masks: c.render.as_ref().is_some_and(|r| r.level_masks),
            passes: c.render.map(|r| r.passes).unwrap_or_default(),
            resolution: c.resolution,
        })
    }
}

/// The problems of one folder of PNGs (`rel`, relative to the setting; `of`: what they
/// are, "images" or "masks"): a count other than `views`, a damaged PNG, or a whole one
/// of another size than `want`.
fn image_problems(
    dir: &Path,
    rel: &str,
    views: usize,
    want: Option<(u32, u32)>,
    of: &'static str,
) -> Vec<SettingProblem> {
    let mut out = Vec::new();
    let images = files_with(dir, "png");
    out.extend(count_problem(rel.into(), images.len(), views, of));
    for (name, p) in &images {
        let path = format!("{rel}/{name}");
        if let Some(fault) = png_fault(p) {
            out.push(SettingProblem::new(path, fault));
        } else if let (Some(want), Some(got)) = (want, png_size(p)) {
            // A whole PNG of another size than meta.json's (a valid image put in its
            // place) is damage too: the loaders stack the images.
            if got != want {
                out.push(SettingProblem::new(path, Fault::Size { got, want }));
            }
        }
    }
    out
}

/// A folder (`rel`) holding `have` files of a kind where there are `want` views.
fn count_problem(
    rel: String,
    have: usize,
    want: usize,
    of: &'static str,
) -> Option<SettingProblem> {
    (have != want).then(|| SettingProblem::new(rel, Fault::Count { have, want, of }))
}

/// The problems of a folder of EXRs (`rel`, relative to the setting: a level's linear/,
/// the sharp level's depth/ and normals/): a count other than `views`, an empty file,
/// one whose header is not of meta.json's size `want`, one that does not decode. A rerun would otherwise keep (and its manifest certify) a
/// cut or bit-flipped EXR: no header read or size finds a block that no longer
/// inflates, so each is decoded (in parallel), as `blurset verify` does.
fn exr_problems(
    dir: &Path,
    rel: &str,
    views: usize,
    want: Option<(u32, u32)>,
) -> Vec<SettingProblem> {
    use rayon::prelude::*;
    let mut out = Vec::new();
    let exrs = files_with(dir, "exr");
    out.extend(count_problem(rel.into(), exrs.len(), views, "EXRs"));
    let faults: Vec<Option<Fault>> = exrs.par_iter().map(|(_, p)| exr_fault(p, want)).collect();
    for ((name, _), fault) in exrs.iter().zip(faults) {
        if let Some(fault) = fault {
            out.push(SettingProblem::new(format!("{rel}/{name}"), fault));
        }
    }
    out
}

/// What is wrong with an EXR of a setting (empty, another size than `want` by its
/// header, read before anything of the size it claims is allocated, or does not
/// decode), or None.
fn exr_fault(path: &Path, want: Option<(u32, u32)>) -> Option<Fault> {
    let bytes = match std::fs::read(path) {
        Ok(bytes) => bytes,
        Err(e) => return Some(Fault::Unreadable(e.kind().to_string())),
    };
    if bytes.is_empty() {
        return Some(Fault::Empty);
    }
    if let Some(want) = want {
        if let Some(got) = header_size_other_than(&bytes, want) {
            return Some(Fault::Size { got, want });
        }
    }
    decode_exr_size(&bytes, path)
        .err()
        .map(|e| Fault::Undecodable(error_reason(&e.to_string())))
}

/// The width and height of a build's EXR, decoded whole: a colour EXR (linear/,
/// normals/), else a one-channel depth EXR (depth/). The one rule of the cheap check
/// and of `blurset verify`'s decode.
pub(crate) fn decode_exr_size(bytes: &[u8], path: &Path) -> Result<(u32, u32)> {
    crate::image::exr::read::decode_exr(bytes)
        .map(|f| (f.width, f.height))
        .or_else(|e| {
            crate::image::geometry::decode_depth_exr(bytes, path)
                .map(|(w, h, _)| (w as u32, h as u32))
                .map_err(|_| e)
        })
}

/// An error's words without the path the caller names anyway (`…: "<path>"`).
pub(crate) fn error_reason(msg: &str) -> String {
    match msg.rfind(": \"") {
        Some(i) if msg.ends_with('"') => msg[..i].to_string(),
        _ => msg.to_string(),
    }
}

/// (name, path) of a folder's files with this extension, sorted by name (none when the
/// folder is missing).
fn files_with(dir: &Path, ext: &str) -> Vec<(String, PathBuf)> {
    let mut found: Vec<(String, PathBuf)> = std::fs::read_dir(dir)
        .map(|rd| {
            rd.filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|p| p.extension().is_some_and(|x| x == ext))
                .map(|p| {
                    let name = p.file_name().map(|n| n.to_string_lossy().into_owned());
                    (name.unwrap_or_default(), p)
                })
                .collect()
        })
        .unwrap_or_default();
    found.sort();
    found
}

/// What is wrong with a PNG file, read without decoding (its signature and its last
/// chunk, IEND: a file cut short by a full disk or a killed copy has none), or None.
pub fn png_fault(path: &Path) -> Option<Fault> {
    match png_state(path) {
        PngState::Whole => None,
        PngState::NotPng => Some(Fault::NotPng),
        PngState::Truncated => Some(Fault::PngTruncated),
    }
}

/// Width and height from a PNG's IHDR chunk (the first, by the format), read without
/// decoding; None when the file does not start with one.
fn png_size(path: &Path) -> Option<(u32, u32)> {
    use std::io::Read;
    let mut head = [0u8; 24];
    std::fs::File::open(path).ok()?.read_exact(&mut head).ok()?;
    if &head[..8] != PNG_MAGIC || &head[12..16] != b"IHDR" {
        return None;
    }
    let be = |b: &[u8]| u32::from_be_bytes([b[0], b[1], b[2], b[3]]);
    Some((be(&head[16..20]), be(&head[20..24])))
}

enum PngState {
    Whole,
    NotPng,
    Truncated,
}

/// A PNG's signature and its last chunk (IEND), read without decoding.
fn png_state(path: &Path) -> PngState {
    use std::io::{Read, Seek, SeekFrom};
    let read = || -> std::io::Result<PngState> {
        let mut f = std::fs::File::open(path)?;
        let size = f.metadata()?.len();
        let mut head = [0u8; 8];
        if size < 67 || f.read_exact(&mut head).is_err() || &head != PNG_MAGIC {
            return Ok(PngState::NotPng);
        }
        let mut tail = [0u8; 12];
        f.seek(SeekFrom::Start(size - 12))?;
        f.read_exact(&mut tail)?;
        Ok(if &tail[4..8] == b"IEND" {
            PngState::Whole
        } else {
            PngState::Truncated
        })
    };
    read().unwrap_or(PngState::NotPng)
}

/// Complete and incomplete setting directories of a build, sorted by name.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Scan {
    pub complete: Vec<String>,
    /// `*.partial` directories, and directories holding `meta.json` or `sharp/` without
    /// the marker (a build still running, or a killed one).
    pub incomplete: Vec<String>,
    /// Whether the directory holds any file only a build writes.
    pub is_build: bool,
}

/// The files of a build that are not settings.
const BUILD_FILES: [&str; 3] = [files::DATASET, files::SPLITS, files::FAILURES];

/// List the setting directories of `out` (hidden directories such as `.work-*` are not
/// settings). A missing or non-directory `out` is an input error.
pub fn scan(out: &Path) -> Result<Scan> {
    let input = |reason: &str| Error::Input {
        reason: reason.into(),
        path: out.into(),
    };
    if !out.exists() {
        return Err(input("no such build directory"));
    }
    if !out.is_dir() {
        return Err(input("not a directory (expected a build)"));
    }
    let rd = std::fs::read_dir(out).map_err(|e| Error::io("cannot list", out, e))?;
    let mut s = Scan::default();
    for entry in rd {
        let entry = entry.map_err(|e| Error::io("cannot list", out, e))?;
        let name = entry.file_name().to_string_lossy().into_owned();
        let path = entry.path();
        if BUILD_FILES.contains(&name.as_str()) {
            s.is_build = true;
        }
        if name.starts_with('.') || !path.is_dir() {
            if name.starts_with(WORK_PREFIX) || name == files::DEMO_OBJECTS {
                s.is_build = true;
            }
            continue;
        }
        let partial = name.ends_with(PARTIAL_SUFFIX);
        if is_complete(&path) {
            s.complete.push(name);
        } else if partial || path.join(files::META).exists() || path.join(SHARP).is_dir() {
            s.incomplete.push(name);
        }
    }
    s.is_build |= !s.complete.is_empty() || !s.incomplete.is_empty();
    s.complete.sort();
    s.incomplete.sort();
    Ok(s)
}

/// The complete setting directories of a build, sorted by name.
pub fn complete_settings(out: &Path) -> Result<Vec<String>> {
    Ok(scan(out)?.complete)
}

/// The path an atomic write of `path` goes through: `.<name>.tmp<pid>` beside it.
pub fn temp_path(path: &Path) -> PathBuf {
    crate::ground::atomic::temp_path(path)
}

/// The (target name, pid) of a temp name `.<name>.tmp<pid>`, or None.
pub fn parse_temp_name(name: &str) -> Option<(String, u32)> {
    let rest = name.strip_prefix('.')?;
    let at = rest.rfind(".tmp")?;
    let (target, pid) = (&rest[..at], &rest[at + 4..]);
    if target.is_empty() || pid.is_empty() || !pid.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    Some((target.to_string(), pid.parse().ok()?))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ground::names::{gain_name, image_name, setting_name, theta0s};
    use crate::plan::kind::{level_dirs, parse_level_dir};

    #[test]
    fn names_and_azimuths() {
        assert_eq!(setting_name("chair", 90.0), "chair_090");
        assert_eq!(setting_name("a", 359.6), "a_360");
        assert_eq!(theta0s(4), [0.0, 90.0, 180.0, 270.0]);
        assert_eq!(theta0s(3)[1], 120.0);
    }

    #[test]
    fn image_names_sort_in_view_order() {
        assert_eq!(image_name(7, 34), "007.png");
        assert_eq!(image_name(7, 1500), "0007.png");
    }

    #[test]
    fn level_directories() {
        assert_eq!(level_dirs(&[1, 4]), ["sharp", "blur_1", "blur_4"]);
        assert_eq!(level_dirs(&[]), ["sharp"]);
        for (name, level) in [
            ("sharp", Some(0)),
            ("blur_1", Some(1)),
            ("blur_64", Some(64)),
        ] {
            assert_eq!(parse_level_dir(name), level);
        }
        for bad in [
            "blur_0", "blur_65", "blur_01", "blur_", "blur_x", "blur_+1", "Sharp",
        ] {
            assert_eq!(parse_level_dir(bad), None, "{bad}");
        }
        assert_eq!(
            sort_level_dirs(&["blur_10", "x", "blur_2", "sharp"]),
            ["sharp", "blur_2", "blur_10"]
        );
    }

    #[test]
    fn gain_names_follow_python_g() {
        let cases = [
            (1.0, "gain_1"),
            (20.0, "gain_20"),
            (2.5, "gain_2.5"),
            (1.0000001, "gain_1"),
            (0.1, "gain_0.1"),
            (1e-7, "gain_1e-07"),
            (1234567.5, "gain_1.23457e+06"),
            (0.00012345678, "gain_0.000123457"),
            (123456.5, "gain_123456"),
            (1e20, "gain_100000000000000000000"),
        ];
        for (g, name) in cases {
            assert_eq!(gain_name(g), name, "{g}");
        }
    }

    /// The smallest file `setting_problem` takes for a whole PNG.
    fn tiny_png() -> Vec<u8> {
        let mut png = PNG_MAGIC.to_vec();
        png.extend([0u8; 60]);
        png.extend(b"\0\0\0\0IEND\xaeB`\x82");
        png
    }

    /// A fresh folder for a test setting, named after `tag`.
    fn problem_dir(tag: &str) -> std::path::PathBuf {
        let dir = std::env::temp_dir().join(format!("blurset-{tag}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        dir
    }

    #[test]
    fn setting_problems_are_named() -> Result<()> {
        let dir = problem_dir("problem");
        let put = |rel: &str, bytes: &[u8]| write_atomic(&dir.join(rel), bytes);
        assert_eq!(
            setting_problem(&dir).as_deref(),
            Some("meta.json is missing")
        );
        put("meta.json", b"[]")?;
        let p = setting_problem(&dir).unwrap_or_default();
        assert!(p.starts_with("meta.json is unreadable"), "{p}");
        put(
            "meta.json",
            br#"{"views": [{}, {}], "levels": ["sharp"], "uid": "x"}"#,
        )?;
        assert_eq!(
            setting_problem(&dir).as_deref(),
            Some("transforms.json is missing")
        );
        put("transforms.json", b"{}")?;
        assert_eq!(
            setting_problem(&dir).as_deref(),
            Some("level folder sharp/ is missing")
        );
        let png = tiny_png();
        put("sharp/images/000.png", &png)?;
        assert_eq!(
            setting_problem(&dir).as_deref(),
            Some("sharp/images holds 1 of 2 images")
        );
        put("sharp/images/001.png", &png[..png.len() - 4])?;
        assert_eq!(
            setting_problem(&dir).as_deref(),
            Some("sharp/images/001.png is truncated")
        );
        put("sharp/images/001.png", &png)?;
        assert_eq!(
            setting_problem(&dir).as_deref(),
            Some("sharp/poses_bounds.npy is missing")
        );
        put("sharp/poses_bounds.npy", &[0u8; 100])?;
        assert_eq!(
            setting_problem(&dir).as_deref(),
            Some("sharp/poses_bounds.npy is truncated")
        );
        put("sharp/poses_bounds.npy", &[0u8; 400])?;
        assert_eq!(setting_problem(&dir), None);
        let _ = std::fs::remove_dir_all(&dir);
        Ok(())
    }

    #[test]
    fn problems_of_copies_and_of_many_files_are_named() -> Result<()> {
        let dir = problem_dir("problems");
        let put = |rel: &str, bytes: &[u8]| write_atomic(&dir.join(rel), bytes);
        let png = tiny_png();
        put("transforms.json", b"{}")?;
        put("sharp/images/000.png", &png)?;
        put("sharp/images/001.png", &png)?;
        put("sharp/poses_bounds.npy", &[0u8; 400])?;
        // A build with `images_<f>/` copies: each must hold every view, whole.
        put(
            "meta.json",
            br#"{"views": [{}, {}], "levels": ["sharp"], "downsample": [4]}"#,
        )?;
        put("sharp/images_4/000.png", &png)?;
        assert_eq!(
            setting_problem(&dir).as_deref(),
            Some("sharp/images_4 holds 1 of 2 images")
        );
        put("sharp/images_4/001.png", &png[..png.len() - 4])?;
        assert_eq!(
            setting_problem(&dir).as_deref(),
            Some("sharp/images_4/001.png is truncated")
        );
        put("sharp/images_4/001.png", &png)?;
        assert_eq!(setting_problem(&dir), None);
        // Every problem is listed (verify names them all), linear EXRs when kept.
        put(
            "meta.json",
            br#"{"views": [{}, {}], "levels": ["sharp", "blur_1"], "render": {"linear": true}}"#,
        )?;
        put("sharp/images/001.png", &png[..png.len() - 4])?;
        put("sharp/linear/000.exr", b"")?;
        let all: Vec<(String, String)> = setting_problems(&dir)
            .into_iter()
            .map(|p| (p.path, p.fault.what()))
            .collect();
        let want = [
            ("sharp/images/001.png", "truncated (no PNG end chunk)"),
            ("sharp/linear", "holds 1 of 2 EXRs"),
            ("sharp/linear/000.exr", "empty"),
            ("blur_1", "level folder missing"),
        ];
        assert_eq!(
            all,
            want.map(|(a, b)| (a.to_string(), b.to_string())).to_vec()
        );
        let _ = std::fs::remove_dir_all(&dir);
        Ok(())
    }

    /// A complete sharp-only setting of two views with linear and depth EXRs.
    fn exr_setting(tag: &str) -> Result<std::path::PathBuf> {
        use crate::image::exr::write::write_exr;
        use crate::image::geometry::{write_depth_exr, Geometry};
        let dir = problem_dir(tag);
        let put = |rel: &str, bytes: &[u8]| write_atomic(&dir.join(rel), bytes);
        put(
            "meta.json",
            br#"{"views": [{}, {}], "levels": ["sharp"], "render": {"linear": true, "passes": ["depth"]}}"#,
        )?;
        put("transforms.json", b"{}")?;
        put("sharp/poses_bounds.npy", &[0u8; 400])?;
        let png = tiny_png();
        let (w, h) = (48usize, 40usize);
        // Varied pixels, so each block is compressed data a flipped byte breaks.
        let px: Vec<f32> = (0..w * h * 4)
            .map(|i| ((i * 7919) % 1013) as f32 / 97.0)
            .collect();
        let g = Geometry {
            width: w,
            height: h,
            depth: px[..w * h].to_vec(),
            normal: Vec::new(),
        };
        for v in ["000", "001"] {
            put(&format!("sharp/images/{v}.png"), &png)?;
            write_exr(
                &dir.join(format!("sharp/linear/{v}.exr")),
                w as u32,
                h as u32,
                &px,
            )?;
            write_depth_exr(&dir.join(format!("sharp/depth/{v}.exr")), &g)?;
        }
        Ok(dir)
    }

    #[test]
    fn a_complete_setting_with_exrs_has_no_problem() -> Result<()> {
        let dir = exr_setting("exrs-whole")?;
        assert_eq!(setting_problems(&dir), vec![]);
        let _ = std::fs::remove_dir_all(&dir);
        Ok(())
    }

    #[test]
    fn exrs_of_a_complete_setting_are_decoded() -> Result<()> {
        let dir = exr_setting("exrs")?;
        let put = |rel: &str, bytes: &[u8]| write_atomic(&dir.join(rel), bytes);
        let read = |rel: &str| std::fs::read(dir.join(rel)).unwrap_or_default();
        let whole_linear = read("sharp/linear/001.exr");
        let whole_depth = read("sharp/depth/000.exr");
        // Cut short (a header and part of its blocks: the file still has a size), and a
        // flipped byte inside a compressed block.
        put(
            "sharp/linear/001.exr",
            &whole_linear[..whole_linear.len() * 2 / 3],
        )?;
        let mut flipped = whole_depth.clone();
        let at = flipped.len() - 40;
        flipped[at] ^= 0x5a;
        put("sharp/depth/000.exr", &flipped)?;
        let found: Vec<(String, &str)> = setting_problems(&dir)
            .into_iter()
            .map(|p| (p.path, p.fault.kind()))
            .collect();
        assert_eq!(
            found,
            vec![
                ("sharp/linear/001.exr".to_string(), "undecodable"),
                ("sharp/depth/000.exr".to_string(), "undecodable"),
            ]
        );
        let said = setting_problem(&dir).unwrap_or_default();
        assert!(
            said.starts_with("sharp/linear/001.exr does not decode ("),
            "{said}"
        );
        let _ = std::fs::remove_dir_all(&dir);
        Ok(())
    }

    #[test]
    fn an_exr_of_another_size_is_named_from_its_header() -> Result<()> {
        let dir = exr_setting("exrs-size")?;
        let put = |rel: &str, bytes: &[u8]| write_atomic(&dir.join(rel), bytes);
        let meta = br#"{"views": [{}, {}], "levels": ["sharp"], "resolution": [48, 40],
            "render": {"linear": true, "passes": ["depth"]}}"#;
        put("meta.json", meta)?;
        // A header that claims 16384² (its blocks cannot hold it): its size is named
        // from the header, nothing of that size decoded.
        let mut big = std::fs::read(dir.join("sharp/linear/001.exr")).unwrap_or_default();
        let name = b"dataWindow\0box2i\0";
        if let Some(i) = big.windows(name.len()).position(|x| x == name) {
            let at = i + name.len() + 4;
            big[at + 8..at + 16].copy_from_slice(&[0xFF, 0x3F, 0, 0, 0xFF, 0x3F, 0, 0]);
        }
        put("sharp/linear/001.exr", &big)?;
        let found: Vec<(String, String)> = setting_problems(&dir)
            .into_iter()
            .filter(|p| p.path.ends_with(".exr"))
            .map(|p| (p.path, p.fault.what()))
            .collect();
        let want = (
            "sharp/linear/001.exr".into(),
            "16384x16384 px, not 48x40".into(),
        );
        assert_eq!(found, vec![want]);
        let _ = std::fs::remove_dir_all(&dir);
        Ok(())
    }

    #[test]
    fn the_files_a_build_writes_in_a_setting() {
        for rel in [
            "meta.json",
            "transforms.json",
            "preview.png",
            "sharp/poses_bounds.npy",
            "blur_4/transforms.json",
            "sharp/images/000.png",
            "blur_1/images_4/007.png",
            "defocus_2/linear/000.exr",
            "sharp/depth_4/000.exr",
            "sharp/normals/000.exr",
            "sharp/masks/000.png",
            "blur_4/masks_4/000.png",
        ] {
            assert!(is_build_file(rel), "{rel}");
        }
        for rel in [
            "mynote.txt",
            "sharp/README",
            "notes/a.txt",
            "blur_0/images/000.png",
            "sharp/images/notes.txt",
            "sharp/images_x/000.png",
            "sharp/images/sub/000.png",
            "sharp/other/000.png",
        ] {
            assert!(!is_build_file(rel), "{rel}");
        }
    }

    #[test]
    fn temp_names_round_trip() {
        let p = temp_path(Path::new("/x/dataset.json"));
        let name = p.file_name().map(|n| n.to_string_lossy().into_owned());
        let parsed = name.as_deref().and_then(parse_temp_name);
        assert_eq!(
            parsed,
            Some(("dataset.json".to_string(), std::process::id()))
        );
        assert_eq!(parse_temp_name(".notes.tmpl"), None);
        assert_eq!(parse_temp_name("a.tmp1"), None);
        assert_eq!(parse_temp_name(".a.b.tmp12"), Some(("a.b".into(), 12)));
    }

    #[test]
    fn complete_means_final_with_marker() -> Result<()> {
        let dir = std::env::temp_dir().join(format!("blurset-layout-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let mk = |p: &Path| std::fs::create_dir_all(p).map_err(|e| Error::io("mkdir", p, e));
        let final_dir = dir.join("a_000");
        let partial = partial_dir(&final_dir);
        assert_eq!(partial, dir.join("a_000.partial"));
        mk(&partial.join(SHARP))?;
        write_atomic(&partial.join(MARKER), b"x")?;
        // A marker inside a .partial directory never counts.
        assert!(!is_complete(&partial));
        std::fs::remove_file(partial.join(MARKER)).map_err(|e| Error::io("rm", &dir, e))?;
        mk(&dir.join("b_000/sharp"))?;
        mk(&dir.join(".work-a"))?;
        mk(&dir.join("notes"))?;
        let s = scan(&dir)?;
        assert_eq!((s.complete.len(), s.incomplete.len()), (0, 2));
        publish(&partial, &final_dir, "2024-01-01T00:00:00")?;
        assert!(is_complete(&final_dir) && !partial.exists());
        assert_eq!(complete_settings(&dir)?, ["a_000"]);
        // Publishing again replaces the older directory.
        mk(&partial)?;
        publish(&partial, &final_dir, "later")?;
        assert!(!final_dir.join(SHARP).exists() && is_complete(&final_dir));
        assert_eq!(setting_levels(&dir.join("b_000"))?, ["sharp"]);
        let _ = std::fs::remove_dir_all(&dir);
        Ok(())
    }
}
