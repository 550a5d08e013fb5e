//! Streaming accumulation of linear latent frames and their display encoding.
//!
//! A blurry image is the mean of its m latent frames *in linear light* (DESIGN §2).
//! Frames arrive one at a time (from EXR files or from memory) and are summed into one
//! f64 accumulator, so memory is one frame plus the accumulator whatever m is. The
//! sharp image goes through the same path with one frame, so sharp and blurry images
//! share a single encoding: composite over a background (premultiplied alpha, §3),
//! sRGB-encode (IEC 61966-2-1), quantize to 8 bits.
use super::exr::read as exr_frame;
use crate::dataset::atomic::write_atomic;
use crate::error::{Error, Result};
use image::ImageEncoder;
use rayon::prelude::*;
use std::io::Cursor;
use std::path::Path;

/// Linear value at which the sRGB curve switches from the line to the power law.
pub const SRGB_LINEAR_BREAK: f64 = 0.003_130_8;
/// Encoded value at which the inverse curve switches from the line to the power law.
pub const SRGB_ENCODED_BREAK: f64 = 0.040_45;

/// RGBA f32 channels per pixel.
const CH: usize = 4;

/// The exact IEC 61966-2-1 encoding of a linear value, clamped to [0, 1]; NaN maps to 0.
///
/// Evaluated in f64 so that the f32 result is correctly rounded and 8-bit quantization
/// never depends on where the accumulation rounded.
pub fn srgb_encode_f64(linear: f64) -> f64 {
    // `clamp` passes NaN through; a NaN must not reach a PNG byte as an arbitrary value.
    let x = if linear.is_nan() {
        0.0
    } else {
        linear.clamp(0.0, 1.0)
    };
    if x <= SRGB_LINEAR_BREAK {
        12.92 * x
    } else {
        1.055 * libm::pow(x, 1.0 / 2.4) - 0.055
    }
}

/// The exact IEC 61966-2-1 decoding of an encoded value, clamped to [0, 1]; NaN maps to 0.
pub fn srgb_decode_f64(encoded: f64) -> f64 {
    let x = if encoded.is_nan() {
        0.0
    } else {
        encoded.clamp(0.0, 1.0)
    };
    if x <= SRGB_ENCODED_BREAK {
        x / 12.92
    } else {
        libm::pow((x + 0.055) / 1.055, 2.4)
    }
}

/// sRGB encoding of one linear value (see [`srgb_encode_f64`]).
pub fn srgb_encode(linear: f32) -> f32 {
    srgb_encode_f64(f64::from(linear)) as f32
}

/// sRGB encoding of many values, in parallel.
pub fn srgb_encode_slice(linear: &[f32]) -> Vec<f32> {
    linear.par_iter().map(|&x| srgb_encode(x)).collect()
}

/// Linear value quantized to an 8-bit sRGB code (round to nearest).
pub fn srgb_encode_u8(linear: f64) -> u8 {
    // The encoding is clamped to [0, 1], so the rounded value fits in a u8.
    (srgb_encode_f64(linear) * 255.0).round() as u8
}

/// A premultiplied RGBA pixel over an opaque background: `rgb + (1 - a) * bg`, in linear light.
///
/// Alpha is film coverage; it is clamped to [0, 1] so that a stray value never
/// subtracts background.
pub fn composite_over(rgba_premul: [f64; 4], background: [f64; 3]) -> [f64; 3] {
    let t = 1.0 - rgba_premul[3].clamp(0.0, 1.0);
    [
        rgba_premul[0] + t * background[0],
        rgba_premul[1] + t * background[1],
        rgba_premul[2] + t * background[2],
    ]
}

/// An RGBA f32 image read from an EXR file: `rgba` is row-major, 4 channels per pixel.
#[derive(Clone, Debug, PartialEq)]
pub struct Frame {
    pub width: u32,
    pub height: u32,
    pub rgba: Vec<f32>,
}

