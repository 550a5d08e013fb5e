//! Reading a Blender render with its denoising guide passes (issue 28): the combined
//! RGBA and Cycles' "Denoising Albedo" (RGB) and "Denoising Normal" (XYZ), which Blender
//! writes as a multi-layer EXR (one part per pass, channels named
//! `<view layer>.<pass>.<channel>`). The latent frames of a denoised build are few and
//! small next to the decode of the default path, so this goes through the `exr` crate's
//! generic reader.
use crate::error::{Error, Result};
use crate::ground::limits;
use exr::prelude::{FlatSamples, ReadChannels, ReadLayers};
use std::io::Cursor;
use std::path::Path;

/// One render: RGBA (4 f32 per pixel), albedo and normal (3 f32 per pixel each), rows
/// from the top.
#[derive(Clone, Debug, PartialEq)]
pub struct Passes {
    pub width: usize,
    pub height: usize,
    pub rgba: Vec<f32>,
    pub albedo: Vec<f32>,
    pub normal: Vec<f32>,
}

/// A pass of a multi-layer render: its name in the file and its channels' letters, in
/// the order they are stored per pixel.
pub(crate) type PassSpec = (&'static str, &'static str);

/// The combined pass and the denoiser's two guides.
const GUIDES: [PassSpec; 3] = [
    ("Combined", "RGBA"),
    ("Denoising Albedo", "RGB"),
    ("Denoising Normal", "XYZ"),
];

/// Where a channel goes among `passes`: (pass index, channel index), by the end of its
/// full name. A single-layer file's plain R, G, B, A count as the combined pass.
fn slot(passes: &[PassSpec], full: &str) -> Option<(usize, usize)> {
    let (pass, ch) = full.rsplit_once('.').unwrap_or(("Combined", full));
    let pass = pass.rsplit('.').next().unwrap_or(pass);
    if ch.len() != 1 {
        return None;
    }
    let i = passes.iter().position(|(name, _)| *name == pass)?;
    passes[i].1.find(ch).map(|c| (i, c))
}

/// A decoded multi-layer file: its size and, per pass asked for, the values
/// (interleaved, a pass's letters per pixel) and which of its channels were there.
pub(crate) struct Decoded {
    pub width: usize,
    pub height: usize,
    pub passes: Vec<(Vec<f32>, Vec<bool>)>,
}

/// Decode the EXR file `bytes` (`path` names it in errors) into the `passes` asked for,
/// all of one size; a channel that is absent reads 1 for the combined alpha, else 0.
pub(crate) fn decode_named(bytes: &[u8], path: &Path, passes: &[PassSpec]) -> Result<Decoded> {
    let bad = |reason: String| Error::Image {
        reason,
        path: path.to_path_buf(),
    };
    let image = read_layers(bytes).map_err(bad)?;
    let mut gathered = Gathered::new(passes);
    for layer in image.layer_data {
        let layer_name = layer
            .attributes
            .layer_name
            .as_ref()
            .map(|t| t.to_string())
            .unwrap_or_default();
        let (w, h) = (layer.size.width(), layer.size.height());
        for ch in layer.channel_data.list {
            let name = ch.name.to_string();
            let full = if layer_name.is_empty() || name.starts_with(&layer_name) {
                name
            } else {
                format!("{layer_name}.{name}")
            };
            gathered.add(&full, (w, h), ch.sample_data).map_err(bad)?;
        }
    }
    gathered.finish().map_err(bad)
}

/// A file's layers as the crate reads them: every channel, samples of any type.
type Layers = exr::prelude::Image<exr::prelude::Layers<exr::prelude::AnyChannels<FlatSamples>>>;

/// Every layer of the file at its full resolution.
fn read_layers(bytes: &[u8]) -> std::result::Result<Layers, String> {
    // The crate allocates every channel from the header's size, and cannot fail to:
    // check it first, and that the process can hold them.
    let meta = exr::meta::MetaData::read_from_buffered(Cursor::new(bytes), false)
        .map_err(|e| format!("EXR: {e}"))?;
    super::read::check_sizes(&meta, bytes.len())?;
    let flat = meta.headers.iter().filter(|h| !h.deep);
    limits::can_hold(flat.map(super::read::level0_bytes).sum(), "its channels")?;
    exr::prelude::read()
        .no_deep_data()
        .largest_resolution_level()
        .all_channels()
        .all_layers()
        .all_attributes()
        .from_buffered(Cursor::new(bytes))
        .map_err(|e| format!("EXR: {e}"))
}

/// The passes asked for, filled channel by channel: their values and which of their
/// channels were there, and the one size they share.
struct Gathered<'a> {
    passes: &'a [PassSpec],
    size: Option<(usize, usize)>,
    out: Vec<(Vec<f32>, Vec<bool>)>,
}

impl<'a> Gathered<'a> {
    fn new(passes: &'a [PassSpec]) -> Self {
        Gathered {
            passes,
            size: None,
            out: passes
                .iter()
                .map(|(_, letters)| (Vec::new(), vec![false; letters.len()]))
                .collect(),
        }
    }

