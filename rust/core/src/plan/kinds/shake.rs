//! Camera shake levels (issue 49): a hand-held camera turning about its centre during
//! the exposure, rendered like a blur level (latent frames averaged, or one Cycles motion
//! blur render along keys), recorded in meta.json as `views[i].shake["<l>"]`.
//!
//! Per view the image centre follows a smooth random path d(t) = (u(t), v(t)) px over
//! the exposure t ∈ [0, 1]: each coordinate a sum of [`HARMONICS`] sinusoids
//! c_j · sin(2π j t + φ_j), c_j uniform in [0, 1/j] (the higher, the weaker: smooth) and
//! φ_j uniform, drawn once per view. Whole periods average to zero, so the mean pose
//! over the exposure is the written pose. Level l scales the path so the largest
//! displacement of the image centre is [`amplitude_px`]`(l)`: 2^(l+1) px at 512 px
//! (4, 8, 16, 32 px for levels 1–4), scaled with the resolution. The camera turns by
//! yaw atan(u / F) and pitch atan(v / F) (F the focal length in pixels), which moves the
//! image centre by d to first order in the angles.
use crate::error::Result;
use crate::plan::choices::{BlurMethod, LatentSampling};
use crate::plan::degradation::{
    fewest_frames, Degradation, RenderCx, ViewCx, MOTION_KEY_TOLERANCE_PX, MOTION_STEPS_RANGE,
};
use crate::plan::render::{Motion, Render};
use crate::plan::sampling_config::SamplingConfig;
use crate::plan::spec::config_error;
use crate::plan::kind::ImageKind;
use glam::{DMat3, DMat4};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::f64::consts::TAU;

/// Sinusoids per coordinate of the path.
pub const HARMONICS: usize = 3;

/// The fewest averaged frames a shake level takes: evenly spread frames cancel each
/// harmonic j (their mean is the written pose) only when their count does not divide j.
pub const MIN_FRAMES: usize = HARMONICS + 1;

/// The highest shake level: its largest displacement, 2^8 = 256 px at 512 px, is half
/// the image; a higher level would turn the object out of the frame.
pub const MAX_SHAKE_LEVEL: u32 = 7;

/// The resolution the amplitudes are stated at.
const REFERENCE_PX: f64 = 512.0;

/// Points of the path its largest displacement and its length are measured on.
const GRID: usize = 512;

/// The largest displacement of the image centre (px) at shake level `level`
/// (1..=[`MAX_SHAKE_LEVEL`]) at `resolution` pixels wide.
pub fn amplitude_px(level: u32, resolution: u32) -> f64 {
    2f64.powi(level.min(MAX_SHAKE_LEVEL) as i32 + 1) * f64::from(resolution) / REFERENCE_PX
}

/// The camera's turn at one instant of the exposure.
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ShakePose {
    /// Position in the exposure, 0..=1.
    pub t: f64,
    /// Turn about the camera's up axis (degrees).
    pub yaw_deg: f64,
    /// Turn about the camera's right axis (degrees).
    pub pitch_deg: f64,
}

/// One shake level of one view, as meta.json records it (`views[i].shake[l]`).
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ShakePlan {
    /// The largest displacement of the image centre from the written pose (px).
    pub amplitude_px: f64,
    /// The length of the image centre's path over the exposure (px).
    pub path_px: f64,
    /// `average` (latent frames) or `motion_blur` (one render along motion keys).
    pub method: BlurMethod,
    /// Cycles samples of each render.
    pub samples_per_frame: u32,
    /// Under latents auto: the largest gap (px) between consecutive latent frames on
    /// the image centre's path, within `max_ghost_px` unless `latents_max` capped them.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_gap_px: Option<f64>,
    /// The camera at each latent frame (average) or motion key (motion blur).
    pub poses: Vec<ShakePose>,
    /// Cycles seed of each render (one under motion blur).
    pub seeds: Vec<u32>,
    /// Under sample subsets: each frame's first sample in a sequence of
    /// `sample_sequence` samples on the view's sharp seed.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub sample_offsets: Vec<u32>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sample_sequence: Option<u32>,
    /// Motion blur: Cycles motion steps (2^steps + 1 keys).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub motion_steps: Option<u32>,
}

/// A view's shake level, as the statistics read it from meta.json.
#[derive(Debug, Deserialize)]
pub struct ShakeStat {
    pub path_px: f64,
}

