//! The noise model: transfer curve, gain → σ table, white balance, and the keys and
//! streams that address every draw.
use crate::error::{Error, Result};
use crate::image::color;
use crate::rng;

/// Transfer curve between the stored codes and linear values.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Gamma {
    /// `y = x^2.2`: NAN's re-linearisation, the default.
    Power22,
    /// The exact piecewise sRGB curve (IEC 61966-2-1).
    Srgb,
}

impl Gamma {
    pub fn parse(s: &str) -> Result<Self> {
        match s.to_ascii_lowercase().as_str() {
            "2.2" | "power2.2" => Ok(Gamma::Power22),
            "srgb" => Ok(Gamma::Srgb),
            _ => Err(Error::Value(format!(
                "gamma {s:?}, expected \"2.2\" or \"srgb\""
            ))),
        }
    }

    /// Code value in [0, 1] → linear.
    pub fn decode(self, x: f64) -> f64 {
        match self {
            Gamma::Power22 => libm::pow(x.clamp(0.0, 1.0), 2.2),
            Gamma::Srgb => color::srgb_decode_f64(x),
        }
    }

    /// Linear in [0, 1] → code value (inverse of `decode`).
    pub fn encode(self, y: f64) -> f64 {
        match self {
            Gamma::Power22 => libm::pow(y.clamp(0.0, 1.0), 1.0 / 2.2),
            Gamma::Srgb => color::srgb_encode_f64(y),
        }
    }
}

/// Gain → σ mapping: `log10 σ(g) = log10 σ(1) + step · log2 g`, read and shot apart.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NoiseLevels {
    pub log10_read: f64,
    pub read_step: f64,
    pub log10_shot: f64,
    pub shot_step: f64,
}

impl NoiseLevels {
    /// blurset's default table; NOT the values of KPN's test file that NAN reads (that
    /// file is not redistributable; pass it with `from_kpn` to reproduce NAN).
    /// Derived from the ranges KPN (Mildenhall et al. 2018, §4) trains on,
    /// log10 σ_r ∈ [−3, −1.5] and log10 σ_s ∈ [−4, −2], assuming its six test levels
    /// are log-uniform over that range with gain 4 (level 4) at its top: one level per
    /// doubling of gain, so the step is a quarter of each range and gain 1 (level 2)
    /// sits half-way. Gain 8 then lies beyond the training range, like KPN's
    /// "extreme" level, and 16 and 20 extrapolate as in NAN.
    pub const DEFAULT: NoiseLevels = NoiseLevels {
        log10_read: -2.25,
        read_step: 0.375,
        log10_shot: -3.0,
        shot_step: 0.5,
    };

    /// NAN's mapping from KPN's synthetic test file: sorted unique values, the two
    /// lowest dropped; the first remaining gives σ(1), the next one the step.
    pub fn from_kpn(sig_read: &[f64], sig_shot: &[f64]) -> Result<Self> {
        fn first_two(name: &str, values: &[f64]) -> Result<(f64, f64)> {
            if let Some(v) = values.iter().find(|v| !v.is_finite() || **v <= 0.0) {
                return Err(Error::Value(format!(
                    "{name} holds {v}, expected positive values"
                )));
            }
            let mut u = values.to_vec();
            u.sort_by(f64::total_cmp);
            u.dedup();
            if u.len() < 4 {
                return Err(Error::Value(format!(
                    "{name} has {} distinct values, expected at least 4 (two dropped, two used)",
                    u.len()
                )));
            }
            let (a, b) = (libm::log10(u[2]), libm::log10(u[3]));
            Ok((a, b - a))
        }
        let (log10_read, read_step) = first_two("sig_read", sig_read)?;
        let (log10_shot, shot_step) = first_two("sig_shot", sig_shot)?;
        Ok(NoiseLevels {
            log10_read,
            read_step,
            log10_shot,
            shot_step,
        })
    }

    /// (σ_read, σ_shot) at a gain.
    pub fn sigmas(&self, gain: f64) -> Result<(f64, f64)> {
        if !(gain.is_finite() && gain > 0.0) {
            return Err(Error::Value(format!(
                "gain {gain}, expected a positive number"
            )));
        }
        let l = libm::log2(gain);
        Ok((
            libm::pow(10.0, self.log10_read + self.read_step * l),
            libm::pow(10.0, self.log10_shot + self.shot_step * l),
        ))
    }
}

