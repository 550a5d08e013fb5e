//! What blurset writes, and what each command may touch (DESIGN §10): the one owner.
//!
//! - Every output names its kind in a record it writes: a build its `dataset.json`, a
//!   noise output its `noise_dataset.json` (a build's levels) or `noise_scene.json` (one
//!   scene), an export its `export.json`, a statistics folder its `stats.json`.
//!   [`output_kind`] recognises an output from that record and nothing else.
//! - [`claim`] says whether a command may write into a folder: a new or empty folder,
//!   or an output of its own kind; an export may also live beside other things (IBRNet's
//!   `data/` holds many datasets). Any other folder is refused by name.
//! - [`owned_entries`] are the entries an output of a kind wrote: the only ones a
//!   re-run or `--overwrite` may replace. A build's are never replaced by another
//!   command.
//! - [`build_state`] says whether a build is finished or provisional (a run writing or
//!   interrupted, files that disagree with each other): readers refuse a provisional
//!   build or say what they skipped.
//! - A file blurset writes among a user's files (a dataset card) carries a mark of its
//!   own content ([`mark_text`]); [`text_owner`] tells an unedited one from one a person
//!   edited or wrote, which is replaced only when asked.
use super::layout::{parse_temp_name, scan, PARTIAL_SUFFIX};
use super::read::{check_shape, read_record, Record};
use crate::error::{Error, Result};
use crate::ground::names::{files, nerfstudio_depth_dir, pass_dir, OBJECT_LOCK_PREFIX, PASSES};
use sha2::{Digest, Sha256};
use std::path::{Path, PathBuf};

/// The kinds of output blurset writes into a folder of their own.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum OutputKind {
    Build,
    Noise,
    NoiseScene,
    Export,
    Stats,
}

impl OutputKind {
    pub const ALL: [OutputKind; 5] = [
        OutputKind::Build,
        OutputKind::Noise,
        OutputKind::NoiseScene,
        OutputKind::Export,
        OutputKind::Stats,
    ];

    /// How messages name the kind.
    pub fn name(self) -> &'static str {
        match self {
            OutputKind::Build => "build",
            OutputKind::Noise => "noise output",
            OutputKind::NoiseScene => "noise output (one scene)",
            OutputKind::Export => "export",
            OutputKind::Stats => "statistics folder",
        }
    }

    /// The record that says what the folder is.
    pub fn record(self) -> Record {
        match self {
            OutputKind::Build => Record::Dataset,
            OutputKind::Noise => Record::NoiseDataset,
            OutputKind::NoiseScene => Record::NoiseScene,
            OutputKind::Export => Record::Export,
            OutputKind::Stats => Record::Stats,
        }
    }

    /// The lock file a writer of this kind holds in the folder (a build's is `.lock`,
    /// shared by every process building into it).
    pub fn lock_name(self) -> &'static str {
        match self {
            OutputKind::Build => ".lock",
            OutputKind::Noise | OutputKind::NoiseScene => ".noise.lock",
            OutputKind::Export => ".export.lock",
            OutputKind::Stats => ".stats.lock",
        }
    }

    /// The `kind` field of the record, for the kinds whose record carries one.
    fn kind_field(self) -> Option<&'static str> {
        match self {
            OutputKind::NoiseScene => Some("blurset noise scene"),
            OutputKind::Export => Some("blurset export"),
            _ => None,
        }
    }

    /// Whether `doc`, the kind's record file, is one blurset wrote: the right shape and,
    /// for the kinds that carry it, the right `kind` (a user's own `dataset.json` or
    /// `stats.json` is not ours).
    fn recognises(self, doc: &serde_json::Value) -> bool {
        if check_shape(doc, self.record()).is_err() {
            return false;
        }
        match self.kind_field() {
            Some(k) => doc.get("kind").and_then(|v| v.as_str()) == Some(k),
            None if self == OutputKind::Build => doc
                .get("name")
                .and_then(|v| v.as_str())
                .is_some_and(|n| n.starts_with("blurset")),
            None => true,
        }
    }

    /// The kind by its `name()`.
    pub fn of_name(name: &str) -> Option<OutputKind> {
        OutputKind::ALL.into_iter().find(|k| k.name() == name)
    }
}

fn list(dir: &Path) -> Result<Vec<(String, PathBuf)>> {
    let rd = std::fs::read_dir(dir).map_err(|e| Error::io("cannot list", dir, e))?;
    let mut v = Vec::new();
    for entry in rd {
        let entry = entry.map_err(|e| Error::io("cannot list", dir, e))?;
        v.push((
            entry.file_name().to_string_lossy().into_owned(),
            entry.path(),
        ));
    }
    v.sort();
    Ok(v)
}

/// A noise output of one scene written before its record existed: every visible entry a
/// `gain_<g>` folder holding a noise.json (or a `gain_<g>.partial` one).
fn legacy_scene_noise(dir: &Path) -> Result<bool> {
    let entries = list(dir)?;
    let visible: Vec<_> = entries
        .iter()
        .filter(|(n, _)| !n.starts_with('.'))
        .collect();
    Ok(!visible.is_empty()
        && visible.iter().all(|(n, p)| {
            n.starts_with("gain_")
                && p.is_dir()
                && (p.join(files::NOISE).is_file() || n.ends_with(PARTIAL_SUFFIX))
        }))
}

