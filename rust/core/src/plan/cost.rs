//! What a blurry image costs on the device that renders it, and the blur method that
//! costs less (`blur_method auto`, which the accuracy presets set; issue 47). A render
//! call costs a fixed time whatever its samples plus a time per sample; averaged latent
//! frames pay the fixed time once per frame and half in every round of a render target,
//! one Cycles motion-blur render once per half. Where calls are dear (a GPU: ~0.12 s
//! each) motion blur costs less; where samples are (the CPU, whose frames of one job
//! cost what their pixels cost) averaged frames do. Both reach the same target: the
//! rounds of `plan/target.rs` render each image until its own noise reaches it, and the
//! ghost bound and the motion keys' interpolation bound (`MOTION_KEY_TOLERANCE_PX`)
//! both keep the blur's shape under a pixel.
//!
//! The one rule is [`Pricing::choose`]; its record is [`BlurChoice`] (meta.json's
//! `render.blur_choice`).
use super::choices::{BlurMethod, Choice};
use super::render::Render;
use crate::error::{Error, Result};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// The resolution the per-sample costs were measured at; an image of `res` px costs
/// (res / 512)² of it per sample (its fixed cost per call stays).
pub const REFERENCE_PX: f64 = 512.0;

/// GPU, the fixed cost of a render call: 0.121 s for one sample at 512 px, one Cycles job
/// of many frames (NVIDIA H200, OptiX; shared/tools/DEVICE.md, "What was measured there").
pub const GPU_CALL_S: f64 = 0.121;
/// GPU, seconds per sample at 512 px: (0.258 s at 256 samples − 0.121 s at 1) / 255
/// (DEVICE.md).
pub const GPU_SAMPLE_S: f64 = (0.258 - 0.121) / 255.0;
/// GPU, what a sample of one Cycles motion-blur render costs against a latent frame's:
/// 0.73 s for 34 × 32 samples over 33 keys (DEVICE.md), less one call, over those
/// samples at [`GPU_SAMPLE_S`]: ≈ 1.04.
pub const GPU_MOTION_BLUR_FACTOR: f64 = (0.73 - GPU_CALL_S) / (34.0 * 32.0 * GPU_SAMPLE_S);

/// CPU, the fixed cost of a latent frame in a render call of many: none measurable. The
/// 34 frames of a blurry image rendered as one animation job cost 0.99× a sharp image
/// of the same samples per traced pixel (bench/results.json `blur_cost_vs_sharp`,
/// 2-core EPYC, 512 px, 136 samples); a call of its own costs 3–23 ms more
/// (`blur_cost_vs_sharp_per_call`), which the build never makes.
pub const CPU_CALL_S: f64 = 0.0;
/// CPU, seconds per sample at 512 px: the sharp image of `motion_blur_cost_vs_sharp`'s
/// baseline, 11.48 s for 136 samples on the bench's 2 cores (a larger CPU is faster;
/// without a fixed cost only the ratio [`CPU_MOTION_BLUR_FACTOR`] decides).
pub const CPU_SAMPLE_S: f64 = 11.48 / 136.0;
/// CPU, a motion-blur sample against a latent frame's: `motion_blur_cost_vs_sharp` 1.36×
/// over the 1.16× that `blur_cost_vs_sharp` spends on the larger region the exposure
/// covers (bench/results.json): ≈ 1.17.
pub const CPU_MOTION_BLUR_FACTOR: f64 = 1.36 / 1.16;

/// CPU, the cores [`CPU_SAMPLE_S`] was measured on; a machine of n cores renders
/// [`CPU_CORES`]/n of its time (Cycles spreads a frame over every core).
pub const CPU_CORES: f64 = 2.0;
/// CPU, seconds per sample of a whole 512 px frame of traced pixels (a render traces
/// only its region, the object's): 0.137, each setting's samples over its renders'
/// regions against its time in the recorded paper preset at 512 px
/// (`settings_per_hour_512px_paper`: MapPin 0.131, MazdaRX7 0.131, WaterBottle 0.148;
/// its 128 px rows agree to 0.89-0.98). [`CPU_SAMPLE_S`] is one sharp image's, region
/// and all, which `blur_method auto` compares the methods by.
pub const CPU_TRACED_SAMPLE_S: f64 = 0.137;
/// CPU, what a latent frame costs at 512 px whatever its samples, inside one job: its
/// pixels' own work (film, filter, the EXR written and read back), 0.28 µs a pixel
/// (region.rs `call_cost_px`, bench/bench_blur_cost.py).
pub const CPU_FRAME_S: f64 = 0.28e-6 * REFERENCE_PX * REFERENCE_PX;

