//! The raw noise models of `blurset noise --model` (issue 61): which model a name
//! means, and every parameter of one variant (one gain of one scene) with its source.
//!
//! - `paper`: the LLFF-N model of [`super::model`] (not a raw model).
//! - `unprocess`: Brooks et al. 2019. Per scene (its seed): a colour matrix between
//!   their four cameras' (weights U[0, 1), normalised), an overall gain 1/N(0.8, 0.1),
//!   `ln shot ~ U(ln 1e-4, ln 0.012)` and `ε ~ N(0, 0.26)`. At gain g the shot
//!   variance per unit signal is `shot · g` and the read variance
//!   `exp(2.18 · ln(shot · g) + 1.20 + ε)`: their fitted line, moved along by g.
//!   Gaussian noise of variance `shot_g · x + read_g` per photosite, no quantization,
//!   their smoothstep tone curve and 2.2 gamma between linear light and codes.
//! - `eld:<Camera>`: Wei et al. 2020/2021, a camera of ELD's release. Gain g means
//!   the system gain `K = g · Kmin` (DN per electron; Kmin is the camera's lowest
//!   calibrated K, so gain 1 is its base ISO and K ∝ ISO): Poisson shot noise of the
//!   signal's electrons, Tukey-lambda read noise of scale `exp(G_scale(ln K))` and
//!   shape λ, row noise `N(0, exp(R_scale(ln K)))` per sensor row, rounding to integer
//!   DN, clipping to [0, white]. λ: the release lists one per calibrated capture,
//!   lowest ISO first, without the ISOs; they are taken as evenly spaced in ln K over
//!   [Kmin, Kmax] and interpolated at K.
use super::camera::LEVELS_SOURCE;
use super::camera::{eld_camera, EldCamera, BROOKS_XYZ_TO_CAM, ELD_BITS, ELD_SOURCE};
use super::draws::{normal, tukey_variance};
use super::matrix::{cam_from_rgb, inverse, Mat3};
use super::model::{Gamma, WhiteBalance};
use super::mosaic::DEMOSAIC;
use crate::error::{Error, Result};
use crate::rng;
use serde_json::{json, Value};

/// The model a `--model` value names.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ModelKind {
    Paper,
    Unprocess,
    Eld(&'static EldCamera),
}

impl ModelKind {
    /// `paper`, `unprocess` or `eld:<Camera>` (case-insensitive).
    pub fn parse(s: &str) -> Result<Self> {
        let low = s.trim().to_ascii_lowercase();
        if low == "paper" {
            return Ok(ModelKind::Paper);
        }
        if low == "unprocess" {
            return Ok(ModelKind::Unprocess);
        }
        let cams: Vec<&str> = super::camera::ELD_CAMERAS.iter().map(|c| c.name).collect();
        let camera = low.strip_prefix("eld:").and_then(|c| eld_camera(c.trim()));
        camera.map(ModelKind::Eld).ok_or_else(|| {
            Error::Value(format!(
                "unknown model '{s}': paper, unprocess or eld:<camera> with camera one of {}",
                cams.join(", ")
            ))
        })
    }

    /// The canonical name (`eld:SonyA7S2`).
    pub fn name(&self) -> String {
        match self {
            ModelKind::Paper => "paper".into(),
            ModelKind::Unprocess => "unprocess".into(),
            ModelKind::Eld(c) => format!("eld:{}", c.name),
        }
    }
}

/// The noise at one photosite, in DN of the model's raw.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum RawNoise {
    /// ELD: Poisson electrons at `k` DN/e⁻, Tukey-lambda read noise (`read_scale`,
    /// `lambda`) and row noise of σ `row_sigma`.
    Physics {
        k: f64,
        read_scale: f64,
        lambda: f64,
        row_sigma: f64,
    },
    /// Brooks: Gaussian of variance `shot · x + read` (x the signal, white = 1).
    Gaussian { shot: f64, read: f64 },
}

