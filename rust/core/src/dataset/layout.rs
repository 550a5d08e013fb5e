//! The names a build gives its parts on disk: setting directories, image files and
//! the marker of a complete setting.

/// The marker a setting directory gets last, when it is complete.
pub const MARKER: &str = ".complete";

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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_and_azimuths() {
        assert_eq!(setting_name("chair", 90.0), "chair_090");
        assert_eq!(setting_name("a", 359.6), "a_360");
        assert_eq!(theta0s(4), [0.0, 90.0, 180.0, 270.0]);
        assert_eq!(theta0s(3)[1], 120.0);
    }

    #[test]
    fn image_names_sort_in_view_order() {
        assert_eq!(image_name(7, 34), "007.png");
        assert_eq!(image_name(7, 1500), "0007.png");
    }
}
