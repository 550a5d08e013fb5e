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

#[cfg(test)]
mod tests {
    use super::*;

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