/// Camera white-balance gains of the red and blue channels (green is 1).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WhiteBalance {
    pub red: f64,
    pub blue: f64,
}

/// One draw per scene in the unprocessing ranges (Brooks et al. 2019):
/// red U[1.9, 2.4], blue U[1.5, 1.9].
pub fn sample_white_balance(seed: u64) -> WhiteBalance {
    let key = rng::derive_seed(seed, &[rng::fnv1a64(b"white_balance")]);
    let mut s = rng::Stream::new(key, 0);
    let red = s.uniform_in(1.9, 2.4);
    let blue = s.uniform_in(1.5, 1.9);
    WhiteBalance { red, blue }
}

/// Everything that decides the noisy values of one variant, except randomness.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NoiseModel {
    pub sigma_read: f64,
    pub sigma_shot: f64,
    pub gamma: Gamma,
    /// `None` leaves the channels alone (NAN parity).
    pub white_balance: Option<WhiteBalance>,
    /// Linear value of a white code; NAN tests at 1 and trains on 10^−U[0,1].
    pub white_level: f64,
}

/// Below this the forward processing divides by a number so small that every noisy
/// value saturates; a white level there is a unit mistake, not an experiment.
pub const MIN_WHITE_LEVEL: f64 = 1e-6;

impl NoiseModel {
    pub fn validate(&self) -> Result<()> {
        for (name, v) in [
            ("sigma_read", self.sigma_read),
            ("sigma_shot", self.sigma_shot),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(Error::Value(format!(
                    "{name} = {v}, expected a finite value >= 0"
                )));
            }
        }
        if !(MIN_WHITE_LEVEL..=1.0).contains(&self.white_level) {
            return Err(Error::Value(format!(
                "white level {}, expected {MIN_WHITE_LEVEL} <= white level <= 1",
                self.white_level
            )));
        }
        if let Some(wb) = self.white_balance {
            for (name, v) in [("red", wb.red), ("blue", wb.blue)] {
                if !(v.is_finite() && v > 0.0) {
                    return Err(Error::Value(format!(
                        "white balance {name} = {v}, expected a positive number"
                    )));
                }
            }
        }
        Ok(())
    }

    /// Linear value per unit of processed value, per colour channel.
    pub(crate) fn channel_scale(&self, c: usize, color_channels: usize) -> f64 {
        let wb = match (self.white_balance, color_channels) {
            (Some(wb), 3) => [wb.red, 1.0, wb.blue][c],
            // Gray images have no red or blue to balance.
            _ => 1.0,
        };
        self.white_level / wb
    }

    /// Standard deviation of the noise at clean linear value `y`: `sqrt(σ_r² + σ_s²·y)`.
    pub(crate) fn noise_std(&self, y: f64) -> f64 {
        let var_read = self.sigma_read * self.sigma_read;
        let var_shot = self.sigma_shot * self.sigma_shot;
        libm::sqrt(var_read + var_shot * y)
    }
}

/// The Philox key of one gain of one seed.
pub fn noise_key(seed: u64, gain: f64) -> u64 {
    rng::derive_seed(seed, &[rng::fnv1a64(b"noise"), gain.to_bits()])
}

/// The Philox key of a variant's `images_<factor>/` copy: the variant's own key at
/// factor 1 (so full-size files do not change), else one derived from it, so the
/// smaller noise is drawn afresh rather than reusing the full-size draws.
pub fn factor_key(key: u64, factor: u32) -> u64 {
    if factor == 1 {
        return key;
    }
    rng::derive_seed(key, &[rng::fnv1a64(b"downsample"), u64::from(factor)])
}

/// The Philox stream of one frame of one view.
pub fn stream_id(view: u32, frame: u32) -> u64 {
    ((view as u64) << 32) | frame as u64
}

