//! The options that take one of a few named values, as types: every name is spelled once,
//! in its enum's [`choice_enum!`] declaration, which gives serde (records), the option
//! parser (case-insensitive) and the declarations' `choices` (the CLI and the stub's
//! `Literal` types) the same list. Above the option specs (a choice is read by
//! [`choice_index`], as a `Spec::Choice`), below the config and the plan.
use super::spec::{choice_index, Kind, OptionValue, Raw, Spec};
use serde::{Deserialize, Serialize};

/// An option value that is one of a fixed set of names.
pub trait Choice: Copy + PartialEq + Sized + 'static {
    /// Every value's name, as flags, TOML files and records spell it.
    const NAMES: &'static [&'static str];
    /// Every value, in the order of [`Choice::NAMES`].
    const ALL: &'static [Self];

    /// The value's name.
    fn name(self) -> &'static str {
        let i = Self::ALL.iter().position(|v| *v == self).unwrap_or(0);
        Self::NAMES[i]
    }

    /// The value named `text`, in any case and without surrounding blanks (`CUDA`,
    /// ` Cuda` name `cuda`).
    fn from_name(text: &str) -> Option<Self> {
        choice_index(Self::NAMES, text).map(|i| Self::ALL[i])
    }
}

/// The spec of a [`Choice`] option: its names.
pub const fn choice<T: Choice>() -> Spec {
    Spec::Choice(T::NAMES)
}

