//! Defocus blur levels (issue 35): depth of field of a thin lens, which Cycles renders
//! natively (one render, the aperture sampled by the path tracer; no latent frames).
//!
//! Per view a focus distance s is drawn uniformly inside the object's depth range
//! [near, far] along the viewing axis, so part of the object is sharp. A point at depth z
//! then spreads over a circle of confusion of diameter
//!
//! ```text
//! c(z) = 2 · R · F · |1/z − 1/s|   pixels
//! ```
//!
//! (R the aperture radius in world units, F the focal length in pixels): the thin lens
//! with the lens at the camera centre, which is Cycles' model. Level l sets R so that the
//! largest circle on the object, at near or far, is [`coc_px`]`(l)`: 2^l px at 512 px,
//! scaled with the resolution (2, 4, 8, 16 px for levels 1–4), as the motion levels double
//! their blur level to level.
use crate::plan::degradation::{Degradation, RenderCx, ViewCx};
use crate::plan::render::{Dof, Render};
use crate::plan::kind::ImageKind;
use crate::rng::Stream;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// Defocus as a [`Degradation`]: one render per level at the view's pose and the sharp
/// image's samples, through the thin lens of its [`DefocusPlan`].
pub struct Defocus;

/// A view's defocus level, as the statistics read it from meta.json.
#[derive(Debug, Deserialize)]
pub struct DefocusStat {
    /// [smallest, largest] circle of confusion on the object, px.
    pub coc_px: [f64; 2],
}

impl Degradation for Defocus {
    type Level = DefocusPlan;
    type Record = DefocusPlan;
    type Read = DefocusStat;
    const NAME: &'static str = "defocus";
    /// Its blur levels use purposes 1..=MAX_LEVEL; its renders' seeds are those of
    /// levels 1000 + l.
    const PURPOSE: u64 = 1000;
    const STAT: (&'static str, &'static str, &'static str) = (
        "defocus_coc_px",
        "px",
        "largest circle of confusion (diameter) on the object at defocus level l: 2^l px at \
         512 px, scaled with the resolution (--defocus builds; one per defocused view)",
    );
    const FIGURE: (&'static str, &'static str) = (
        "Defocus blur extent per level",
        "largest circle of confusion on the object  (px at build resolution)",
    );
    const MEANS: &'static str = "the same views out of focus at level l";
    const MAX_LEVEL: u32 = MAX_DEFOCUS_LEVEL;
    const LEVEL_RANGE: &'static str = "level l blurs the object by circles of up to 2^l px \
        at 512 px; a higher level's are wider than the image";
    const OPTION_HELP: &'static str = "defocus levels 1 to 9, e.g. 1,2,3,4: defocus_<l>/ \
        beside the blur levels, each view focused inside the object's depth range and the \
        largest circle of confusion on the object 2^l px at 512 px (scaled with \
        --resolution)";

    fn kind(level: u32) -> ImageKind {
        ImageKind::Defocus(level)
    }

    fn plan_view(cx: &ViewCx, levels: &[u32]) -> BTreeMap<String, DefocusPlan> {
        plan_view(
            levels,
            cx.near,
            cx.far,
            cx.resolution,
            cx.fov_deg,
            &mut (cx.stream)(Self::PURPOSE),
            |level| (cx.seed)(Self::PURPOSE + u64::from(level), 0),
        )
    }

    fn renders(cx: &RenderCx, level: u32, d: &DefocusPlan) -> Vec<Render> {
        let exr = cx.exr_dir.join(format!("{:04}_d{level}.exr", cx.view));
        vec![Render {
            sample_offset: cx.pin.map(|_| 0),
            sample_sequence: cx.pin,
            dof: Some(Dof {
                focus_distance: d.focus_distance,
                aperture_radius: d.aperture_radius,
            }),
            ..Render::still(
                cx.view,
                Self::kind(level),
                cx.c2w,
                d.seed,
                exr.display().to_string(),
            )
        }]
    }

    fn record(l: &DefocusPlan) -> DefocusPlan {
        l.clone()
    }

    fn stat(d: &DefocusStat) -> Option<f64> {
        Some(d.coc_px[1])
    }
}

/// The width of the sensor the f-number refers to (Blender's default, 36 mm, fitted
/// horizontally): only the recorded f-number depends on it, never an image.
pub const SENSOR_WIDTH_MM: f64 = 36.0;

