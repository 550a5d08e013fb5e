//! `MANIFEST.sha256`: the checksum of every file a build (or a noise output) publishes,
//! in `sha256sum` format, so `sha256sum -c MANIFEST.sha256` run inside it proves it
//! arrived whole.
//!
//! What is listed is decided here and nowhere else (`is_listed`): every regular file
//! under the root, except the manifest itself, anything whose path has a component
//! starting with `.` (the `.lock`, the `.complete` markers, temp files of atomic writes,
//! `.work-*` scratch, `.local/` with the builder's own paths) and `*.partial` staging
//! directories (another shard may be writing one right now); inside a build's setting,
//! only the files a build writes there (`layout::is_build_file`: a user's note kept in a
//! redone setting is not the build's to certify).
//!
//! A rerun certifies only what it wrote or checked (`rewrite_manifest`): a file the
//! existing manifest lists keeps its line unless the run wrote it, so damage since (bit
//! rot, a file copied over another) stays a mismatch for `blurset verify` instead of
//! being hashed anew; what a rerun reuses is checked against those lines first
//! (`manifest_mismatches`), and redone when it differs.
use super::layout::{is_build_file, is_gain_dir, is_noise_gain_file};
use crate::error::{Error, Result};
use crate::ground::atomic::write_atomic;
use crate::ground::names::files;
use rayon::prelude::*;
use sha2::{Digest, Sha256};
use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::io::Read;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

/// The manifest's file name, at the root of what it lists.
pub const MANIFEST: &str = "MANIFEST.sha256";

const PARTIAL_SUFFIX: &str = ".partial";

/// Whether a file at `rel` ('/'-separated, relative to the root) belongs in the manifest.
pub fn is_listed(rel: &str) -> bool {
    if rel == MANIFEST || rel.is_empty() {
        return false;
    }
    let parts: Vec<&str> = rel.split('/').collect();
    let (dirs, _) = parts.split_at(parts.len() - 1);
    !parts.iter().any(|p| p.is_empty() || p.starts_with('.'))
        && !dirs.iter().any(|d| d.ends_with(PARTIAL_SUFFIX))
}

/// Every file the manifest of `root` lists: relative, '/'-separated, sorted bytewise
/// (the order of `LC_ALL=C sort`). Symlinked files are listed (sha256sum follows them);
/// symlinked directories are not entered.
pub fn list_files(root: &Path) -> Result<Vec<String>> {
    let mut out = Vec::new();
    walk(root, "", &mut out)?;
    let settings = setting_dirs(root);
    out.retain(|rel| in_setting_rule(rel, &settings));
    out.sort_unstable_by(|a, b| a.as_bytes().cmp(b.as_bytes()));
    Ok(out)
}

/// The settings of a build at `root`: its top folders holding a meta.json (a noise
/// output's folders hold none).
fn setting_dirs(root: &Path) -> BTreeSet<String> {
    let Ok(rd) = std::fs::read_dir(root) else {
        return BTreeSet::new();
    };
    rd.filter_map(|e| e.ok())
        .filter(|e| e.path().join(files::META).is_file())
        .filter_map(|e| e.file_name().to_str().map(str::to_owned))
        .collect()
}

/// Whether `rel` passes the setting rule: inside a setting only what a build writes,
/// inside a noise unit's gain folder only what noise writes, elsewhere anything listable.
fn in_setting_rule(rel: &str, settings: &BTreeSet<String>) -> bool {
    match rel.split_once('/') {
        Some((top, rest)) if settings.contains(top) => is_build_file(rest),
        _ => in_gain_rule(rel),
    }
}

/// Below a `gain_<g>` folder (a noise output's unit), only the files noise writes there.
fn in_gain_rule(rel: &str) -> bool {
    let mut at = 0;
    for part in rel.split('/') {
        at += part.len() + 1;
        if is_gain_dir(part) && at < rel.len() {
            return is_noise_gain_file(&rel[at..]);
        }
    }
    true
}

