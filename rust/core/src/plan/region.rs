//! The pixels Cycles has to trace for one camera: where the object can appear, widened by
//! the reach of the pixel filter. Every other pixel's camera ray leaves the scene at once
//! and sees only the transparent film, 0 in all four channels, so a render restricted to
//! the region has a full render's pixels (same pixel coordinates, so the same sample
//! sequences) without tracing empty space, and Cycles' per-render buffer work shrinks
//! with it (issue 16).
use glam::{DMat4, DVec3};

/// How far outside its own square a pixel's camera rays can land: Cycles samples the
/// pixel filter (Blackman-Harris, 1.5 px wide) around the pixel centre, i.e. up to 0.75 px
/// past the pixel's edge. Rounded up, with one more pixel for Blender turning the border
/// into whole pixels.
pub const FILTER_REACH_PX: f64 = 2.0;

/// A half-open pixel rectangle `[x0, x1) × [y0, y1)`, y down from the top row.
pub type Region = [u32; 4];

/// The region of a `size`² image (focal `focal` px, OpenGL camera `c2w`) that can see the
/// axis-aligned box `lo`–`hi`; None when the whole image must be rendered: a box corner
/// at or behind the camera plane (the projection of the box is then unbounded), or a
/// region that covers the image anyway.
pub fn object_region(c2w: &DMat4, lo: DVec3, hi: DVec3, focal: f64, size: u32) -> Option<Region> {
    let w2c = c2w.inverse();
    let (mut x0, mut y0, mut x1, mut y1) = (
        f64::INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::NEG_INFINITY,
    );
    for i in 0..8 {
        let corner = DVec3::new(
            if i & 1 == 0 { lo.x } else { hi.x },
            if i & 2 == 0 { lo.y } else { hi.y },
            if i & 4 == 0 { lo.z } else { hi.z },
        );
        let p = w2c.transform_point3(corner);
        // In front of the camera (NaN included in "not"): otherwise unbounded.
        if p.z.is_nan() || p.z >= -1e-9 {
            return None;
        }
        let (u, v) = (
            0.5 * size as f64 + focal * p.x / -p.z,
            0.5 * size as f64 - focal * p.y / -p.z,
        );
        x0 = x0.min(u);
        x1 = x1.max(u);
        y0 = y0.min(v);
        y1 = y1.max(v);
    }
    let n = size as f64;
    let clamp = |x: f64| x.clamp(0.0, n) as u32;
    let r = [
        clamp((x0 - FILTER_REACH_PX).floor()),
        clamp((y0 - FILTER_REACH_PX).floor()),
        clamp((x1 + FILTER_REACH_PX).ceil()),
        clamp((y1 + FILTER_REACH_PX).ceil()),
    ];
    // An empty region (the box is off screen) still renders: Cycles needs ≥ 1 pixel, and
    // the full image is the safe answer for a view that should not exist anyway.
    let full = r == [0, 0, size, size];
    (r[0] < r[2] && r[1] < r[3] && !full).then_some(r)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plan::camera::{focal_px, orbit_c2w};

    fn unit_box() -> (DVec3, DVec3) {
        (DVec3::splat(-0.5), DVec3::splat(0.5))
    }

    #[test]
    fn centred_box_gives_a_centred_region_with_the_filter_margin() {
        let (lo, hi) = unit_box();
        let c2w = orbit_c2w(4.0, 90.0, 0.0);
        let f = focal_px(512, 40.0);
        let r = object_region(&c2w, lo, hi, f, 512).expect("region");
        // Symmetric about the centre, inside the image, and wider than the box's own
        // projection by at least the filter reach on every side.
        assert_eq!(r[0] + r[2], 512, "{r:?}");
        assert!(r[0] > 0 && r[2] < 512 && r[1] > 0 && r[3] < 512, "{r:?}");
        let w2c = c2w.inverse();
        for i in 0..8 {
            let c = DVec3::new(
                if i & 1 == 0 { -0.5 } else { 0.5 },
                if i & 2 == 0 { -0.5 } else { 0.5 },
                if i & 4 == 0 { -0.5 } else { 0.5 },
            );
            let p = w2c.transform_point3(c);
            let u = 256.0 + f * p.x / -p.z;
            let v = 256.0 - f * p.y / -p.z;
            assert!(u - r[0] as f64 >= FILTER_REACH_PX && r[2] as f64 - u >= FILTER_REACH_PX);
            assert!(v - r[1] as f64 >= FILTER_REACH_PX && r[3] as f64 - v >= FILTER_REACH_PX);
        }
    }

    #[test]
    fn a_box_the_camera_sits_in_or_fills_the_frame_renders_everything() {
        let (lo, hi) = unit_box();
        let f = focal_px(64, 40.0);
        // Camera inside the box: corners behind the camera plane.
        assert_eq!(
            object_region(&orbit_c2w(0.1, 90.0, 0.0), lo, hi, f, 64),
            None
        );
        // Close enough that the box overflows the image on all sides.
        assert_eq!(
            object_region(&orbit_c2w(0.9, 90.0, 0.0), lo, hi, f, 64),
            None
        );
        // Off to the side but in front: a region clamped to the image.
        let far = object_region(&orbit_c2w(30.0, 90.0, 0.0), lo, hi, f, 64).expect("region");
        assert!(far[2] - far[0] < 16 && far[3] - far[1] < 16, "{far:?}");
    }
}
