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
}

/// Each degraded kind's directory prefix, in level order (sharp comes first).
const PREFIXES: [(&str, fn(u32) -> ImageKind); 2] =
    [("blur_", ImageKind::Blur), ("defocus_", ImageKind::Defocus)];

impl ImageKind {
    /// The level directory of this image: `sharp` or `<prefix><l>`.
    pub fn dir(self) -> String {
        match self.degraded() {
            None => SHARP.to_string(),
            Some((i, l)) => format!("{}{l}", PREFIXES[i].0),
        }
    }

    /// The kind of a level directory name (`sharp`, or a prefix and a level in
    /// 1..=[`MAX_LEVEL`] written without leading zeros); anything else → None.
    pub fn parse(name: &str) -> Option<ImageKind> {
        if name == SHARP {
            return Some(ImageKind::Sharp);
        }
        PREFIXES.iter().find_map(|(prefix, make)| {
            let num = name.strip_prefix(prefix)?;
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

    /// Level order: sharp, then each kind's levels by number, kinds as in [`PREFIXES`].
    pub fn order(self) -> (usize, u32) {
        self.degraded().map_or((0, 0), |(i, l)| (i + 1, l))
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
    }

    #[test]
    fn it_crosses_as_a_tagged_record() {
        let j = serde_json::to_string(&ImageKind::Defocus(2)).expect("json");
        assert_eq!(j, r#"{"type":"defocus","level":2}"#);
        let s = serde_json::to_string(&ImageKind::Sharp).expect("json");
        assert_eq!(s, r#"{"type":"sharp"}"#);
    }
}