/// Read the first RGB(A) layer of an EXR file as RGBA f32 (alpha 1 when the file has none).
///
/// Channels are matched by name (`R`, `G`, `B`, optional `A`; half, float or uint
/// samples); blocks are decompressed in parallel on the rayon pool. Values are returned
/// as stored: no check for NaN or inf (see [`Accumulator::add_exr`]).
pub fn read_exr(path: &Path) -> Result<Frame> {
    let bytes = std::fs::read(path).map_err(|e| Error::io("cannot open EXR", path, e))?;
    let mut rgba = Vec::new();
    let d = exr_frame::decode_rgba(&bytes, path, &mut rgba)?;
    Ok(Frame {
        width: d.width as u32,
        height: d.height as u32,
        rgba,
    })
}

/// Encode an RGBA f32 image as a ZIP-compressed (lossless) EXR file, written atomically.
pub fn write_exr(path: &Path, width: u32, height: u32, rgba: &[f32]) -> Result<()> {
    use exr::prelude::{Encoding, Image, Layer, LayerAttributes, SpecificChannels, WritableImage};
    check_len(width, height, rgba.len())?;
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
    let mut buf = Cursor::new(Vec::new());
    Image::from_layer(layer)
        .write()
        .to_buffered(&mut buf)
        .map_err(|e| Error::Image {
            reason: format!("cannot encode EXR: {e}"),
            path: path.to_path_buf(),
        })?;
    write_atomic(path, buf.get_ref())
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
    let mut buf = Vec::new();
    image::codecs::png::PngEncoder::new(&mut buf)
        .write_image(rgb, width, height, image::ExtendedColorType::Rgb8)
        .map_err(|e| Error::Image {
            reason: format!("cannot encode PNG: {e}"),
            path: path.to_path_buf(),
        })?;
    write_atomic(path, &buf)
}

fn encode_run(out: &mut [u8], pixels: impl Iterator<Item = [f64; 4]>, bg: [f64; 3]) {
    // Renders are mostly flat background: a value equal to the one before reuses its
    // code instead of another `pow` (same function, same result).
    let mut last = (f64::NAN.to_bits(), 0u8);
    let mut encode = |x: f64| {
        if x.to_bits() != last.0 {
            last = (x.to_bits(), srgb_encode_u8(x));
        }
        last.1
    };
    for (o, p) in out.chunks_exact_mut(3).zip(pixels) {
        let c = composite_over(p, bg);
        o[0] = encode(c[0]);
        o[1] = encode(c[1]);
        o[2] = encode(c[2]);
    }
}

/// Read a whole file into `buf`, reusing its memory; on Unix the two halves are read
/// at once on the rayon pool (the copy out of the page cache is a visible share of a
/// frame's time).
fn read_into(path: &Path, buf: &mut Vec<u8>) -> Result<()> {
    use std::io::Read;
    let err = |e| Error::io("cannot open EXR", path, e);
    let mut f = std::fs::File::open(path).map_err(err)?;
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileExt;
        let len = f.metadata().map_err(err)?.len();
        if let Ok(len) = usize::try_from(len) {
            buf.resize(len, 0);
            let (a, b) = buf.split_at_mut(len / 2);
            let (ra, rb) = rayon::join(
                || f.read_exact_at(a, 0),
                || f.read_exact_at(b, (len / 2) as u64),
            );
            ra.and(rb).map_err(err)?;
            // A file that grew since `metadata` keeps its tail.
            f.read_to_end(buf).map_err(err)?;
            return Ok(());
        }
    }
    buf.clear();
    f.read_to_end(buf).map_err(err)?;
    Ok(())
}

fn check_len(width: u32, height: u32, len: usize) -> Result<()> {
    let expected = width as usize * height as usize * CH;
    if len != expected {
        return Err(Error::Shape(format!(
            "frame has {len} values, a {width}x{height} RGBA frame needs {expected}"
        )));
    }
    Ok(())
}