/// What an object costs before its first frame: a worker's Blender start, the GLB's
/// import and normalization, its scene set-up (the demo's objects on the idle 2-core
/// machine, bench/bench_estimate.py).
pub const OBJECT_LOAD_S: f64 = 4.0;

/// A plan's renders priced on one device: `blurset build --dry-run`'s estimate.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct RendersCost {
    pub renders: u64,
    /// Samples per pixel over the renders, a band's in proportion to its rows.
    pub samples: u64,
    pub seconds: f64,
}

/// What a render costs on one kind of device.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct CostModel {
    /// `cpu` or `gpu`.
    pub kind: DeviceKind,
    /// Seconds every render call (latent frame, sharp or motion-blur render) costs
    /// whatever its samples.
    pub call_s: f64,
    /// Seconds per Cycles sample of a 512 px latent frame, scaled by pixels.
    pub sample_s_512px: f64,
    /// A motion-blur render's cost per sample against a latent frame's.
    pub motion_blur_factor: f64,
}

/// The kinds of device whose costs were measured.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(rename_all = "lowercase")]
pub enum DeviceKind {
    Cpu,
    Gpu,
}

impl CostModel {
    pub const CPU: CostModel = CostModel {
        kind: DeviceKind::Cpu,
        call_s: CPU_CALL_S,
        sample_s_512px: CPU_SAMPLE_S,
        motion_blur_factor: CPU_MOTION_BLUR_FACTOR,
    };
    pub const GPU: CostModel = CostModel {
        kind: DeviceKind::Gpu,
        call_s: GPU_CALL_S,
        sample_s_512px: GPU_SAMPLE_S,
        motion_blur_factor: GPU_MOTION_BLUR_FACTOR,
    };

    /// The model of a Cycles backend as the worker reports it (`CPU`, `OPTIX`, `CUDA`,
    /// `HIP`, `ONEAPI`, `METAL`, any case); anything else is refused.
    pub fn of_backend(backend: &str) -> Result<CostModel> {
        match backend.trim().to_ascii_lowercase().as_str() {
            "cpu" => Ok(CostModel::CPU),
            "optix" | "cuda" | "hip" | "oneapi" | "metal" => Ok(CostModel::GPU),
            other => Err(Error::Value(format!(
                "blur_method auto: no cost model for the Cycles backend {other:?} (known: \
                 cpu, optix, cuda, hip, oneapi, metal); give blur_method average or \
                 motion_blur"
            ))),
        }
    }

    /// What `renders` (a plan's, at `res` px) cost on `cores` cores (a CPU's costs were
    /// measured on [`CPU_CORES`]; a GPU's are its own): one call and a frame's own cost
    /// each, and their samples over the rows they trace (a band its own), a motion-blur
    /// render at its factor. The estimate `blurset build --dry-run` prints.
    pub fn renders_cost(&self, renders: &[Render], res: u32, cores: usize) -> RendersCost {
        // A CPU's samples cost what the pixels they trace cost (the region: the object's).
        let (per_core, frame_s, sample_s) = match self.kind {
            DeviceKind::Cpu => (
                CPU_CORES / cores.max(1) as f64,
                CPU_FRAME_S,
                CPU_TRACED_SAMPLE_S,
            ),
            DeviceKind::Gpu => (1.0, 0.0, self.sample_s_512px),
        };
        let whole = f64::from(res).powi(2);
        let px = whole / REFERENCE_PX.powi(2);
        let mut cost = RendersCost::default();
        for r in renders {
            let samples = f64::from(r.samples.unwrap_or(1));
            let rows = r
                .band
                .map_or(1.0, |b| f64::from(b.rows[1] - b.rows[0]) / f64::from(res));
            let share = match (r.region, self.kind) {
                (Some([x0, y0, x1, y1]), DeviceKind::Cpu) => {
                    f64::from((x1 - x0) * (y1 - y0)) / whole
                }
                _ => rows,
            };
            let factor = if r.motion.is_some() {
                self.motion_blur_factor
            } else {
                1.0
            };
            let s = self.call_s + frame_s * px + samples * share * sample_s * px * factor;
            cost.seconds += s * per_core;
            cost.renders += 1;
            cost.samples += (samples * rows).ceil() as u64;
        }
        cost
    }