/// Everything that decides a raw-model variant's values, except randomness.
#[derive(Clone, Debug, PartialEq)]
pub struct RawModel {
    /// `unprocess` or `eld:<Camera>`.
    pub name: String,
    pub cam_from_rgb: Mat3,
    pub rgb_from_cam: Mat3,
    /// Per camera channel: raw = camera RGB / wb.
    pub wb: [f64; 3],
    /// Raw levels (DN): the signal spans [black, white].
    pub black: f64,
    pub white: f64,
    /// Round to integer DN and clip to [0, white] (ELD); none for Brooks.
    pub quantize: bool,
    pub noise: RawNoise,
    /// Brooks' smoothstep tone curve and 2.2 gamma between linear and codes; else `gamma`.
    pub tone_curve: bool,
    pub gamma: Gamma,
    pub white_level: f64,
    /// False: the clean pipeline (a clean view), no noise or quantization.
    pub noisy: bool,
    /// Every parameter and its source, as noise.json's `raw_model`.
    pub record: Value,
}

/// The camera's white balance gains from the scene's draw (None: 1, 1, 1).
fn wb_gains(wb: Option<WhiteBalance>) -> [f64; 3] {
    wb.map_or([1.0; 3], |w| [w.red, 1.0, w.blue])
}

fn matrices(xyz_to_cam: &Mat3) -> Result<(Mat3, Mat3)> {
    let cam = cam_from_rgb(xyz_to_cam);
    let rgb = inverse(&cam).ok_or_else(|| Error::Value("singular colour matrix".into()))?;
    Ok((cam, rgb))
}

/// The Tukey λ of camera `c` at system gain `k` (see the module docs).
pub fn eld_lambda(c: &EldCamera, k: f64) -> f64 {
    let n = c.shape.len();
    let t = libm::log(k / c.k_min) / libm::log(c.k_max / c.k_min) * (n - 1) as f64;
    let t = t.clamp(0.0, (n - 1) as f64);
    let i = (t.floor() as usize).min(n.saturating_sub(2));
    let f = t - i as f64;
    c.shape[i] * (1.0 - f) + c.shape[(i + 1).min(n - 1)] * f
}

/// The shared part of a raw model: the display transfer, white level and balance.
#[derive(Clone, Copy, Debug)]
pub struct Display {
    pub gamma: Gamma,
    pub white_balance: Option<WhiteBalance>,
    pub white_level: f64,
}

impl RawModel {
    /// ELD camera `c` at `gain` (K = gain · Kmin).
    pub fn eld(c: &'static EldCamera, gain: f64, d: Display) -> Result<RawModel> {
        let k = gain * c.k_min;
        let (cam, rgb) = matrices(&c.xyz_to_cam)?;
        let noise = RawNoise::Physics {
            k,
            read_scale: c.read_scale.at(k),
            lambda: eld_lambda(c, k),
            row_sigma: c.row_scale.at(k),
        };
        let wb = wb_gains(d.white_balance);
        let record = eld_record(c, k, &noise, &cam, wb);
        Ok(RawModel {
            name: format!("eld:{}", c.name),
            cam_from_rgb: cam,
            rgb_from_cam: rgb,
            wb,
            black: c.black,
            white: c.white,
            quantize: true,
            noise,
            tone_curve: false,
            gamma: d.gamma,
            white_level: d.white_level,
            noisy: true,
            record,
        })
    }

    /// Brooks et al.'s unprocessing at `gain`, its draws from the scene's `seed`.
    pub fn unprocess(seed: u64, gain: f64, d: Display) -> Result<RawModel> {
        let key = rng::derive_seed(seed, &[rng::fnv1a64(b"unprocess")]);
        let mut s = rng::Stream::new(key, 0);
        let weights: Vec<f64> = (0..4).map(|_| s.uniform()).collect();
        let total: f64 = weights.iter().sum::<f64>().max(f64::MIN_POSITIVE);
        let mut xyz = [[0.0; 3]; 3];
        for (w, m) in weights.iter().zip(BROOKS_XYZ_TO_CAM.iter()) {
            for i in 0..3 {
                for j in 0..3 {
                    xyz[i][j] += w / total * m[i][j];
                }
            }
        }
        // 1 / N(0.8, 0.1), kept away from 0 and negative values (a 8σ draw).
        let rgb_gain = 1.0 / (0.8 + 0.1 * normal(&mut s)).max(0.05);
        let ln_shot = s.uniform_in(libm::log(1e-4), libm::log(0.012));
        let eps = 0.26 * normal(&mut s);
        let shot = libm::exp(ln_shot) * gain;
        let read = libm::exp(2.18 * libm::log(shot) + 1.20 + eps);
        let (cam, rgb) = matrices(&xyz)?;
        let wb = wb_gains(d.white_balance).map(|g| g * rgb_gain);
        let draws = (&weights[..], rgb_gain, libm::exp(ln_shot), eps);
        let record = unprocess_record(draws, shot, read, &cam, wb);
        Ok(RawModel {
            name: "unprocess".into(),
            cam_from_rgb: cam,
            rgb_from_cam: rgb,
            wb,
            black: 0.0,
            white: 1.0,
            quantize: false,
            noise: RawNoise::Gaussian { shot, read },
            tone_curve: true,
            gamma: d.gamma,
            white_level: d.white_level,
            noisy: true,
            record,
        })
    }