/// The resolution the circle-of-confusion sizes are stated at.
const COC_REFERENCE_PX: f64 = 512.0;

/// The highest defocus level: its largest circle of confusion, 2^9 = 512 px at 512 px,
/// is as wide as the image. A higher level would spread a point of the object over
/// more than the whole frame (level 31 asked for circles of 2^31 px), which no view
/// shows and no aperture in meta.json should claim.
pub const MAX_DEFOCUS_LEVEL: u32 = 9;

/// The largest circle of confusion on the object (diameter, pixels) of defocus level
/// `level` (1..=[`MAX_DEFOCUS_LEVEL`]) at `resolution` pixels wide: 2^level at 512 px,
/// scaled with the resolution.
pub fn coc_px(level: u32, resolution: u32) -> f64 {
    2f64.powi(level.min(MAX_DEFOCUS_LEVEL) as i32) * f64::from(resolution) / COC_REFERENCE_PX
}

/// The circle of confusion (diameter, pixels) of a point at depth `z` along the viewing
/// axis, for a lens of `aperture_radius` (world units) focused at `focus`, with a focal
/// length of `focal_px` pixels.
pub fn circle_of_confusion(z: f64, focus: f64, aperture_radius: f64, focal_px: f64) -> f64 {
    2.0 * aperture_radius * focal_px * (1.0 / z - 1.0 / focus).abs()
}

/// One defocus level of one view, as meta.json records it (`views[i].defocus[l]`).
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct DefocusPlan {
    /// Distance of the plane in focus along the viewing axis (world units): the view's,
    /// the same at every level.
    pub focus_distance: f64,
    /// Radius of the lens aperture (world units).
    pub aperture_radius: f64,
    /// The f-number of that aperture for a [`SENSOR_WIDTH_MM`] sensor at the build's
    /// field of view (focal length / aperture diameter).
    pub f_number: f64,
    /// The circle of confusion on the object (diameter, pixels): [smallest, largest]
    /// over its depth range; 0 at the plane in focus, which lies inside it.
    pub coc_px: [f64; 2],
    /// Cycles seed of the render.
    pub seed: u32,
}

