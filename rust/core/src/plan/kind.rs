//! What an image of a setting is: the sharp image or one level of a degradation. Its
//! level directory (`sharp`, `blur_2`, `defocus_3`), its record key in meta.json, its
//! place in level order and the render phase it belongs to are derived here and nowhere
//! else, from the kind's name: motion blur's (`blur`, the paper's kind, recorded under
//! `levels`) and each registered kind's module name ([`crate::kinds!`]), which also
//! makes its variant. What a kind's images are (seen from the written pose, own masks,
//! what a level means) is its own module's to say ([`super::kinds`]).
use serde::{Deserialize, Serialize};

pub use crate::ground::names::{MAX_LEVEL, SHARP};

/// The variant, the names and the constructors of every kind of the registry.
macro_rules! image_kind {
    ({} $($module:ident :: $Kind:ident),* $(,)?) => {
        /// One image of a view: the sharp image, or level `l` (1..=its kind's highest)
        /// of a degradation: motion blur (`blur_<l>`), or a kind of the registry
        /// ([`crate::kinds!`]), its variant named as its type. Crosses the FFI as
        /// `{"type": "blur", "level": 2}`.
        #[derive(
            Clone, Copy, Debug, Default, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize,
            Deserialize, schemars::JsonSchema,
        )]
        #[serde(tag = "type", content = "level", rename_all = "snake_case")]
        pub enum ImageKind {
            #[default]
            Sharp,
            /// Motion blur of the camera's trajectory during the exposure (`blur_<l>`).
            Blur(u32),
            $(
                #[doc = concat!("A level of ", stringify!($module), " (`", stringify!($module), "_<l>`).")]
                $Kind(u32),
            )*
        }

        /// Each degraded kind in level order, motion blur's first: its name (the prefix
        /// of its level directories), its records' key in a view of meta.json and the
        /// image of a level.
        const KINDS: &[(&str, &str, fn(u32) -> ImageKind)] = &[
            ("blur", "levels", ImageKind::Blur),
            $((stringify!($module), stringify!($module), ImageKind::$Kind),)*
        ];

        impl ImageKind {
            /// A degraded image's place in [`KINDS`] and its level (None: sharp).
            pub(crate) fn degraded(self) -> Option<(usize, u32)> {
                if let ImageKind::Blur(l) = self {
                    return Some((0, l));
                }
                let mut row = 0;
                $(
                    row += 1;
                    if let ImageKind::$Kind(l) = self {
                        return Some((row, l));
                    }
                )*
                None
            }
        }
    };
}

crate::kinds!([image_kind] {});

impl ImageKind {
    /// The level directory of this image: `sharp` or `<name>_<l>`.
    pub fn dir(self) -> String {
        match self.degraded() {
            None => SHARP.to_string(),
            Some((i, l)) => format!("{}_{l}", KINDS[i].0),
        }
    }

    /// The kind of a level directory name (`sharp`, or a kind's name, `_` and a level in
    /// 1..=[`MAX_LEVEL`] written without leading zeros); anything else → None.
    pub fn parse(name: &str) -> Option<ImageKind> {
        if name == SHARP {
            return Some(ImageKind::Sharp);
        }
        KINDS.iter().find_map(|(prefix, _, make)| {
            let num = name.strip_prefix(prefix)?.strip_prefix('_')?;
            if num.is_empty() || num.starts_with('0') || !num.bytes().all(|b| b.is_ascii_digit()) {
                return None;
            }
            num.parse::<u32>()
                .ok()
                .filter(|l| (1..=MAX_LEVEL).contains(l))
                .map(make)
        })
    }

    /// The level of a degraded image (0: the sharp image).
    pub fn level(self) -> u32 {
        self.degraded().map_or(0, |(_, l)| l)
    }

    /// Level order: sharp, then each kind's levels by number, kinds as the registry
    /// lists them.
    pub fn order(self) -> (usize, u32) {
        self.degraded().map_or((0, 0), |(i, l)| (i + 1, l))
    }

    /// Where meta.json records this image in each view: (the key of its kind's map,
    /// its level's key in it), `("levels", "2")` for `blur_2`; None for the sharp image.
    pub fn record(self) -> Option<(&'static str, String)> {
        self.degraded().map(|(i, l)| (KINDS[i].1, l.to_string()))
    }

