//! Writing linear float images as OpenEXR files.
use crate::error::{Error, Result};
use crate::ground::atomic::write_atomic;
use crate::image::{check_rgba_len, CH};
use std::io::Cursor;
use std::path::Path;

/// Encode an RGBA f32 image as a ZIP-compressed (lossless) EXR file, written atomically.
pub fn write_exr(path: &Path, width: u32, height: u32, rgba: &[f32]) -> Result<()> {
    use exr::prelude::{Encoding, Image, Layer, LayerAttributes, SpecificChannels, WritableImage};
    check_rgba_len(width, height, rgba.len())?;
    let (w, h) = (width as usize, height as usize);
    let channels = SpecificChannels::rgba(|p: exr::math::Vec2<usize>| {
        let i = (p.y() * w + p.x()) * CH;
        (rgba[i], rgba[i + 1], rgba[i + 2], rgba[i + 3])
    });
    let layer = Layer::new(
        (w, h),
        LayerAttributes::default(),
        Encoding::SMALL_LOSSLESS,
        channels,
    );
    write_encoded(path, |buf| {
        Image::from_layer(layer).write().to_buffered(buf)
    })
}

/// Write the EXR `encode` puts in a buffer to `path`, atomically; an encoder's error
/// names the file.
pub(crate) fn write_encoded(
    path: &Path,
    encode: impl FnOnce(&mut Cursor<Vec<u8>>) -> exr::error::UnitResult,
) -> Result<()> {
    let mut buf = Cursor::new(Vec::new());
    encode(&mut buf).map_err(|e| Error::Image {
        reason: format!("cannot encode EXR: {e}"),
        path: path.to_path_buf(),
    })?;
    write_atomic(path, buf.get_ref())
}

/// Encode float RGB (3 channels) or RGBA (4) as an uncompressed 32-bit float EXR of
/// increasing scan lines, written sequentially: exr's parallel writer emits blocks
/// in completion order, which would make the bytes depend on thread timing.
pub fn exr_bytes(width: u32, height: u32, channels: usize, data: &[f32]) -> Result<Vec<u8>> {
    use exr::prelude::{Encoding, SpecificChannels, Vec2, WritableImage};
    let (w, h) = (width as usize, height as usize);
    if !(channels == 3 || channels == 4) {
        return Err(Error::Shape(format!(
            "EXR needs 3 or 4 channels, got {channels}"
        )));
    }
    if data.len() != w * h * channels {
        return Err(Error::Shape(format!(
            "{} floats for a {width} x {height} x {channels} EXR",
            data.len()
        )));
    }
    let at = |p: Vec2<usize>, c: usize| data[(p.y() * w + p.x()) * channels + c];
    let mut cur = std::io::Cursor::new(Vec::new());
    let res = if channels == 3 {
        let ch = SpecificChannels::rgb(|p: Vec2<usize>| (at(p, 0), at(p, 1), at(p, 2)));
        exr::image::Image::from_encoded_channels((w, h), Encoding::UNCOMPRESSED, ch)
            .write()
            .non_parallel()
            .to_buffered(&mut cur)
    } else {
        let ch = SpecificChannels::rgba(|p: Vec2<usize>| (at(p, 0), at(p, 1), at(p, 2), at(p, 3)));
        exr::image::Image::from_encoded_channels((w, h), Encoding::UNCOMPRESSED, ch)
            .write()
            .non_parallel()
            .to_buffered(&mut cur)
    };
    res.map_err(|e| Error::Value(format!("EXR encoding failed: {e}")))?;
    Ok(cur.into_inner())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exr_has_the_right_size() -> Result<()> {
        let b = exr_bytes(4, 2, 3, &[0.5; 24])?;
        assert!(b.len() > 24 * 4);
        assert!(exr_bytes(4, 2, 3, &[0.5; 23]).is_err());
        Ok(())
    }
}