/// What blurset output `dir` is, from the record it holds: None for a folder that holds
/// none (new, empty or a user's). Two kinds' records in one folder is an input error.
pub fn output_kind(dir: &Path) -> Result<Option<OutputKind>> {
    if !dir.is_dir() {
        return Ok(None);
    }
    let mut found = Vec::new();
    for kind in OutputKind::ALL {
        let p = dir.join(kind.record().file_name());
        if !p.is_file() {
            continue;
        }
        let doc = std::fs::read(&p)
            .ok()
            .and_then(|t| serde_json::from_slice::<serde_json::Value>(&t).ok());
        if doc.is_some_and(|d| kind.recognises(&d)) {
            found.push(kind);
        }
    }
    match found.as_slice() {
        [] => {
            // A build's first moments: its lock exists before its provisional record.
            if dir.join(OutputKind::Build.lock_name()).exists() {
                return Ok(Some(OutputKind::Build));
            }
            Ok(legacy_scene_noise(dir)?.then_some(OutputKind::NoiseScene))
        }
        [one] => Ok(Some(*one)),
        many => Err(Error::Input {
            reason: format!(
                "holds the records of {} outputs ({})",
                many.len(),
                many.iter()
                    .map(|k| k.record().file_name())
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
            path: dir.into(),
        }),
    }
}

/// What a command may do with the folder it was asked to write into.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Claim {
    /// It does not exist: the command creates it.
    New,
    /// It exists and holds nothing visible (dot files are not counted).
    Empty,
    /// It is an output of the command's own kind: the command may replace its own
    /// entries (a re-run, or `--overwrite`; the caller compares the records).
    Same,
    /// It holds other things and the kind lives beside them (an export): the command
    /// writes its entries and touches nothing else.
    Beside,
}

/// May a command writing an output of `kind` write into `dir`? `option` names the
/// command's option in a refusal. Refused: a file, a dangling link, another kind's
/// output, and (but for an export) a folder holding anything else.
pub fn claim(dir: &Path, kind: OutputKind, option: &str) -> Result<Claim> {
    let refuse = |detail: String| Error::Config {
        option: option.into(),
        detail,
    };
    match std::fs::symlink_metadata(dir) {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Claim::New),
        Err(e) => return Err(Error::io("cannot read", dir, e)),
        Ok(m) if m.file_type().is_symlink() && !dir.exists() => {
            return Err(refuse(format!("is a link to nothing: {}", dir.display())))
        }
        Ok(_) => {}
    }
    if !dir.is_dir() {
        return Err(refuse(format!(
            "exists and is not a directory: {}",
            dir.display()
        )));
    }
    match output_kind(dir)? {
        Some(k) if k == kind => Ok(Claim::Same),
        // The two noise kinds share a command: still not each other's.
        Some(k) => Err(refuse(format!(
            "is a blurset {} ({}), not a {}: {}",
            k.name(),
            k.record().file_name(),
            kind.name(),
            dir.display()
        ))),
        None => {
            let visible = list(dir)?.into_iter().any(|(n, _)| !n.starts_with('.'));
            if !visible {
                Ok(Claim::Empty)
            } else if kind == OutputKind::Export {
                Ok(Claim::Beside)
            } else {
                Err(refuse(format!(
                    "is a folder with other files, not a blurset {}: {} (give a new or \
                     empty folder)",
                    kind.name(),
                    dir.display()
                )))
            }
        }
    }
}

/// The entries (relative paths) an output of `kind` in `dir` wrote: the only ones its
/// re-run or `--overwrite` may remove. Dot-prefixed temp names of a dead process are
/// not listed here (`layout.remove_stale_temps` removes those).
pub fn owned_entries(dir: &Path, kind: OutputKind) -> Result<Vec<String>> {
    let present = |files: &[&str]| -> Vec<String> {
        files
            .iter()
            .filter(|f| dir.join(f).exists())
            .map(|f| f.to_string())
            .collect()
    };
    match kind {
        OutputKind::Build => Err(Error::Input {
            reason: "a build is never replaced by another command".into(),
            path: dir.into(),
        }),
        OutputKind::Noise => {
            let mut out = present(&[
                Record::NoiseDataset.file_name(),
                Record::Splits.file_name(),
                super::manifest::MANIFEST,
            ]);
            out.extend(noise_units(dir)?);
            Ok(out)
        }
        OutputKind::NoiseScene => {
            let mut out = present(&[Record::NoiseScene.file_name()]);
            for (g, gp) in list(dir)? {
                if g.starts_with("gain_") && gp.is_dir() {
                    out.push(g);
                }
            }
            Ok(out)
        }
        OutputKind::Export => {
            let rec = dir.join(Record::Export.file_name());
            if !rec.is_file() {
                return Ok(Vec::new());
            }
            let mut out: Vec<String> = export_entries(&rec)?
                .into_iter()
                .filter(|r| dir.join(r).exists())
                .collect();
            out.extend(present(&[
                "train.txt",
                "test.txt",
                Record::Export.file_name(),
            ]));
            Ok(out)
        }
        // Statistics rewrite their own files in place and never remove any.
        OutputKind::Stats => Ok(Vec::new()),
    }
}

