//! `MANIFEST.sha256`: the checksum of every file a build (or a noise output) publishes,
//! in `sha256sum` format, so `sha256sum -c MANIFEST.sha256` run inside it proves it
//! arrived whole.
//!
//! What is listed is decided here and nowhere else (`is_listed`): every regular file
//! under the root, except the manifest itself, anything whose path has a component
//! starting with `.` (the `.lock`, the `.complete` markers, temp files of atomic writes,
//! `.work-*` scratch, `.local/` with the builder's own paths) and `*.partial` staging
//! directories (another shard may be writing one right now).
use crate::error::{Error, Result};
use crate::ground::atomic::write_atomic;
use rayon::prelude::*;
use sha2::{Digest, Sha256};
use std::collections::{BTreeMap, BTreeSet};
use std::io::Read;
use std::path::Path;

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
    out.sort_unstable_by(|a, b| a.as_bytes().cmp(b.as_bytes()));
    Ok(out)
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
