//! The render list of a planned setting: what the Blender worker renders, in the order
//! the driver streams the frames into accumulators (per view: sharp, then each level of
//! each kind, motion blur's first).
use super::degradation::RenderCx;
use super::region::{call_cost_px, object_region, render_calls, Region};
pub use super::render::{Motion, Render};
use super::sampling::SettingPlan;
use crate::plan::kind::ImageKind;
use glam::{DMat4, DVec3};
use std::path::Path;

/// `renders` each carrying its samples: those that carry none (the sharp image's, and a
/// defocus image's, one render at the sharp image's count) take `sharp_samples`.
pub fn with_samples(mut renders: Vec<Render>, sharp_samples: u32) -> Vec<Render> {
    for r in &mut renders {
        r.samples = r.samples.or(Some(sharp_samples));
    }
    renders
}

impl SettingPlan {
    /// Every render of the setting, EXRs under `exr_dir`: per view the sharp render at p
    /// (`<view>_s.exr`), then each level's renders (`<view>_<level>_…`, then each other
    /// kind's). `pin`
    /// ([`crate::BuildConfig::cycles_samples`]): the sharp image renders the first samples
    /// of a `pin`-sample sequence and the latent frames their blocks of it.
    pub fn renders(&self, exr_dir: &Path, pin: Option<u32>) -> Vec<Render> {
        self.renders_except(exr_dir, &[], pin)
    }

    /// [`Self::renders`] without the blur renders of `sharp_views`, whose blur levels
    /// get a copy of the sharp image (Deblur-NeRF's test views).
    pub fn renders_except(
        &self,
        exr_dir: &Path,
        sharp_views: &[usize],
        pin: Option<u32>,
    ) -> Vec<Render> {
        let mut out = Vec::new();
        for v in &self.views {
            let i = v.index;
            let out_sharp = exr_dir.join(format!("{i:04}_s.exr")).display().to_string();
            out.push(Render {
                sample_offset: pin.map(|_| 0),
                sample_sequence: pin,
                ..Render::still(i, ImageKind::Sharp, v.c2w, v.sharp_seed, out_sharp)
            });
            if sharp_views.contains(&i) {
                continue;
            }
            let cx = RenderCx {
                view: i,
                c2w: v.c2w,
                exr_dir,
                pin,
            };
            out.extend(v.kind_renders(&cx));
        }
        self.with_regions(out)
    }

    /// `renders` with their render calls and regions: the still frames of one image
    /// (view and level) split into calls by [`render_calls`], each frame traced in its
    /// call's region; a motion blur render is a whole-image call of its own.
    pub fn with_regions(&self, mut renders: Vec<Render>) -> Vec<Render> {
        let size = self.resolution[0];
        let own: Vec<Option<Region>> = match self.object_box {
            Some([lo, hi]) => {
                let (lo, hi) = (DVec3::from_array(lo), DVec3::from_array(hi));
                renders
                    .iter()
                    .map(|r| {
                        let c2w = DMat4::from_cols_array_2d(&r.c2w).transpose();
                        object_region(&c2w, lo, hi, self.focal_px, size)
                    })
                    .collect()
            }
            None => vec![None; renders.len()],
        };
        let mut call = 0;
        let mut i = 0;
        while i < renders.len() {
            let image = (renders[i].view, renders[i].level.clone());
            let mut j = i + 1;
            while j < renders.len()
                && !renders[i].whole()
                && !renders[j].whole()
                && renders[i].band.is_none()
                && (renders[j].view, &renders[j].level) == (image.0, &image.1)
            {
                j += 1;
            }
            let samples = renders[i].samples.unwrap_or(1);
            let calls = if renders[i].whole() {
                vec![(i..j, None)]
            } else if let Some(b) = renders[i].band {
                // A band is a call of its own, traced only where its rows meet the object.
                vec![(i..i + 1, band_region(own[i], b.rows, size))]
            } else {
                render_calls(&own[i..j], size, call_cost_px(samples))
                    .into_iter()
                    .map(|(r, u)| (r.start + i..r.end + i, u))
                    .collect()
            };
            for (range, region) in calls {
                for r in &mut renders[range] {
                    (r.region, r.call) = (region, Some(call));
                }
                call += 1;
            }
            i = j;
        }
        renders
    }
}

