//! Atomic file writes: a reader sees the old file or the whole new one, never half.
use crate::error::{Error, Result};
use std::io::Write;
use std::path::{Path, PathBuf};

/// The temporary sibling a write goes to before the rename (same directory, so the
/// rename stays on one filesystem).
pub fn temp_path(path: &Path) -> PathBuf {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    path.with_file_name(format!(".{name}.tmp{}", std::process::id()))
}

/// Write `bytes` to `path` through a temp file + rename.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    if let Some(dir) = path.parent() {
        if !dir.as_os_str().is_empty() {
            std::fs::create_dir_all(dir)
                .map_err(|e| Error::io("cannot create directory", dir, e))?;
        }
    }
    let tmp = temp_path(path);
    let res = (|| {
        let mut f = std::fs::File::create(&tmp)?;
        f.write_all(bytes)?;
        f.sync_all()
    })();
    if let Err(e) = res {
        let _ = std::fs::remove_file(&tmp);
        return Err(Error::io("cannot write", path, e));
    }
    std::fs::rename(&tmp, path).map_err(|e| {
        let _ = std::fs::remove_file(&tmp);
        Error::io("cannot rename into place", path, e)
    })
}

/// Put the folder `new` at `dst`, replacing what is there: the one rule every writer
/// of a folder follows (a setting, a noise unit, a gain, an exported scene).
///
/// The old entry is renamed aside (to `dst`'s temp name), the new one renamed in, and
/// only then is the old one removed: a failure before the second rename puts the old
/// one back, and a kill leaves at `dst` the old or the new entry, never a half-deleted
/// one (at worst the old one aside under a temp name whose process is gone, which a
/// rerun's stale-temp sweep clears).
pub fn replace_dir(new: &Path, dst: &Path) -> Result<()> {
    let aside = temp_path(dst);
    let had_old = dst.symlink_metadata().is_ok();
    if had_old {
        remove_entry(&aside)?;
        std::fs::rename(dst, &aside).map_err(|e| Error::io("cannot move aside", dst, e))?;
    }
    if let Err(e) = std::fs::rename(new, dst) {
        if had_old {
            let _ = std::fs::rename(&aside, dst);
        }
        return Err(Error::io("cannot move into place", dst, e));
    }
    remove_entry(&aside)
}

/// Remove a file, a symlink or a folder with everything in it; nothing there is fine.
pub fn remove_entry(path: &Path) -> Result<()> {
    let res = match path.symlink_metadata() {
        Err(_) => return Ok(()),
        Ok(m) if m.is_dir() => std::fs::remove_dir_all(path),
        Ok(_) => std::fs::remove_file(path),
    };
    res.map_err(|e| Error::io("cannot remove", path, e))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scratch(tag: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("blurset-replace-{tag}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        d
    }

    fn names(dir: &Path) -> Vec<String> {
        let mut v: Vec<String> = std::fs::read_dir(dir)
            .map(|r| {
                r.filter_map(|e| e.ok())
                    .map(|e| e.file_name().to_string_lossy().into_owned())
                    .collect()
            })
            .unwrap_or_default();
        v.sort();
        v
    }

    #[test]
    fn replace_dir_swaps_a_folder_and_leaves_nothing_aside() -> Result<()> {
        let d = scratch("swap");
        let (new, dst) = (d.join("new"), d.join("dst"));
        for (dir, text) in [(&new, "new"), (&dst, "old")] {
            write_atomic(&dir.join("sub/f.txt"), text.as_bytes())?;
        }
        write_atomic(&dst.join("only_old.txt"), b"x")?;
        replace_dir(&new, &dst)?;
        let f = dst.join("sub/f.txt");
        assert_eq!(
            std::fs::read(&f).map_err(|e| Error::io("read", &f, e))?,
            b"new"
        );
        assert!(
            !dst.join("only_old.txt").exists(),
            "the old folder's files are gone"
        );
        assert_eq!(
            names(&d),
            vec!["dst".to_string()],
            "no temp name or source left"
        );
        let _ = std::fs::remove_dir_all(&d);
        Ok(())
    }

    #[test]
    fn replace_dir_into_nothing_and_over_a_file() -> Result<()> {
        let d = scratch("fresh");
        let (new, dst) = (d.join("new"), d.join("dst"));
        write_atomic(&new.join("a.txt"), b"a")?;
        replace_dir(&new, &dst)?;
        assert!(dst.join("a.txt").is_file());
        write_atomic(&new.join("b.txt"), b"b")?;
        let file = d.join("file");
        write_atomic(&file, b"was a file")?;
        replace_dir(&new, &file)?;
        assert!(file.join("b.txt").is_file());
        assert_eq!(names(&d), vec!["dst".to_string(), "file".to_string()]);
        let _ = std::fs::remove_dir_all(&d);
        Ok(())
    }

    #[test]
    fn replace_dir_keeps_the_old_folder_when_the_new_one_is_missing() -> Result<()> {
        let d = scratch("keep");
        let dst = d.join("dst");
        write_atomic(&dst.join("f.txt"), b"old")?;
        let err = replace_dir(&d.join("absent"), &dst);
        assert!(err.is_err(), "a missing source is an error");
        let f = dst.join("f.txt");
        assert_eq!(
            std::fs::read(&f).map_err(|e| Error::io("read", &f, e))?,
            b"old"
        );
        assert_eq!(
            names(&d),
            vec!["dst".to_string()],
            "the old folder is back in place"
        );
        let _ = std::fs::remove_dir_all(&d);
        Ok(())
    }

    #[test]
    fn writes_whole_file_and_leaves_no_temp() -> Result<()> {
        let dir = std::env::temp_dir().join(format!("blurset-atomic-{}", std::process::id()));
        let p = dir.join("a/b.txt");
        write_atomic(&p, b"hello")?;
        write_atomic(&p, b"world!")?;
        assert_eq!(
            std::fs::read(&p).map_err(|e| Error::io("read", &p, e))?,
            b"world!"
        );
        let names: Vec<_> = std::fs::read_dir(p.parent().unwrap_or(&dir))
            .map_err(|e| Error::io("ls", &dir, e))?
            .filter_map(|e| e.ok())
            .collect();
        assert_eq!(names.len(), 1);
        let _ = std::fs::remove_dir_all(&dir);
        Ok(())
    }
}