/// A noise output's units, `<setting>/<level>/gain_<g>[.partial]`: nothing else of
/// those folders.
fn noise_units(dir: &Path) -> Result<Vec<String>> {
    let mut out = Vec::new();
    for (s, sp) in list(dir)? {
        if s.starts_with('.') || !sp.is_dir() {
            continue;
        }
        for (l, lp) in list(&sp)? {
            if !lp.is_dir() {
                continue;
            }
            for (g, gp) in list(&lp)? {
                if g.starts_with("gain_") && gp.is_dir() {
                    out.push(format!("{s}/{l}/{g}"));
                }
            }
        }
    }
    Ok(out)
}

/// The scene folders an export's record `rec` names, and the entries a stopped export
/// was about to own (`owns`), sorted, each once; a name that leaves the folder is
/// refused.
fn export_entries(rec: &Path) -> Result<Vec<String>> {
    let doc = read_record(rec, Record::Export)?;
    let refuse = |what: &str, name: &str| Error::Input {
        reason: format!("export.json {what} outside its folder: {name:?}"),
        path: rec.into(),
    };
    let scenes_dir = doc
        .get("scenes_dir")
        .and_then(|v| v.as_str())
        .unwrap_or(".")
        .to_string();
    if scenes_dir != "." && !safe_rel(&scenes_dir) {
        return Err(refuse("has a scenes_dir", &scenes_dir));
    }
    let names: Vec<String> = doc
        .get("scenes")
        .and_then(|v| v.as_object())
        .map(|m| m.keys().cloned().collect())
        .unwrap_or_default();
    let mut rels = Vec::new();
    for n in names {
        if !safe_rel(&n) {
            return Err(refuse("names a scene", &n));
        }
        rels.push(if scenes_dir == "." {
            n
        } else {
            format!("{scenes_dir}/{n}")
        });
    }
    // An export stopped while replacing: the entries it was about to own as well.
    for v in doc
        .get("owns")
        .and_then(|v| v.as_array())
        .into_iter()
        .flatten()
    {
        let rel = v.as_str().unwrap_or_default();
        if !safe_rel(rel) {
            return Err(refuse("owns an entry", rel));
        }
        rels.push(rel.to_string());
    }
    rels.sort();
    rels.dedup();
    Ok(rels)
}

/// A single path component that stays inside its folder.
fn safe_name(n: &str) -> bool {
    !n.is_empty() && n != "." && n != ".." && !n.contains('/') && !n.contains('\\')
}

/// A relative path of such components (`nerf_llff_data/a_000__sharp`).
fn safe_rel(rel: &str) -> bool {
    !rel.is_empty() && rel.split('/').all(safe_name)
}

// -- what an owned entry holds that its command did not write --------------------------

/// What a folder an output of a kind owns may hold: the files at its top, the folders
/// `<base>` / `<base>_<f>` of image files (one per downsampling factor), and whether
/// links are the command's own (an export links its scenes into the build).
struct EntryRule {
    files: Vec<String>,
    folders: Vec<String>,
    links: bool,
}

impl EntryRule {
    /// The rule of a folder entry `name` of `kind`: a noise unit (`gain_<g>`) or an
    /// exported scene; None for an entry that is no such folder (a record, a list).
    fn of(kind: OutputKind, name: &str) -> Option<EntryRule> {
        let s = |v: &[&str]| v.iter().map(|x| x.to_string()).collect::<Vec<_>>();
        match kind {
            OutputKind::Noise | OutputKind::NoiseScene if name.starts_with("gain_") => {
                Some(EntryRule {
                    files: s(&[
                        files::POSES_BOUNDS,
                        files::TRANSFORMS,
                        files::NOISE,
                        super::layout::MARKER,
                    ]),
                    folders: s(&[files::IMAGES, files::LINEAR]),
                    links: false,
                })
            }
            OutputKind::Export => {
                let mut folders = s(&[files::IMAGES]);
                folders.extend(PASSES.iter().map(|p| pass_dir(p, 1)));
                folders.push(nerfstudio_depth_dir(1));
                Some(EntryRule {
                    files: s(&[files::POSES_BOUNDS, files::TRANSFORMS]),
                    folders,
                    links: true,
                })
            }
            _ => None,
        }
    }

    /// `base` or `base_<f>` of one of the rule's folders.
    fn is_folder(&self, name: &str) -> bool {
        self.folders.iter().any(|base| {
            name == base
                || name
                    .strip_prefix(base.as_str())
                    .and_then(|r| r.strip_prefix('_'))
                    .is_some_and(|f| !f.is_empty() && f.bytes().all(|b| b.is_ascii_digit()))
        })
    }
}

enum Shape {
    Link,
    Folder,
    File,
}

/// An image file's name (what the folders of an entry hold).
fn is_image_name(name: &str) -> bool {
    let lower = name.to_ascii_lowercase();
    [".png", ".exr", ".jpg", ".jpeg"]
        .iter()
        .any(|e| lower.ends_with(e))
}

