//! Images: colour, the accumulation of linear frames, EXR and PNG files, and the QA
//! numbers of a rendered view.
use crate::error::{Error, Result};

pub mod accumulate;
pub mod color;
pub mod denoise;
pub mod exr;
pub mod geometry;
pub mod io;
pub mod qa;
pub mod resample;

/// Channels per pixel of a linear frame: premultiplied RGBA, f32.
pub(crate) const CH: usize = 4;

/// Refuse an RGBA buffer that is not `width · height` pixels.
pub(crate) fn check_rgba_len(width: u32, height: u32, len: usize) -> Result<()> {
    let expected = width as usize * height as usize * CH;
    if len != expected {
        return Err(Error::Shape(format!(
            "frame has {len} values, a {width}x{height} RGBA frame needs {expected}"
        )));
    }
    Ok(())
}
