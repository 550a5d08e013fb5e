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

/// The least alpha that is coverage. Cycles writes a background pixel's alpha as 1 − its
/// transparency summed over N samples and scaled by 1/N in f32, which leaves up to ~1e-7
/// where N is not a power of two (measured: 1.6e-8 over whole backgrounds at 1,088
/// samples). A real hit is at least one sample of a render's N, ≥ 1e-5 at 65,536 samples,
/// so anything under 1e-6 is rounding, not object: counted, it made every pixel of a
/// motion-blur image part of its exposure mask and diluted a target's object-pixel error.
pub const COVERAGE_EPS: f32 = 1e-6;

/// Whether a pixel of alpha `a` is covered by the object (see [`COVERAGE_EPS`]).
#[inline]
pub fn covers(a: f32) -> bool {
    a > COVERAGE_EPS
}

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