/// The defocus levels of a view whose object spans depths [near, far] (its vertices,
/// not the LLFF bounds), drawn from `stream`: the focus distance once, then each level's
/// aperture. `seed(level)` gives each render its Cycles seed.
pub fn plan_view(
    levels: &[u32],
    near: f64,
    far: f64,
    resolution: u32,
    fov_deg: f64,
    stream: &mut Stream,
    seed: impl Fn(u32) -> u32,
) -> BTreeMap<String, DefocusPlan> {
    if levels.is_empty() {
        return BTreeMap::new();
    }
    let focus = stream.uniform_in(near, far);
    let half = (fov_deg.to_radians() / 2.0).tan();
    let focal_px = f64::from(resolution) / (2.0 * half);
    let lens_mm = SENSOR_WIDTH_MM / (2.0 * half);
    // The largest |1/z − 1/s| on the object: at its near or its far end. An object with
    // no depth extent is all in focus (a flat card facing the camera): no aperture
    // blurs it, so none is set.
    let spread = (1.0 / near - 1.0 / focus).max(1.0 / focus - 1.0 / far);
    levels
        .iter()
        .map(|&level| {
            let target = coc_px(level, resolution);
            let radius = if spread > 0.0 {
                target / (2.0 * focal_px * spread)
            } else {
                0.0
            };
            let largest = if spread > 0.0 { target } else { 0.0 };
            let plan = DefocusPlan {
                focus_distance: focus,
                aperture_radius: radius,
                f_number: if radius > 0.0 {
                    lens_mm * 1e-3 / (2.0 * radius)
                } else {
                    f64::INFINITY
                },
                coc_px: [0.0, largest],
                seed: seed(level),
            };
            (level.to_string(), plan)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_largest_circle_on_the_object_is_the_levels_size() {
        let mut s = Stream::new(7, 1);
        let plan = plan_view(&[1, 2, 3, 4], 1.5, 2.7, 512, 40.0, &mut s, |l| l);
        let f = 512.0 / (2.0 * 20f64.to_radians().tan());
        for (l, want) in [("1", 2.0), ("2", 4.0), ("3", 8.0), ("4", 16.0)] {
            let p = &plan[l];
            assert!(1.5 <= p.focus_distance && p.focus_distance <= 2.7);
            let at = |z| circle_of_confusion(z, p.focus_distance, p.aperture_radius, f);
            let largest = at(1.5).max(at(2.7));
            assert!((largest - want).abs() < 1e-9, "{l}: {largest}");
            assert!((p.coc_px[1] - want).abs() < 1e-12 && p.coc_px[0] == 0.0);
            assert!(at(p.focus_distance) < 1e-12);
            // f-number: focal length (mm) over the aperture's diameter (mm).
            let lens_mm = 36.0 / (2.0 * 20f64.to_radians().tan());
            assert!((p.f_number - lens_mm / (2.0 * p.aperture_radius * 1e3)).abs() < 1e-9);
        }
        // One focus per view; apertures double with the level.
        assert_eq!(plan["1"].focus_distance, plan["4"].focus_distance);
        assert!((plan["4"].aperture_radius / plan["1"].aperture_radius - 8.0).abs() < 1e-9);
        // Scaled with the resolution: 4 px at 256 px for level 3.
        assert!((coc_px(3, 256) - 4.0).abs() < 1e-12);
    }

    #[test]
    fn each_view_focuses_somewhere_inside_the_object_not_at_an_end() {
        // The focus is a uniform draw over (near, far): over many views it lies strictly
        // inside, covers both halves of the range, so both ends of the object are blurred
        // (a focus at near or far would leave that end sharp in every view).
        let (near, far) = (1.5, 2.7);
        let f = 512.0 / (2.0 * 20f64.to_radians().tan());
        let focuses: Vec<f64> = (0..64)
            .map(|view| {
                let mut s = Stream::new(11, view);
                let p = &plan_view(&[2], near, far, 512, 40.0, &mut s, |_| 0)["2"];
                let at = |z| circle_of_confusion(z, p.focus_distance, p.aperture_radius, f);
                assert!(at(near) > 1e-3 && at(far) > 1e-3, "view {view}: {p:?}");
                p.focus_distance
            })
            .collect();
        assert!(focuses.iter().all(|&s| near < s && s < far));
        let mid = (near + far) / 2.0;
        let below = focuses.iter().filter(|&&s| s < mid).count();
        assert!((16..=48).contains(&below), "{below} of 64 below the middle");
    }

    #[test]
    fn a_level_renders_once_at_the_views_pose_through_its_lens() {
        let mut s = Stream::new(3, 4);
        let plan = plan_view(&[2], 1.5, 2.7, 64, 40.0, &mut s, |l| 10 + l);
        let c2w = [[0.5; 4]; 4];
        let cx = RenderCx {
            view: 7,
            c2w,
            exr_dir: std::path::Path::new("/x"),
            pin: Some(99),
        };
        let r = crate::plan::degradation::kind_renders::<Defocus>(&cx, &plan);
        assert_eq!(r.len(), 1);
        let (r, p) = (&r[0], &plan["2"]);
        assert_eq!(
            (r.level.as_str(), r.kind),
            ("defocus_2", ImageKind::Defocus(2))
        );
        assert_eq!(
            (r.view, r.c2w, r.seed, r.out.as_str()),
            (7, c2w, 12, "/x/0007_d2.exr")
        );
        assert_eq!((r.sample_offset, r.sample_sequence), (Some(0), Some(99)));
        let dof = r.dof.expect("a lens");
        assert_eq!(dof.aperture_radius, p.aperture_radius);
        assert_eq!(dof.focus_distance, p.focus_distance);
        // The sharp image's count (None: the caller's) and a phase after the blur levels.
        assert_eq!(r.samples, None);
        assert!(r.phase > ImageKind::Blur(2).phase());
    }

    #[test]
    fn an_object_without_depth_is_all_in_focus() {
        let mut s = Stream::new(1, 2);
        let plan = plan_view(&[2], 2.0, 2.0, 64, 40.0, &mut s, |_| 0);
        assert_eq!(plan["2"].aperture_radius, 0.0);
        assert_eq!(plan["2"].coc_px, [0.0, 0.0]);
        assert!(plan_view(&[], 1.0, 2.0, 64, 40.0, &mut s, |_| 0).is_empty());
    }
}
