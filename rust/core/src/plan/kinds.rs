//! The degradation kinds beside motion blur (issue 59): each is its own file in `kinds/`
//! (a [`Degradation`] with its constants: highest level, written pose, own masks, what
//! a level means, its option's help) and one line of [`kinds!`]. Everything a kind
//! needs elsewhere is made from that list: its [`ImageKind`] variant and level folders
//! ([`super::kind`]), its option of `blurset build` (the config field, flag, range
//! check and help: [`kind_rows!`]), its levels in the sampling config
//! ([`super::kind_levels`]), and here: its levels in each view of the plan and of
//! meta.json ([`ViewKinds`]), its renders, its checks, its renders per setting, what its
//! images are ([`KIND_ROWS`]) and its statistic ([`KIND_STATS`]). The kind's name (its
//! module's) is its option, its key in meta.json and its folders' prefix.
use super::degradation::{kind_renders, records, Degradation, KindStat, RenderCx, ViewCx};
use super::kind::{ImageKind, SHARP};
use super::kind_levels::KindLevels;
use super::motion::Motion;
use super::render::Render;
use super::sampling_config::SamplingConfig;
use crate::error::{Error, Result};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// The registry: every degradation kind beside motion blur, one line each
/// (`module::Kind`, its file `kinds/<module>.rs`), in level order. The option, the
/// meta.json key and the level folders' prefix of a kind are its module's name. A
/// generator, `kinds!([path::to::macro] { args })`, gets `{ args } module::Kind, …`.
#[macro_export]
macro_rules! kinds {
    ([$($then:tt)*] { $($args:tt)* }) => {
        $($then)*! { { $($args)* }
            defocus::Defocus,
            shake::Shake,
            rolling_shutter::RollingShutter,
        }
    };
}

/// What the registry makes here (see the module docs).
macro_rules! declare_kinds {
    ({} $($module:ident :: $Kind:ident),* $(,)?) => {
        $(pub mod $module;)*

        /// What sets each degraded kind's images apart, in level order: motion blur's
        /// row, then each registered kind's.
        pub static KIND_ROWS: &[KindRow] = &[
            KindRow::of::<Motion>(),
            $(KindRow::of::<$module::$Kind>(),)*
        ];

        /// Each kind's levels within its range, and what the kind needs of the rest of
        /// the config.
        pub fn check(levels: &KindLevels, cfg: &SamplingConfig) -> Result<()> {
            $(check_levels::<$module::$Kind>(stringify!($module), &levels.$module, cfg)?;)*
            Ok(())
        }

        /// The renders of one view at most, every level of every kind.
        pub fn frames(levels: &KindLevels, cfg: &SamplingConfig) -> usize {
            0 $(+ levels.$module.len() * <$module::$Kind>::frames_per_level(cfg))*
        }

        /// Each registered kind's levels of one view, by level number (meta.json's
        /// `views[i].<kind>["<l>"]`; a kind without levels is absent).
        #[derive(Clone, Debug, Default, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
        pub struct ViewKinds {
            $(
                #[doc = concat!("Each ", stringify!($module), " level of the view; absent without them.")]
                #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
                pub $module: BTreeMap<String, <$module::$Kind as Degradation>::Level>,
            )*
        }

        impl ViewKinds {
            /// Every kind's levels of one view.
            pub fn plan(cx: &ViewCx, levels: &KindLevels) -> ViewKinds {
                ViewKinds { $($module: <$module::$Kind>::plan_view(cx, &levels.$module),)* }
            }

            /// The renders of every level of every kind, in level order.
            pub fn renders(&self, cx: &RenderCx) -> Vec<Render> {
                let mut out = Vec::new();
                $(out.extend(kind_renders::<$module::$Kind>(cx, &self.$module));)*
                out
            }

            /// The levels as meta.json records them.
            pub fn records(&self) -> ViewKinds {
                ViewKinds { $($module: records::<$module::$Kind>(&self.$module),)* }
            }
        }

        /// Every registered kind as the statistics see it, in level order (motion
        /// blur's statistic is listed with its w_l and m, which stats.json keeps as
        /// fields of their own).
        pub static KIND_STATS: &[KindStat] = &[$(KindStat::of::<$module::$Kind>()),*];
    };
}

kinds!([declare_kinds] {});

/// What sets a degraded kind's images apart, from its own constants: one row per kind,
/// motion blur's and then each registered kind's ([`KIND_ROWS`]).
pub struct KindRow {
    /// Whether its images are seen from the written pose (a lens, a shake about the
    /// camera's centre), or are means over a moving camera whose mean latent pose
    /// meta.json records (motion blur).
    pub written_pose: bool,
    /// Whether its image integrates a camera that moves during the exposure, so the
    /// object covers more than the sharp silhouette and the level holds masks of its
    /// own (the pixels its exposure covered); else it takes the sharp masks (a lens
    /// renders one instant at the written pose).
    pub own_masks: bool,
    /// What a level of the kind is, as a dataset card says it ("`blur_l` the same views
    /// blurred at level l").
    pub means: &'static str,
}

impl KindRow {
    /// The row of kind `D`, from its constants.
    pub const fn of<D: Degradation>() -> KindRow {
        KindRow {
            written_pose: D::WRITTEN_POSE,
            own_masks: D::OWN_MASKS,
            means: D::MEANS,
        }
    }
}