    /// The kind's name (its meta.json tag): `sharp`, `blur`, `defocus`, `shake`.
    pub fn name(self) -> &'static str {
        match self.degraded() {
            None => SHARP,
            Some((i, _)) => KINDS[i].0,
        }
    }

    /// The pattern of this kind's level directories: `sharp`, `blur_<l>`, `shake_<l>`.
    pub fn dir_pattern(self) -> String {
        match self.degraded() {
            None => SHARP.to_string(),
            Some((i, _)) => format!("{}_<l>", KINDS[i].0),
        }
    }

    /// The render phase of this image's renders, in the order a setting renders them:
    /// 0 the sharp images, whose QA is checked before any other phase is rendered (a
    /// bad view fails its setting before the costly renders); then one phase per kind.
    pub fn phase(self) -> u32 {
        self.order().0 as u32
    }
}

/// Directory of a blur level (`blur_<l>`); level 0 is the sharp image.
pub fn level_dir(level: u32) -> String {
    if level == 0 {
        ImageKind::Sharp.dir()
    } else {
        ImageKind::Blur(level).dir()
    }
}

/// `sharp`, then `blur_<l>` of every blur level, in the given order.
pub fn level_dirs(levels: &[u32]) -> Vec<String> {
    std::iter::once(0)
        .chain(levels.iter().copied())
        .map(level_dir)
        .collect()
}

/// The level of a level directory name: `sharp` → 0, `blur_<l>` → l for l in
/// 1..=MAX_LEVEL written without leading zeros; anything else → None.
pub fn parse_level_dir(name: &str) -> Option<u32> {
    match ImageKind::parse(name)? {
        ImageKind::Sharp => Some(0),
        ImageKind::Blur(l) => Some(l),
        _ => None,
    }
}

/// Whether `name` is a level directory a build writes: `sharp` or a level of any kind.
pub fn is_level_dir(name: &str) -> bool {
    ImageKind::parse(name).is_some()
}

/// Level directories sorted in level order (sharp first, then the blur levels by number,
/// then the defocus levels); names that are not level directories are dropped.
pub fn sort_level_dirs<S: AsRef<str>>(names: &[S]) -> Vec<String> {
    let mut v: Vec<((usize, u32), String)> = names
        .iter()
        .filter_map(|n| {
            let kind = ImageKind::parse(n.as_ref())?;
            Some((kind.order(), n.as_ref().to_string()))
        })
        .collect();
    v.sort();
    v.into_iter().map(|(_, n)| n).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_kind_and_its_directory_go_both_ways() {
        for k in [
            ImageKind::Sharp,
            ImageKind::Blur(1),
            ImageKind::Blur(64),
            ImageKind::Defocus(3),
        ] {
            assert_eq!(ImageKind::parse(&k.dir()), Some(k));
        }
        assert_eq!(ImageKind::Blur(2).dir(), "blur_2");
        assert_eq!(ImageKind::Defocus(3).dir(), "defocus_3");
        for bad in [
            "blur_0", "blur_01", "blur_65", "defocus_", "blur", "Sharp", "x_1",
        ] {
            assert_eq!(ImageKind::parse(bad), None, "{bad}");
        }
        // Sharp renders first; each kind is a phase of its own, in level order.
        assert!(ImageKind::Sharp.phase() < ImageKind::Blur(9).phase());
        assert!(ImageKind::Blur(9).phase() < ImageKind::Defocus(1).phase());
        assert!(ImageKind::Blur(9).order() < ImageKind::Defocus(1).order());
        // meta.json's records, and which images are seen from the written pose.
        assert_eq!(ImageKind::Blur(2).record(), Some(("levels", "2".into())));
        assert_eq!(
            ImageKind::Defocus(3).record(),
            Some(("defocus", "3".into()))
        );
        assert_eq!(ImageKind::Sharp.record(), None);
        assert!(ImageKind::Sharp.written_pose() && ImageKind::Defocus(1).written_pose());
        assert!(!ImageKind::Blur(1).written_pose());
        // Which kinds' levels hold masks of their own: those whose camera moves.
        assert!(ImageKind::Blur(1).own_masks() && ImageKind::Shake(2).own_masks());
        assert!(!ImageKind::Sharp.own_masks() && !ImageKind::Defocus(2).own_masks());
        assert_eq!(ImageKind::Shake(4).dir_pattern(), "shake_<l>");
        assert_eq!(ImageKind::Sharp.means(), None);
        assert_eq!(
            (ImageKind::Defocus(2).name(), ImageKind::Sharp.name()),
            ("defocus", "sharp")
        );
        assert!(ImageKind::Shake(1)
            .means()
            .is_some_and(|m| m.contains("hand-held")));
    }

    #[test]
    fn it_crosses_as_a_tagged_record() {
        let j = serde_json::to_string(&ImageKind::Defocus(2)).expect("json");
        assert_eq!(j, r#"{"type":"defocus","level":2}"#);
        let s = serde_json::to_string(&ImageKind::Sharp).expect("json");
        assert_eq!(s, r#"{"type":"sharp"}"#);
    }
}
