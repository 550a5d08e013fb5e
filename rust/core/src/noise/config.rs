//! The noise configuration: every option of `blurset noise`, its default, its range and
//! the one validator, declared once like the build's (`noise_options!`, made into a
//! struct by [`config_struct!`]). Python makes the command's flags from
//! [`NoiseConfig::declarations`] and passes the validated config through the noise
//! modes; an error names the option, which Python turns into its flag.
use crate::error::Result;
use crate::noise::raw_model::ModelKind;
use crate::plan::choices::{choice, NoiseGamma, NoiseProfile, NoiseSource};
use crate::plan::options::{config_struct, shapes_outputs, Meta, OptionInfo};
use crate::plan::spec::{check, config_error, convert, specs, Kind, Raw, Spec};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// The gain levels of the LLFF-N benchmark (NAN, Pearl et al. 2022).
pub const LLFF_N_GAINS: [f64; 6] = [1.0, 2.0, 4.0, 8.0, 16.0, 20.0];

/// A count of at least one with no upper bound of its own.
const AT_LEAST_ONE: Spec = Spec::int(1, u32::MAX as i128);

/// The most noisy frames per view: a burst of KPN's 8 many times over, and a bound on
/// the names and files one run plans (100 000 000 grew past 3 GB before writing any).
pub const MAX_FRAMES: u32 = 256;

/// The options of `blurset noise`, declared once: `name: Type = default, range,
/// shapes|run { flags, help, … }` ([`crate::plan::options::Meta`]). The table is a
/// macro so that one list makes the struct here and the binding's getters
/// (`rust/py/src/config.rs`).
#[macro_export]
macro_rules! noise_options {
    ($then:ident $({ $($extra:tt)* })?) => { $then! { $({ $($extra)* })?
    /// Every option of `blurset noise` (see the module docs).
    NoiseConfig, "blurset noise";
    /// The output directory.
    out: Option<String> = None, Spec::Str, run {
        help: "output directory (must not exist; required)",
    };
    /// Gains as given (numbers; the LLFF-N levels unless any_gain).
    gains: Vec<String> = vec!["1".into(), "2".into(), "4".into(), "8".into(), "16".into(),
        "20".into()], Spec::StrList, shapes {
        help: "gain levels, each one of the LLFF-N levels unless --any-gain",
    };
    /// The scene's image folder: images_<F>/ (1: images/), written under the same name.
    factor: Option<u32> = None, AT_LEAST_ONE, shapes {
        help: "read the scene's images_<F>/ (1: images/) and write each gain's noisy images \
            under that name, hwf unchanged as LLFF loaders expect",
        unset: Some("the scene's one images*/ folder (of several: refused, naming them)"),
    };
    seed: u64 = 0, specs::SEED, shapes {
        help: "seed of all noise and white balance",
    };
    profile: NoiseProfile = NoiseProfile::Paper, choice::<NoiseProfile>(), shapes {
        help: "paper: random white balance per scene; nan: none (parity with NAN's evaluation)",
    };
    /// The noise model: `paper`, `unprocess` or `eld:<Camera>` (issue 61).
    model: String = "paper".into(), Spec::Str, shapes {
        help: "noise model: paper (LLFF-N, the default), unprocess (Brooks et al. 2019) or \
            eld:<camera> (Wei et al. ELD: SonyA7S2, NikonD850, CanonEOS70D, CanonEOS700D, \
            CanonEOS5D4); see the noise guide",
        metavar: Some("MODEL"),
    };
    frames: u32 = 1, Spec::int(1, MAX_FRAMES as i128), shapes {
        help: "independent noisy frames per view",
    };
    /// KPN's synthetic test file (.npz) whose sigmas NAN used.
    kpn_levels: Option<String> = None, Spec::Str, shapes {
        help: "KPN's synthetic test file (.npz with sig_read, sig_shot) to reproduce NAN's \
            sigmas",
        unset: Some("none, the LLFF-N sigma table"),
    };
    /// Transfer curve; None: 2.2 for a scene, srgb for a build.
    gamma: Option<NoiseGamma> = None, choice::<NoiseGamma>(), shapes {
        help: "transfer curve",
        unset: Some("2.2 as NAN for a scene; srgb, the build's own curve, for a build"),
    };
    white_level: f64 = 1.0, Spec::Num { lo: 1e-6, lo_open: false, hi: 1.0, hi_open: false },
        shapes {
        help: "linear value of white, in [1e-6, 1]",
    };
    any_gain: bool = false, Spec::Bool, run {
        help: "allow gains outside the LLFF-N levels",
    };
    /// images_<f>/ and linear_<f>/ per gain; None: a build's own factors, a scene none.
    downsample: Option<Vec<u32>> = None, Spec::Factors, shapes {
        help: "also images_<f>/ and linear_<f>/ per gain, noise drawn at that size on the \
            clean image area-averaged in linear light",
        unset: Some("a build's own factors; a scene: none"),
    };
    /// Every K-th view (i % K == 0) stays clean: the loaders' `llffhold`.
    clean_views: Option<u32> = None, AT_LEAST_ONE, shapes {
        help: "views i with i % K == 0 stay clean, the held-out targets of llffhold K",
        unset: Some("a scene 8, LLFF's llffhold; a build its test views"),
        metavar: Some("K"),
    };
    no_linear: bool = false, Spec::Bool, shapes {
        help: "leave out the linear EXRs (linear*/), most of an output's bytes",
    };
    overwrite: bool = false, Spec::Bool, run {
        help: "replace OUT if it exists",
    };
    /// Levels of a build to noise (`sharp,blur_4`); None: all.
    levels: Option<String> = None, Spec::Str, shapes {
        kind: Some(Kind::Text),
        help: "levels to noise, e.g. sharp,blur_4",
        unset: Some("all"),
        section: Some("build mode (SCENE is a build directory)"),
    };
    source: NoiseSource = NoiseSource::Auto, choice::<NoiseSource>(), shapes {
        help: "clean image: the build's linear EXRs (--keep-linear) or its PNGs \
            (auto: linear when every chosen level has them)",
        section: Some("build mode (SCENE is a build directory)"),
    };
    noisy_test_views: bool = false, Spec::Bool, shapes {
        help: "noise the held-out views too (off: they stay clean, NAN's protocol)",
    };
    quiet: bool = false, Spec::Bool, run {
        help: "no progress line",
        section: Some("build mode (SCENE is a build directory)"),
    };
    } };
}