/// The entries (paths relative to `dir`) inside the owned entry `rel` of the output of
/// `kind` in `dir` that no command of that kind writes: what removing `rel` would take
/// with it that is not blurset's (a user's notes in a gain or scene folder). A killed
/// writer's temp names (`.<name>.tmp<pid>`) are the command's own. Empty for a file
/// entry, and for a link where the kind writes links.
pub fn not_written(dir: &Path, kind: OutputKind, rel: &str) -> Result<Vec<String>> {
    let top = dir.join(rel);
    let Ok(meta) = std::fs::symlink_metadata(&top) else {
        return Ok(Vec::new());
    };
    let name = rel.rsplit('/').next().unwrap_or(rel);
    let base = name.strip_suffix(PARTIAL_SUFFIX).unwrap_or(name);
    let rule = EntryRule::of(kind, base);
    if !meta.is_dir() {
        return Ok(match &rule {
            Some(r) if meta.file_type().is_symlink() && !r.links => vec![rel.to_string()],
            _ => Vec::new(),
        });
    }
    let Some(rule) = rule else {
        // A record's or a list's name that is a folder: not one blurset wrote.
        return Ok(vec![rel.to_string()]);
    };
    // What an entry is, never following a link: a link, a real folder or a file.
    let what = |p: &Path| match p.symlink_metadata() {
        Ok(m) if m.file_type().is_symlink() => Shape::Link,
        Ok(m) if m.is_dir() => Shape::Folder,
        _ => Shape::File,
    };
    let mut found = Vec::new();
    for (n, p) in list(&top)? {
        let here = format!("{rel}/{n}");
        let ours = match what(&p) {
            _ if parse_temp_name(&n).is_some() => true,
            Shape::Link => rule.links && (rule.files.contains(&n) || rule.is_folder(&n)),
            Shape::File => rule.files.contains(&n),
            Shape::Folder if rule.is_folder(&n) => {
                for (m, q) in list(&p)? {
                    let image = match what(&q) {
                        Shape::Folder => false,
                        Shape::Link => rule.links && is_image_name(&m),
                        Shape::File => is_image_name(&m),
                    };
                    if !image && parse_temp_name(&m).is_none() {
                        found.push(format!("{here}/{m}"));
                    }
                }
                true
            }
            Shape::Folder => false,
        };
        if !ours {
            found.push(here);
        }
    }
    Ok(found)
}

/// The first entry on the way from `dir` to one of `rels`, each `rel` itself included,
/// that is a link, relative to `dir`. A command writes and removes only in folders it
/// made and never makes a link where it writes: such a link is someone else's, and
/// writing through it would put files anywhere on disk (and let a rerun remove there).
pub fn linked_entry(dir: &Path, rels: &[String]) -> Option<String> {
    let link = |r: &&str| std::fs::symlink_metadata(dir.join(r)).is_ok_and(|m| m.is_symlink());
    let mut ways = rels.iter().flat_map(|rel| {
        let parents = rel.match_indices('/').map(|(i, _)| &rel[..i]);
        parents.chain([rel.as_str()])
    });
    ways.find(link).map(str::to_string)
}

/// Remove the entries `owned_entries` lists (then the folders a noise output's units
/// leave empty): what `--overwrite` does, and nothing else. Returns what was removed.
/// An entry holding a file the command did not write ([`not_written`]) is refused by
/// name before anything is removed.
pub fn remove_owned(dir: &Path, kind: OutputKind) -> Result<Vec<String>> {
    let entries = owned_entries(dir, kind)?;
    for rel in &entries {
        if let Some(first) = not_written(dir, kind, rel)?.first() {
            return Err(Error::Input {
                reason: format!(
                    "holds {first}, which blurset {} did not write and would delete with \
                     {rel}: move it out, then rerun (nothing was removed)",
                    kind.name()
                ),
                path: dir.into(),
            });
        }
    }
    for rel in &entries {
        let p = dir.join(rel);
        crate::ground::atomic::remove_entry(&p)?;
        // A unit's level and setting folders, when nothing else is left in them.
        let mut parent = p.parent();
        while let Some(d) = parent {
            if d == dir || std::fs::remove_dir(d).is_err() {
                break;
            }
            parent = d.parent();
        }
    }
    Ok(entries)
}

// -- is a build finished? ----------------------------------------------------------------

/// A build as its readers see it: its complete settings, and why it is provisional
/// (empty when it is finished: every record agrees with the disk and nothing is running
/// or interrupted).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct BuildState {
    pub complete: Vec<String>,
    pub provisional: Vec<String>,
}

/// Whether `out` is a finished build (see [`BuildState`]). Provisional: no run has
/// finished (`dataset.json` missing or provisional), a setting is being written or was
/// left by a killed run (`*.partial`, an object's `.lock-<uid>`), splits.json or
/// dataset.json disagree with the complete settings on disk.
pub fn build_state(out: &Path) -> Result<BuildState> {
    let s = scan(out)?;
    let mut why = Vec::new();
    let running: Vec<String> = list(out)?
        .into_iter()
        .filter_map(|(n, _)| n.strip_prefix(OBJECT_LOCK_PREFIX).map(String::from))
        .filter(|uid| !uid.is_empty())
        .collect();
    if !running.is_empty() {
        why.push(format!(
            "objects being built, or left by a killed run: {}",
            first(&running)
        ));
    }
    if !s.incomplete.is_empty() {
        why.push(format!("incomplete settings: {}", first(&s.incomplete)));
    }
    let dataset = out.join(Record::Dataset.file_name());
    match read_record(&dataset, Record::Dataset) {
        Err(e) => why.push(short(&e, files::DATASET)),
        Ok(doc) => {
            if doc.get("provisional").and_then(|v| v.as_bool()) == Some(true) {
                why.push("dataset.json is provisional: no run of the build has finished".into());
            } else {
                disagree(
                    files::DATASET,
                    &strings(doc.get("settings")),
                    &s.complete,
                    &mut why,
                );
            }
        }
    }
    let splits = out.join(Record::Splits.file_name());
    match read_record(&splits, Record::Splits) {
        Err(e) => why.push(short(&e, files::SPLITS)),
        Ok(doc) => {
            let mut listed = strings(doc.get("train"));
            listed.extend(strings(doc.get("test")));
            listed.sort();
            disagree(files::SPLITS, &listed, &s.complete, &mut why);
        }
    }
    Ok(BuildState {
        complete: s.complete,
        provisional: why,
    })
}

