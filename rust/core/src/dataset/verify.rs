//! The expensive half of `blurset verify`: decode every image of a build in parallel
//! and compare its size with the one its meta.json promises. (Which files must exist
//! is decided by the caller from meta.json; this only reads pixels.)
use super::layout::{decode_exr_size, error_reason as reason};
use crate::error::Error;
use crate::image::io::read_image;
use rayon::prelude::*;
use std::path::PathBuf;

/// An image and the size it must have.
#[derive(Clone, Debug)]
pub struct ImageCheck {
    pub path: PathBuf,
    pub width: u32,
    pub height: u32,
}

/// What is wrong with each image (None when it decodes whole at its size), in order.
/// `.exr` files are read as linear EXRs (or depth EXRs), anything else as PNG/JPEG.
pub fn check_images(items: &[ImageCheck]) -> Vec<Option<String>> {
    items.par_iter().map(check_one).collect()
}

fn check_one(item: &ImageCheck) -> Option<String> {
    if !item.path.is_file() {
        return Some("missing".into());
    }
    let is_exr = item
        .path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("exr"));
    let size = if is_exr {
        // The file is read once, decoded as the cheap check of a rerun decodes it.
        std::fs::read(&item.path)
            .map_err(|e| Error::io("cannot open EXR", &item.path, e))
            .and_then(|bytes| decode_exr_size(&bytes, &item.path))
    } else {
        read_image(&item.path).map(|i| (i.width, i.height))
    };
    match size {
        Err(e) => Some(format!("does not decode ({})", reason(&e.to_string()))),
        Ok((w, h)) if (w, h) != (item.width, item.height) => Some(format!(
            "is {w}x{h}, expected {}x{}",
            item.width, item.height
        )),
        Ok(_) => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::image::io::write_png_rgb8;

    #[test]
    fn good_truncated_wrong_size_and_missing() -> crate::Result<()> {
        let d = std::env::temp_dir().join(format!("blurset-verify-{}", std::process::id()));
        let good = d.join("good.png");
        write_png_rgb8(&good, 8, 6, &[7u8; 8 * 6 * 3])?;
        let bytes = std::fs::read(&good).unwrap_or_default();
        let cut = d.join("cut.png");
        std::fs::write(&cut, &bytes[..bytes.len() / 2]).ok();
        let item = |p: &std::path::Path, w, h| ImageCheck {
            path: p.to_path_buf(),
            width: w,
            height: h,
        };
        let got = check_images(&[
            item(&good, 8, 6),
            item(&good, 6, 8),
            item(&cut, 8, 6),
            item(&d.join("none.png"), 8, 6),
        ]);
        assert_eq!(got[0], None);
        assert_eq!(got[1].as_deref(), Some("is 8x6, expected 6x8"));
        let cut_msg = got[2].clone().unwrap_or_default();
        assert!(cut_msg.starts_with("does not decode"), "{cut_msg}");
        assert!(!cut_msg.contains("cut.png"), "{cut_msg}");
        assert_eq!(got[3].as_deref(), Some("missing"));
        let _ = std::fs::remove_dir_all(&d);
        Ok(())
    }
}
