//! The names of a build's parts (settings, levels, images, gains) and the indices of
//! its held-out views: pure functions of numbers and ids, below every module that
//! writes or plans (`plan`, `image`, `noise`, `dataset`). What is on disk and what
//! "complete" means stays in `dataset::layout`.

/// The level directory of the sharp image.
pub const SHARP: &str = "sharp";
/// Largest level of any kind a build can write.
pub const MAX_LEVEL: u32 = 64;

/// The files and folders of the layout, named here only: every reader and writer (the
/// core's and Python's, through `blurset.layout`) spells them with these.
pub mod files {
    /// A setting's record (views, poses, sampling, object).
    pub const META: &str = "meta.json";
    /// A build's record (config, counts, provisional until the run finishes).
    pub const DATASET: &str = "dataset.json";
    /// A build's train/test split of settings and held-out views.
    pub const SPLITS: &str = "splits.json";
    /// A build's failed objects and settings, one JSON line each.
    pub const FAILURES: &str = "failures.jsonl";
    /// LLFF poses and bounds of one image folder's views.
    pub const POSES_BOUNDS: &str = "poses_bounds.npy";
    /// nerfstudio's camera file (exports).
    pub const TRANSFORMS: &str = "transforms.json";
    /// A noisy scene's record (gain, noise parameters, source).
    pub const NOISE: &str = "noise.json";
    /// The record of `blurset noise` over a build.
    pub const NOISE_DATASET: &str = "noise_dataset.json";
    /// The record of `blurset noise` over one LLFF scene.
    pub const NOISE_SCENE: &str = "noise_scene.json";
    /// The record of `blurset export`.
    pub const EXPORT: &str = "export.json";
    /// The record of `blurset stats`.
    pub const STATS: &str = "stats.json";
    /// The full-size 8-bit images of a level or scene.
    pub const IMAGES: &str = "images";
    /// The full-size linear EXRs of a level (`--write-linear`).
    pub const LINEAR: &str = "linear";
    /// A build's demo objects (`--demo`), written beside its settings.
    pub const DEMO_OBJECTS: &str = ".demo_objects";
}

/// The private folder an object's worker writes its scratch in (`.work-<uid>`).
pub fn work_dir(uid: &str) -> String {
    format!("{WORK_PREFIX}{uid}")
}

/// What every object's scratch folder name starts with.
pub const WORK_PREFIX: &str = ".work-";

/// The lock a build holds while it builds one object (`.lock-<uid>`).
pub fn object_lock(uid: &str) -> String {
    format!("{OBJECT_LOCK_PREFIX}{uid}")
}

/// What every object lock's name starts with.
pub const OBJECT_LOCK_PREFIX: &str = ".lock-";

/// The linear EXR of an image (`007.png` → `007.exr`), in a level's `linear/`.
pub fn linear_name(image: &str) -> String {
    let stem = image.strip_suffix(".png").unwrap_or(image);
    format!("{stem}.exr")
}

/// The image folder at downsampling factor `factor`: `images` at 1, else `images_<f>`
/// (the LLFF loaders' names).
pub fn images_dir(factor: u32) -> String {
    if factor <= 1 {
        files::IMAGES.to_string()
    } else {
        format!("{}_{factor}", files::IMAGES)
    }
}

/// The per-view outputs besides colour a build can write (`--passes`), in the order
/// they are listed: depth along the viewing axis, world-space normals, object masks.
pub const PASSES: [&str; 3] = ["depth", "normal", "mask"];

/// The passes a geometry render gives (one per view and size); the mask comes from the
/// sharp image's coverage.
pub const RENDERED_PASSES: [&str; 2] = ["depth", "normal"];

/// The folder of a pass in the sharp level at downsampling factor `factor` (`depth`,
/// `normals`, `masks`; `depth_4`, …, as `images_4` beside `images`).
pub fn pass_dir(pass: &str, factor: u32) -> String {
    let base = match pass {
        "normal" => "normals",
        "mask" => "masks",
        other => other,
    };
    if factor <= 1 {
        base.to_string()
    } else {
        format!("{base}_{factor}")
    }
}