fn strings(v: Option<&serde_json::Value>) -> Vec<String> {
    let mut out: Vec<String> = v
        .and_then(|v| v.as_array())
        .map(|a| {
            a.iter()
                .filter_map(|x| x.as_str().map(String::from))
                .collect()
        })
        .unwrap_or_default();
    out.sort();
    out
}

/// Why a record that lists settings (`listed`) disagrees with the complete settings on
/// disk, pushed onto `why`.
fn disagree(record: &str, listed: &[String], disk: &[String], why: &mut Vec<String>) {
    let new: Vec<String> = disk
        .iter()
        .filter(|x| !listed.contains(x))
        .cloned()
        .collect();
    let gone: Vec<String> = listed
        .iter()
        .filter(|x| !disk.contains(x))
        .cloned()
        .collect();
    if !new.is_empty() {
        why.push(format!(
            "{record} does not list complete settings: {}",
            first(&new)
        ));
    }
    if !gone.is_empty() {
        why.push(format!(
            "{record} lists settings that are not complete: {}",
            first(&gone)
        ));
    }
}

fn first(names: &[String]) -> String {
    let shown: Vec<&str> = names.iter().take(3).map(String::as_str).collect();
    let more = names.len().saturating_sub(3);
    if more > 0 {
        format!("{} and {more} more", shown.join(", "))
    } else {
        shown.join(", ")
    }
}

fn short(e: &Error, name: &str) -> String {
    match e {
        Error::Input { reason, .. } => reason.clone(),
        _ => format!("{name} is unreadable"),
    }
}

// -- settings whose source file now has another id ----------------------------------------

/// Complete settings of `out` made from one of this build's source files under an id
/// that file no longer has (a name collision that appeared on a rerun: `with_space.glb`,
/// then `with space.glb` beside it, and both get hashed ids). `current` holds (uid,
/// source path as meta.json records it) of every object of the build. Returned:
/// (setting, its source path, the source's id now).
pub fn superseded_settings(
    out: &Path,
    current: &[(String, String)],
) -> Result<Vec<(String, String, String)>> {
    let mut found = Vec::new();
    for name in scan(out)?.complete {
        let meta = out.join(&name).join(Record::Meta.file_name());
        // A setting whose meta.json does not read is redone by its object's run.
        let Ok(doc) = read_record(&meta, Record::Meta) else {
            continue;
        };
        let uid = doc.get("uid").and_then(|v| v.as_str()).unwrap_or_default();
        let path = doc
            .get("object")
            .and_then(|o| o.get("path"))
            .and_then(|v| v.as_str())
            .unwrap_or_default();
        if path.is_empty() || current.iter().any(|(u, _)| u == uid) {
            continue;
        }
        if let Some((now, _)) = current.iter().find(|(_, p)| p == path) {
            found.push((name, path.to_string(), now.clone()));
        }
    }
    Ok(found)
}

// -- files blurset writes among a user's files ----------------------------------------------

const MARK_OPEN: &str = "<!-- written by blurset ";
const MARK_SHA: &str = "; sha256 ";

/// `text` with a last line that marks it as written by `command` and holds the sha256
/// of everything before it: a later run tells an unedited file from an edited one.
pub fn mark_text(text: &str, command: &str) -> String {
    let body = if text.ends_with('\n') {
        text.to_string()
    } else {
        format!("{text}\n")
    };
    let digest = hex(&Sha256::digest(body.as_bytes()));
    format!("{body}{MARK_OPEN}{command}{MARK_SHA}{digest} -->\n")
}

/// Who a text file at `path` belongs to.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TextOwner {
    /// No such file.
    Absent,
    /// Written by this command and unchanged since.
    Ours,
    /// Written by this command, then edited.
    Edited,
    /// Not written by this command.
    Foreign,
}

