//! Integer images on disk: reading the images of an LLFF scene (8- and 16-bit PNG,
//! JPEG, grayscale or colour, with or without alpha, kept in their own sample depth so
//! a 16-bit input is not silently truncated) and writing PNGs.
use crate::error::{Error, Result};
use crate::ground::atomic::write_atomic;
use crate::ground::limits::{self, MAX_IMAGE_ALLOC, MAX_IMAGE_PIXELS, MAX_IMAGE_SIDE};
use image::{DynamicImage, ImageDecoder, ImageEncoder, ImageFormat, ImageReader};
use std::path::Path;

/// Integer samples, interleaved, row-major.
#[derive(Clone, Debug, PartialEq)]
pub enum Samples {
    U8(Vec<u8>),
    U16(Vec<u16>),
}

impl Samples {
    pub fn len(&self) -> usize {
        match self {
            Samples::U8(v) => v.len(),
            Samples::U16(v) => v.len(),
        }
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The largest code of the sample type (255 or 65535).
    pub fn max_code(&self) -> u32 {
        match self {
            Samples::U8(_) => u8::MAX as u32,
            Samples::U16(_) => u16::MAX as u32,
        }
    }
}

/// An image with 1 (gray), 2 (gray + alpha), 3 (RGB) or 4 (RGBA) channels.
#[derive(Clone, Debug, PartialEq)]
pub struct Image {
    pub width: u32,
    pub height: u32,
    pub channels: usize,
    pub samples: Samples,
}

impl Image {
    pub fn new(width: u32, height: u32, channels: usize, samples: Samples) -> Result<Self> {
        if !(1..=4).contains(&channels) {
            return Err(Error::Shape(format!(
                "{channels} channels, expected 1 to 4"
            )));
        }
        let n = width as usize * height as usize * channels;
        if samples.len() != n {
            return Err(Error::Shape(format!(
                "{} samples for a {width} x {height} x {channels} image, expected {n}",
                samples.len()
            )));
        }
        Ok(Image {
            width,
            height,
            channels,
            samples,
        })
    }

    /// Colour channels (1 or 3); an alpha channel, if any, is the last one.
    pub fn color_channels(&self) -> usize {
        if self.channels >= 3 {
            3
        } else {
            1
        }
    }

