//! The render list of a planned setting: what the Blender worker renders, in the order
//! the driver streams the frames into accumulators (per view: sharp, then each level).
use super::sampling::{LevelPlan, SettingPlan};
use crate::dataset::layout::{level_dir, SHARP};
use serde::Serialize;
use std::path::Path;

/// The camera path of one Cycles motion blur render.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct Motion {
    pub steps: u32,
    /// OpenGL camera-to-world matrices (row-major) at t_k = k / 2^steps.
    pub keys: Vec<[[f64; 4]; 4]>,
}

/// One render: the camera, its Cycles seed and samples, the EXR it writes, and the
/// view and level directory it is accumulated into.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct Render {
    pub view: usize,
    pub level: String,
    /// OpenGL camera-to-world, row-major.
    pub c2w: [[f64; 4]; 4],
    pub seed: u32,
    /// Cycles samples of this render; None: the caller's (the sharp render's own count).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub samples: Option<u32>,
    pub out: String,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub motion: Option<Motion>,
}

/// The renders of one blurry image: its latent frames (average method) or its single
/// motion blur render, writing `<prefix>_<k>.exr` / `<prefix>_mb.exr`.
pub fn level_renders(view: usize, level: u32, lp: &LevelPlan, prefix: &str) -> Vec<Render> {
    let dir = level_dir(level);
    if let Some(mb) = &lp.motion_blur {
        let keys: Vec<_> = mb.keys.iter().map(|k| k.c2w).collect();
        return vec![Render {
            view,
            level: dir,
            c2w: keys[0],
            seed: mb.seed,
            samples: Some(lp.samples_per_frame),
            out: format!("{prefix}_mb.exr"),
            motion: Some(Motion {
                steps: mb.motion_steps,
                keys,
            }),
        }];
    }
    lp.latent_frames
        .iter()
        .enumerate()
        .map(|(k, f)| Render {
            view,
            level: dir.clone(),
            c2w: f.c2w,
            seed: f.seed,
            samples: Some(lp.samples_per_frame),
            out: format!("{prefix}_{k:04}.exr"),
            motion: None,
        })
        .collect()
}

impl SettingPlan {
    /// Every render of the setting, EXRs under `exr_dir`: per view the sharp render at p
    /// (`<view>_s.exr`), then each level's renders (`<view>_<level>_…`).
    pub fn renders(&self, exr_dir: &Path) -> Vec<Render> {
        self.renders_except(exr_dir, &[])
    }

    /// [`Self::renders`] without the blur renders of `sharp_views`, whose blur levels
    /// get a copy of the sharp image (Deblur-NeRF's test views).
    pub fn renders_except(&self, exr_dir: &Path, sharp_views: &[usize]) -> Vec<Render> {
        let mut out = Vec::new();
        for v in &self.views {
            let i = v.index;
            out.push(Render {
                view: i,
                level: SHARP.into(),
                c2w: v.c2w,
                seed: v.sharp_seed,
                samples: None,
                out: exr_dir.join(format!("{i:04}_s.exr")).display().to_string(),
                motion: None,
            });
            if sharp_views.contains(&i) {
                continue;
            }
            for (key, lp) in &v.levels {
                let level: u32 = key.parse().unwrap_or(0);
                let prefix = exr_dir.join(format!("{i:04}_{key}"));
                out.extend(level_renders(i, level, lp, &prefix.display().to_string()));
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plan::config::BuildConfig;
    use crate::plan::sampling::plan_setting;

    #[test]
    fn render_list_order_names_and_counts() -> crate::Result<()> {
        let cfg = BuildConfig {
            views: 2,
            levels: vec![1, 10],
            latents: 3,
            ..Default::default()
        };
        let plan = plan_setting(&cfg.sampling(), "u", 0.0, 1, [1.0; 3], &[])?;
        let r = plan.renders(Path::new("/x"));
        assert_eq!(r.len(), cfg.frames_per_setting());
        assert_eq!(
            (r[0].level.as_str(), r[0].out.as_str()),
            ("sharp", "/x/0000_s.exr")
        );
        // Levels in the plan's key order ("1" < "10"), frames numbered per level.
        assert_eq!(r[1].out, "/x/0000_1_0000.exr");
        assert_eq!(
            (r[4].level.as_str(), r[4].out.as_str()),
            ("blur_10", "/x/0000_10_0000.exr")
        );
        assert_eq!(r[7].view, 1);
        assert!(r.iter().skip(1).take(6).all(|f| f.samples == Some(32)));
        // A Deblur-NeRF test view renders only its sharp image.
        let kept = plan.renders_except(Path::new("/x"), &[0]);
        assert_eq!(kept.len(), r.len() - 6);
        assert_eq!((kept[0].view, kept[1].view), (0, 1));
        assert_eq!(kept[1..], r[7..]);
        let mb = BuildConfig {
            blur_method: "motion_blur".into(),
            ..cfg
        };
        let plan = plan_setting(&mb.sampling(), "u", 0.0, 1, [1.0; 3], &[])?;
        let r = plan.renders(Path::new("/x"));
        assert_eq!(r.len(), 2 * 3);
        assert!(r[1].out.ends_with("0000_1_mb.exr") && r[1].motion.is_some());
        Ok(())
    }
}
