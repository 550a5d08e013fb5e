//! Licences of the objects a build publishes (issue 19): the ids `--licenses` accepts,
//! the SPDX id a model's licence text names, and the filter. Python's
//! blurset.attribution reads the texts out of GLBs and annotations; the rules are here.

/// A licence text that names none.
pub const UNKNOWN: &str = "unknown";
/// A licence text that maps to no SPDX id (the raw text is kept beside it).
pub const OTHER: &str = "other";

/// The Creative Commons kinds Sketchfab and Objaverse use.
const CC_KINDS: [&str; 6] = ["by", "by-sa", "by-nd", "by-nc", "by-nc-sa", "by-nc-nd"];
const CC_VERSIONS: [&str; 4] = ["4.0", "3.0", "2.5", "2.0"];

/// Every SPDX id `--licenses` accepts (besides `other` and `unknown`).
pub fn spdx_ids() -> Vec<String> {
    let mut ids: Vec<String> = CC_KINDS
        .iter()
        .flat_map(|k| CC_VERSIONS.iter().map(move |v| cc_id(k, v)))
        .collect();
    ids.push("CC0-1.0".into());
    ids.push("CC-PDDC".into());
    // blurset's own licence, which its built-in demo objects carry.
    ids.push("MIT".into());
    ids
}

fn cc_id(kind: &str, version: &str) -> String {
    format!("CC-{}-{version}", kind.to_uppercase())
}

/// The canonical spelling of a licence id as a user gives it (case-insensitive): an
/// SPDX id, `other` or `unknown`; None for anything else (a typo would skip every object).
pub fn canonical(id: &str) -> Option<String> {
    let low = id.trim().to_lowercase();
    if low == UNKNOWN || low == OTHER {
        return Some(low);
    }
    spdx_ids().into_iter().find(|s| s.to_lowercase() == low)
}

/// The SPDX id a licence text names (`CC-BY-4.0 (http://creativecommons.org/…)`, a
/// Creative Commons URL, an Objaverse annotation's code such as `by-nc`), `other` for
/// text that maps to none, `unknown` for no text. Nothing is guessed.
pub fn spdx_of(text: Option<&str>) -> String {
    let t = text
        .map(|s| s.split_whitespace().collect::<Vec<_>>().join(" "))
        .unwrap_or_default();
    if t.is_empty() {
        return UNKNOWN.into();
    }
    let low = t.to_lowercase();
    let head = low
        .split(' ')
        .next()
        .unwrap_or("")
        .trim_matches(|c| "(),;".contains(c));
    if let Some(id) = canonical(head).filter(|c| c != UNKNOWN && c != OTHER) {
        return id;
    }
    if CC_KINDS.contains(&low.as_str()) {
        return cc_id(&low, "4.0");
    }
    if low == "cc0"
        || low.contains("creativecommons.org/publicdomain/zero/1.0")
        || low
            .strip_prefix("cc0")
            .is_some_and(|rest| rest.trim_start() == "1.0")
    {
        return "CC0-1.0".into();
    }
    if let Some(i) = low.find("creativecommons.org/licenses/") {
        let rest = &low[i + "creativecommons.org/licenses/".len()..];
        if let Some((kind, tail)) = rest.split_once('/') {
            let version: String = tail.chars().take(3).collect();
            let b = version.as_bytes();
            let is_version =
                b.len() == 3 && b[0].is_ascii_digit() && b[1] == b'.' && b[2].is_ascii_digit();
            if is_version && CC_KINDS.contains(&kind) {
                return cc_id(kind, &version);
            }
        }
    }
    OTHER.into()
}

/// Whether an object under licence `id` passes the filter (None lets every one pass).
pub fn allowed(id: &str, licenses: Option<&[String]>) -> bool {
    licenses.is_none_or(|l| l.iter().any(|x| x.eq_ignore_ascii_case(id)))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn texts_map_to_spdx_ids() {
        let cases = [
            (
                "CC-BY-4.0 (http://creativecommons.org/licenses/by/4.0/)",
                "CC-BY-4.0",
            ),
            (
                "CC-BY-NC-SA-4.0 (http://creativecommons.org/licenses/by-nc-sa/4.0/)",
                "CC-BY-NC-SA-4.0",
            ),
            (
                "CC0-1.0 (http://creativecommons.org/publicdomain/zero/1.0/)",
                "CC0-1.0",
            ),
            (
                "Attribution (https://creativecommons.org/licenses/by-sa/3.0/)",
                "CC-BY-SA-3.0",
            ),
            ("by-nd", "CC-BY-ND-4.0"),
            ("cc0", "CC0-1.0"),
            ("CC0 1.0", "CC0-1.0"),
            (
                "SKETCHFAB-Standard (https://sketchfab.com/licenses)",
                "other",
            ),
            ("free-st", "other"),
            ("MIT (https://opensource.org/licenses/MIT)", "MIT"),
            ("https://creativecommons.org/licenses/by/x.y/", "other"),
            ("  ", "unknown"),
        ];
        for (text, want) in cases {
            assert_eq!(spdx_of(Some(text)), want, "{text}");
        }
        assert_eq!(spdx_of(None), "unknown");
    }

    #[test]
    fn ids_and_filter() {
        assert_eq!(canonical(" cc-by-nc-4.0").as_deref(), Some("CC-BY-NC-4.0"));
        assert_eq!(canonical("Unknown").as_deref(), Some("unknown"));
        assert_eq!(canonical("cc-by-4"), None);
        assert_eq!(spdx_ids().len(), 27);
        assert_eq!(canonical("mit").as_deref(), Some("MIT"));
        let only = ["CC-BY-4.0".to_string()];
        assert!(allowed("CC-BY-4.0", Some(&only)));
        assert!(!allowed("unknown", Some(&only)));
        assert!(allowed("unknown", None));
    }
}