/// One view's path before scaling: per coordinate, (c_j, φ_j) of each harmonic.
struct Path([[(f64, f64); HARMONICS]; 2]);

impl Path {
    fn draw(stream: &mut crate::rng::Stream) -> Path {
        let mut coord = || {
            std::array::from_fn(|j| {
                let c = stream.uniform_in(0.0, 1.0 / (j + 1) as f64);
                (c, stream.uniform_in(0.0, TAU))
            })
        };
        Path([coord(), coord()])
    }

    /// d(t) before scaling.
    fn at(&self, t: f64) -> [f64; 2] {
        self.0.map(|h| {
            h.iter()
                .enumerate()
                .map(|(j, (c, phi))| c * (TAU * (j + 1) as f64 * t + phi).sin())
                .sum()
        })
    }

    /// (largest |d|, length of d) on the grid, before scaling.
    fn measure(&self) -> (f64, f64) {
        let pts: Vec<[f64; 2]> = (0..=GRID)
            .map(|i| self.at(i as f64 / GRID as f64))
            .collect();
        let largest = pts.iter().map(|p| p[0].hypot(p[1])).fold(0.0, f64::max);
        let length = pts
            .windows(2)
            .map(|w| (w[1][0] - w[0][0]).hypot(w[1][1] - w[0][1]))
            .sum();
        (largest, length)
    }
}

/// The fewest motion steps whose keys, joined linearly, stay within
/// [`MOTION_KEY_TOLERANCE_PX`] of the path `d` (px) at the middle of every interval.
fn motion_steps(d: impl Fn(f64) -> [f64; 2]) -> u32 {
    let (lo, hi) = MOTION_STEPS_RANGE;
    (lo..=hi)
        .find(|&steps| {
            let n = 1u32 << steps;
            (0..n).all(|k| {
                let (a, b) = (f64::from(k) / f64::from(n), f64::from(k + 1) / f64::from(n));
                let (pa, pb, pm) = (d(a), d(b), d((a + b) / 2.0));
                let err = (pm[0] - (pa[0] + pb[0]) / 2.0).hypot(pm[1] - (pa[1] + pb[1]) / 2.0);
                err <= MOTION_KEY_TOLERANCE_PX
            })
        })
        .unwrap_or(hi)
}

/// The latent frames' times, evenly spread over the exposure, and the largest gap (px)
/// between consecutive frames on the path `d`, the two uncovered ends counting as one
/// gap (as a blur level's, `motion::max_gap`). The build's `latents` frames, or under
/// latents auto the fewest m <= `latents_max` whose gap is within `max_ghost_px`, so a
/// shake image is a smear to the same bound as a blur image, not a few ghost copies.
fn frame_times(cx: &ViewCx, d: impl Fn(f64) -> [f64; 2]) -> (Vec<f64>, f64) {
    let dist = |a: [f64; 2], b: [f64; 2]| (a[0] - b[0]).hypot(a[1] - b[1]);
    let times = |m: usize| -> Vec<f64> { (0..m).map(|k| (k as f64 + 0.5) / m as f64).collect() };
    let gap = |ts: &[f64]| {
        let ends = dist(d(0.0), d(ts[0])) + dist(d(ts[ts.len() - 1]), d(1.0));
        ts.windows(2)
            .map(|w| dist(d(w[0]), d(w[1])))
            .fold(ends, f64::max)
    };
    let cfg = cx.cfg;
    if !cfg.latents_auto {
        let ts = times(cx.latents.max(1));
        let g = gap(&ts);
        return (ts, g);
    }
    // Evenly spread frames leave gaps of about path / m, so the search starts there.
    let length: f64 = (0..GRID)
        .map(|i| dist(d(i as f64 / GRID as f64), d((i + 1) as f64 / GRID as f64)))
        .sum();
    let first = ((length / cfg.max_ghost_px - 1e-9).ceil() as usize)
        .min(cfg.latents_max)
        .max(MIN_FRAMES);
    fewest_frames(first, cfg.latents_max, cfg.max_ghost_px, |m| {
        let ts = times(m);
        let g = gap(&ts);
        (ts, g)
    })
}