    /// Seconds of `calls` render calls of `samples` samples in all at `res` px, motion
    /// blur renders or latent frames.
    pub fn seconds(&self, calls: u64, samples: u64, res: u32, motion_blur: bool) -> f64 {
        let px = (f64::from(res) / REFERENCE_PX).powi(2);
        let factor = if motion_blur {
            self.motion_blur_factor
        } else {
            1.0
        };
        calls as f64 * self.call_s + samples as f64 * self.sample_s_512px * px * factor
    }
}

/// The prices of one blurry image by either method: one round of the target's pilot
/// samples (every round of the image costs alike: the same rounds render either way).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ImagePrice {
    /// The latent frames the ghost bound plans for the image (averaged frames).
    pub frames: usize,
    pub average_s: f64,
    pub motion_blur_s: f64,
}

impl ImagePrice {
    /// The cheaper method; a tie keeps averaged frames (the paper's).
    pub fn cheaper(&self) -> BlurMethod {
        if self.motion_blur_s < self.average_s {
            BlurMethod::MotionBlur
        } else {
            BlurMethod::Average
        }
    }
}

/// How the images of a setting are priced: the device's model, the backend it was taken
/// from, the target's pilot samples (its pilot round is what is priced: both halves,
/// `TargetRule::pilot_samples`) and the resolution.
#[derive(Clone, Debug, PartialEq)]
pub struct Pricing {
    pub backend: String,
    pub model: CostModel,
    pub pilot_samples: u32,
    pub resolution: u32,
}

impl Pricing {
    /// The pricing of `backend` (the worker's `device.backend`) for a target whose pilot
    /// round renders `pilot_samples` at `res` px.
    pub fn new(backend: &str, pilot_samples: u32, resolution: u32) -> Result<Pricing> {
        Ok(Pricing {
            backend: backend.trim().to_ascii_lowercase(),
            model: CostModel::of_backend(backend)?,
            pilot_samples,
            resolution,
        })
    }

    /// One round of a blurry image of `frames` latent frames, priced both ways at the
    /// same samples, the pilot's (`target_pilot_samples`, both halves): averaged frames
    /// make 2 × frames calls (each frame once per half), motion blur 2. The samples are
    /// the same because the target, not the method, decides them.
    pub fn price(&self, frames: usize) -> ImagePrice {
        let samples = u64::from(self.pilot_samples.max(2));
        let res = self.resolution;
        let m = self.model;
        ImagePrice {
            frames,
            average_s: m.seconds(2 * frames.max(1) as u64, samples, res, false),
            motion_blur_s: m.seconds(2, samples, res, true),
        }
    }

    /// The method an image of `frames` planned frames renders by: the cheaper one.
    pub fn choose(&self, frames: usize) -> BlurMethod {
        self.price(frames).cheaper()
    }

