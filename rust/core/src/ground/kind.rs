//! What an image of a setting is: the sharp image or one level of a degradation. Its
//! level directory (`sharp`, `blur_2`, `defocus_3`), its place in level order and the
//! render phase it belongs to are derived here and nowhere else, so a new kind is one
//! new variant and one row of [`PREFIXES`].
use serde::{Deserialize, Serialize};

/// The level directory of the sharp image.
pub const SHARP: &str = "sharp";
/// Largest level of any kind a build can write.
pub const MAX_LEVEL: u32 = 64;

/// One image of a view: the sharp image, or level `l` (1..=[`MAX_LEVEL`]) of a
/// degradation. Crosses the FFI as `{"type": "blur", "level": 2}`.
#[derive(
    Clone,
    Copy,
    Debug,
    PartialEq,
    Eq,
    PartialOrd,
    Ord,
    Hash,
    Serialize,
    Deserialize,
    schemars::JsonSchema,
)]
#[serde(tag = "type", content = "level", rename_all = "snake_case")]
pub enum ImageKind {
    Sharp,
    /// Motion blur of the camera's trajectory during the exposure (`blur_<l>`).
    Blur(u32),
    /// Depth of field of a thin lens (`defocus_<l>`, issue 35).
    Defocus(u32),
    /// A hand-held camera turning about its centre during the exposure (`shake_<l>`).
    Shake(u32),
}

/// What sets a degraded kind's images apart, one row per kind in level order (sharp
/// comes first).
struct Row {
    /// Its level directories' prefix.
    prefix: &'static str,
    make: fn(u32) -> ImageKind,
    /// Its records' key in a view of meta.json (`views[i].<key>["<l>"]`).
    record: &'static str,
    /// Whether its images are seen from the written pose (a lens, a shake about the
    /// camera's centre), or are means over a moving camera whose mean latent pose
    /// meta.json records (motion blur).
    written_pose: bool,
    /// Whether its image integrates a camera that moves during the exposure, so the
    /// object covers more than the sharp silhouette and the level holds masks of its
    /// own (the pixels its exposure covered); else it takes the sharp masks (a lens
    /// renders one instant at the written pose).
    own_masks: bool,
    /// What a level of the kind is, as a dataset card says it ("`blur_l` the same views
    /// blurred at level l").
    means: &'static str,
}

const PREFIXES: [Row; 3] = [
    Row {
        prefix: "blur_",
        make: ImageKind::Blur,
        record: "levels",
        written_pose: false,
        own_masks: true,
        means: "the same views blurred at level l",
    },
    Row {
        prefix: "defocus_",
        make: ImageKind::Defocus,
        record: "defocus",
        written_pose: true,
        own_masks: false,
        means: "the same views out of focus at level l",
    },
    Row {
        prefix: "shake_",
        make: ImageKind::Shake,
        record: "shake",
        written_pose: true,
        own_masks: true,
        means: "the same views shaken by a hand-held camera at level l",
    },
];

impl ImageKind {
    /// The level directory of this image: `sharp` or `<prefix><l>`.
    pub fn dir(self) -> String {
        match self.degraded() {
            None => SHARP.to_string(),
            Some((i, l)) => format!("{}{l}", PREFIXES[i].prefix),
        }
    }

    /// The kind of a level directory name (`sharp`, or a prefix and a level in
    /// 1..=[`MAX_LEVEL`] written without leading zeros); anything else → None.
    pub fn parse(name: &str) -> Option<ImageKind> {
        if name == SHARP {
            return Some(ImageKind::Sharp);
        }
        PREFIXES.iter().find_map(|row| {
            let num = name.strip_prefix(row.prefix)?;
            if num.is_empty() || num.starts_with('0') || !num.bytes().all(|b| b.is_ascii_digit()) {
                return None;
            }
            num.parse::<u32>()
                .ok()
                .filter(|l| (1..=MAX_LEVEL).contains(l))
                .map(row.make)
        })
    }

    /// The level of a degraded image (0: the sharp image).
    pub fn level(self) -> u32 {
        self.degraded().map_or(0, |(_, l)| l)
    }

    /// Level order: sharp, then each kind's levels by number, kinds as in [`PREFIXES`].
    pub fn order(self) -> (usize, u32) {
        self.degraded().map_or((0, 0), |(i, l)| (i + 1, l))
    }

    /// Where meta.json records this image in each view: (the key of its kind's map,
    /// its level's key in it), `("levels", "2")` for `blur_2`; None for the sharp image.
    pub fn record(self) -> Option<(&'static str, String)> {
        self.degraded()
            .map(|(i, l)| (PREFIXES[i].record, l.to_string()))
    }

    /// Whether the image is seen from the view's written pose (the sharp image, a lens,
    /// a shake about the camera's centre) rather than being a mean over a moving camera
    /// whose mean latent pose meta.json records.
    pub fn written_pose(self) -> bool {
        self.degraded()
            .is_none_or(|(i, _)| PREFIXES[i].written_pose)
    }

    /// The kind's name (its meta.json tag): `sharp`, `blur`, `defocus`, `shake`.
    pub fn name(self) -> &'static str {
        match self.degraded() {
            None => SHARP,
            Some((i, _)) => PREFIXES[i].prefix.trim_end_matches('_'),
        }
    }

    /// What a level of this kind is, as a dataset card says it (None: the sharp image).
    pub fn means(self) -> Option<&'static str> {
        self.degraded().map(|(i, _)| PREFIXES[i].means)
    }

    /// The pattern of this kind's level directories: `sharp`, `blur_<l>`, `shake_<l>`.
    pub fn dir_pattern(self) -> String {
        match self.degraded() {
            None => SHARP.to_string(),
            Some((i, _)) => format!("{}<l>", PREFIXES[i].prefix),
        }
    }

    /// Whether this image's level holds masks of its own (the coverage of a moving
    /// exposure: motion blur, shake) rather than the sharp image's.
    pub fn own_masks(self) -> bool {
        self.degraded().is_some_and(|(i, _)| PREFIXES[i].own_masks)
    }

    /// The render phase of this image's renders, in the order a setting renders them:
    /// 0 the sharp images, whose QA is checked before any other phase is rendered (a
    /// bad view fails its setting before the costly renders); then one phase per kind.
    pub fn phase(self) -> u32 {
        self.order().0 as u32
    }

    fn degraded(self) -> Option<(usize, u32)> {
        match self {
            ImageKind::Sharp => None,
            ImageKind::Blur(l) => Some((0, l)),
            ImageKind::Defocus(l) => Some((1, l)),
            ImageKind::Shake(l) => Some((2, l)),
        }
    }
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