/// (samples of each render, sample blocks) of a level of `own` frames (latents auto),
/// else the build's exposure, which is every level's.
fn exposure(cx: &ViewCx, own: Option<usize>) -> (u32, Option<(u32, Vec<u32>)>) {
    match own {
        Some(m) => (
            cx.cfg.samples_per_frame(m),
            (cx.cfg.latent_sampling == LatentSampling::Subsets).then(|| cx.cfg.sample_blocks(m)),
        ),
        None => (cx.samples_per_frame, cx.blocks.clone()),
    }
}

/// Camera shake as a [`Degradation`].
pub struct Shake;

impl Degradation for Shake {
    type Level = ShakePlan;
    type Record = ShakePlan;
    type Read = ShakeStat;
    const NAME: &'static str = "shake";
    const PURPOSE: u64 = 2000;
    const STAT: (&'static str, &'static str, &'static str) = (
        "shake_path_px",
        "px",
        "length of the image centre's path over the exposure at shake level l, whose \
         largest displacement is 2^(l+1) px at 512 px, scaled with the resolution (--shake \
         builds; one per shaken view)",
    );
    const FIGURE: (&'static str, &'static str) = (
        "Camera shake per level",
        "length of the image centre's path over the exposure  (px at build resolution)",
    );
    const MEANS: &'static str = "the same views shaken by a hand-held camera at level l";
    /// The camera turns during the exposure: the object covers more than the sharp
    /// silhouette.
    const OWN_MASKS: bool = true;
    const MAX_LEVEL: u32 = MAX_SHAKE_LEVEL;
    const LEVEL_RANGE: &'static str = "level l moves the image centre up to 2^(l+1) px at \
        512 px; a higher level turns the object out of the frame";
    const OPTION_HELP: &'static str = "camera shake levels 1 to 7, e.g. 1,2,3,4: shake_<l>/ \
        beside the blur levels, the camera turning about its centre during the exposure \
        along a smooth random path that moves the image centre up to 2^(l+1) px at 512 px \
        (scaled with --resolution), rendered as the blur levels are (--blur-method); none \
        by default";

    fn kind(level: u32) -> ImageKind {
        ImageKind::Shake(level)
    }

    /// An exposure of as many frames as a blurry image can have.
    fn frames_per_level(cfg: &SamplingConfig) -> usize {
        cfg.max_latents()
    }

    /// Averaged frames need at least [`MIN_FRAMES`] of them: with fewer, the frames'
    /// mean is not the written pose.
    fn check(cfg: &SamplingConfig, levels: &[u32]) -> Result<()> {
        if cfg.blur_method == BlurMethod::MotionBlur {
            return Ok(());
        }
        let (option, most) = if cfg.latents_auto {
            ("latents_max", cfg.latents_max)
        } else {
            ("latents", cfg.latents)
        };
        if most >= MIN_FRAMES {
            return Ok(());
        }
        Err(config_error(
            option,
            format!(
                "{most}: shake levels ({levels:?}) average their frames to the written pose \
                 only from {MIN_FRAMES} frames on (each axis of the path is {HARMONICS} \
                 harmonics); give {MIN_FRAMES} or more, or blur_method motion_blur"
            ),
        ))
    }

    fn plan_view(cx: &ViewCx, levels: &[u32]) -> BTreeMap<String, ShakePlan> {
        if levels.is_empty() {
            return BTreeMap::new();
        }
        let path = Path::draw(&mut (cx.stream)(Self::PURPOSE));
        levels
            .iter()
            .map(|&level| (level.to_string(), plan_level(cx, &path, level)))
            .collect()
    }

    fn renders(cx: &RenderCx, level: u32, p: &ShakePlan) -> Vec<Render> {
        let base = DMat4::from_cols_array_2d(&cx.c2w).transpose();
        let c2w = |pose: &ShakePose| {
            let turn = DMat3::from_rotation_y(pose.yaw_deg.to_radians())
                * DMat3::from_rotation_x(pose.pitch_deg.to_radians());
            (base * DMat4::from_mat3(turn))
                .transpose()
                .to_cols_array_2d()
        };
        let prefix = cx.exr_dir.join(format!("{:04}_sh{level}", cx.view));
        let prefix = prefix.display().to_string();
        // Under sample subsets a frame renders its block of the sequence the build is
        // pinned to (or the level's own).
        let block = |k: usize| match p.sample_offsets.get(k) {
            Some(&offset) => (Some(offset), cx.pin.or(p.sample_sequence)),
            None => (None, None),
        };
        let kind = Self::kind(level);
        if let Some(steps) = p.motion_steps {
            let keys: Vec<_> = p.poses.iter().map(c2w).collect();
            let (sample_offset, sample_sequence) = block(0);
            let first = Render::still(
                cx.view,
                kind,
                keys[0],
                p.seeds[0],
                format!("{prefix}_mb.exr"),
            );
            return vec![Render {
                samples: Some(p.samples_per_frame),
                sample_offset,
                sample_sequence,
                motion: Some(Motion { steps, keys }),
                ..first
            }];
        }
        p.poses
            .iter()
            .enumerate()
            .map(|(k, pose)| {
                let (sample_offset, sample_sequence) = block(k);
                let out = format!("{prefix}_{k:04}.exr");
                Render {
                    samples: Some(p.samples_per_frame),
                    sample_offset,
                    sample_sequence,
                    ..Render::still(cx.view, kind, c2w(pose), p.seeds[k], out)
                }
            })
            .collect()
    }