    /// Place the channel named `full` (of a `w` x `h` layer) if it belongs to a pass
    /// asked for; every such channel must be of the first one's size.
    fn add(
        &mut self,
        full: &str,
        (w, h): (usize, usize),
        samples: FlatSamples,
    ) -> std::result::Result<(), String> {
        let Some((pass, c)) = slot(self.passes, full) else {
            return Ok(());
        };
        match self.size {
            None => self.size = Some((w, h)),
            Some(s) if s != (w, h) => {
                return Err(format!(
                    "pass {full:?} is {w}x{h}, other passes are {}x{}",
                    s.0, s.1
                ))
            }
            _ => {}
        }
        let stride = self.passes[pass].1.len();
        let (buf, seen) = &mut self.out[pass];
        seen[c] = true;
        // A pass of one float channel is the crate's samples themselves: no copy.
        let samples = match (stride, samples) {
            (1, FlatSamples::F32(v)) if v.len() == w * h => {
                *buf = v;
                return Ok(());
            }
            (_, s) => s,
        };
        if buf.is_empty() {
            let fill = if self.passes[pass] == ("Combined", "RGBA") {
                1.0
            } else {
                0.0
            };
            let n = w * h * stride;
            buf.try_reserve_exact(n)
                .map_err(|_| format!("cannot allocate {} bytes for its {full} pass", n * 4))?;
            buf.resize(n, fill);
        }
        copy_channel(&samples, buf, stride, c);
        Ok(())
    }

    fn finish(self) -> std::result::Result<Decoded, String> {
        let Some((width, height)) = self.size else {
            return Err("none of the passes asked for is in the file".into());
        };
        let mut passes = self.out;
        for (buf, _) in &mut passes {
            if buf.is_empty() {
                buf.resize(width * height, 0.0); // a pass with no channel: callers check `seen`
            }
        }
        Ok(Decoded {
            width,
            height,
            passes,
        })
    }
}

/// One channel's samples into every `stride`-th value of `buf` from offset `c`.
fn copy_channel(samples: &FlatSamples, buf: &mut [f32], stride: usize, c: usize) {
    let values: Box<dyn Iterator<Item = f32>> = match samples {
        FlatSamples::F16(v) => Box::new(v.iter().map(|x| x.to_f32())),
        FlatSamples::F32(v) => Box::new(v.iter().copied()),
        FlatSamples::U32(v) => Box::new(v.iter().map(|&x| x as f32)),
    };
    for (dst, v) in buf.chunks_exact_mut(stride).zip(values) {
        dst[c] = v;
    }
}

/// Decode the EXR file `bytes` (`path` names it in errors) into its combined pass and
/// guides; every pass must be there and of one size (alpha 1 when absent).
pub fn decode_passes(bytes: &[u8], path: &Path) -> Result<Passes> {
    let d = decode_named(bytes, path, &GUIDES)?;
    for ((_, seen), what) in
        d.passes
            .iter()
            .zip(["combined R, G, B", "Denoising Albedo", "Denoising Normal"])
    {
        if !seen[..3].iter().all(|&s| s) {
            return Err(Error::Image {
                reason: format!("no {what} pass: render with the denoising guides (denoise oidn)"),
                path: path.to_path_buf(),
            });
        }
    }
    let mut bufs = d.passes.into_iter().map(|(b, _)| b);
    let (rgba, albedo, normal) = (
        bufs.next().unwrap_or_default(),
        bufs.next().unwrap_or_default(),
        bufs.next().unwrap_or_default(),
    );
    Ok(Passes {
        width: d.width,
        height: d.height,
        rgba,
        albedo,
        normal,
    })
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // a failing unwrap is a failing test
mod tests {
    use super::*;

    #[test]
    fn channels_go_to_their_pass_by_name() {
        let slot = |full: &str| slot(&GUIDES, full);
        assert_eq!(slot("ViewLayer.Combined.R"), Some((0, 0)));
        assert_eq!(slot("ViewLayer.Combined.A"), Some((0, 3)));
        assert_eq!(slot("A"), Some((0, 3)));
        assert_eq!(slot("ViewLayer.Denoising Albedo.B"), Some((1, 2)));
        assert_eq!(slot("ViewLayer.Denoising Normal.Y"), Some((2, 1)));
        assert_eq!(slot("ViewLayer.Denoising Depth.Z"), None);
        assert_eq!(slot("ViewLayer.Normal.Y"), None);
        assert_eq!(slot("ViewLayer.Combined.RG"), None);
    }

    #[test]
    fn a_plain_rgba_file_lacks_the_guides() -> Result<()> {
        let p = std::env::temp_dir().join(format!("blurset-passes-{}.exr", std::process::id()));
        crate::image::exr::write::write_exr(&p, 3, 2, &[0.5; 24])?;
        let bytes = std::fs::read(&p).map_err(|e| Error::io("read", &p, e))?;
        let _ = std::fs::remove_file(&p);
        let e = decode_passes(&bytes, &p).unwrap_err().to_string();
        assert!(
            e.contains("Denoising Albedo") && e.contains("denoise oidn"),
            "{e}"
        );
        Ok(())
    }
}