    /// The model of `kind` at `gain` for a scene of seed `seed` (None for `paper`).
    pub fn of(kind: ModelKind, seed: u64, gain: f64, d: Display) -> Result<Option<RawModel>> {
        match kind {
            ModelKind::Paper => Ok(None),
            ModelKind::Unprocess => RawModel::unprocess(seed, gain, d).map(Some),
            ModelKind::Eld(c) => RawModel::eld(c, gain, d).map(Some),
        }
    }

    /// The same model without noise or quantization (a clean view).
    pub fn clean(&self) -> RawModel {
        RawModel {
            noisy: false,
            ..self.clone()
        }
    }

    /// The model's noise as the paper's two σ in raw signal units (white − black = 1):
    /// `σ_shot² = K / (white − black)` and `σ_read²` the variance at zero signal (read,
    /// row and quantization), for noise.json's `sigma_read` and `sigma_shot`.
    pub fn sigma_equivalents(&self) -> (f64, f64) {
        let range = self.white - self.black;
        match self.noise {
            RawNoise::Physics {
                k,
                read_scale,
                lambda,
                row_sigma,
            } => {
                let var = read_scale * read_scale * tukey_variance(lambda)
                    + row_sigma * row_sigma
                    + 1.0 / 12.0;
                (libm::sqrt(var) / range, libm::sqrt(k / range))
            }
            RawNoise::Gaussian { shot, read } => (libm::sqrt(read), libm::sqrt(shot)),
        }
    }
}

fn eld_record(c: &EldCamera, k: f64, noise: &RawNoise, cam: &Mat3, wb: [f64; 3]) -> Value {
    let RawNoise::Physics {
        read_scale,
        lambda,
        row_sigma,
        ..
    } = *noise
    else {
        return Value::Null;
    };
    let fit = |f: &super::camera::Fit| json!({"slope": f.slope, "bias": f.bias, "sigma": f.sigma});
    json!({
        "name": format!("eld:{}", c.name),
        "camera": c.name,
        "source": ELD_SOURCE,
        "levels_source": LEVELS_SOURCE,
        "system_gain_k": k,
        "k_min": c.k_min,
        "k_max": c.k_max,
        "k_over_k_min": k / c.k_min,
        "iso_stops_above_k_min": libm::log2(k / c.k_min),
        "iso": "gain g sets K = g * k_min: ISO = g x the camera's ISO at k_min (ELD's \
            release gives K, not ISO; k_max = 64 k_min for every camera, six stops)",
        "extrapolated": k > c.k_max * (1.0 + 1e-9),
        "read_noise": {"distribution": "tukey-lambda", "scale_dn": read_scale,
            "lambda": lambda, "scale_fit": fit(&c.read_scale),
            "lambda_rule": "G_shape entries evenly spaced in ln K over [k_min, k_max], \
                linear interpolation", "g_shape": c.shape},
        "row_noise": {"distribution": "normal per sensor row", "sigma_dn": row_sigma,
            "fit": fit(&c.row_scale)},
        "fit_spread": "the fits' residual sigma is recorded, not drawn",
        "shot_noise": "poisson(electrons = signal_dn / K) * K",
        "quantization": "round to integer DN", "bits": ELD_BITS,
        "black_level_dn": c.black, "white_level_dn": c.white, "clip": "[0, white_level_dn]",
        "cfa": "RGGB", "demosaic": DEMOSAIC,
        "xyz_to_cam": c.xyz_to_cam, "cam_from_rgb": cam, "white_balance_gains": wb,
        "transfer": "the run's gamma",
    })
}

