//! The one error type of blurset-core.
//!
//! Guide: add a variant with the numbers that explain it, put paths last, and map it
//! to a Python exception in `rust/py/src/error.rs` (one `match`, nothing else).
use std::path::PathBuf;

#[derive(Debug, thiserror::Error)]
pub enum Error {
    #[error("{what}: {source}: {path:?}")]
    Io {
        what: &'static str,
        source: std::io::Error,
        path: PathBuf,
    },
    #[error("cannot read image ({reason}): {path:?}")]
    Image { reason: String, path: PathBuf },
    #[error("bad pose file ({reason}): {path:?}")]
    PoseFormat { reason: String, path: PathBuf },
    #[error("shape mismatch: {0}")]
    Shape(String),
    #[error("invalid value: {0}")]
    Value(String),
    /// An option out of its range: the option, then the value and what it must be.
    #[error("{option} {detail}")]
    Config { option: String, detail: String },
    /// Bad input data (a build's meta.json, splits.json, …): the reason, then the file.
    #[error("{reason}: {path:?}")]
    Input { reason: String, path: PathBuf },
}

pub type Result<T> = std::result::Result<T, Error>;

impl Error {
    pub fn io(what: &'static str, path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Error::Io {
            what,
            source,
            path: path.into(),
        }
    }
}