/// The first non-finite value of an RGBA buffer, as (x, y, channel, value).
fn first_non_finite(width: u32, rgba: &[f32]) -> Option<(usize, usize, usize, f32)> {
    exr_frame::first_non_finite(width as usize, rgba)
}

/// Running sum of linear RGBA frames of one size; the mean is the blurry image.
#[derive(Clone, Debug)]
pub struct Accumulator {
    width: u32,
    height: u32,
    // f64: the sum of hundreds of f32 frames keeps every f32 bit of their mean.
    sum: Vec<f64>,
    count: u32,
    /// The frame being added by `add_exr`, kept so its memory is reused.
    staging: Vec<f32>,
    /// The bytes of the EXR file being added, kept for the same reason.
    file: Vec<u8>,
}

impl Accumulator {
    pub fn new(width: u32, height: u32) -> Self {
        Accumulator {
            width,
            height,
            sum: vec![0.0; width as usize * height as usize * CH],
            count: 0,
            staging: Vec::new(),
            file: Vec::new(),
        }
    }

    pub fn width(&self) -> u32 {
        self.width
    }

    pub fn height(&self) -> u32 {
        self.height
    }

    /// Number of frames added so far.
    pub fn count(&self) -> u32 {
        self.count
    }

    /// Add one premultiplied linear RGBA frame (row-major, 4 f32 per pixel).
    ///
    /// A frame with a NaN or inf is refused whole, so the sum is never poisoned.
    pub fn add_frame(&mut self, rgba: &[f32]) -> Result<()> {
        check_len(self.width, self.height, rgba.len())?;
        if let Some((x, y, c, v)) = first_non_finite(self.width, rgba) {
            return Err(Error::Value(format!(
                "frame has a non-finite value {v} at pixel ({x}, {y}) channel {}",
                "RGBA".as_bytes()[c] as char
            )));
        }
        self.add_unchecked(rgba);
        Ok(())
    }

    /// Read an RGBA f32 EXR (alpha 1 when absent) and add it; the file must match the
    /// accumulator size and hold only finite values.
    pub fn add_exr(&mut self, path: &Path) -> Result<()> {
        let mut file = std::mem::take(&mut self.file);
        let mut staging = std::mem::take(&mut self.staging);
        let res = read_into(path, &mut file).and_then(|()| {
            let d = exr_frame::decode_rgba(&file, path, &mut staging)?;
            if (d.width, d.height) != (self.width as usize, self.height as usize) {
                return Err(Error::Shape(format!(
                    "EXR is {}x{} but the accumulator is {}x{}: {path:?}",
                    d.width, d.height, self.width, self.height
                )));
            }
            if let Some((x, y, c, v)) = d.non_finite {
                return Err(Error::Image {
                    reason: format!(
                        "non-finite value {v} at pixel ({x}, {y}) channel {}; a render must not poison the average",
                        "RGBA".as_bytes()[c] as char
                    ),
                    path: path.to_path_buf(),
                });
            }
            self.add_unchecked(&staging);
            Ok(())
        });
        self.file = file;
        self.staging = staging;
        res
    }

    fn add_unchecked(&mut self, rgba: &[f32]) {
        let row = (self.width as usize * CH).max(1);
        self.sum
            .par_chunks_mut(row)
            .zip(rgba.par_chunks(row))
            .for_each(|(s, f)| {
                for (s, &f) in s.iter_mut().zip(f) {
                    *s += f64::from(f);
                }
            });
        self.count += 1;
    }

    fn require_frames(&self) -> Result<()> {
        if self.count == 0 {
            return Err(Error::Value(
                "the accumulator has no frames yet; add at least one before taking the mean".into(),
            ));
        }
        Ok(())
    }

    /// The mean of the frames added, premultiplied linear RGBA f32.
    pub fn mean(&self) -> Result<Vec<f32>> {
        self.require_frames()?;
        let inv = 1.0 / f64::from(self.count);
        Ok(self.sum.par_iter().map(|&s| (s * inv) as f32).collect())
    }