/// The file of view `image` (`007.png`) in a pass's folder: `007.exr` (depth, normals:
/// float), `007.png` (masks: 8-bit).
pub fn pass_file(pass: &str, image: &str) -> String {
    if pass == "mask" {
        image.to_string()
    } else {
        linear_name(image)
    }
}

/// nerfstudio's depth folder in an exported scene at downsampling factor `factor`:
/// `depths`, `depths_4` (its parser reads `depths_<f>/` when it downscales), holding the
/// depth pass as 16-bit millimetre PNGs.
pub fn nerfstudio_depth_dir(factor: u32) -> String {
    if factor <= 1 {
        "depths".to_string()
    } else {
        format!("depths_{factor}")
    }
}

/// The linear EXR folder at downsampling factor `factor`: `linear` or `linear_<f>`.
pub fn linear_dir(factor: u32) -> String {
    if factor <= 1 {
        files::LINEAR.to_string()
    } else {
        format!("{}_{factor}", files::LINEAR)
    }
}

/// `<uid>_<theta0>`: the directory of one setting, θ0 rounded to whole degrees.
pub fn setting_name(uid: &str, theta0_deg: f64) -> String {
    format!("{uid}_{:03}", theta0_deg.round() as i64)
}

/// The θ0 of each setting of an object: `n` azimuths evenly spaced from 0°.
pub fn theta0s(settings_per_object: usize) -> Vec<f64> {
    (0..settings_per_object)
        .map(|k| 360.0 * k as f64 / settings_per_object as f64)
        .collect()
}

/// Image file name of view `index` among `n`: zero-padded so sorted order is view order.
pub fn image_name(index: usize, n: usize) -> String {
    let width = n.saturating_sub(1).to_string().len().max(3);
    format!("{index:0width$}.png")
}

/// Every `stride`-th view index below `views` (the held-out views, LLFF's llffhold).
pub fn test_views(views: usize, stride: usize) -> Vec<usize> {
    (0..views).step_by(stride.max(1)).collect()
}

/// Directory name of a noise gain: `gain_4`, `gain_2.5` (Python's `%g` for fractions, so
/// 6 significant digits: two gains closer than that share a name and are refused).
pub fn gain_name(gain: f64) -> String {
    if gain.is_finite() && gain.fract() == 0.0 {
        format!("gain_{gain:.0}")
    } else {
        format!("gain_{}", format_g(gain))
    }
}

/// C's `%g` (precision 6), as Python's `format(x, "g")` writes it.
fn format_g(x: f64) -> String {
    if x.is_nan() {
        return "nan".into();
    }
    if x.is_infinite() {
        return if x > 0.0 { "inf" } else { "-inf" }.into();
    }
    if x == 0.0 {
        return if x.is_sign_negative() { "-0" } else { "0" }.into();
    }
    let sci = format!("{x:.5e}");
    let (mant, exp) = sci.split_once('e').unwrap_or((&sci, "0"));
    let exp: i32 = exp.parse().unwrap_or(0);
    let strip = |s: &str| -> String {
        if s.contains('.') {
            s.trim_end_matches('0').trim_end_matches('.').to_string()
        } else {
            s.to_string()
        }
    };
    if (-4..6).contains(&exp) {
        let decimals = (5 - exp) as usize;
        strip(&format!("{x:.decimals$}"))
    } else {
        let sign = if exp < 0 { '-' } else { '+' };
        format!("{}e{sign}{:02}", strip(mant), exp.abs())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn private_names_of_a_build() {
        assert_eq!(work_dir("abc"), ".work-abc");
        assert!(work_dir("abc").starts_with(WORK_PREFIX));
        assert_eq!(object_lock("abc"), ".lock-abc");
        assert!(object_lock("abc").starts_with(OBJECT_LOCK_PREFIX));
        assert_eq!(linear_name("007.png"), "007.exr");
        assert_eq!(linear_name(&image_name(7, 1500)), "0007.exr");
    }
}