fn walk(dir: &Path, prefix: &str, out: &mut Vec<String>) -> Result<()> {
    let entries = std::fs::read_dir(dir).map_err(|e| Error::io("cannot list", dir, e))?;
    for entry in entries {
        let entry = entry.map_err(|e| Error::io("cannot list", dir, e))?;
        let name = entry.file_name();
        let Some(name) = name.to_str() else {
            return Err(Error::Input {
                reason: "file name is not UTF-8 (a manifest cannot name it)".into(),
                path: entry.path(),
            });
        };
        let rel = if prefix.is_empty() {
            name.to_string()
        } else {
            format!("{prefix}/{name}")
        };
        if name.starts_with('.') {
            continue;
        }
        let path = entry.path();
        let ft = entry
            .file_type()
            .map_err(|e| Error::io("cannot stat", &path, e))?;
        if ft.is_dir() {
            if !name.ends_with(PARTIAL_SUFFIX) {
                walk(&path, &rel, out)?;
            }
        } else if (ft.is_file() || (ft.is_symlink() && path.is_file())) && is_listed(&rel) {
            out.push(rel);
        }
    }
    Ok(())
}

/// sha256 of a file's bytes, lowercase hex.
pub fn sha256_file(path: &Path) -> Result<String> {
    let mut f = std::fs::File::open(path).map_err(|e| Error::io("cannot open", path, e))?;
    let mut hasher = Sha256::new();
    let mut buf = vec![0u8; 1 << 20];
    loop {
        let n = f
            .read(&mut buf)
            .map_err(|e| Error::io("cannot read", path, e))?;
        if n == 0 {
            break;
        }
        hasher.update(&buf[..n]);
    }
    Ok(hex(&hasher.finalize()))
}

fn hex(bytes: &[u8]) -> String {
    const DIGITS: &[u8; 16] = b"0123456789abcdef";
    let mut s = String::with_capacity(bytes.len() * 2);
    for b in bytes {
        s.push(DIGITS[(b >> 4) as usize] as char);
        s.push(DIGITS[(b & 15) as usize] as char);
    }
    s
}

/// The sha256 of each file (`root`/`rel`), hashed in parallel, in the order given.
pub fn hash_files(root: &Path, rels: &[String]) -> Result<Vec<String>> {
    rels.par_iter()
        .map(|rel| sha256_file(&root.join(rel)))
        .collect()
}

/// One `sha256sum` line. A name holding a backslash or a newline is escaped as GNU
/// coreutils does: the line starts with `\`, and `\` and newline become `\\` and `\n`.
fn line(digest: &str, rel: &str) -> String {
    if rel.contains(['\\', '\n']) {
        let escaped = rel.replace('\\', "\\\\").replace('\n', "\\n");
        format!("\\{digest}  {escaped}\n")
    } else {
        format!("{digest}  {rel}\n")
    }
}

fn render(entries: &BTreeMap<Vec<u8>, (String, String)>) -> String {
    entries.values().map(|(rel, d)| line(d, rel)).collect()
}

/// Hash every listed file of `root` and write `root/MANIFEST.sha256` atomically;
/// returns the number of files listed.
pub fn write_manifest(root: &Path) -> Result<usize> {
    let rels = list_files(root)?;
    let digests = hash_files(root, &rels)?;
    let entries: BTreeMap<Vec<u8>, (String, String)> = rels
        .into_iter()
        .zip(digests)
        .map(|(r, d)| (r.as_bytes().to_vec(), (r, d)))
        .collect();
    write_atomic(&root.join(MANIFEST), render(&entries).as_bytes())?;
    Ok(entries.len())
}

/// Parse a manifest's text into (relative path, digest) pairs, in file order.
pub fn parse_manifest(text: &str, path: &Path) -> Result<Vec<(String, String)>> {
    let mut out = Vec::new();
    for (n, raw) in text.lines().enumerate() {
        if raw.is_empty() {
            continue;
        }
        let bad = || Error::Input {
            reason: format!(
                "line {} is not `<sha256>  <path>`: {:?}",
                n + 1,
                raw.chars().take(80).collect::<String>()
            ),
            path: path.to_path_buf(),
        };
        let (escaped, body) = match raw.strip_prefix('\\') {
            Some(rest) => (true, rest),
            None => (false, raw),
        };
        if body.len() < 66 || !body.is_char_boundary(64) {
            return Err(bad());
        }
        let (digest, rest) = body.split_at(64);
        if !digest.bytes().all(|c| c.is_ascii_hexdigit()) {
            return Err(bad());
        }
        let name = rest
            .strip_prefix("  ")
            .or_else(|| rest.strip_prefix(" *"))
            .ok_or_else(bad)?;
        let name = if escaped {
            unescape(name).ok_or_else(bad)?
        } else {
            name.to_string()
        };
        out.push((name, digest.to_ascii_lowercase()));
    }
    Ok(out)
}