    pub fn has_alpha(&self) -> bool {
        self.channels == 2 || self.channels == 4
    }
}

/// A reader of the image file at `path`, its format guessed from its first bytes.
fn open_reader(path: &Path) -> Result<ImageReader<std::io::BufReader<std::fs::File>>> {
    ImageReader::open(path)
        .map_err(|e| Error::io("cannot open image", path, e))?
        .with_guessed_format()
        .map_err(|e| Error::io("cannot read image", path, e))
}

/// Width, height, channels and bits per sample from the file header only (cheap:
/// used to validate a whole scene before any pixel is decoded).
pub fn image_info(path: &Path) -> Result<(u32, u32, usize, u32)> {
    let bad = |reason: String| Error::Image {
        reason,
        path: path.into(),
    };
    let decoder = open_reader(path)?
        .into_decoder()
        .map_err(|e| bad(e.to_string()))?;
    let (w, h) = decoder.dimensions();
    let ct = decoder.color_type();
    let channels = ct.channel_count() as usize;
    let bits = (ct.bytes_per_pixel() as u32 * 8) / channels.max(1) as u32;
    Ok((w, h, channels, bits))
}

/// Refuse an image header promising a side past [`MAX_IMAGE_SIDE`] or more than
/// [`MAX_IMAGE_PIXELS`], before its pixels are allocated.
fn check_size(w: u32, h: u32) -> std::result::Result<(), String> {
    let what = format!("header promises a {w}x{h} image");
    limits::check(
        &format!("{what}, side"),
        u64::from(w.max(h)),
        u64::from(MAX_IMAGE_SIDE),
        "MAX_IMAGE_SIDE",
    )?;
    limits::check(
        &format!("{what}, pixels"),
        u64::from(w) * u64::from(h),
        MAX_IMAGE_PIXELS,
        "MAX_IMAGE_PIXELS",
    )
}

/// A PNG's header may promise no more pixel data than its file's bytes can inflate to
/// (zlib's bound, [`limits::ZLIB_MAX_RATIO`]): the decoder allocates the whole image
/// before it inflates anything, so a 1 KB file promising 16384² would cost 1 GiB before
/// being refused (issue 48). The data's size is read from IHDR (width, height, bit depth,
/// colour type: a palette or 1-bit image holds fewer bytes than it decodes to); a file
/// that is not a PNG passes.
fn check_png_fits_file(path: &Path) -> std::result::Result<(), String> {
    use std::io::Read;
    let mut head = [0u8; 26];
    let len = std::fs::File::open(path)
        .and_then(|mut f| {
            f.read_exact(&mut head)?;
            f.metadata()
        })
        .map(|m| m.len());
    let Ok(len) = len else {
        return Ok(()); // too short for a PNG header: the decoder says what is wrong
    };
    if &head[..8] != b"\x89PNG\r\n\x1a\n" || &head[12..16] != b"IHDR" {
        return Ok(());
    }
    let be = |at: usize| {
        u64::from(u32::from_be_bytes([
            head[at],
            head[at + 1],
            head[at + 2],
            head[at + 3],
        ]))
    };
    let (w, h, depth) = (be(16), be(20), u64::from(head[24]));
    // Samples a pixel by colour type: gray, -, RGB, palette index, gray + alpha, -, RGBA.
    let samples = match head[25] {
        0 | 3 => 1,
        2 => 3,
        4 => 2,
        6 => 4,
        _ => return Ok(()),
    };
    let data = (w * samples * depth).div_ceil(8).saturating_mul(h);
    let most = len.saturating_mul(limits::ZLIB_MAX_RATIO);
    if data > most {
        return Err(format!(
            "PNG header promises a {w}x{h} image of {data} bytes of pixel data, more than a \
             file of {len} bytes can hold (at most {}:1); refused before reading it",
            limits::ZLIB_MAX_RATIO
        ));
    }
    Ok(())
}

/// Decode an image file (format guessed from its bytes) into 8- or 16-bit samples,
/// within the limits of `ground::limits` (the decoder allocates at most
/// [`MAX_IMAGE_ALLOC`]).
pub fn read_image(path: &Path) -> Result<Image> {
    let bad = |reason: String| Error::Image {
        reason,
        path: path.into(),
    };
    let mut reader = open_reader(path)?;
    // Another format (an EXR: float samples) is refused before its decoder allocates.
    let Some(ImageFormat::Png | ImageFormat::Jpeg) = reader.format() else {
        return Err(bad("not a PNG or JPEG file".into()));
    };
    let mut lim = image::Limits::default();
    lim.max_alloc = Some(MAX_IMAGE_ALLOC);
    reader.limits(lim);
    let decoder = reader.into_decoder().map_err(|e| bad(e.to_string()))?;
    let (w, h) = decoder.dimensions();
    check_size(w, h).map_err(bad)?;
    check_png_fits_file(path).map_err(bad)?;
    // The decoder allocates the image (and nothing else of its size) at once.
    limits::can_hold(decoder.total_bytes(), &format!("its {w}x{h} image")).map_err(bad)?;
    let img = DynamicImage::from_decoder(decoder).map_err(|e| bad(e.to_string()))?;
    let (channels, samples) = match img {
        DynamicImage::ImageLuma8(b) => (1, Samples::U8(b.into_raw())),
        DynamicImage::ImageLumaA8(b) => (2, Samples::U8(b.into_raw())),
        DynamicImage::ImageRgb8(b) => (3, Samples::U8(b.into_raw())),
        DynamicImage::ImageRgba8(b) => (4, Samples::U8(b.into_raw())),
        DynamicImage::ImageLuma16(b) => (1, Samples::U16(b.into_raw())),
        DynamicImage::ImageLumaA16(b) => (2, Samples::U16(b.into_raw())),
        DynamicImage::ImageRgb16(b) => (3, Samples::U16(b.into_raw())),
        DynamicImage::ImageRgba16(b) => (4, Samples::U16(b.into_raw())),
        other => {
            return Err(bad(format!(
                "{:?} samples; expected 8- or 16-bit integer PNG or JPEG",
                other.color()
            )))
        }
    };
    if w == 0 || h == 0 {
        return Err(bad("empty image".into()));
    }
    Image::new(w, h, channels, samples)
}

/// Encode as PNG in the image's own sample depth.
pub fn png_bytes(img: &Image) -> Result<Vec<u8>> {
    use image::ExtendedColorType as C;
    let res = match &img.samples {
        Samples::U8(v) => {
            let ct = [C::L8, C::La8, C::Rgb8, C::Rgba8][img.channels - 1];
            encode_png(v, img.width, img.height, ct)
        }
        Samples::U16(v) => {
            let ct = [C::L16, C::La16, C::Rgb16, C::Rgba16][img.channels - 1];
            // PNG stores 16-bit samples big-endian; the encoder takes native bytes.
            let bytes: Vec<u8> = v.iter().flat_map(|s| s.to_ne_bytes()).collect();
            encode_png(&bytes, img.width, img.height, ct)
        }
    };
    res.map_err(|e| Error::Value(format!("PNG encoding failed: {e}")))
}

/// Encode an 8-bit RGB image as a PNG file, written atomically.
pub fn write_png_rgb8(path: &Path, width: u32, height: u32, rgb: &[u8]) -> Result<()> {
    let expected = width as usize * height as usize * 3;
    if rgb.len() != expected {
        return Err(Error::Shape(format!(
            "RGB buffer has {} values, a {width}x{height} image needs {expected}",
            rgb.len()
        )));
    }
    let buf = encode_png(rgb, width, height, image::ExtendedColorType::Rgb8).map_err(|e| {
        Error::Image {
            reason: format!("cannot encode PNG: {e}"),
            path: path.to_path_buf(),
        }
    })?;
    write_atomic(path, &buf)
}

/// The PNG file of `samples` (native bytes) laid out as `color`, with the encoder's
/// default compression and filter.
fn encode_png(
    samples: &[u8],
    width: u32,
    height: u32,
    color: image::ExtendedColorType,
) -> image::ImageResult<Vec<u8>> {
    let mut out = Vec::new();
    image::codecs::png::PngEncoder::new(&mut out).write_image(samples, width, height, color)?;
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tmp(name: &str) -> std::path::PathBuf {
        std::env::temp_dir().join(format!("blurset-imageio-{}-{name}", std::process::id()))
    }

    #[test]
    fn a_png_header_promising_more_than_its_file_holds_is_refused_before_decoding() -> Result<()> {
        // IHDR of a 16384^2 RGBA8 image (1 GiB decoded) over one tiny IDAT: the decoder
        // used to allocate the whole image before finding the data short.
        let chunk = |ty: &[u8], data: &[u8]| -> Vec<u8> {
            let mut c = (data.len() as u32).to_be_bytes().to_vec();
            c.extend_from_slice(ty);
            c.extend_from_slice(data);
            // CRC-32 of type and data (bitwise, reflected 0xEDB88320).
            let mut crc = !0u32;
            for &b in &c[4..] {
                crc ^= u32::from(b);
                for _ in 0..8 {
                    crc = (crc >> 1) ^ (0xEDB8_8320 & (crc & 1).wrapping_neg());
                }
            }
            c.extend_from_slice(&(!crc).to_be_bytes());
            c
        };
        let mut ihdr = 16384u32.to_be_bytes().repeat(2);
        ihdr.extend_from_slice(&[8, 6, 0, 0, 0]);
        let mut png = b"\x89PNG\r\n\x1a\n".to_vec();
        for (ty, data) in [
            (&b"IHDR"[..], &ihdr[..]),
            (b"IDAT", &[0x78, 1, 3, 0][..]),
            (b"IEND", &[]),
        ] {
            png.extend(chunk(ty, data));
        }
        let p = tmp("huge.png");
        std::fs::write(&p, &png).map_err(|e| Error::io("write", &p, e))?;
        let e = read_image(&p)
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
        assert!(
            e.contains("PNG header promises a 16384x16384 image of 1073741824 bytes")
                && e.contains("more than a file of")
                && e.contains("huge.png"),
            "{e}"
        );
        // A flat image compresses far, but never past zlib's bound: read whole.
        write_png_rgb8(&p, 2000, 1500, &vec![0u8; 2000 * 1500 * 3])?;
        assert_eq!(read_image(&p)?.width, 2000);
        let _ = std::fs::remove_file(&p);
        Ok(())
    }

    #[test]
    fn png_roundtrip_all_layouts() -> Result<()> {
        for channels in 1..=4 {
            for wide in [false, true] {
                let n = 5 * 3 * channels;
                let samples = if wide {
                    Samples::U16((0..n).map(|i| (i * 4099 % 65536) as u16).collect())
                } else {
                    Samples::U8((0..n).map(|i| (i * 37 % 256) as u8).collect())
                };
                let img = Image::new(5, 3, channels, samples)?;
                let p = tmp(&format!("rt{channels}{wide}.png"));
                std::fs::write(&p, png_bytes(&img)?).map_err(|e| Error::io("write", &p, e))?;
                assert_eq!(read_image(&p)?, img);
                let bits = if wide { 16 } else { 8 };
                assert_eq!(image_info(&p)?, (5, 3, channels, bits));
                let _ = std::fs::remove_file(&p);
            }
        }
        Ok(())
    }

    /// The CRC-32 of a PNG chunk (type and data).
    fn crc32(bytes: &[u8]) -> u32 {
        let mut c = !0u32;
        for &b in bytes {
            c ^= u32::from(b);
            for _ in 0..8 {
                c = if c & 1 != 0 {
                    0xEDB8_8320 ^ (c >> 1)
                } else {
                    c >> 1
                };
            }
        }
        !c
    }

    #[test]
    fn a_header_promising_more_than_the_limit_is_refused_named() -> Result<()> {
        let img = Image::new(4, 4, 3, Samples::U8(vec![7; 48]))?;
        let png = png_bytes(&img)?;
        for (w, h, limit) in [
            (20000u32, 20000u32, "(MAX_IMAGE_PIXELS)"),
            (70000, 1, "(MAX_IMAGE_SIDE)"),
        ] {
            // IHDR: length at 8, type at 12, width and height at 16 and 20, CRC at 29.
            let mut b = png.clone();
            b[16..20].copy_from_slice(&w.to_be_bytes());
            b[20..24].copy_from_slice(&h.to_be_bytes());
            let crc = crc32(&b[12..29]);
            b[29..33].copy_from_slice(&crc.to_be_bytes());
            let p = tmp(&format!("huge{w}.png"));
            std::fs::write(&p, &b).map_err(|e| Error::io("write", &p, e))?;
            assert_eq!(image_info(&p)?.0, w, "the header is read as patched");
            let err = read_image(&p)
                .err()
                .map(|e| e.to_string())
                .unwrap_or_default();
            assert!(
                err.contains(&format!("header promises a {w}x{h} image"))
                    && err.contains(limit)
                    && err.contains(&format!("huge{w}.png")),
                "{err}"
            );
            let _ = std::fs::remove_file(&p);
        }
        Ok(())
    }

    #[test]
    fn garbage_is_an_image_error_naming_the_file() {
        let p = tmp("garbage.png");
        let _ = std::fs::write(&p, b"not an image at all");
        let err = read_image(&p)
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
        assert!(err.contains("garbage.png"), "{err}");
        let _ = std::fs::remove_file(&p);
    }
}
