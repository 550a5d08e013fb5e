//! The pixels Cycles has to trace for one camera: where the object can appear, widened by
//! the reach of the pixel filter. Every other pixel's camera ray leaves the scene at once
//! and sees only the transparent film, 0 in all four channels, so a render restricted to
//! the region has a full render's pixels (same pixel coordinates, so the same sample
//! sequences) without tracing empty space, and Cycles' per-render buffer work shrinks
//! with it (issue 16).
use glam::{DMat4, DVec3};

/// How far outside its own square a pixel's camera rays can land: Cycles samples the
/// pixel filter (Blackman-Harris, 1.5 px wide, set by the worker's scene set-up) around
/// the pixel centre, i.e. up to 0.25 px past the pixel's edge. Rounded up, with one more
/// pixel for Blender turning the border into whole pixels.
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

/// What one more Blender render call costs, in pixel-frames of an image region at
/// `samples` per frame: a call costs ≈ 31 ms of CPU (session set-up, result transfer),
/// a pixel ≈ 0.28 µs per frame plus ≈ 0.155 µs per sample where it sees only the
/// background (bench/bench_blur_cost.py, 512², 2026-11-30). Only the split of frames into
/// calls depends on it, never a pixel.
pub fn call_cost_px(samples: u32) -> f64 {
    const CALL_S: f64 = 0.031;
    const PIXEL_FRAME_S: f64 = 0.28e-6;
    const PIXEL_SAMPLE_S: f64 = 0.155e-6;
    CALL_S / (PIXEL_FRAME_S + PIXEL_SAMPLE_S * samples as f64)
}

fn union(a: Option<Region>, b: Option<Region>) -> Option<Region> {
    let (a, b) = (a?, b?);
    Some([
        a[0].min(b[0]),
        a[1].min(b[1]),
        a[2].max(b[2]),
        a[3].max(b[3]),
    ])
}

fn area(r: Option<Region>, size: u32) -> f64 {
    r.map_or((size as f64).powi(2), |r| {
        (r[2] - r[0]) as f64 * (r[3] - r[1]) as f64
    })
}

/// Split the consecutive frames of one image (their own regions, None: the whole image)
/// into render calls. Blender reads the region once per call, so a call renders all its
/// frames in the union of their regions: one call for frames that barely move, more when
/// the union of a moving camera's regions would trace more empty pixels than a call
/// costs. Returns each call's frame range and region; the partition minimizes
/// Σ calls (call_cost + frames · union area), exactly (dynamic programming).
pub fn render_calls(
    regions: &[Option<Region>],
    size: u32,
    call_cost: f64,
) -> Vec<(std::ops::Range<usize>, Option<Region>)> {
    let n = regions.len();
    // best[j]: cheapest split of frames 0..j; from[j]: where its last call starts.
    let mut best = vec![0.0f64; n + 1];
    let mut from = vec![0usize; n + 1];
    for j in 1..=n {
        best[j] = f64::INFINITY;
        let mut u = regions[j - 1];
        for i in (0..j).rev() {
            if i + 1 < j {
                u = union(u, regions[i]);
            }
            let c = best[i] + call_cost + (j - i) as f64 * area(u, size);
            if c < best[j] {
                (best[j], from[j]) = (c, i);
            }
        }
    }
    let mut calls = Vec::new();
    let mut j = n;
    while j > 0 {
        let i = from[j];
        let u = regions[i..j]
            .iter()
            .skip(1)
            .fold(regions[i], |u, r| union(u, *r));
        calls.push((i..j, u));
        j = i;
    }
    calls.reverse();
    calls
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

    #[test]
    fn frames_that_barely_move_share_one_call_and_far_ones_split() {
        let a = Some([10, 10, 50, 50]);
        let b = Some([11, 10, 51, 50]);
        let far = Some([400, 400, 440, 440]);
        let calls = render_calls(&[a, b, a, b], 512, call_cost_px(4));
        assert_eq!(calls, vec![(0..4, Some([10, 10, 51, 50]))]);
        // Two groups far apart: their union would trace ~150k empty pixels per frame.
        let calls = render_calls(&[a, b, far, far], 512, call_cost_px(4));
        assert_eq!(
            calls.iter().map(|c| c.0.clone()).collect::<Vec<_>>(),
            vec![0..2, 2..4]
        );
        // A frame without a region makes its call whole.
        let calls = render_calls(&[a, None], 512, 1e12);
        assert_eq!(calls, vec![(0..2, None)]);
        assert!(render_calls(&[], 512, 1.0).is_empty());
    }

    proptest::proptest! {
        #[test]
        fn calls_cover_the_frames_in_order_and_contain_their_regions(
            rs in proptest::collection::vec(
                proptest::option::weighted(0.9, (0u32..500, 0u32..500, 1u32..60, 1u32..60)),
                0..40,
            ),
            cost in 0.0f64..1e6,
        ) {
            let regions: Vec<Option<Region>> = rs
                .iter()
                .map(|r| r.map(|(x, y, w, h)| [x, y, (x + w).min(512), (y + h).min(512)]))
                .collect();
            let calls = render_calls(&regions, 512, cost);
            let mut next = 0;
            for (range, u) in &calls {
                proptest::prop_assert_eq!(range.start, next);
                proptest::prop_assert!(range.end > range.start);
                next = range.end;
                for r in &regions[range.clone()] {
                    match (r, u) {
                        (Some(r), Some(u)) => proptest::prop_assert!(
                            u[0] <= r[0] && u[1] <= r[1] && r[2] <= u[2] && r[3] <= u[3]
                        ),
                        (None, u) => proptest::prop_assert!(u.is_none()),
                        (Some(_), None) => {}
                    }
                }
            }
            proptest::prop_assert_eq!(next, regions.len());
            // Never worse than one call, nor than one call per frame.
            let total = |calls: &[(std::ops::Range<usize>, Option<Region>)]| -> f64 {
                calls.iter().map(|(r, u)| cost + r.len() as f64 * area(*u, 512)).sum()
            };
            let one = render_calls(&regions, 512, f64::INFINITY);
            let each: Vec<_> = regions.iter().enumerate().map(|(k, r)| (k..k + 1, *r)).collect();
            if !regions.is_empty() {
                let t = total(&calls);
                let single = regions.iter().skip(1).fold(regions[0], |u, r| union(u, *r));
                proptest::prop_assert!(t <= cost + regions.len() as f64 * area(single, 512) + 1e-6);
                proptest::prop_assert!(t <= total(&each) + 1e-6);
                proptest::prop_assert_eq!(one.len(), 1);
            }
        }
    }
}