/// Whether the file at `path` is one `command` wrote with [`mark_text`], unedited.
pub fn text_owner(path: &Path, command: &str) -> Result<TextOwner> {
    let bytes = match std::fs::read(path) {
        Ok(b) => b,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(TextOwner::Absent),
        Err(e) => return Err(Error::io("cannot read", path, e)),
    };
    let Ok(text) = std::str::from_utf8(&bytes) else {
        return Ok(TextOwner::Foreign);
    };
    // The last mark line; text added after it is an edit as much as a changed body.
    let at = if text.starts_with(MARK_OPEN) {
        Some(0)
    } else {
        text.rfind(&format!("\n{MARK_OPEN}")).map(|i| i + 1)
    };
    let Some(at) = at else {
        return Ok(TextOwner::Foreign);
    };
    let (body, rest) = text.split_at(at);
    let (line, after) = rest.split_once('\n').unwrap_or((rest, ""));
    let Some((cmd, digest)) = line
        .strip_prefix(MARK_OPEN)
        .and_then(|r| r.strip_suffix(" -->"))
        .and_then(|r| r.split_once(MARK_SHA))
    else {
        return Ok(TextOwner::Foreign);
    };
    if cmd != command {
        return Ok(TextOwner::Foreign);
    }
    Ok(
        if after.trim().is_empty() && hex(&Sha256::digest(body.as_bytes())) == digest {
            TextOwner::Ours
        } else {
            TextOwner::Edited
        },
    )
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

#[allow(clippy::unwrap_used)] // a failing unwrap is a failing test
#[cfg(test)]
mod tests {
    use super::*;

    fn tmp(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("blurset-outputs-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        d
    }

    fn write(p: &Path, text: &str) {
        if let Some(d) = p.parent() {
            std::fs::create_dir_all(d).expect("mkdir");
        }
        std::fs::write(p, text).expect("write");
    }

    #[test]
    fn kinds_come_from_their_records_only() -> Result<()> {
        let d = tmp("kinds");
        std::fs::create_dir_all(&d).map_err(|e| Error::io("mkdir", &d, e))?;
        assert_eq!(output_kind(&d)?, None);
        assert_eq!(claim(&d, OutputKind::Noise, "--out")?, Claim::Empty);
        // A user's own dataset.json is not a build.
        write(&d.join("dataset.json"), r#"{"images": 3}"#);
        assert_eq!(output_kind(&d)?, None);
        let e = claim(&d, OutputKind::Noise, "--out")
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("--out is a folder with other files"), "{e}");
        assert_eq!(claim(&d, OutputKind::Export, "--out")?, Claim::Beside);
        write(
            &d.join("dataset.json"),
            r#"{"name": "blurset Objaverse-Blur", "config": {}, "provisional": true}"#,
        );
        assert_eq!(output_kind(&d)?, Some(OutputKind::Build));
        for kind in [OutputKind::Noise, OutputKind::Export, OutputKind::Stats] {
            let e = claim(&d, kind, "--out").unwrap_err().to_string();
            assert!(
                e.starts_with("--out is a blurset build (dataset.json)"),
                "{e}"
            );
        }
        write(&d.join("export.json"), r#"{"kind": "blurset export"}"#);
        assert!(output_kind(&d).is_err());
        let _ = std::fs::remove_dir_all(&d);
        Ok(())
    }

    #[test]
    fn an_export_owns_only_what_its_record_names() -> Result<()> {
        let d = tmp("export");
        write(
            &d.join("export.json"),
            r#"{"kind": "blurset export", "scenes_dir": "nerf_llff_data",
                "scenes": {"a_000__sharp": "a_000/sharp"}, "owns": ["nerf_llff_data/b_000__sharp"]}"#,
        );
        write(&d.join("nerf_llff_data/a_000__sharp/poses_bounds.npy"), "x");
        write(&d.join("nerf_llff_data/fern/poses_bounds.npy"), "keep");
        write(&d.join("model.pth"), "keep");
        write(&d.join("train.txt"), "a_000__sharp\n");
        let owned = owned_entries(&d, OutputKind::Export)?;
        assert_eq!(
            owned,
            ["nerf_llff_data/a_000__sharp", "train.txt", "export.json"]
        );
        remove_owned(&d, OutputKind::Export)?;
        assert!(d.join("nerf_llff_data/fern/poses_bounds.npy").is_file());
        assert!(d.join("model.pth").is_file());
        assert!(!d.join("export.json").exists());
        write(
            &d.join("export.json"),
            r#"{"kind": "blurset export", "scenes_dir": "nerf_llff_data", "scenes": {"..": "x"}}"#,
        );
        assert!(owned_entries(&d, OutputKind::Export).is_err());
        write(
            &d.join("export.json"),
            r#"{"kind": "blurset export", "scenes_dir": "../..", "scenes": {"a": "x"}}"#,
        );
        assert!(owned_entries(&d, OutputKind::Export).is_err());
        write(
            &d.join("export.json"),
            r#"{"kind": "blurset export", "scenes": {}, "owns": ["nerf_llff_data/../../x"]}"#,
        );
        assert!(owned_entries(&d, OutputKind::Export).is_err());
        let _ = std::fs::remove_dir_all(&d);
        Ok(())
    }

    #[test]
    fn noise_overwrite_keeps_what_it_did_not_write() -> Result<()> {
        let d = tmp("noise");
        write(
            &d.join("noise_dataset.json"),
            r#"{"build": "b", "params": {}}"#,
        );
        write(&d.join("a_000/sharp/gain_1/noise.json"), "{}");
        write(&d.join("a_000/notes.txt"), "mine");
        write(&d.join("thesis.tex"), "mine");
        assert_eq!(output_kind(&d)?, Some(OutputKind::Noise));
        remove_owned(&d, OutputKind::Noise)?;
        assert!(d.join("a_000/notes.txt").is_file() && d.join("thesis.tex").is_file());
        assert!(!d.join("a_000/sharp").exists());
        let _ = std::fs::remove_dir_all(&d);
        Ok(())
    }

    #[test]
    fn noise_owns_only_its_gain_folders_a_users_folder_inside_a_level_is_kept() -> Result<()> {
        // A build's noise output: the gain folders are its units; a folder of the
        // user's beside them (inside a level) is not, and --overwrite keeps it.
        let d = tmp("noise-level");
        write(
            &d.join("noise_dataset.json"),
            r#"{"build": "b", "params": {}}"#,
        );
        write(&d.join("a_000/blur_3/gain_4/noise.json"), "{}");
        write(&d.join("a_000/blur_3/gain_8.partial/images/000.png"), "x");
        write(&d.join("a_000/blur_3/my_notes/n.txt"), "mine");
        write(&d.join("a_000/blur_3/gain_notes.txt"), "mine");
        let owned = owned_entries(&d, OutputKind::Noise)?;
        assert_eq!(
            owned,
            [
                "noise_dataset.json",
                "a_000/blur_3/gain_4",
                "a_000/blur_3/gain_8.partial"
            ]
        );
        remove_owned(&d, OutputKind::Noise)?;
        assert_eq!(
            std::fs::read_to_string(d.join("a_000/blur_3/my_notes/n.txt")).ok(),
            Some("mine".into())
        );
        assert!(d.join("a_000/blur_3/gain_notes.txt").is_file());
        assert!(!d.join("a_000/blur_3/gain_4").exists());
        // One noisy scene: likewise at its top.
        let s = tmp("noise-scene-level");
        write(
            &s.join("noise_scene.json"),
            r#"{"kind": "blurset noise", "gains": []}"#,
        );
        write(&s.join("gain_2/noise.json"), "{}");
        write(&s.join("images/mine.png"), "mine");
        assert_eq!(
            owned_entries(&s, OutputKind::NoiseScene)?,
            ["noise_scene.json", "gain_2"]
        );
        let _ = std::fs::remove_dir_all(&d);
        let _ = std::fs::remove_dir_all(&s);
        Ok(())
    }

    #[test]
    fn overwrite_refuses_a_unit_holding_a_file_noise_did_not_write() -> Result<()> {
        let d = tmp("noise-foreign");
        write(
            &d.join("noise_dataset.json"),
            r#"{"build": "b", "params": {}}"#,
        );
        let unit = d.join("a_000/blur_4/gain_1");
        for f in [
            "noise.json",
            ".complete",
            "poses_bounds.npy",
            "images/000.png",
        ] {
            write(&unit.join(f), "x");
        }
        write(&unit.join("linear_2/000.exr"), "x");
        write(&unit.join("images/.001.png.tmp99"), "a killed writer's");
        assert_eq!(
            not_written(&d, OutputKind::Noise, "a_000/blur_4/gain_1")?,
            Vec::<String>::new()
        );
        write(&unit.join("mynote.txt"), "mine");
        write(&unit.join("images/mine.txt"), "mine");
        write(&unit.join("depth/000.exr"), "not noise's");
        assert_eq!(
            not_written(&d, OutputKind::Noise, "a_000/blur_4/gain_1")?,
            [
                "a_000/blur_4/gain_1/depth",
                "a_000/blur_4/gain_1/images/mine.txt",
                "a_000/blur_4/gain_1/mynote.txt"
            ]
        );
        let e = remove_owned(&d, OutputKind::Noise).unwrap_err().to_string();
        assert!(
            e.contains("holds a_000/blur_4/gain_1/depth, which blurset noise output did not"),
            "{e}"
        );
        // Nothing removed, the records neither.
        assert!(unit.join("mynote.txt").is_file() && d.join("noise_dataset.json").is_file());
        // One scene's gains, likewise.
        let s = tmp("noise-scene-foreign");
        write(&s.join("noise_scene.json"), "{}");
        write(&s.join("gain_2/noise.json"), "{}");
        write(&s.join("gain_2/README"), "mine");
        assert_eq!(
            not_written(&s, OutputKind::NoiseScene, "gain_2")?,
            ["gain_2/README"]
        );
        assert!(remove_owned(&s, OutputKind::NoiseScene).is_err());
        assert!(s.join("gain_2/README").is_file());
        let _ = std::fs::remove_dir_all(&d);
        let _ = std::fs::remove_dir_all(&s);
        Ok(())
    }

    #[cfg(unix)]
    #[test]
    fn the_first_link_on_the_way_to_an_entry_is_named() {
        let d = tmp("linked");
        write(&d.join("user/sharp/x"), "mine");
        write(&d.join("out/nerf_llff_data/a/poses_bounds.npy"), "x");
        std::os::unix::fs::symlink(d.join("user"), d.join("out/data")).expect("link");
        let out = d.join("out");
        let rels = |v: &[&str]| v.iter().map(|r| r.to_string()).collect::<Vec<_>>();
        // A real folder's entries, and names not written yet: no link on their way.
        let real = rels(&["nerf_llff_data/a/images", "train.txt", "new/b"]);
        assert_eq!(linked_entry(&out, &real), None);
        // The link itself, an entry past it, and one of several.
        for rel in ["data", "data/sharp/train-0.parquet", "data/new/x"] {
            let many = rels(&["train.txt", rel]);
            assert_eq!(linked_entry(&out, &many).as_deref(), Some("data"), "{rel}");
        }
        let _ = std::fs::remove_dir_all(&d);
    }

    #[test]
    fn an_exported_scene_owns_its_pass_folders_and_links() -> Result<()> {
        let d = tmp("export-foreign");
        let scene = d.join("a_000__sharp");
        write(&scene.join("poses_bounds.npy"), "x");
        write(&scene.join("depths_4/000.png"), "x");
        write(&scene.join("masks/000.png"), "x");
        write(&d.join("build/depth/000.exr"), "x");
        #[cfg(unix)]
        {
            let link = |to: &str, at: &str| {
                std::os::unix::fs::symlink(d.join(to), scene.join(at)).expect("link")
            };
            link("build/depth", "depth");
            link("build/depth", "normals_4");
            link("build/depth/000.exr", "images");
        }
        assert_eq!(
            not_written(&d, OutputKind::Export, "a_000__sharp")?,
            Vec::<String>::new()
        );
        write(&scene.join("notes.txt"), "mine");
        write(&scene.join("depths/notes.txt"), "mine");
        assert_eq!(
            not_written(&d, OutputKind::Export, "a_000__sharp")?,
            ["a_000__sharp/depths/notes.txt", "a_000__sharp/notes.txt"]
        );
        let _ = std::fs::remove_dir_all(&d);
        Ok(())
    }

    fn setting(d: &Path, name: &str, uid: &str, source: &str) {
        write(
            &d.join(name).join("meta.json"),
            &format!(
                r#"{{"uid": "{uid}", "theta0_deg": 0.0, "resolution": [8, 8], "levels": ["sharp"],
                    "views": [], "object": {{"path": "{source}"}}}}"#
            ),
        );
        write(&d.join(name).join(".complete"), "x");
    }

    #[test]
    fn a_build_is_finished_only_when_its_records_agree_with_the_disk() -> Result<()> {
        let d = tmp("state");
        setting(&d, "a_000", "a", "a.glb");
        setting(&d, "b_000", "b", "b.glb");
        write(
            &d.join("dataset.json"),
            r#"{"name": "blurset Objaverse-Blur", "config": {}, "settings": ["a_000", "b_000"]}"#,
        );
        write(
            &d.join("splits.json"),
            r#"{"view_stride": 16, "train": ["a_000"], "test": ["b_000"], "test_views": {}}"#,
        );
        assert_eq!(build_state(&d)?.provisional, Vec::<String>::new());
        setting(&d, "c_000", "c", "c.glb");
        let why = build_state(&d)?.provisional;
        assert_eq!(why.len(), 2, "{why:?}");
        assert!(why[1].starts_with("splits.json does not list complete settings: c_000"));
        std::fs::remove_dir_all(d.join("c_000")).map_err(|e| Error::io("rm", &d, e))?;
        write(&d.join(".lock-c"), "pid 1");
        std::fs::create_dir_all(d.join("c_000.partial")).map_err(|e| Error::io("mk", &d, e))?;
        let why = build_state(&d)?.provisional;
        assert!(
            why[0].contains("killed run: c") && why[1].contains("c_000.partial"),
            "{why:?}"
        );
        let _ = std::fs::remove_dir_all(&d);
        Ok(())
    }

    #[test]
    fn a_source_that_changed_id_supersedes_its_old_settings() -> Result<()> {
        let d = tmp("superseded");
        setting(&d, "with_space_000", "with_space", "with_space.glb");
        setting(&d, "other_000", "other", "elsewhere/other.glb");
        let now = [
            ("with_space_1a2b".to_string(), "with_space.glb".to_string()),
            ("with_space_3c4d".to_string(), "with space.glb".to_string()),
        ];
        let found = superseded_settings(&d, &now)?;
        assert_eq!(
            found,
            [(
                "with_space_000".to_string(),
                "with_space.glb".to_string(),
                "with_space_1a2b".to_string()
            )]
        );
        let _ = std::fs::remove_dir_all(&d);
        Ok(())
    }

    #[test]
    fn a_marked_text_knows_when_it_was_edited() -> Result<()> {
        let d = tmp("mark");
        std::fs::create_dir_all(&d).map_err(|e| Error::io("mkdir", &d, e))?;
        let p = d.join("README.md");
        assert_eq!(text_owner(&p, "card")?, TextOwner::Absent);
        std::fs::write(&p, mark_text("# card\nbody", "card")).map_err(|e| Error::io("w", &p, e))?;
        assert_eq!(text_owner(&p, "card")?, TextOwner::Ours);
        assert_eq!(text_owner(&p, "stats")?, TextOwner::Foreign);
        let edited = std::fs::read_to_string(&p)
            .map_err(|e| Error::io("r", &p, e))?
            .replace("body", "my notes");
        std::fs::write(&p, edited).map_err(|e| Error::io("w", &p, e))?;
        assert_eq!(text_owner(&p, "card")?, TextOwner::Edited);
        let appended = format!("{}more notes\n", mark_text("# card\nbody", "card"));
        std::fs::write(&p, appended).map_err(|e| Error::io("w", &p, e))?;
        assert_eq!(text_owner(&p, "card")?, TextOwner::Edited);
        std::fs::write(&p, "# my own README\n").map_err(|e| Error::io("w", &p, e))?;
        assert_eq!(text_owner(&p, "card")?, TextOwner::Foreign);
        let _ = std::fs::remove_dir_all(&d);
        Ok(())
    }
}