    /// meta.json's record of a setting's choice, from the price of each of its blurry
    /// images.
    pub fn record(&self, prices: &[ImagePrice]) -> BlurChoice {
        let mut images = BTreeMap::new();
        let (mut average, mut motion_blur, mut chosen) = (0.0, 0.0, 0.0);
        for p in prices {
            let c = p.cheaper();
            *images.entry(c.name().to_string()).or_insert(0usize) += 1;
            average += p.average_s;
            motion_blur += p.motion_blur_s;
            chosen += p.average_s.min(p.motion_blur_s);
        }
        let m = &self.model;
        let why = match m.kind {
            DeviceKind::Gpu => format!(
                "a render call costs {:.3} s whatever its samples on a GPU, so an image of m \
                 latent frames pays 2m calls a round averaged and 2 as one motion-blur render",
                m.call_s
            ),
            DeviceKind::Cpu => format!(
                "a latent frame costs no more than its samples on a CPU, and a motion-blur \
                 sample {:.2}x a latent frame's",
                m.motion_blur_factor
            ),
        };
        let counts: Vec<String> = images.iter().map(|(k, n)| format!("{n} {k}")).collect();
        BlurChoice {
            rule: "auto".into(),
            device: self.backend.clone(),
            model: *m,
            priced: format!(
                "one round of {} samples (target_pilot_samples, both halves) per blurry \
                 image at {} px, the same for both methods",
                self.pilot_samples.max(2),
                self.resolution
            ),
            images,
            cost_s: CostSeconds {
                average: round_ms(average),
                motion_blur: round_ms(motion_blur),
                chosen: round_ms(chosen),
            },
            reason: format!(
                "priced on {}: {why}; images: {}",
                self.backend,
                if counts.is_empty() {
                    "none blurry".into()
                } else {
                    counts.join(", ")
                }
            ),
        }
    }
}

fn round_ms(s: f64) -> f64 {
    (s * 1000.0).round() / 1000.0
}

/// The priced seconds of a setting's blurry images (one pilot round each).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct CostSeconds {
    /// Every image as averaged latent frames.
    pub average: f64,
    /// Every image as one motion-blur render.
    pub motion_blur: f64,
    /// Each image by its chosen method.
    pub chosen: f64,
}

