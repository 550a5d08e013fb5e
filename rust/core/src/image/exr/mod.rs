//! Linear float images on disk (OpenEXR).
pub(crate) mod read;