fn unescape(s: &str) -> Option<String> {
    let mut out = String::with_capacity(s.len());
    let mut chars = s.chars();
    while let Some(c) = chars.next() {
        if c == '\\' {
            match chars.next()? {
                '\\' => out.push('\\'),
                'n' => out.push('\n'),
                _ => return None,
            }
        } else {
            out.push(c);
        }
    }
    Some(out)
}

/// What is wrong with one file against the manifest.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum ManifestProblem {
    /// Listed, but not there.
    Missing,
    /// Listed, there, with other bytes.
    Mismatch,
    /// There and listable, but not listed (added after the manifest was written).
    Unlisted,
}

impl ManifestProblem {
    /// The kind's name, as the bindings give it.
    pub fn kind(&self) -> &'static str {
        match self {
            ManifestProblem::Missing => "missing",
            ManifestProblem::Mismatch => "mismatch",
            ManifestProblem::Unlisted => "unlisted",
        }
    }

    /// What is wrong, in words.
    pub fn as_str(&self) -> &'static str {
        match self {
            ManifestProblem::Missing => "missing",
            ManifestProblem::Mismatch => "checksum mismatch",
            ManifestProblem::Unlisted => "not in MANIFEST.sha256",
        }
    }
}

/// Check `root` against its manifest: every listed file hashed (in parallel) and
/// compared, and the files on disk the manifest does not list. Sorted by path.
pub fn check_manifest(root: &Path) -> Result<Vec<(String, ManifestProblem)>> {
    let path = root.join(MANIFEST);
    let text = std::fs::read_to_string(&path).map_err(|e| Error::io("cannot read", &path, e))?;
    let listed = parse_manifest(&text, &path)?;
    let results: Vec<Option<ManifestProblem>> = listed
        .par_iter()
        .map(|(rel, digest)| {
            let file = root.join(rel);
            if !file.is_file() {
                return Some(ManifestProblem::Missing);
            }
            match sha256_file(&file) {
                Ok(d) if &d == digest => None,
                _ => Some(ManifestProblem::Mismatch),
            }
        })
        .collect();
    let mut problems: Vec<(String, ManifestProblem)> = listed
        .iter()
        .zip(results)
        .filter_map(|((rel, _), p)| p.map(|p| (rel.clone(), p)))
        .collect();
    let names: BTreeSet<&str> = listed.iter().map(|(r, _)| r.as_str()).collect();
    for rel in list_files(root)? {
        if !names.contains(rel.as_str()) {
            problems.push((rel, ManifestProblem::Unlisted));
        }
    }
    problems.sort_by(|a, b| a.0.as_bytes().cmp(b.0.as_bytes()));
    Ok(problems)
}

/// Rehash the given files (relative paths) into an existing manifest, adding or
/// replacing their lines and dropping those no longer on disk, without rehashing the
/// rest; returns the number of files listed. Files `is_listed` refuses are ignored.
pub fn update_manifest(root: &Path, rels: &[String]) -> Result<usize> {
    let path = root.join(MANIFEST);
    let text = std::fs::read_to_string(&path).map_err(|e| Error::io("cannot read", &path, e))?;
    let mut entries: BTreeMap<Vec<u8>, (String, String)> = parse_manifest(&text, &path)?
        .into_iter()
        .map(|(r, d)| (r.as_bytes().to_vec(), (r, d)))
        .collect();
    let wanted: Vec<String> = rels.iter().filter(|r| is_listed(r)).cloned().collect();
    let (present, gone): (Vec<String>, Vec<String>) =
        wanted.into_iter().partition(|r| root.join(r).is_file());
    for r in gone {
        entries.remove(r.as_bytes());
    }
    let digests = hash_files(root, &present)?;
    for (r, d) in present.into_iter().zip(digests) {
        entries.insert(r.as_bytes().to_vec(), (r, d));
    }
    write_atomic(&path, render(&entries).as_bytes())?;
    Ok(entries.len())
}