/// The noise seed of one level of one setting of a build, from the one seed given to
/// `blurset noise BUILD`: `derive_seed(seed, [fnv1a64("build_noise"), fnv1a64(setting),
/// fnv1a64(level)])`. It depends on neither the gains nor the levels chosen, so adding
/// a gain or a level later reproduces what exists. It plays the role of `--seed` of the
/// single-scene command (white balance and `noise_key(seed, gain)` come from it).
pub fn scene_seed(seed: u64, setting: &str, level: &str) -> u64 {
    rng::derive_seed(
        seed,
        &[
            rng::fnv1a64(b"build_noise"),
            rng::fnv1a64(setting.as_bytes()),
            rng::fnv1a64(level.as_bytes()),
        ],
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn white_balance_draws_fill_the_unprocessing_ranges() {
        // Red U[1.9, 2.4], blue U[1.5, 1.9] (Brooks et al. 2019; DESIGN §5): a swap of
        // the two ranges, or a narrowed one, fails here.
        let draws: Vec<WhiteBalance> = (0..4000u64).map(sample_white_balance).collect();
        let span = |f: fn(&WhiteBalance) -> f64| {
            draws
                .iter()
                .map(f)
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), x| {
                    (lo.min(x), hi.max(x))
                })
        };
        let (r_lo, r_hi) = span(|w| w.red);
        let (b_lo, b_hi) = span(|w| w.blue);
        assert!(
            (1.9..1.91).contains(&r_lo) && (2.39..=2.4).contains(&r_hi),
            "red {r_lo} {r_hi}"
        );
        assert!(
            (1.5..1.51).contains(&b_lo) && (1.89..=1.9).contains(&b_hi),
            "blue {b_lo} {b_hi}"
        );
        let mean = |f: fn(&WhiteBalance) -> f64| draws.iter().map(f).sum::<f64>() / 4000.0;
        assert!((mean(|w| w.red) - 2.15).abs() < 0.01);
        assert!((mean(|w| w.blue) - 1.7).abs() < 0.01);
    }

    #[test]
    fn scene_seeds_differ_and_are_stable() {
        let a = scene_seed(7, "demo_box_000", "blur_2");
        assert_eq!(a, scene_seed(7, "demo_box_000", "blur_2"));
        assert_ne!(a, scene_seed(7, "demo_box_000", "blur_3"));
        assert_ne!(a, scene_seed(7, "demo_box_090", "blur_2"));
        assert_ne!(a, scene_seed(8, "demo_box_000", "blur_2"));
        // Not a plain concatenation: ("ab", "c") and ("a", "bc") differ.
        assert_ne!(scene_seed(0, "ab", "c"), scene_seed(0, "a", "bc"));
    }

    /// On a linear image whose values are exactly the decoded PNG codes, the linear
    /// path reproduces the PNG path's linear output bit for bit (shared draws and
    /// arithmetic), and its processed codes within one code (tie rounding).

    #[test]
    fn kpn_mapping_drops_two_lowest() -> Result<()> {
        // Six levels, each repeated, as in KPN's file; gains 1, 2 are levels 2, 3.
        let read: Vec<f64> = (0..12)
            .map(|i| 10f64.powf(-3.0 + 0.25 * (i / 2) as f64))
            .collect();
        let shot: Vec<f64> = (0..12)
            .map(|i| 10f64.powf(-4.0 + 0.5 * (i % 6) as f64))
            .collect();
        let l = NoiseLevels::from_kpn(&read, &shot)?;
        assert!((l.log10_read + 2.5).abs() < 1e-12 && (l.read_step - 0.25).abs() < 1e-12);
        assert!((l.log10_shot + 3.0).abs() < 1e-12 && (l.shot_step - 0.5).abs() < 1e-12);
        let (r8, s8) = l.sigmas(8.0)?;
        assert!((r8.log10() - (-2.5 + 0.75)).abs() < 1e-12);
        assert!((s8.log10() - (-3.0 + 1.5)).abs() < 1e-12);
        assert!(NoiseLevels::from_kpn(&[1.0, 2.0, 3.0], &shot).is_err());
        assert!(NoiseLevels::from_kpn(&read, &[0.0, 1.0, 2.0, 3.0, 4.0]).is_err());
        assert!(NoiseLevels::DEFAULT.sigmas(0.0).is_err());
        Ok(())
    }
}