/// The pixels a band of `rows` (at least one) traces: its rows of the object's region
/// (all of them when the region is the whole image), or its first pixel when the object
/// is outside the band (the band is background; Cycles still needs a border to render).
fn band_region(object: Option<Region>, rows: [u32; 2], size: u32) -> Option<Region> {
    let [x0, y0, x1, y1] = object.unwrap_or([0, 0, size, size]);
    let (top, bottom) = (rows[0].max(y0), rows[1].min(y1));
    Some(if top < bottom && x0 < x1 {
        [x0, top, x1, bottom]
    } else {
        [0, rows[0], 1, rows[0] + 1]
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plan::choices::{BlurBudget, BlurMethod, LatentSampling};
    use crate::plan::config::BuildConfig;
    use crate::plan::sampling::plan_setting;

    #[test]
    fn render_list_order_names_and_counts() -> crate::Result<()> {
        let cfg = BuildConfig {
            views: 2,
            levels: vec![1, 10],
            latents: 3,
            blur_budget: BlurBudget::Flat,
            ..Default::default()
        };
        let plan = plan_setting(&cfg.sampling(), "u", 0.0, 1, [1.0; 3], &[])?;
        let r = plan.renders(Path::new("/x"), None);
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
        let kept = plan.renders_except(Path::new("/x"), &[0], None);
        assert_eq!(kept.len(), r.len() - 6);
        assert_eq!((kept[0].view, kept[1].view), (0, 1));
        let uncalled = |v: &[Render]| -> Vec<Render> {
            v.iter()
                .map(|f| Render {
                    call: None,
                    ..f.clone()
                })
                .collect()
        };
        assert_eq!(uncalled(&kept[1..]), uncalled(&r[7..]));
        // Render calls: consecutive, never across images; each sharp render its own.
        let calls: Vec<usize> = r.iter().map(|f| f.call.expect("call")).collect();
        assert!(calls.windows(2).all(|w| w[1] == w[0] || w[1] == w[0] + 1));
        for w in r.windows(2) {
            if w[0].call == w[1].call {
                assert_eq!((w[0].view, &w[0].level), (w[1].view, &w[1].level));
                assert_eq!(w[0].region, w[1].region);
            }
        }
        assert!(r.iter().filter(|f| f.level == "sharp").all(|f| calls
            .iter()
            .filter(|c| Some(**c) == f.call)
            .count()
            == 1));
        let mb = BuildConfig {
            blur_method: BlurMethod::MotionBlur,
            ..cfg
        };
        let plan = plan_setting(&mb.sampling(), "u", 0.0, 1, [1.0; 3], &[])?;
        let r = plan.renders(Path::new("/x"), None);
        assert_eq!(r.len(), 2 * 3);
        assert!(r[1].out.ends_with("0000_1_mb.exr") && r[1].motion.is_some());
        Ok(())
    }

    #[test]
    fn subsets_render_blocks_of_one_pinned_sequence() -> crate::Result<()> {
        let cfg = BuildConfig {
            views: 1,
            levels: vec![2],
            latents: 7,
            samples_total: Some(300),
            sharp_samples: Some(200),
            blur_budget: BlurBudget::Flat,
            ..Default::default()
        };
        let plan = plan_setting(&cfg.sampling(), "u", 0.0, 1, [1.0; 3], &[])?;
        // 7 blocks of ⌈300/7⌉ = 43 samples: the sequence is 301 > the sharp 200.
        let pin = cfg.cycles_samples();
        assert_eq!(pin, Some(301));
        let r = plan.renders(Path::new("/x"), pin);
        assert_eq!((r[0].sample_offset, r[0].sample_sequence), (Some(0), pin));
        let offsets: Vec<_> = r[1..].iter().map(|f| f.sample_offset).collect();
        assert_eq!(offsets, (0..7).map(|k| Some(43 * k)).collect::<Vec<_>>());
        assert!(r[1..]
            .iter()
            .all(|f| f.sample_sequence == pin && f.seed == r[0].seed));
        // Unpinned: each level its own sequence, the sharp render none.
        let r = plan.renders(Path::new("/x"), None);
        assert_eq!(r[0].sample_sequence, None);
        assert!(r[1..].iter().all(|f| f.sample_sequence == Some(301)));
        // Independent: no blocks and no pin, frame seeds of their own.
        let ind = BuildConfig {
            latent_sampling: LatentSampling::Independent,
            ..cfg
        };
        assert_eq!(ind.cycles_samples(), None);
        let plan = plan_setting(&ind.sampling(), "u", 0.0, 1, [1.0; 3], &[])?;
        let r = plan.renders(Path::new("/x"), None);
        assert!(r.iter().all(|f| f.sample_offset.is_none()));
        assert!(r[1..].iter().all(|f| f.seed != r[0].seed));
        Ok(())
    }
}