/// How `blur_method auto` chose each blurry image's method in a setting (meta.json
/// `render.blur_choice`; each level's own `method` says which it got).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct BlurChoice {
    /// `auto`: each image the method its device renders for less.
    pub rule: String,
    /// The Cycles backend the images were priced for (the worker's, lower case).
    pub device: String,
    pub model: CostModel,
    /// What was priced, in words.
    pub priced: String,
    /// Blurry images by chosen method: every view's levels as planned, the held-out
    /// views' included (whose levels then hold a copy of the sharp image instead).
    pub images: BTreeMap<String, usize>,
    pub cost_s: CostSeconds,
    pub reason: String,
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pricing(backend: &str, res: u32) -> Pricing {
        Pricing::new(backend, 32, res).expect("known backend")
    }

    #[test]
    fn a_plan_costs_its_samples_over_the_rows_it_traces_on_the_cores_it_has() {
        let frame = |samples, band: Option<[u32; 2]>| Render {
            samples: Some(samples),
            band: band.map(|rows| crate::plan::render::Band { rows, of: 4 }),
            ..Render::still(
                0,
                crate::plan::kind::ImageKind::Sharp,
                [[0.0; 4]; 4],
                1,
                String::new(),
            )
        };
        let cpu = CostModel::CPU;
        let one = cpu.renders_cost(&[frame(64, None)], 512, 2);
        assert_eq!((one.renders, one.samples), (1, 64));
        assert!((one.seconds - (64.0 * CPU_TRACED_SAMPLE_S + CPU_FRAME_S)).abs() < 1e-12);
        // A region of a quarter of the image traces a quarter of the pixels.
        let quarter = Render {
            region: Some([0, 0, 256, 256]),
            ..frame(64, None)
        };
        let q = cpu.renders_cost(&[quarter], 512, 2).seconds;
        assert!((q - (16.0 * CPU_TRACED_SAMPLE_S + CPU_FRAME_S)).abs() < 1e-12);
        // Four bands tiling the rows trace one image's samples, at four frames' own cost.
        let bands: Vec<Render> = (0..4)
            .map(|k| frame(64, Some([k * 128, k * 128 + 128])))
            .collect();
        let four = cpu.renders_cost(&bands, 512, 2);
        assert_eq!((four.renders, four.samples), (4, 64));
        assert!((four.seconds - one.seconds - 3.0 * CPU_FRAME_S).abs() < 1e-9);
        // Twice the cores, half the time; a quarter of the pixels at 256 px.
        assert!(
            (cpu.renders_cost(&[frame(64, None)], 512, 4).seconds - one.seconds / 2.0).abs()
                < 1e-12
        );
        assert!(
            (cpu.renders_cost(&[frame(64, None)], 256, 2).seconds - one.seconds / 4.0).abs()
                < 1e-12
        );
        // A GPU pays its call whatever the cores.
        let gpu = CostModel::GPU.renders_cost(&[frame(1, None)], 512, 64);
        assert!((gpu.seconds - GPU_CALL_S - GPU_SAMPLE_S).abs() < 1e-12);
    }

    #[test]
    fn the_constants_are_the_measurements() {
        // DEVICE.md: 34 averaged frames x 32 samples cost 4.8 s on the H200.
        let avg = CostModel::GPU.seconds(34, 34 * 32, 512, false);
        assert!((avg - 4.8).abs() < 0.2, "{avg}");
        let mb = CostModel::GPU.seconds(1, 34 * 32, 512, true);
        assert!((mb - 0.73).abs() < 1e-9, "{mb}");
        assert!((GPU_MOTION_BLUR_FACTOR - 1.04).abs() < 0.01);
        assert!((CPU_MOTION_BLUR_FACTOR - 1.17).abs() < 0.01);
    }

    #[test]
    fn cpu_averages_at_every_size_and_frame_count() {
        for res in [8, 16, 96, 512, 2048] {
            let p = pricing("CPU", res);
            for m in 1..=64 {
                assert_eq!(p.choose(m), BlurMethod::Average, "{res} px, m = {m}");
            }
        }
    }

    #[test]
    fn gpus_render_motion_blur_where_frames_are_many() {
        for backend in ["OPTIX", "cuda", "HIP", "oneapi", "Metal"] {
            for res in [16, 128, 512] {
                let p = pricing(backend, res);
                // One frame: one call either way, and a motion-blur sample costs more.
                assert_eq!(p.choose(1), BlurMethod::Average, "{backend} {res}");
                for m in [2, 5, 34, 64] {
                    assert_eq!(p.choose(m), BlurMethod::MotionBlur, "{backend} {res} {m}");
                }
            }
        }
    }

    #[test]
    fn prices_grow_with_frames_samples_and_pixels() {
        for model in [CostModel::CPU, CostModel::GPU] {
            let mut last = 0.0;
            for m in 1..40u64 {
                let s = model.seconds(2 * m, 32, 64, false);
                assert!(s >= last);
                last = s;
            }
            for mb in [false, true] {
                assert!(model.seconds(2, 64, 64, mb) > model.seconds(2, 32, 64, mb));
                assert!(model.seconds(2, 32, 128, mb) > model.seconds(2, 32, 64, mb));
                assert!(model.seconds(3, 32, 64, mb) >= model.seconds(2, 32, 64, mb));
            }
        }
    }

    #[test]
    fn unknown_backends_are_refused() {
        assert!(CostModel::of_backend("tpu").is_err());
        assert!(CostModel::of_backend("").is_err());
        assert_eq!(CostModel::of_backend(" cpu ").ok(), Some(CostModel::CPU));
    }

    #[test]
    fn the_record_counts_and_sums() {
        let p = pricing("cuda", 512);
        let prices: Vec<ImagePrice> = [1, 34, 10].iter().map(|&m| p.price(m)).collect();
        let r = p.record(&prices);
        assert_eq!(r.images.get("average"), Some(&1));
        assert_eq!(r.images.get("motion_blur"), Some(&2));
        assert_eq!(r.device, "cuda");
        assert!(r.cost_s.chosen <= r.cost_s.average && r.cost_s.chosen <= r.cost_s.motion_blur);
        assert!(r.reason.contains("cuda"), "{}", r.reason);
    }
}