impl ImageKind {
    fn row(self) -> Option<&'static KindRow> {
        self.degraded().map(|(i, _)| &KIND_ROWS[i])
    }

    /// Whether the image is seen from the view's written pose (the sharp image, a lens,
    /// a shake about the camera's centre) rather than being a mean over a moving camera
    /// whose mean latent pose meta.json records.
    pub fn written_pose(self) -> bool {
        self.row().is_none_or(|r| r.written_pose)
    }

    /// What a level of this kind is, as a dataset card says it (None: the sharp image).
    pub fn means(self) -> Option<&'static str> {
        self.row().map(|r| r.means)
    }

    /// Whether this image's level holds masks of its own (the coverage of a moving
    /// exposure: motion blur, shake) rather than the sharp image's.
    pub fn own_masks(self) -> bool {
        self.row().is_some_and(|r| r.own_masks)
    }
}

/// The level folder that holds `level`'s files of `pass`: in a setting whose levels hold
/// masks of their own (`level_masks`, meta.json `render.level_masks`), a level of a kind
/// whose camera moves during the exposure (motion blur's `blur_<l>` and any other
/// [`ImageKind::own_masks`] says) holds its masks, because its image covers more than the
/// sharp silhouette (issue 48); every other pass, the masks of the sharp and defocus
/// levels (one render at the written pose each) and every mask of a setting built
/// before blur levels had their own, are the sharp level's.
pub fn pass_level<'a>(pass: &str, level: &'a str, level_masks: bool) -> &'a str {
    match ImageKind::parse(level) {
        Some(k) if k.own_masks() && pass == "mask" && level_masks => level,
        _ => SHARP,
    }
}

/// The rows of `blurset build`'s table for the registered kinds, one option each (named
/// as its module, its help the kind's), placed between the rows `head` and `tail` of
/// the table (`build_options!`) before `then` makes anything of it.
#[macro_export]
macro_rules! kind_rows {
    ({ $then:ident { $($head:tt)* } { $($tail:tt)* } } $($module:ident :: $Kind:ident),* $(,)?) => {
        $then! {
            $($head)*
            $(
                $module: Vec<u32> = Vec::new(), $crate::plan::spec::Spec::Levels, shapes {
                    help: <$crate::plan::kinds::$module::$Kind as $crate::plan::degradation::Degradation>::OPTION_HELP,
                    before: Some(Vec::new()),
                };
            )*
            $($tail)*
        }
    };
}

/// Kind `D`'s levels (option `option`): distinct, each in 1..=its highest, and what the
/// kind needs of the rest of the config.
fn check_levels<D: Degradation>(option: &str, levels: &[u32], cfg: &SamplingConfig) -> Result<()> {
    use super::spec::{check, Spec};
    check(option, &levels.to_vec(), &Spec::Levels)?;
    if let Some(l) = levels.iter().find(|&&l| l > D::MAX_LEVEL) {
        return Err(Error::Config {
            option: option.into(),
            detail: format!(
                "{l}: {option} levels must be in 1..={} ({})",
                D::MAX_LEVEL,
                D::LEVEL_RANGE
            ),
        });
    }
    if levels.is_empty() {
        return Ok(());
    }
    D::check(cfg, levels)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plan::config::BuildConfig;
    use crate::plan::kind::parse_level_dir;

    #[test]
    fn a_moving_exposure_holds_its_own_masks_and_nothing_else_of_the_passes() {
        assert_eq!(pass_level("mask", "blur_4", true), "blur_4");
        // A setting built before blur levels had masks of their own: the sharp one.
        assert_eq!(pass_level("mask", "blur_4", false), SHARP);
        for (pass, level) in [
            ("mask", SHARP),
            ("mask", "defocus_2"),
            ("depth", "blur_4"),
            ("normal", "blur_1"),
            ("mask", "blur_04"),
        ] {
            assert_eq!(pass_level(pass, level, true), SHARP, "{pass} of {level}");
        }
        assert_eq!(parse_level_dir("shake_2"), None);
    }

    #[test]
    fn every_kind_is_named_by_its_module() {
        // The variant's tag, the meta.json key, the option and the folders' prefix are
        // one name; levels are ordered as the registry lists the kinds.
        let names: Vec<&str> = KIND_STATS.iter().map(|s| s.name).collect();
        assert_eq!(names, ["defocus", "shake", "rolling_shutter"]);
        // Each kind's NAME (its meta.json key and statistic's kind) is its module's
        // name, which names its variant's folders and tag.
        for name in &names {
            let k = ImageKind::parse(&format!("{name}_3")).unwrap_or(ImageKind::Sharp);
            assert_eq!((k.name(), k.record()), (*name, Some((*name, "3".into()))));
            let tag = serde_json::to_value(k).unwrap_or_default();
            assert_eq!(tag["type"], *name);
        }
        assert_eq!(
            KIND_ROWS.len(),
            names.len() + 1,
            "motion blur's row, then each kind's"
        );
        let decls = BuildConfig::declarations();
        for name in names {
            let d = decls.iter().find(|d| d.name == name);
            let flag = format!("--{}", name.replace('_', "-"));
            assert!(d.is_some_and(|d| d.flags == [flag] && d.shapes_outputs));
        }
    }
}