type Draws<'a> = (&'a [f64], f64, f64, f64);

fn unprocess_record(d: Draws<'_>, shot: f64, read: f64, cam: &Mat3, wb: [f64; 3]) -> Value {
    let (weights, rgb_gain, shot_1, eps) = d;
    json!({
        "name": "unprocess",
        "source": "Brooks et al. 2019, Unprocessing Images for Learned Raw Denoising \
            (CVPR), unprocess.py of google-research/unprocessing",
        "ccm_weights": weights, "xyz_to_cam": BROOKS_XYZ_TO_CAM, "cam_from_rgb": cam,
        "rgb_gain": rgb_gain, "white_balance_gains": wb,
        "shot_noise_gain_1": shot_1, "read_noise_residual": eps,
        "shot_noise": shot, "read_noise": read,
        "noise": "x + sqrt(shot_noise * x + read_noise) * N(0, 1) per photosite; \
            ln shot ~ U(ln 1e-4, ln 0.012) per scene, times gain; ln read = 2.18 ln shot \
            + 1.20 + N(0, 0.26)",
        "quantization": "none", "clip": "none in raw",
        "tone_curve": "smoothstep 3x^2 - 2x^3 after gamma 1/2.2 (inverted on the way in)",
        "cfa": "RGGB", "demosaic": DEMOSAIC,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::noise::camera::ELD_CAMERAS;
    use crate::noise::linear::LinearRgb;
    use crate::noise::mosaic::cfa_channel;
    use crate::noise::raw::{clean_raw, noisy_mosaic};

    #[test]
    fn eld_read_noise_per_photosite_is_the_calibrations() {
        // At zero signal a photosite holds read noise, row noise and rounding; less each
        // row's mean, read noise and rounding. Its variance, measured over many draws,
        // against the calibration's own numbers (G_scale's fit at K = gain * Kmin, G_shape
        // at K), not the model's fields: a scale 1.1 off is a variance 1.21 off.
        let d = Display {
            gamma: Gamma::Srgb,
            white_balance: None,
            white_level: 1.0,
        };
        for (name, gain) in [("SonyA7S2", 8.0), ("CanonEOS70D", 20.0), ("NikonD850", 1.0)] {
            let c = ELD_CAMERAS.iter().find(|c| c.name == name).expect("camera");
            let m = RawModel::eld(c, gain, d).expect("model");
            let k = gain * c.k_min;
            let scale = (c.read_scale.slope * k.ln() + c.read_scale.bias).exp();
            let rec = m.record["read_noise"]["scale_dn"].as_f64().expect("scale");
            assert!(
                (rec / scale - 1.0).abs() < 1e-12,
                "{name}: {rec} vs {scale}"
            );
            let w = 1024usize;
            let img = LinearRgb::new(w as u32, w as u32, vec![0.0; w * w * 3]).expect("image");
            let noisy = noisy_mosaic(&m, &clean_raw(&img, &m), w, 11, 12);
            let range = m.white - m.black;
            let mut sum = [0.0; 3];
            let mut n = [0.0; 3];
            for (y, row) in noisy.chunks_exact(w).enumerate() {
                let mean = row.iter().sum::<f64>() / w as f64;
                for (x, v) in row.iter().enumerate() {
                    let c = cfa_channel(x, y);
                    sum[c] += ((v - mean) * range).powi(2);
                    n[c] += 1.0;
                }
            }
            let want = (scale * scale * tukey_variance(eld_lambda(c, k)) + 1.0 / 12.0)
                * (1.0 - 1.0 / w as f64);
            for ch in 0..3 {
                let ratio = sum[ch] / n[ch] / want;
                eprintln!("{name} gain {gain} channel {ch}: variance / calibration {ratio:.4}");
                assert!((ratio - 1.0).abs() < 0.05, "{name} channel {ch}: {ratio}");
            }
        }
    }
}