/// An enum of named values: `pub enum E { Variant = "name", … }`, each name given once;
/// serde writes and reads that name, [`Choice`] lists it, and [`OptionValue`] reads it
/// as an option's value.
macro_rules! choice_enum {
    (
        $(#[$meta:meta])*
        pub enum $name:ident {
            $( $(#[$vmeta:meta])* $variant:ident = $text:literal ),+ $(,)?
        }
    ) => {
        $(#[$meta])*
        #[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq, Eq, schemars::JsonSchema)]
        pub enum $name {
            $( $(#[$vmeta])* #[serde(rename = $text)] $variant, )+
        }

        impl Choice for $name {
            const NAMES: &'static [&'static str] = &[$($text),+];
            const ALL: &'static [Self] = &[$($name::$variant),+];
        }

        impl OptionValue for $name {
            fn from_raw(raw: &Raw, _: &Spec) -> Option<Self> {
                match raw {
                    Raw::Str(s) => Self::from_name(s),
                    _ => None,
                }
            }
            fn to_raw(&self) -> Raw {
                Raw::Str(self.name().into())
            }
            fn kind(_: &Spec) -> Kind {
                Kind::Choice
            }
        }

        impl std::fmt::Display for $name {
            fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                f.write_str(self.name())
            }
        }
    };
}

choice_enum! {
    /// Where a blurry image's latent positions t_i lie on its segment.
    pub enum LatentPositions {
        /// t_i ~ U[0, 1], as in the paper.
        Random = "random",
        /// t_i = (i + u_i) / m: one draw per stratum, no gaps larger than 2/m.
        Stratified = "stratified",
    }
}

choice_enum! {
    /// Where the written pose p sits on a blurry image's segment (DESIGN §2, §12). The
    /// same seeded draws, δ and w_l either way; only the latent positions t move by ½.
    #[derive(Default)]
    pub enum TrajectoryAnchor {
        /// The paper's U(p, p + w_l·δ): the exposure starts at p, t ∈ [0, 1].
        #[default]
        Start = "start",
        /// U(p − w_l·δ/2, p + w_l·δ/2), t ∈ [−½, ½]: the sharp image, the written pose and
        /// the exposure's middle coincide, which is what SfM recovers from a blurry image.
        Centered = "centered",
    }
}

impl TrajectoryAnchor {
    /// The latent position t at which the exposure opens; it closes at `t_open() + 1`.
    pub fn t_open(self) -> f64 {
        match self {
            TrajectoryAnchor::Start => 0.0,
            TrajectoryAnchor::Centered => -0.5,
        }
    }
}

choice_enum! {
    /// How a blurry image is made from its trajectory segment.
    pub enum BlurMethod {
        /// The mean of m latent frames rendered at positions t_1..t_m (the paper).
        Average = "average",
        /// One Cycles render with the camera keyframed along the segment over the
        /// shutter: every path sample gets its own time, so the image integrates the
        /// whole segment.
        MotionBlur = "motion_blur",
        /// Per blurry image, whichever of the two the rendering device makes for less
        /// (`plan/cost.rs`): motion blur where a render call is dear (a GPU), averaged
        /// frames where samples are (the CPU). Needs a render target, which fixes the
        /// accuracy both methods reach.
        Auto = "auto",
    }
}

impl BlurMethod {
    /// Whether images may be averaged latent frames (`average`, or `auto`, which plans
    /// them before it prices them).
    pub fn averages(self) -> bool {
        self != BlurMethod::MotionBlur
    }
}

choice_enum! {
    /// How the Cycles samples of a blurry image's m latent frames relate.
    pub enum LatentSampling {
        /// The frames render the m consecutive blocks of ONE sample sequence on the view's
        /// seed (Cycles `use_sample_subset`): frame i takes samples [i·L, (i + 1)·L) of a
        /// sequence of m·L, L = `samples_per_frame`. Their mean is a stratified estimator
        /// over the exposure, and at zero motion it IS the render of that sequence, which
        /// the sharp image renders too (its first `sharp_samples` samples, same seed).
        Subsets = "subsets",
        /// Every frame its own seed and the first L samples of its own sequence (older
        /// builds): the mean of m such renders converges like plain Monte Carlo, ≈ 2× the
        /// error of one render at m·L samples.
        Independent = "independent",
    }
}

choice_enum! {
    /// How many samples a blurry image gets against the sharp image's budget.
    pub enum BlurBudget {
        /// The budget times [`super::sampling_config::parity_factor`] of the image's m: a moving
        /// camera shows a pixel other content in every latent frame, so the frames'
        /// sample blocks stop adding up to one stratified sequence and m frames at S/m
        /// samples carry more render noise than one frame at S. The factor buys that
        /// back, so the blurry image is no noisier than its sharp truth (measured:
        /// bench/bench_render_parity.py).
        Parity = "parity",
        /// The budget as given: m frames at S/m samples (older builds).
        Flat = "flat",
        /// Parity bought by the image's measured motion:
        /// [`super::sampling_config::need_factor`] of m and the screen motion between its
        /// frames, never more than the parity factor. A level whose frames move ≪ 0.5 px
        /// apart still renders nearly one stratified sequence and needs little more than
        /// the budget.
        Need = "need",
    }
}

choice_enum! {
    /// Whether a build's images are denoised.
    pub enum Denoise {
        /// Images as rendered.
        None = "none",
        /// Every image denoised once by Open Image Denoise: a blurry image after
        /// averaging, with its frames' albedo and normal guides averaged the same way.
        Oidn = "oidn",
    }
}

choice_enum! {
    /// How many light-path bounces an object's renders get.
    pub enum LightPaths {
        /// From the object's materials.
        Auto = "auto",
        /// The same for every object (older builds).
        Fixed = "fixed",
    }
}

choice_enum! {
    /// The Cycles device (run-only: the pixels are the plan's on any device, within noise).
    pub enum Device {
        /// The best backend Cycles reports (OptiX > CUDA > HIP > oneAPI > Metal > CPU).
        Auto = "auto",
        Cpu = "cpu",
        Optix = "optix",
        Cuda = "cuda",
        Hip = "hip",
        Oneapi = "oneapi",
        Metal = "metal",
    }
}

choice_enum! {
    /// Where a build's objects run.
    pub enum Executor {
        /// A local process pool.
        Local = "local",
        /// Ray tasks (a local Ray or a cluster).
        Ray = "ray",
    }
}

choice_enum! {
    /// The white balance of `blurset noise`.
    pub enum NoiseProfile {
        /// A random white balance per scene (the paper).
        Paper = "paper",
        /// None (parity with NAN's evaluation).
        Nan = "nan",
    }
}

choice_enum! {
    /// The transfer curve `blurset noise` linearises with.
    pub enum NoiseGamma {
        /// `y = x^2.2` (NAN's).
        Power22 = "2.2",
        /// The exact sRGB curve (a build's own).
        Srgb = "srgb",
    }
}

choice_enum! {
    /// The clean image `blurset noise` starts from in a build.
    pub enum NoiseSource {
        /// Linear when every chosen level has its EXRs, else the PNGs.
        Auto = "auto",
        /// The build's linear EXRs (`--keep-linear`).
        Linear = "linear",
        /// The build's PNGs.
        Png = "png",
    }
}

choice_enum! {
    /// A named set of build options (`plan/presets.rs` holds what each sets).
    pub enum Preset {
        /// The paper's construction: the defaults.
        Paper = "paper",
        /// Frames by motion, every image rendered to 50 dB on its object's pixels.
        Balanced = "balanced",
        /// Frames by motion, every image rendered to the 8-bit floor (58.9 dB).
        Floor = "floor",
        /// Frames by motion (2 px gaps), every image rendered to 40 dB.
        Fast = "fast",
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// serde's names are the parser's names, for every value of every choice.
    fn same_names<T: Choice + Serialize + for<'de> Deserialize<'de> + std::fmt::Debug>(
    ) -> serde_json::Result<()> {
        assert_eq!(T::NAMES.len(), T::ALL.len());
        for (v, n) in T::ALL.iter().zip(T::NAMES) {
            assert_eq!(serde_json::to_value(v)?, serde_json::json!(n));
            assert_eq!(serde_json::from_value::<T>(serde_json::json!(n))?, *v);
            assert_eq!(T::from_name(&n.to_uppercase()), Some(*v));
            assert_eq!(T::from_name(&format!(" {n} ")), Some(*v));
            assert_eq!(v.name(), *n);
        }
        assert_eq!(T::from_name("nothing"), None);
        assert_eq!(T::from_name(""), None);
        Ok(())
    }

    #[test]
    fn every_choice_reads_and_writes_its_names() -> serde_json::Result<()> {
        same_names::<LatentPositions>()?;
        same_names::<TrajectoryAnchor>()?;
        same_names::<BlurMethod>()?;
        same_names::<LatentSampling>()?;
        same_names::<BlurBudget>()?;
        same_names::<Denoise>()?;
        same_names::<LightPaths>()?;
        same_names::<Device>()?;
        same_names::<Executor>()?;
        same_names::<NoiseProfile>()?;
        same_names::<NoiseGamma>()?;
        same_names::<NoiseSource>()?;
        same_names::<Preset>()?;
        Ok(())
    }
}
