//! A throwaway kind (tests/test_kinds.py copies the core, adds this file as
//! `plan/kinds/tilt.rs` and one line to the registry, and runs the tests below): the
//! camera rolled about its viewing axis by 2·l degrees, one still render per level.
use crate::plan::kind::ImageKind;
use crate::plan::degradation::{Degradation, RenderCx, ViewCx};
use crate::plan::render::Render;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// The camera rolled about its viewing axis.
pub struct Tilt;

/// One tilt level of one view.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
pub struct TiltPlan {
    pub roll_deg: f64,
    pub seed: u32,
}

#[derive(Debug, Deserialize)]
pub struct TiltStat {
    pub roll_deg: f64,
}

impl Degradation for Tilt {
    type Level = TiltPlan;
    type Record = TiltPlan;
    type Read = TiltStat;
    const NAME: &'static str = "tilt";
    const PURPOSE: u64 = 9000;
    const STAT: (&'static str, &'static str, &'static str) =
        ("tilt_roll_deg", "deg", "roll of the camera at tilt level l");
    const FIGURE: (&'static str, &'static str) = ("Tilt per level", "roll  (deg)");
    const MEANS: &'static str = "the same views rolled by 2·l degrees";
    const MAX_LEVEL: u32 = 4;
    const LEVEL_RANGE: &'static str = "level l rolls the camera by 2·l degrees";
    const OPTION_HELP: &'static str =
        "tilt levels 1 to 4: tilt_<l>/ beside the blur levels, the camera rolled by 2·l degrees";

    fn kind(level: u32) -> ImageKind {
        ImageKind::Tilt(level)
    }

    fn plan_view(cx: &ViewCx, levels: &[u32]) -> BTreeMap<String, TiltPlan> {
        let plan = |l: u32| TiltPlan {
            roll_deg: 2.0 * f64::from(l),
            seed: (cx.seed)(Self::PURPOSE + u64::from(l), 0),
        };
        levels.iter().map(|&l| (l.to_string(), plan(l))).collect()
    }

    fn renders(cx: &RenderCx, level: u32, p: &TiltPlan) -> Vec<Render> {
        let base = glam::DMat4::from_cols_array_2d(&cx.c2w).transpose();
        let roll = glam::DMat4::from_rotation_z(p.roll_deg.to_radians());
        let c2w = (base * roll).transpose().to_cols_array_2d();
        let exr = cx.exr_dir.join(format!("{:04}_t{level}.exr", cx.view));
        vec![Render {
            sample_offset: cx.pin.map(|_| 0),
            sample_sequence: cx.pin,
            ..Render::still(cx.view, Self::kind(level), c2w, p.seed, exr.display().to_string())
        }]
    }

    fn record(l: &TiltPlan) -> TiltPlan {
        l.clone()
    }

    fn stat(s: &TiltStat) -> Option<f64> {
        Some(s.roll_deg)
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // a failing unwrap is a failing test
mod tests {
    use super::*;
    use crate::dataset::finished::ImageWriter;
    use crate::dataset::session::{Counts, Session};
    use crate::image::exr::write::write_exr;
    use crate::plan::config::BuildConfig;
    use crate::plan::kinds::KIND_STATS;
    use crate::plan::renders::with_samples;
    use crate::plan::sampling::plan_setting;
    use crate::plan::spec::Raw;
    use std::path::Path;

    const SIZE: u32 = 16;

    fn config(tilt: &[i128]) -> crate::error::Result<BuildConfig> {
        let list = |v: &[i128]| Raw::List(v.iter().map(|&i| Raw::Int(i)).collect());
        let values = BTreeMap::from([
            ("tilt".to_string(), list(tilt)),
            ("views".to_string(), Raw::Int(2)),
            ("levels".to_string(), list(&[1])),
            ("latents".to_string(), Raw::Int(2)),
            ("resolution".to_string(), Raw::Int(i128::from(SIZE))),
            ("downsample".to_string(), list(&[2])),
            ("passes".to_string(), Raw::List(vec![Raw::Str("mask".into())])),
        ]);
        BuildConfig::from_values(&values)
    }

    #[test]
    fn tilt_is_an_option_of_the_build_with_its_range() {
        let decls = BuildConfig::declarations();
        let d = decls.iter().find(|d| d.name == "tilt").unwrap();
        assert_eq!(d.flags, ["--tilt"]);
        assert!(d.help.contains("rolled") && d.shapes_outputs);
        let e = config(&[5]).unwrap_err().to_string();
        assert!(e.starts_with("tilt 5: tilt levels must be in 1..=4"), "{e}");
        assert!(config(&[1, 1]).is_err(), "levels are distinct");
        assert_eq!(config(&[]).unwrap().level_dirs(), ["sharp", "blur_1"]);
    }

    #[test]
    fn a_build_with_tilt_renders_and_writes_its_levels() {
        let cfg = config(&[1, 3]).unwrap();
        assert_eq!(cfg.level_dirs(), ["sharp", "blur_1", "tilt_1", "tilt_3"]);
        assert_eq!(cfg.frames_per_setting(), 2 * (1 + 2 + 2));
        let plan = plan_setting(&cfg.sampling(), "u", 90.0, 5, [1.0, 0.5, 0.5], &[]).unwrap();
        let rec = serde_json::to_value(plan.views[1].map_levels(|l| l.clone())).unwrap();
        assert_eq!(rec["tilt"]["3"]["roll_deg"], 6.0);
        let stat = KIND_STATS.iter().find(|k| k.name == "tilt").unwrap();
        assert_eq!((stat.read)(&rec["tilt"]["1"]), Some(Some(2.0)));
        assert_eq!(ImageKind::parse("tilt_3"), Some(ImageKind::Tilt(3)));
        assert!(ImageKind::Tilt(1).order() > ImageKind::Blur(9).order());

        let dir = std::env::temp_dir().join(format!("blurset-tilt-{}", std::process::id()));
        let exr = dir.join(".frames");
        std::fs::create_dir_all(&exr).unwrap();
        let renders = with_samples(plan.renders_except(&exr, &[], None), 4);
        let tilted: Vec<&Render> = renders.iter().filter(|r| r.level.starts_with("tilt_")).collect();
        assert_eq!(tilted.len(), 4, "two views, two levels, one still each");
        assert!(tilted.iter().all(|r| r.phase == ImageKind::Tilt(1).phase()));
        // The roll turns the camera's right axis, not its position.
        let sharp = renders.iter().find(|r| r.level == "sharp" && r.view == tilted[0].view);
        let (a, b) = (sharp.unwrap().c2w, tilted[0].c2w);
        assert!((0..3).all(|i| (a[i][3] - b[i][3]).abs() < 1e-12) && (a[0][0] - b[0][0]).abs() > 1e-6);

        let writer = ImageWriter::new(&dir, &cfg, 2, &renders, None).unwrap();
        let mut session = Session::new(renders, Counts::Fixed, SIZE, false, writer);
        loop {
            let batch = session.next_renders().unwrap();
            if batch.is_empty() {
                break;
            }
            for (i, r) in batch.iter().enumerate() {
                // A stand-in render: the object (grey, opaque) over the left half.
                let rgba: Vec<f32> = (0..SIZE * SIZE)
                    .flat_map(|p| {
                        let a = if p % SIZE < SIZE / 2 { 1.0 } else { 0.0 };
                        [0.4 * a, 0.4 * a, 0.4 * a, a]
                    })
                    .collect();
                write_exr(Path::new(&r.out), SIZE, SIZE, &rgba).unwrap();
                session.add_exr(i, Path::new(&r.out), None).unwrap();
            }
        }
        assert_eq!(session.failure(), None);
        for level in ["tilt_1", "tilt_3"] {
            for sub in ["images/000.png", "images_2/001.png"] {
                assert!(dir.join(level).join(sub).is_file(), "{level}/{sub}");
            }
            // A still at the written pose's centre takes the sharp masks.
            assert!(!dir.join(level).join("masks").exists());
        }
        let _ = std::fs::remove_dir_all(&dir);
    }
}