    /// The mean composited over `background` (linear RGB), sRGB-encoded, as RGB8.
    pub fn encode_rgb8(&self, background: [f32; 3]) -> Result<Vec<u8>> {
        self.require_frames()?;
        let inv = 1.0 / f64::from(self.count);
        let bg = background.map(f64::from);
        let mut out = vec![0u8; self.sum.len() / CH * 3];
        let row = (self.width as usize).max(1);
        // Straight from the f64 sum: the PNG never sees the f32 rounding of the mean.
        out.par_chunks_mut(3 * row)
            .zip(self.sum.par_chunks(CH * row))
            .for_each(|(o, s)| {
                let px = s
                    .chunks_exact(CH)
                    .map(|p| [p[0] * inv, p[1] * inv, p[2] * inv, p[3] * inv]);
                encode_run(o, px, bg);
            });
        Ok(out)
    }

    /// Write the mean as an 8-bit sRGB PNG over `background` (linear RGB; white is [1, 1, 1]).
    pub fn write_png(&self, path: &Path, background: [f32; 3]) -> Result<()> {
        let rgb = self.encode_rgb8(background)?;
        write_png_rgb8(path, self.width, self.height, &rgb)
    }

    /// Write the mean as a linear, premultiplied RGBA f32 EXR.
    pub fn write_exr(&self, path: &Path) -> Result<()> {
        let mean = self.mean()?;
        write_exr(path, self.width, self.height, &mean)
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // a failing unwrap is a failing test
mod tests {
    use super::*;
    use proptest::prelude::*;
    use std::path::PathBuf;

    fn tmp(name: &str) -> PathBuf {
        std::env::temp_dir()
            .join(format!("blurset-accumulate-{}", std::process::id()))
            .join(name)
    }

    fn as_bytes(v: &[f32]) -> Vec<u8> {
        v.iter().flat_map(|x| x.to_ne_bytes()).collect()
    }

    fn frame(w: u32, h: u32, seed: u64) -> Vec<f32> {
        let mut s = crate::rng::Stream::new(seed, 0);
        (0..w * h * 4).map(|_| s.uniform() as f32).collect()
    }

    /// The encoding of one frame pixel by pixel, without the encoder's reuse of codes.
    fn reference_rgb8(rgba: &[f32], background: [f32; 3]) -> Vec<u8> {
        let bg = background.map(f64::from);
        rgba.chunks_exact(CH)
            .flat_map(|p| composite_over([p[0], p[1], p[2], p[3]].map(f64::from), bg))
            .map(srgb_encode_u8)
            .collect()
    }

    #[test]
    fn srgb_breakpoints_are_exact() {
        assert_eq!(srgb_encode_f64(0.0), 0.0);
        // 1.055 - 0.055 is one ulp below 1 in f64; the f32 result and the byte are exact.
        assert!((srgb_encode_f64(1.0) - 1.0).abs() < 1e-15);
        assert_eq!(srgb_encode(1.0), 1.0);
        assert_eq!(srgb_decode_f64(1.0), 1.0);
        // Both pieces meet at the break (continuity to ~1e-8, the standard's rounding).
        let lo = 12.92 * SRGB_LINEAR_BREAK;
        let hi = 1.055 * SRGB_LINEAR_BREAK.powf(1.0 / 2.4) - 0.055;
        assert_eq!(srgb_encode_f64(SRGB_LINEAR_BREAK), lo);
        assert!((lo - hi).abs() < 1e-7, "{lo} vs {hi}");
        assert!((lo - SRGB_ENCODED_BREAK).abs() < 1e-6);
        assert_eq!(
            srgb_decode_f64(SRGB_ENCODED_BREAK),
            SRGB_ENCODED_BREAK / 12.92
        );
        assert!(srgb_encode_f64(SRGB_LINEAR_BREAK + 1e-12) > lo - 1e-7);
        assert_eq!(
            srgb_encode(0.5),
            (1.055 * 0.5f64.powf(1.0 / 2.4) - 0.055) as f32
        );
        // Known code values: linear 0.5 is sRGB 188, 0.2159 (the decode of 128/255) is 128.
        assert_eq!(srgb_encode_u8(0.5), 188);
        assert_eq!(srgb_encode_u8(0.215_860_5), 128);
        assert_eq!(srgb_encode_u8(-3.0), 0);
        assert_eq!(srgb_encode_u8(7.0), 255);
        assert_eq!(srgb_encode_u8(f64::NAN), 0);
    }

    #[test]
    fn composite_alpha_zero_gives_background_alpha_one_gives_colour() {
        let bg = [0.25, 0.5, 1.0];
        assert_eq!(composite_over([0.0, 0.0, 0.0, 0.0], bg), bg);
        assert_eq!(composite_over([0.1, 0.2, 0.3, 1.0], bg), [0.1, 0.2, 0.3]);
        // Half coverage of premultiplied red over white.
        assert_eq!(
            composite_over([0.5, 0.0, 0.0, 0.5], [1.0; 3]),
            [1.0, 0.5, 0.5]
        );
    }

    #[test]
    fn mean_of_known_frames() -> Result<()> {
        let mut acc = Accumulator::new(2, 1);
        acc.add_frame(&[0.0, 1.0, 2.0, 1.0, 4.0, 0.0, 0.0, 0.0])?;
        acc.add_frame(&[1.0, 1.0, 0.0, 0.0, 2.0, 0.0, 0.0, 1.0])?;
        acc.add_frame(&[2.0, 1.0, 1.0, 0.5, 0.0, 0.0, 3.0, 0.5])?;
        assert_eq!(acc.count(), 3);
        assert_eq!(acc.mean()?, vec![1.0, 1.0, 1.0, 0.5, 2.0, 0.0, 1.0, 0.5]);
        Ok(())
    }

    #[test]
    fn empty_accumulator_and_bad_length_are_errors() {
        let acc = Accumulator::new(3, 2);
        assert!(matches!(acc.mean(), Err(Error::Value(_))));
        assert!(acc.write_png(&tmp("never.png"), [1.0; 3]).is_err());
        assert!(!tmp("never.png").exists());
        let mut acc = Accumulator::new(3, 2);
        let e = acc.add_frame(&[0.0; 5]).unwrap_err();
        assert!(e.to_string().contains("3x2"), "{e}");
        assert_eq!(acc.count(), 0);
    }

    #[test]
    fn nan_frame_is_refused_whole() {
        let mut acc = Accumulator::new(2, 2);
        let mut f = vec![0.5f32; 16];
        f[9] = f32::NAN;
        let e = acc.add_frame(&f).unwrap_err().to_string();
        assert!(e.contains("(0, 1)") && e.contains("channel G"), "{e}");
        assert_eq!(acc.count(), 0);
        assert!(acc.sum.iter().all(|&s| s == 0.0));
    }

    #[test]
    fn exr_roundtrip_png_and_errors_name_the_file() -> Result<()> {
        let (w, h) = (7, 5);
        let f = frame(w, h, 3);
        let p = tmp("frame.exr");
        write_exr(&p, w, h, &f)?;
        let back = read_exr(&p)?;
        assert_eq!((back.width, back.height), (w, h));
        assert_eq!(back.rgba, f);

        let mut acc = Accumulator::new(w, h);
        acc.add_exr(&p)?;
        acc.add_exr(&p)?;
        assert_eq!(acc.mean()?, f);
        let out = tmp("out/mean.exr");
        acc.write_exr(&out)?;
        assert_eq!(read_exr(&out)?.rgba, f);
        let png = tmp("out/mean.png");
        acc.write_png(&png, [1.0, 1.0, 1.0])?;
        let img = image::open(&png)
            .map_err(|e| Error::Value(e.to_string()))?
            .into_rgb8();
        assert_eq!(img.dimensions(), (w, h));
        assert_eq!(img.into_raw(), reference_rgb8(&f, [1.0; 3]));

        let mut small = Accumulator::new(w + 1, h);
        let e = small.add_exr(&p).unwrap_err().to_string();
        assert!(
            e.contains("frame.exr") && e.contains("7x5") && e.contains("8x5"),
            "{e}"
        );

        let mut bad = f.clone();
        bad[4 * (2 * w as usize + 3) + 2] = f32::INFINITY;
        let pn = tmp("nan.exr");
        write_exr(&pn, w, h, &bad)?;
        let e = acc.add_exr(&pn).unwrap_err();
        assert!(matches!(e, Error::Image { .. }));
        let e = e.to_string();
        assert!(
            e.contains("nan.exr") && e.contains("(3, 2)") && e.contains("inf"),
            "{e}"
        );
        assert_eq!(acc.count(), 2);

        let missing = tmp("missing.exr");
        let e = acc.add_exr(&missing).unwrap_err().to_string();
        assert!(e.contains("missing.exr"), "{e}");
        let junk = tmp("junk.exr");
        write_atomic(&junk, b"not an exr")?;
        let e = acc.add_exr(&junk).unwrap_err().to_string();
        assert!(e.contains("junk.exr"), "{e}");
        Ok(())
    }

    #[test]
    fn exr_without_alpha_counts_as_opaque() -> Result<()> {
        let (w, h) = (3, 2);
        let rgb: Vec<f32> = (0..w * h * 3).map(|i| i as f32 / 20.0).collect();
        let p = tmp("rgb.exr");
        let mut buf = Cursor::new(Vec::new());
        image::codecs::openexr::OpenExrEncoder::new(&mut buf)
            .write_image(&as_bytes(&rgb), w, h, image::ExtendedColorType::Rgb32F)
            .map_err(|e| Error::Value(e.to_string()))?;
        write_atomic(&p, buf.get_ref())?;
        let mut acc = Accumulator::new(w, h);
        acc.add_exr(&p)?;
        let m = acc.mean()?;
        for (px, c) in m.chunks_exact(4).zip(rgb.chunks_exact(3)) {
            assert_eq!(&px[..3], c);
            assert_eq!(px[3], 1.0);
        }
        Ok(())
    }

    proptest! {
        #[test]
        fn n_copies_of_a_frame_give_the_frame_back(
            w in 1u32..9, h in 1u32..9, n in 1u32..40, seed in any::<u64>(),
            scale in prop::sample::select(vec![1.0f32, 1e-3, 50.0]),
        ) {
            let f: Vec<f32> = frame(w, h, seed).iter().map(|v| v * scale).collect();
            let mut acc = Accumulator::new(w, h);
            for _ in 0..n {
                acc.add_frame(&f).unwrap();
            }
            prop_assert_eq!(acc.count(), n);
            prop_assert_eq!(acc.mean().unwrap(), f.clone());
            prop_assert_eq!(acc.encode_rgb8([1.0, 0.5, 0.0]).unwrap(), reference_rgb8(&f, [1.0, 0.5, 0.0]));
        }

        #[test]
        fn srgb_roundtrip(x in 0.0f64..=1.0) {
            prop_assert!((srgb_decode_f64(srgb_encode_f64(x)) - x).abs() < 1e-12);
            prop_assert!((srgb_encode_f64(srgb_decode_f64(x)) - x).abs() < 1e-12);
            let y = x as f32;
            let back = srgb_decode_f64(f64::from(srgb_encode(y))) as f32;
            prop_assert!((back - y).abs() <= 2e-7_f32.max(y * 4e-7));
        }

        #[test]
        fn srgb_is_monotone(a in -0.5f64..1.5, b in -0.5f64..1.5) {
            let (lo, hi) = if a <= b { (a, b) } else { (b, a) };
            prop_assert!(srgb_encode_f64(lo) <= srgb_encode_f64(hi));
            prop_assert!(srgb_encode_u8(lo) <= srgb_encode_u8(hi));
        }
    }
}