/// A manifest's lines grouped by their first path component (a setting, or a noise
/// output's setting), parsed once per process and version of the file: a rerun checks
/// each setting it reuses against it.
type Grouped = Arc<HashMap<String, Vec<(String, String)>>>;

struct Cached {
    path: PathBuf,
    stamp: (u64, u64, std::time::SystemTime),
    lines: Grouped,
}

static PARSED: Mutex<Option<Cached>> = Mutex::new(None);

/// The lines of `root`'s manifest by first component, or None when it has none.
fn grouped_lines(root: &Path) -> Result<Option<Grouped>> {
    use std::os::unix::fs::MetadataExt;
    let path = root.join(MANIFEST);
    let meta = match std::fs::metadata(&path) {
        Ok(m) if m.is_file() => m,
        Ok(_) => return Ok(None),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(Error::io("cannot stat", &path, e)),
    };
    let modified = meta
        .modified()
        .map_err(|e| Error::io("cannot stat", &path, e))?;
    let stamp = (meta.ino(), meta.len(), modified);
    let mut cache = PARSED.lock().unwrap_or_else(|p| p.into_inner());
    if let Some(c) = cache
        .as_ref()
        .filter(|c| c.path == path && c.stamp == stamp)
    {
        return Ok(Some(c.lines.clone()));
    }
    let text = std::fs::read_to_string(&path).map_err(|e| Error::io("cannot read", &path, e))?;
    let mut by_top: HashMap<String, Vec<(String, String)>> = HashMap::new();
    for (rel, digest) in parse_manifest(&text, &path)? {
        let top = rel.split('/').next().unwrap_or_default().to_string();
        by_top.entry(top).or_default().push((rel, digest));
    }
    let lines = Arc::new(by_top);
    *cache = Some(Cached {
        path,
        stamp,
        lines: lines.clone(),
    });
    Ok(Some(lines))
}

/// The files `root`'s manifest lists under the folder `dir` (relative, '/'-separated)
/// that are gone or hold other bytes than it lists, hashed in parallel, sorted by path;
/// none without a manifest. A rerun redoes such a setting or noise unit rather than
/// certify what it did not write.
pub fn manifest_mismatches(root: &Path, dir: &str) -> Result<Vec<(String, ManifestProblem)>> {
    let Some(lines) = grouped_lines(root)? else {
        return Ok(Vec::new());
    };
    let top = dir.split('/').next().unwrap_or_default();
    let under = format!("{}/", dir.trim_end_matches('/'));
    let listed: Vec<&(String, String)> = lines
        .get(top)
        .map(|v| v.iter().filter(|(r, _)| r.starts_with(&under)).collect())
        .unwrap_or_default();
    let found: Vec<Option<(String, ManifestProblem)>> = listed
        .par_iter()
        .map(|(rel, digest)| {
            let file = root.join(rel);
            let problem = if !file.is_file() {
                Some(ManifestProblem::Missing)
            } else {
                match sha256_file(&file) {
                    Ok(d) if &d == digest => None,
                    _ => Some(ManifestProblem::Mismatch),
                }
            };
            problem.map(|p| (rel.clone(), p))
        })
        .collect();
    let mut out: Vec<(String, ManifestProblem)> = found.into_iter().flatten().collect();
    out.sort_by(|a, b| a.0.as_bytes().cmp(b.0.as_bytes()));
    Ok(out)
}