    fn record(l: &ShakePlan) -> ShakePlan {
        l.clone()
    }

    fn stat(s: &ShakeStat) -> Option<f64> {
        Some(s.path_px)
    }
}

/// One level's plan: the drawn path scaled to the level's amplitude, sampled at the
/// frames' times (or motion-blur keys), with their seeds.
fn plan_level(cx: &ViewCx, path: &Path, level: u32) -> ShakePlan {
    let (largest, length) = path.measure();
    let amplitude = amplitude_px(level, cx.resolution);
    let scale = if largest > 0.0 {
        amplitude / largest
    } else {
        0.0
    };
    let d = |t: f64| path.at(t).map(|x| x * scale);
    let purpose = <Shake as Degradation>::PURPOSE + u64::from(level);
    let (times, steps, gap): (Vec<f64>, Option<u32>, f64) = if cx.motion_blur {
        let steps = motion_steps(d);
        let n = 1u32 << steps;
        let keys = (0..=n).map(|k| f64::from(k) / f64::from(n)).collect();
        (keys, Some(steps), 0.0)
    } else {
        let (ts, gap) = frame_times(cx, d);
        (ts, None, gap)
    };
    let poses = times
        .iter()
        .map(|&t| {
            let [u, v] = d(t);
            ShakePose {
                t,
                yaw_deg: (u / cx.focal_px).atan().to_degrees(),
                pitch_deg: (v / cx.focal_px).atan().to_degrees(),
            }
        })
        .collect();
    let renders = if cx.motion_blur { 1 } else { times.len() };
    let own = cx.cfg.latents_auto && !cx.motion_blur;
    let (samples_per_frame, blocks) = exposure(cx, own.then_some(renders));
    let (seeds, sample_offsets, sample_sequence) = match blocks {
        Some((sequence, offsets)) => (vec![cx.sharp_seed; renders], offsets, Some(sequence)),
        None => (
            (0..renders).map(|k| (cx.seed)(purpose, k)).collect(),
            Vec::new(),
            None,
        ),
    };
    ShakePlan {
        amplitude_px: amplitude,
        path_px: length * scale,
        method: if cx.motion_blur {
            BlurMethod::MotionBlur
        } else {
            BlurMethod::Average
        },
        samples_per_frame,
        max_gap_px: own.then_some(gap),
        poses,
        seeds,
        sample_offsets,
        sample_sequence,
        motion_steps: steps,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plan::camera::Trajectory;
    use crate::plan::degradation::kind_renders;
    use crate::plan::sampling_config::SamplingConfig;
    use crate::rng::Stream;
    use std::sync::LazyLock;

    /// What shake does not read of the build's sampling.
    static CFG: LazyLock<SamplingConfig> = LazyLock::new(SamplingConfig::default);

    fn cx<'a>(
        stream: &'a dyn Fn(u64) -> Stream,
        seed: &'a dyn Fn(u64, usize) -> u32,
        motion_blur: bool,
        blocks: Option<(u32, Vec<u32>)>,
    ) -> ViewCx<'a> {
        ViewCx {
            near: 1.0,
            far: 2.0,
            resolution: 512,
            fov_deg: 40.0,
            focal_px: 512.0 / (2.0 * 20f64.to_radians().tan()),
            stream,
            seed,
            sharp_seed: 77,
            latents: 8,
            samples_per_frame: 4,
            blocks,
            motion_blur,
            cfg: &CFG,
            r: 3.0,
            phi_deg: 60.0,
            theta_deg: 0.0,
            trajectory: Trajectory {
                dr: 1.0,
                dphi_deg: 1.0,
                dtheta_deg: 1.0,
            },
            w_u: 1.0,
            bbox_dims: [1.0; 3],
            pricing: None,
        }
    }

    /// The image-centre displacement (px) of a camera turned by `p`, exactly: where the
    /// old optical axis projects in the turned camera.
    fn centre_px(p: &ShakePose, f: f64) -> f64 {
        let turn = DMat3::from_rotation_y(p.yaw_deg.to_radians())
            * DMat3::from_rotation_x(p.pitch_deg.to_radians());
        let d = turn.transpose() * glam::DVec3::new(0.0, 0.0, -1.0);
        (f * d.x / -d.z).hypot(f * d.y / -d.z)
    }

    #[test]
    fn each_level_shakes_the_image_centre_by_its_amplitude_about_the_written_pose() {
        let stream = |p| Stream::new(9, p);
        let seed = |p: u64, k: usize| (p as u32) * 100 + k as u32;
        let c = cx(&stream, &seed, false, None);
        let plan = Shake::plan_view(&c, &[1, 2, 3, 4]);
        let f = c.focal_px;
        for (l, want) in [("1", 4.0), ("2", 8.0), ("3", 16.0), ("4", 32.0)] {
            let p = &plan[l];
            assert_eq!(p.amplitude_px, want);
            assert_eq!(p.poses.len(), 8);
            // The frames stay within the amplitude (to first order in the angles) and
            // some come near it. A closed path with its mean at the written pose goes out
            // and back past it: at least twice the amplitude long.
            let reach: Vec<f64> = p.poses.iter().map(|q| centre_px(q, f)).collect();
            assert!(reach.iter().all(|&r| r <= want * 1.001), "{l}: {reach:?}");
            assert!(reach.iter().any(|&r| r > want * 0.3), "{l}: {reach:?}");
            assert!(p.path_px >= 2.0 * want * 0.99, "{l}: {}", p.path_px);
            // Whole periods: over the exposure the image centre's mean displacement
            // (F · tan of the turn) is 0, the written pose.
            let mean = p
                .poses
                .iter()
                .map(|q| q.yaw_deg.to_radians().tan())
                .sum::<f64>()
                / 8.0;
            assert!(mean.abs() < 1e-12, "{l}: {mean}");
            let seeds: Vec<u32> = (0..8)
                .map(|k| seed(2000 + l.parse::<u64>().expect("level"), k))
                .collect();
            assert_eq!(p.seeds, seeds);
        }
        // One path per view, scaled: level 4's turns are 8 times level 1's (small angles).
        let r = plan["4"].poses[3].yaw_deg / plan["1"].poses[3].yaw_deg;
        assert!((r - 8.0).abs() < 1e-2, "{r}");
        // Same seed, same plan; another view's stream, another path.
        assert_eq!(Shake::plan_view(&c, &[2]), Shake::plan_view(&c, &[2]));
        let other = |p| Stream::new(9, p + 1);
        let d = cx(&other, &seed, false, None);
        assert_ne!(Shake::plan_view(&d, &[2])["2"].poses, plan["2"].poses);
    }

    #[test]
    fn under_latents_auto_a_level_takes_the_frames_its_ghost_bound_needs() {
        let stream = |p| Stream::new(9, p);
        let seed = |p: u64, k: usize| (p as u32) * 100 + k as u32;
        let auto = SamplingConfig {
            latents_auto: true,
            latents_max: 4096,
            max_ghost_px: 1.0,
            ..SamplingConfig::default()
        };
        let c = ViewCx {
            cfg: &auto,
            ..cx(&stream, &seed, false, None)
        };
        let plan = Shake::plan_view(&c, &[1, 2, 3, 4]);
        let frames: Vec<usize> = ["1", "2", "3", "4"].map(|l| plan[l].poses.len()).to_vec();
        for l in ["1", "2", "3", "4"] {
            let p = &plan[l];
            let gap = p.max_gap_px.expect("auto records its gap");
            // Within the bound, and not by far more frames than it needs: one frame
            // fewer would leave a gap near the path's length over that count.
            assert!(gap <= 1.0, "{l}: {gap}");
            let m = p.poses.len();
            // A loop of three harmonics moves at most about 3x its mean speed.
            assert!((m as f64) < 3.0 * p.path_px + 2.0, "{l}: {m} frames");
            assert!(
                m as f64 >= p.path_px - 1e-9,
                "{l}: {m} frames for {}",
                p.path_px
            );
            // The level's blocks are its own: one per frame, equal, in one sequence.
            assert_eq!(p.seeds.len(), m);
            assert_eq!(p.sample_offsets.len(), m);
            assert_eq!(p.samples_per_frame, auto.samples_per_frame(m), "{l}");
        }
        // Larger levels move farther, so they take more frames, never 4096; a bound
        // twice as loose takes about half the frames (the fewest that meet it).
        assert!(frames.windows(2).all(|w| w[0] < w[1]), "{frames:?}");
        assert!(frames[3] < 4096, "{frames:?}");
        let loose = SamplingConfig {
            max_ghost_px: 2.0,
            ..auto.clone()
        };
        let c2 = ViewCx {
            cfg: &loose,
            ..cx(&stream, &seed, false, None)
        };
        for (l, &m) in ["1", "2", "3", "4"].iter().zip(&frames) {
            let half = Shake::plan_view(&c2, &[l.parse().expect("level")])[*l]
                .poses
                .len();
            assert!(half <= m / 2 + 1 && half + 2 >= m / 2, "{l}: {half} vs {m}");
        }
        // Without latents auto nothing new is recorded.
        let fixed = Shake::plan_view(&cx(&stream, &seed, false, None), &[2]);
        assert_eq!(fixed["2"].max_gap_px, None);
    }

    #[test]
    fn renders_turn_the_camera_about_its_centre_by_both_methods() {
        let stream = |p| Stream::new(3, p);
        let seed = |_: u64, k: usize| k as u32;
        let c2w = [
            [1.0, 0.0, 0.0, 0.5],
            [0.0, 1.0, 0.0, -0.2],
            [0.0, 0.0, 1.0, 3.0],
            [0.0, 0.0, 0.0, 1.0],
        ];
        let rcx = RenderCx {
            view: 2,
            c2w,
            exr_dir: std::path::Path::new("/x"),
            pin: Some(64),
        };
        let blocks = Some((32, (0..8).map(|k| 4 * k).collect()));
        let avg = Shake::plan_view(&cx(&stream, &seed, false, blocks), &[3]);
        let r = kind_renders::<Shake>(&rcx, &avg);
        assert_eq!(r.len(), 8);
        assert_eq!(
            (r[0].level.as_str(), r[0].kind),
            ("shake_3", ImageKind::Shake(3))
        );
        assert_eq!(r[7].out, "/x/0002_sh3_0007.exr");
        for (k, f) in r.iter().enumerate() {
            // The centre stays; the rotation turns; every frame its block on the
            // sharp seed, pinned to the build's sequence.
            assert_eq!([f.c2w[0][3], f.c2w[1][3], f.c2w[2][3]], [0.5, -0.2, 3.0]);
            assert_ne!(f.c2w, c2w);
            assert_eq!((f.seed, f.samples), (77, Some(4)));
            assert_eq!(
                (f.sample_offset, f.sample_sequence),
                (Some(4 * k as u32), Some(64))
            );
            assert!(f.motion.is_none() && f.dof.is_none());
        }
        let mb = Shake::plan_view(&cx(&stream, &seed, true, None), &[3]);
        let r = kind_renders::<Shake>(&rcx, &mb);
        assert_eq!(r.len(), 1);
        let m = r[0].motion.as_ref().expect("keys");
        let steps = mb["3"].motion_steps.expect("steps");
        assert_eq!(m.keys.len(), (1 << steps) + 1);
        assert_eq!((m.steps, r[0].seed, r[0].sample_offset), (steps, 0, None));
        assert_eq!(r[0].out, "/x/0002_sh3_mb.exr");
        assert_eq!(mb["3"].method, BlurMethod::MotionBlur);
    }

    #[test]
    fn a_shake_level_holds_masks_of_its_own() {
        use crate::plan::kind::SHARP;
        use crate::plan::kinds::pass_level;
        // Its camera turns during the exposure: the smear lies outside the silhouette.
        assert_eq!(pass_level("mask", "shake_2", true), "shake_2");
        // A setting made before levels had masks of their own; other passes.
        assert_eq!(pass_level("mask", "shake_2", false), SHARP);
        assert_eq!(pass_level("depth", "shake_3", true), SHARP);
        assert_eq!(pass_level("mask", "shake_0", true), SHARP);
    }
}