noise_options!(config_struct);

impl NoiseConfig {
    /// Defaults overridden by `values` (option name → value), then validated.
    pub fn from_values(values: &BTreeMap<String, Raw>) -> Result<NoiseConfig> {
        let mut cfg = NoiseConfig::default();
        for (k, v) in values {
            cfg.set(k, v)?;
        }
        cfg.validate()?;
        Ok(cfg)
    }

    /// The one validator: every field in its range, then the gains.
    pub fn validate(&self) -> Result<()> {
        self.check_fields()?;
        self.gain_values()?;
        self.model_kind()?;
        Ok(())
    }

    /// The `llffhold` of a scene's clean views (views i % llffhold == 0): `clean_views`,
    /// else LLFF's default 8; None when `noisy_test_views`.
    pub fn llffhold(&self) -> Option<u32> {
        (!self.noisy_test_views).then(|| self.clean_views.unwrap_or(8))
    }

    /// The model `model` names; an unknown name names the option.
    pub fn model_kind(&self) -> Result<ModelKind> {
        ModelKind::parse(&self.model).map_err(|e| config_error("model", e.to_string()))
    }

    /// The gains as numbers, in the order given: each a positive finite number, one of
    /// the LLFF-N levels unless `any_gain`, none twice.
    pub fn gain_values(&self) -> Result<Vec<f64>> {
        let mut out: Vec<f64> = Vec::new();
        for v in &self.gains {
            let g: f64 = v
                .trim()
                .parse()
                .map_err(|_| config_error("gains", format!("unknown gain '{v}': not a number")))?;
            if !(g.is_finite() && g > 0.0) {
                return Err(config_error(
                    "gains",
                    format!("unknown gain '{v}': gains are positive numbers"),
                ));
            }
            if !self.any_gain && !LLFF_N_GAINS.contains(&g) {
                return Err(config_error(
                    "gains",
                    format!(
                        "unknown gain '{v}': the LLFF-N levels are 1 2 4 8 16 20; pass \
                         --any-gain for other values"
                    ),
                ));
            }
            if out.contains(&g) {
                return Err(config_error("gains", format!("gain '{v}' given twice")));
            }
            out.push(g);
        }
        if out.is_empty() {
            return Err(config_error(
                "gains",
                "none given: at least one gain".into(),
            ));
        }
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plan::options::check_declarations;

    fn with(k: &str, v: Raw) -> Result<NoiseConfig> {
        NoiseConfig::from_values(&BTreeMap::from([(k.to_string(), v)]))
    }

    fn err(k: &str, v: Raw) -> String {
        with(k, v).err().map(|e| e.to_string()).unwrap_or_default()
    }

    #[test]
    fn the_declarations_hold() {
        assert_eq!(check_declarations(&NoiseConfig::declarations()), Ok(()));
        let d = NoiseConfig::default();
        assert_eq!(d.gains.len(), 6);
        assert_eq!((d.frames, d.seed, d.white_level), (1, 0, 1.0));
        assert_eq!(d.gain_values().ok(), Some(LLFF_N_GAINS.to_vec()));
    }

    #[test]
    fn a_bad_value_names_its_option() {
        assert!(err("frames", Raw::Int(0)).starts_with("frames 0:"));
        let e = err("frames", Raw::Int(100_000_000));
        assert!(
            e.starts_with("frames 100000000:") && e.contains("256"),
            "{e}"
        );
        assert!(err("white_level", Raw::Float(2.0)).starts_with("white_level "));
        assert!(err("seed", Raw::Int(-1)).starts_with("seed -1:"));
        assert!(err("factor", Raw::Int(0)).starts_with("factor 0:"));
        assert!(err("clean_views", Raw::Int(0)).starts_with("clean_views 0:"));
        assert!(err("profile", Raw::Str("x".into())).starts_with("profile"));
        assert!(err("model", Raw::Str("eld:Pixel4".into())).contains("SonyA7S2"));
        let eld = with("model", Raw::Str("ELD:sonya7s2".into()));
        assert_eq!(
            eld.ok().and_then(|c| c.model_kind().ok()).map(|k| k.name()),
            Some("eld:SonyA7S2".into())
        );
        let g = |v: &[&str]| Raw::List(v.iter().map(|s| Raw::Str(s.to_string())).collect());
        assert!(err("gains", g(&["1", "3"])).contains("unknown gain '3'"));
        assert!(err("gains", g(&["x"])).contains("not a number"));
        assert!(err("gains", g(&["2", "2"])).contains("given twice"));
        let any = NoiseConfig::from_values(&BTreeMap::from([
            ("gains".to_string(), g(&["3"])),
            ("any_gain".to_string(), Raw::Bool(true)),
        ]));
        assert_eq!(
            any.ok().map(|c| c.gain_values().ok()),
            Some(Some(vec![3.0]))
        );
    }
}