/// Write `root`'s manifest at the end of a run that vouches for `vouched` (relative
/// files or folders; a folder stands for everything under it, removed ones included):
/// what the run wrote, and what it reused after checking it (a complete setting decoded
/// and matched against the old lines). Those are hashed. With `keep_old`, a file the
/// existing manifest lists keeps its line, never hashed anew (damage since stays a
/// mismatch; the run checked what it reused with [`manifest_mismatches`]), and a listed
/// file that is gone keeps its line too (still missing). Nothing else is listed: a file
/// neither vouched for nor listed before (a user's note at the top of OUT, a setting a
/// killed run left and nobody checked) stays unlisted, which `verify` reports as added
/// after the manifest, never as certified. Returns the number of files listed.
pub fn rewrite_manifest(root: &Path, vouched: &[String], keep_old: bool) -> Result<usize> {
    let path = root.join(MANIFEST);
    let old: BTreeMap<String, String> = if keep_old && path.is_file() {
        let text =
            std::fs::read_to_string(&path).map_err(|e| Error::io("cannot read", &path, e))?;
        parse_manifest(&text, &path)?.into_iter().collect()
    } else {
        BTreeMap::new()
    };
    let vouched: BTreeSet<&str> = vouched.iter().map(|w| w.trim_end_matches('/')).collect();
    let vouches = |rel: &str| {
        vouched.contains(rel)
            || rel
                .match_indices('/')
                .any(|(i, _)| vouched.contains(&rel[..i]))
    };
    let on_disk = list_files(root)?;
    let to_hash: Vec<String> = on_disk.iter().filter(|r| vouches(r)).cloned().collect();
    let mut entries: BTreeMap<Vec<u8>, (String, String)> = BTreeMap::new();
    // Kept: listed before and not vouched for now, present (damage stays a mismatch) or
    // gone and not by this run (still missing).
    let settings = setting_dirs(root);
    let present: BTreeSet<&str> = on_disk.iter().map(String::as_str).collect();
    for (r, d) in &old {
        let listable = is_listed(r) && in_setting_rule(r, &settings);
        if !vouches(r) && listable && (present.contains(r.as_str()) || !root.join(r).exists()) {
            entries.insert(r.as_bytes().to_vec(), (r.clone(), d.clone()));
        }
    }
    let digests = hash_files(root, &to_hash)?;
    for (r, d) in to_hash.into_iter().zip(digests) {
        entries.insert(r.as_bytes().to_vec(), (r, d));
    }
    write_atomic(&path, render(&entries).as_bytes())?;
    Ok(entries.len())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tmp(name: &str) -> std::path::PathBuf {
        let d =
            std::env::temp_dir().join(format!("blurset-manifest-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        d
    }

    fn put(root: &Path, rel: &str, bytes: &[u8]) -> Result<()> {
        write_atomic(&root.join(rel), bytes)
    }

    #[test]
    fn known_digests() -> Result<()> {
        let d = tmp("known");
        put(&d, "empty", b"")?;
        put(&d, "abc", b"abc")?;
        assert_eq!(
            sha256_file(&d.join("empty"))?,
            "e3b0c44298fc1c149afbf4c8996fb92427ae41e4649b934ca495991b7852b855"
        );
        assert_eq!(
            sha256_file(&d.join("abc"))?,
            "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad"
        );
        let _ = std::fs::remove_dir_all(&d);
        Ok(())
    }

    #[test]
    fn listing_rules() {
        assert!(is_listed("dataset.json"));
        assert!(is_listed("a_000/sharp/images/000.png"));
        assert!(!is_listed(MANIFEST));
        assert!(!is_listed(".lock"));
        assert!(!is_listed("a_000/.complete"));
        assert!(!is_listed(".local/paths.jsonl"));
        assert!(!is_listed(".work-a/x"));
        assert!(!is_listed("a_000.partial/meta.json"));
        assert!(!is_listed("x/.dataset.json.tmp12"));
        // A nested manifest is an ordinary file of the tree.
        assert!(is_listed("sub/MANIFEST.sha256"));
    }

    #[test]
    fn a_users_file_in_a_noise_gain_is_not_listed() -> Result<()> {
        let d = tmp("gain");
        put(&d, "noise_dataset.json", b"{}")?;
        for rel in [
            "a_000/blur_4/gain_2.5/noise.json",
            "a_000/blur_4/gain_2.5/poses_bounds.npy",
            "a_000/blur_4/gain_2.5/images_4/000.png",
            "a_000/blur_4/gain_2.5/linear_4/000.exr",
        ] {
            put(&d, rel, b"x")?;
        }
        put(&d, "a_000/blur_4/gain_2.5/mynote.txt", b"mine")?;
        put(&d, "a_000/blur_4/gain_2.5/images_4/notes.md", b"mine")?;
        put(&d, "a_000/blur_4/about.txt", b"outside a gain: listed")?;
        let listed = list_files(&d)?;
        assert_eq!(listed.len(), 6, "{listed:?}");
        assert!(!listed
            .iter()
            .any(|r| r.contains("mynote") || r.contains("notes.md")));
        assert!(listed.contains(&"a_000/blur_4/about.txt".to_string()));
        let _ = std::fs::remove_dir_all(&d);
        Ok(())
    }

    #[test]
    fn write_check_and_damage() -> Result<()> {
        let d = tmp("wcd");
        put(&d, "dataset.json", b"{}")?;
        put(&d, "s_000/sharp/images/000.png", b"png bytes")?;
        put(&d, "s_000/.complete", b"x")?;
        put(&d, ".lock", b"")?;
        put(&d, "s_090.partial/meta.json", b"{}")?;
        put(&d, "odd name\\with\nnewline", b"z")?;
        assert_eq!(write_manifest(&d)?, 3);
        let text = std::fs::read_to_string(d.join(MANIFEST)).unwrap_or_default();
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(lines.len(), 3, "{text}"); // the escaped name stays on one line
        assert!(lines[0].ends_with("  dataset.json"), "{text}");
        assert!(lines[1].starts_with('\\') && lines[1].ends_with("with\\nnewline"));
        assert!(lines[2].ends_with("  s_000/sharp/images/000.png"));
        assert_eq!(check_manifest(&d)?, vec![]);

        put(&d, "s_000/sharp/images/000.png", b"pnG bytes")?;
        put(&d, "README.md", b"card")?;
        std::fs::remove_file(d.join("dataset.json")).map_err(|e| Error::io("rm", &d, e))?;
        assert_eq!(
            check_manifest(&d)?,
            vec![
                ("README.md".to_string(), ManifestProblem::Unlisted),
                ("dataset.json".to_string(), ManifestProblem::Missing),
                (
                    "s_000/sharp/images/000.png".to_string(),
                    ManifestProblem::Mismatch
                ),
            ]
        );
        update_manifest(
            &d,
            &[
                "README.md".into(),
                "dataset.json".into(),
                "s_000/sharp/images/000.png".into(),
            ],
        )?;
        assert_eq!(check_manifest(&d)?, vec![]);
        let _ = std::fs::remove_dir_all(&d);
        Ok(())
    }

    /// The manifest's lines, by file.
    fn listed(d: &Path) -> Result<BTreeMap<String, String>> {
        let text = std::fs::read_to_string(d.join(MANIFEST)).unwrap_or_default();
        Ok(parse_manifest(&text, d)?.into_iter().collect())
    }

    /// Two settings and a card under a manifest (its lines returned), damaged since: one
    /// image copied over the other, the card edited, one gone.
    fn damaged(name: &str) -> Result<(PathBuf, BTreeMap<String, String>)> {
        let d = tmp(name);
        put(&d, "dataset.json", b"{}")?;
        put(&d, "a_000/meta.json", b"{}")?;
        put(&d, "a_000/sharp/images/000.png", b"one")?;
        put(&d, "a_000/sharp/images/001.png", b"two")?;
        put(&d, "b_000/meta.json", b"{}")?;
        put(&d, "b_000/sharp/images/000.png", b"three")?;
        put(&d, "README.md", b"card")?;
        assert_eq!(write_manifest(&d)?, 7);
        let before = listed(&d)?;
        put(&d, "a_000/sharp/images/001.png", b"one")?;
        put(&d, "README.md", b"edited")?;
        std::fs::remove_file(d.join("b_000/sharp/images/000.png"))
            .map_err(|e| Error::io("rm", &d, e))?;
        Ok((d, before))
    }

    /// A rerun of `damaged` that wrote only dataset.json and a new setting's file, beside
    /// a user's files (one in a setting, one at the top); the problems found before it.
    fn rerun_writing_dataset_json(d: &Path) -> Result<Vec<(String, ManifestProblem)>> {
        let problems = check_manifest(d)?;
        put(d, "dataset.json", b"{\"new\": 1}")?;
        put(d, "c_000/meta.json", b"{}")?;
        put(d, "a_000/mynote.txt", b"mine")?;
        put(d, "notes.txt", b"mine")?;
        rewrite_manifest(d, &["dataset.json".to_string()], true)?;
        Ok(problems)
    }

    #[test]
    fn a_settings_damage_is_found_in_that_setting() -> Result<()> {
        let (d, _) = damaged("setting")?;
        assert_eq!(
            manifest_mismatches(&d, "a_000")?,
            vec![(
                "a_000/sharp/images/001.png".to_string(),
                ManifestProblem::Mismatch
            )]
        );
        assert_eq!(
            manifest_mismatches(&d, "b_000")?,
            vec![(
                "b_000/sharp/images/000.png".to_string(),
                ManifestProblem::Missing
            )]
        );
        assert_eq!(manifest_mismatches(&d, "a_00")?, vec![]); // a folder, not a prefix
        let _ = std::fs::remove_dir_all(&d);
        Ok(())
    }

    #[test]
    fn a_rerun_certifies_only_what_it_wrote() -> Result<()> {
        let (d, before) = damaged("rerun")?;
        // Nothing the rerun did not write is certified anew, and a user's file in a
        // setting is never listed.
        let problems = rerun_writing_dataset_json(&d)?;
        let after = listed(&d)?;
        let unlisted = |rel: &str| (rel.to_string(), ManifestProblem::Unlisted);
        let mut now = problems.clone();
        now.extend([unlisted("c_000/meta.json"), unlisted("notes.txt")]);
        now.sort_by(|a, b| a.0.as_bytes().cmp(b.0.as_bytes()));
        assert_eq!(check_manifest(&d)?, now);
        assert_ne!(after["dataset.json"], before["dataset.json"]);
        // Neither written nor checked by the run: not certified (a user's top-level
        // note, a setting nobody checked).
        assert!(!after.contains_key("c_000/meta.json"));
        assert!(!after.contains_key("notes.txt"));
        assert!(!after.contains_key("a_000/mynote.txt"));
        for kept in [
            "README.md",
            "a_000/sharp/images/001.png",
            "b_000/sharp/images/000.png",
        ] {
            assert_eq!(after[kept], before[kept], "{kept}");
        }
        let _ = std::fs::remove_dir_all(&d);
        Ok(())
    }

    #[test]
    fn a_redone_setting_is_hashed_anew_and_a_removed_one_drops_its_lines() -> Result<()> {
        let (d, _) = damaged("redone")?;
        rerun_writing_dataset_json(&d)?;
        std::fs::remove_dir_all(d.join("b_000")).map_err(|e| Error::io("rm", &d, e))?;
        let c = "c_000".to_string();
        rewrite_manifest(&d, &["a_000".to_string(), "b_000".to_string(), c], true)?;
        let problems = check_manifest(&d)?;
        assert_eq!(
            problems,
            vec![
                ("README.md".to_string(), ManifestProblem::Mismatch),
                ("notes.txt".to_string(), ManifestProblem::Unlisted)
            ]
        );
        let _ = std::fs::remove_dir_all(&d);
        Ok(())
    }

    #[test]
    fn without_a_manifest_only_what_is_vouched_for_is_listed() -> Result<()> {
        let (d, _) = damaged("vouched")?;
        rerun_writing_dataset_json(&d)?;
        std::fs::remove_dir_all(d.join("b_000")).map_err(|e| Error::io("rm", &d, e))?;
        // Without a manifest (or without keeping it) only what is vouched for is listed.
        std::fs::remove_file(d.join(MANIFEST)).map_err(|e| Error::io("rm", &d, e))?;
        assert_eq!(rewrite_manifest(&d, &[], true)?, 0);
        let c = "c_000".to_string();
        assert_eq!(rewrite_manifest(&d, &["a_000".to_string(), c], false)?, 4);
        assert_eq!(manifest_mismatches(&d, "a_000")?, vec![]);
        assert!(!listed(&d)?.contains_key("notes.txt"));
        let _ = std::fs::remove_dir_all(&d);
        Ok(())
    }

    #[test]
    fn bad_manifest_lines_name_the_line() {
        let p = Path::new("/x/MANIFEST.sha256");
        let err = parse_manifest("abc  file\n", p)
            .err()
            .map(|e| e.to_string());
        assert!(err.unwrap_or_default().contains("line 1"));
        let ok = parse_manifest(&format!("{}  a b\n", "0".repeat(64)), p);
        assert_eq!(ok.ok(), Some(vec![("a b".to_string(), "0".repeat(64))]));
    }
}
