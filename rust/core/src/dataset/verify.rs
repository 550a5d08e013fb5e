//! The expensive half of `blurset verify`: decode every image of a build in parallel
//! and compare its size with the one its meta.json promises. (Which files must exist
//! is decided by the caller from meta.json; this only reads pixels.) The decodes in
//! flight together hold at most [`MAX_PARALLEL_DECODE_BYTES`] (or one image alone).
use super::layout::{decode_exr_size, error_reason as reason};
use crate::error::Error;
use crate::ground::limits::MAX_PARALLEL_DECODE_BYTES;
use crate::image::exr::read::{decode_cost as exr_decode_cost, header_size_other_than};
use crate::image::io::{image_info, read_image};
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
    let costs: Vec<u64> = items.par_iter().map(decode_cost).collect();
    let mut found = Vec::with_capacity(items.len());
    for batch in batches(&costs, MAX_PARALLEL_DECODE_BYTES) {
        found.par_extend(items[batch].par_iter().map(check_one));
    }
    found
}

fn is_exr(item: &ImageCheck) -> bool {
    item.path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("exr"))
}

/// The most bytes checking `item` may hold: an EXR's as its reader counts it, a PNG's
/// or JPEG's file and samples (what its header promises; its length when that does
/// not parse, as the decode then refuses it).
fn decode_cost(item: &ImageCheck) -> u64 {
    if is_exr(item) {
        return exr_decode_cost(&item.path);
    }
    let len = std::fs::metadata(&item.path).map_or(0, |m| m.len());
    image_info(&item.path).map_or(len, |(w, h, channels, bits)| {
        len + u64::from(w) * u64::from(h) * channels as u64 * u64::from(bits.div_ceil(8))
    })
}

/// `costs` cut into consecutive ranges whose sums stay within `budget` (a cost over it
/// is a range alone): the decodes of one range run in parallel, the ranges in turn.
fn batches(costs: &[u64], budget: u64) -> Vec<std::ops::Range<usize>> {
    let mut out = Vec::new();
    let (mut start, mut sum) = (0, 0u64);
    for (i, &c) in costs.iter().enumerate() {
        if i > start && sum.saturating_add(c) > budget {
            out.push(start..i);
            (start, sum) = (i, 0);
        }
        sum = sum.saturating_add(c);
    }
    if start < costs.len() {
        out.push(start..costs.len());
    }
    out
}

fn check_one(item: &ImageCheck) -> Option<String> {
    if !item.path.is_file() {
        return Some("missing".into());
    }
    let want = (item.width, item.height);
    let size = if is_exr(item) {
        // The file is read once, decoded as the cheap check of a rerun decodes it; a
        // header of another size is named before anything of its size is allocated.
        std::fs::read(&item.path)
            .map_err(|e| Error::io("cannot open EXR", &item.path, e))
            .and_then(|bytes| match header_size_other_than(&bytes, want) {
                Some(size) => Ok(size),
                None => decode_exr_size(&bytes, &item.path),
            })
    } else {
        read_image(&item.path).map(|i| (i.width, i.height))
    };
    match size {
        Err(e) => Some(format!("does not decode ({})", reason(&e.to_string()))),
        Ok((w, h)) if (w, h) != want => Some(format!(
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
    fn parallel_decodes_hold_at_most_the_budget_together() {
        let costs = [5u64, 3, 2, 9, 1, 1, 12, 0, 4];
        for budget in [1u64, 4, 8, 10, 12, 100] {
            let got = batches(&costs, budget);
            // Every image once, in order; a batch over the budget is one image alone.
            let flat: Vec<usize> = got.iter().flat_map(|r| r.clone()).collect();
            assert_eq!(flat, (0..costs.len()).collect::<Vec<_>>(), "{budget}");
            for r in &got {
                let sum: u64 = costs[r.clone()].iter().sum();
                assert!(sum <= budget || r.len() == 1, "{budget}: {r:?} holds {sum}");
            }
        }
        assert_eq!(batches(&costs, 100), vec![0..costs.len()]);
        assert_eq!(batches(&[], 1), Vec::<std::ops::Range<usize>>::new());
    }

    #[test]
    fn an_images_cost_is_what_its_decode_holds() -> crate::Result<()> {
        let d = std::env::temp_dir().join(format!("blurset-cost-{}", std::process::id()));
        std::fs::create_dir_all(&d).ok();
        let item = |p: &std::path::Path| ImageCheck {
            path: p.to_path_buf(),
            width: 0,
            height: 0,
        };
        let png = d.join("a.png");
        write_png_rgb8(&png, 40, 30, &[7u8; 40 * 30 * 3])?;
        let len = std::fs::metadata(&png).map_or(0, |m| m.len());
        assert_eq!(decode_cost(&item(&png)), len + 40 * 30 * 3);
        let exr = d.join("a.exr");
        crate::image::exr::write::write_exr(&exr, 40, 30, &[0.5; 40 * 30 * 4])?;
        let len = std::fs::metadata(&exr).map_or(0, |m| m.len());
        // The file, its samples (4 channels of at least 2 bytes) and the f32 frame.
        let cost = decode_cost(&item(&exr));
        assert!(
            cost >= len + 40 * 30 * (8 + 16) && cost <= len + 40 * 30 * 32,
            "{cost}"
        );
        // A header that promises more than its file can hold costs the file alone.
        let mut huge = std::fs::read(&exr).unwrap_or_default();
        let name = b"dataWindow\0box2i\0";
        if let Some(i) = huge.windows(name.len()).position(|x| x == name) {
            let at = i + name.len() + 4;
            huge[at + 8..at + 16].copy_from_slice(&[0xFF, 0x3F, 0, 0, 0xFF, 0x3F, 0, 0]);
        }
        std::fs::write(&exr, &huge).ok();
        assert_eq!(decode_cost(&item(&exr)), huge.len() as u64);
        let _ = std::fs::remove_dir_all(&d);
        Ok(())
    }

    #[test]
    fn an_exr_of_another_size_is_named_from_its_header() -> crate::Result<()> {
        let d = std::env::temp_dir().join(format!("blurset-verify-size-{}", std::process::id()));
        std::fs::create_dir_all(&d).ok();
        let exr = d.join("a.exr");
        crate::image::exr::write::write_exr(&exr, 40, 30, &[0.5; 40 * 30 * 4])?;
        // A header that claims 16384² (its blocks cannot hold it): named by its size,
        // read from the header, where a decode would have refused the blocks.
        let mut big = std::fs::read(&exr).unwrap_or_default();
        let name = b"dataWindow\0box2i\0";
        if let Some(i) = big.windows(name.len()).position(|x| x == name) {
            let at = i + name.len() + 4;
            big[at + 8..at + 16].copy_from_slice(&[0xFF, 0x3F, 0, 0, 0xFF, 0x3F, 0, 0]);
        }
        let big_path = d.join("big.exr");
        std::fs::write(&big_path, &big).ok();
        let item = |p: &std::path::Path| ImageCheck {
            path: p.to_path_buf(),
            width: 40,
            height: 30,
        };
        let got = check_images(&[item(&exr), item(&big_path)]);
        assert_eq!(got[0], None);
        assert_eq!(got[1].as_deref(), Some("is 16384x16384, expected 40x30"));
        let _ = std::fs::remove_dir_all(&d);
        Ok(())
    }

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
