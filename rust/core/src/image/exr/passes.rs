//! Reading a Blender render with its denoising guide passes (issue 28): the combined
//! RGBA and Cycles' "Denoising Albedo" (RGB) and "Denoising Normal" (XYZ), which Blender
//! writes as a multi-layer EXR (one part per pass, channels named
//! `<view layer>.<pass>.<channel>`). The latent frames of a denoised build are few and
//! small next to the decode of the default path, so this goes through the `exr` crate's
//! generic reader.
use crate::error::{Error, Result};
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

/// Where a channel goes: (0 rgba | 1 albedo | 2 normal, channel index), by the end of
/// its full name. A single-layer file's plain R, G, B, A count as the combined pass.
fn slot(full: &str) -> Option<(usize, usize)> {
    let (pass, ch) = full.rsplit_once('.').unwrap_or(("Combined", full));
    let pass = pass.rsplit('.').next().unwrap_or(pass);
    let pick = |names: &str| names.find(ch).filter(|_| ch.len() == 1);
    match pass {
        "Combined" => pick("RGBA").map(|c| (0, c)),
        "Denoising Albedo" => pick("RGB").map(|c| (1, c)),
        "Denoising Normal" => pick("XYZ").map(|c| (2, c)),
        _ => None,
    }
}

/// Decode the EXR file `bytes` (`path` names it in errors) into its combined pass and
/// guides; every pass must be there and of one size (alpha 1 when absent).
pub fn decode_passes(bytes: &[u8], path: &Path) -> Result<Passes> {
    let bad = |reason: String| Error::Image {
        reason,
        path: path.to_path_buf(),
    };
    // The crate allocates every channel from the header's size: check it first.
    let meta = exr::meta::MetaData::read_from_buffered(Cursor::new(bytes), false)
        .map_err(|e| bad(format!("EXR: {e}")))?;
    super::read::check_sizes(&meta).map_err(bad)?;
    let image = exr::prelude::read()
        .no_deep_data()
        .largest_resolution_level()
        .all_channels()
        .all_layers()
        .all_attributes()
        .from_buffered(Cursor::new(bytes))
        .map_err(|e| bad(format!("EXR: {e}")))?;
    let mut size: Option<(usize, usize)> = None;
    let mut bufs: [Vec<f32>; 3] = Default::default();
    let mut seen = [[false; 4]; 3];
    const WIDTH: [usize; 3] = [4, 3, 3];
    for layer in &image.layer_data {
        let layer_name = layer
            .attributes
            .layer_name
            .as_ref()
            .map(|t| t.to_string())
            .unwrap_or_default();
        for ch in &layer.channel_data.list {
            let name = ch.name.to_string();
            let full = if layer_name.is_empty() || name.starts_with(&layer_name) {
                name
            } else {
                format!("{layer_name}.{name}")
            };
            let Some((pass, c)) = slot(&full) else {
                continue;
            };
            let (w, h) = (layer.size.width(), layer.size.height());
            match size {
                None => size = Some((w, h)),
                Some(s) if s != (w, h) => {
                    return Err(bad(format!(
                        "pass {full:?} is {w}x{h}, other passes are {}x{}",
                        s.0, s.1
                    )))
                }
                _ => {}
            }
            let buf = &mut bufs[pass];
            let stride = WIDTH[pass];
            if buf.is_empty() {
                *buf = vec![if pass == 0 { 1.0 } else { 0.0 }; w * h * stride];
            }
            let values: Box<dyn Iterator<Item = f32>> = match &ch.sample_data {
                FlatSamples::F16(v) => Box::new(v.iter().map(|x| x.to_f32())),
                FlatSamples::F32(v) => Box::new(v.iter().copied()),
                FlatSamples::U32(v) => Box::new(v.iter().map(|&x| x as f32)),
            };
            for (dst, v) in buf.chunks_exact_mut(stride).zip(values) {
                dst[c] = v;
            }
            seen[pass][c] = true;
        }
    }
    let Some((width, height)) = size else {
        return Err(bad("no combined pass (R, G, B channels)".into()));
    };
    for (pass, what, n) in [
        (0, "combined R, G, B", 3),
        (1, "Denoising Albedo", 3),
        (2, "Denoising Normal", 3),
    ] {
        if !seen[pass][..n].iter().all(|&s| s) {
            return Err(bad(format!(
                "no {what} pass: render with the denoising guides (denoise oidn)"
            )));
        }
    }
    let [rgba, albedo, normal] = bufs;
    Ok(Passes {
        width,
        height,
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
        assert_eq!(slot("ViewLayer.Combined.R"), Some((0, 0)));
        assert_eq!(slot("ViewLayer.Combined.A"), Some((0, 3)));
        assert_eq!(slot("A"), Some((0, 3)));
        assert_eq!(slot("ViewLayer.Denoising Albedo.B"), Some((1, 2)));
        assert_eq!(slot("ViewLayer.Denoising Normal.Y"), Some((2, 1)));
        assert_eq!(slot("ViewLayer.Denoising Depth.Z"), None);
        assert_eq!(slot("ViewLayer.Combined.RG"), None);
    }

    #[test]
    fn a_plain_rgba_file_lacks_the_guides() -> Result<()> {
        let p = std::env::temp_dir().join(format!("blurset-passes-{}.exr", std::process::id()));
        crate::image::exr::write::write_exr(&p, 3, 2, &[0.5; 24])?;
        let bytes = std::fs::read(&p).map_err(|e| Error::io("read", &p, e))?;
        let e = decode_passes(&bytes, &p).unwrap_err().to_string();
        assert!(
            e.contains("Denoising Albedo") && e.contains("denoise oidn"),
            "{e}"
        );
        Ok(())
    }
}
