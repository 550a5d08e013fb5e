//! `failures.jsonl` of a build (DESIGN §10): what is failing now, in one place for the
//! build's own bookkeeping and for `blurset stats`.
//!
//! A record is one JSON object per line: `uid, path, stage, reason, seconds, …`, plus
//! `setting` when a single setting failed (render QA) rather than the whole object.
//! Records are appended; a rerun retries failed work. So the failures *now* are the
//! latest record per (uid, setting) whose work is still not complete: a setting record
//! until its setting is complete, an object record until every setting of the object is.
//! A line that does not parse (a record torn by a kill mid-append) is skipped, counted.
use crate::error::{Error, Result};
use crate::ground::names::setting_name;
use serde_json::Value;
use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

/// The stage of the record of an object `--licenses` leaves out: skipped by request,
/// not a failure (progress lines, the build's summary and `stats` say so).
pub const LICENSE_STAGE: &str = "license";

/// Whether a record is such a skip.
pub fn is_license_skip(stage: Option<&str>) -> bool {
    stage == Some(LICENSE_STAGE)
}

/// The records of a failures.jsonl (none when the file is absent) and the number of
/// lines skipped because they are not a JSON object with a string `uid`.
pub fn read_records(path: &Path) -> Result<(Vec<Value>, usize)> {
    let Some(bytes) = super::read::read_limited(path, "failures.jsonl")? else {
        return Ok((Vec::new(), 0));
    };
    let text = String::from_utf8(bytes).map_err(|e| {
        let e = std::io::Error::new(std::io::ErrorKind::InvalidData, e);
        Error::io("cannot read failures", path, e)
    })?;
    let mut records = Vec::new();
    let mut skipped = 0;
    for line in text.lines().filter(|l| !l.trim().is_empty()) {
        match serde_json::from_str::<Value>(line) {
            Ok(v) if v.get("uid").is_some_and(Value::is_string) => records.push(v),
            _ => skipped += 1,
        }
    }
    Ok((records, skipped))
}

fn key(r: &Value) -> (String, Option<String>) {
    let s = |k: &str| r.get(k).and_then(Value::as_str).map(str::to_owned);
    (s("uid").unwrap_or_default(), s("setting"))
}

/// The failures now: the latest record per (uid, setting), sorted by that key, whose
/// work is not complete. `theta0s` names an object's settings; without it (a build
/// whose config is not known yet) object records are kept.
pub fn current(
    records: &[Value],
    complete: &BTreeSet<String>,
    theta0s: Option<&[f64]>,
) -> Vec<Value> {
    let mut latest: BTreeMap<(String, Option<String>), &Value> = BTreeMap::new();
    for r in records {
        latest.insert(key(r), r);
    }
    latest
        .into_iter()
        .filter(|((uid, setting), _)| match (setting, theta0s) {
            (Some(s), _) => !complete.contains(s),
            (None, Some(ts)) => !ts.iter().all(|&t| complete.contains(&setting_name(uid, t))),
            (None, None) => true,
        })
        .map(|(_, r)| r.clone())
        .collect()
}

/// Rewrite failures.jsonl as `records`, one a line, atomically. A line is spelled as
/// the builder appends one (Python's `json.dumps`: `", "` and `": "`, non-ASCII escaped),
/// so the file reads the same whichever wrote a line.
pub fn write_records(path: &Path, records: &[Value]) -> Result<()> {
    let mut text = String::new();
    for r in records {
        python_json(r, &mut text);
        text.push('\n');
    }
    crate::ground::atomic::write_atomic(path, text.as_bytes())
}

/// `value` as Python's `json.dumps(value)` writes it.
fn python_json(value: &Value, out: &mut String) {
    match value {
        Value::Null => out.push_str("null"),
        Value::Bool(b) => out.push_str(if *b { "true" } else { "false" }),
        Value::Number(n) => match n.as_f64() {
            Some(x) if n.is_f64() => out.push_str(&python_float(x)),
            _ => out.push_str(&n.to_string()),
        },
        Value::String(s) => python_string(s, out),
        Value::Array(items) => {
            out.push('[');
            for (i, v) in items.iter().enumerate() {
                if i > 0 {
                    out.push_str(", ");
                }
                python_json(v, out);
            }
            out.push(']');
        }
        Value::Object(map) => {
            out.push('{');
            for (i, (k, v)) in map.iter().enumerate() {
                if i > 0 {
                    out.push_str(", ");
                }
                python_string(k, out);
                out.push_str(": ");
                python_json(v, out);
            }
            out.push('}');
        }
    }
}

/// Python's `repr` of a float: the shortest digits that read back, positional from
/// 1e-4 up to 1e16, else `d.ddde±XX`.
fn python_float(x: f64) -> String {
    if !x.is_finite() {
        return (if x.is_nan() {
            "NaN"
        } else if x > 0.0 {
            "Infinity"
        } else {
            "-Infinity"
        })
        .into();
    }
    let sci = format!("{x:e}"); // shortest digits: `-1.2345e-5`
    let (mantissa, exp) = sci.split_once('e').unwrap_or((&sci, "0"));
    let exp: i32 = exp.parse().unwrap_or(0);
    let (sign, mantissa) = mantissa
        .strip_prefix('-')
        .map_or(("", mantissa), |m| ("-", m));
    let digits: String = mantissa.chars().filter(char::is_ascii_digit).collect();
    if (-4..16).contains(&exp) {
        let point = exp + 1; // digits before the decimal point
        let body = if point <= 0 {
            format!("0.{}{digits}", "0".repeat((-point) as usize))
        } else if (point as usize) >= digits.len() {
            format!("{digits}{}.0", "0".repeat(point as usize - digits.len()))
        } else {
            let (int, frac) = digits.split_at(point as usize);
            format!("{int}.{frac}")
        };
        format!("{sign}{body}")
    } else {
        let (first, rest) = digits.split_at(1);
        let frac = if rest.is_empty() {
            String::new()
        } else {
            format!(".{rest}")
        };
        let esign = if exp < 0 { '-' } else { '+' };
        format!("{sign}{first}{frac}e{esign}{:02}", exp.abs())
    }
}

/// A JSON string as Python's `json.dumps` (ensure_ascii) writes it.
fn python_string(s: &str, out: &mut String) {
    out.push('"');
    for c in s.chars() {
        match c {
            '"' => out.push_str("\\\""),
            '\\' => out.push_str("\\\\"),
            '\n' => out.push_str("\\n"),
            '\r' => out.push_str("\\r"),
            '\t' => out.push_str("\\t"),
            '\u{8}' => out.push_str("\\b"),
            '\u{c}' => out.push_str("\\f"),
            ' '..='~' => out.push(c),
            _ => {
                let mut units = [0u16; 2];
                for u in c.encode_utf16(&mut units) {
                    out.push_str(&format!("\\u{u:04x}"));
                }
            }
        }
    }
    out.push('"');
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ground::names::theta0s;
    use serde_json::json;

    #[test]
    fn latest_record_of_unfinished_work_survives() {
        let recs = vec![
            json!({"uid": "d", "stage": "load", "reason": "old"}),
            json!({"uid": "a", "stage": "render", "reason": "crash, later rebuilt"}),
            json!({"uid": "d", "stage": "load", "reason": "bad glb"}),
            json!({"uid": "q", "setting": "q_090", "stage": "qa", "reason": "black"}),
            json!({"uid": "q", "setting": "q_000", "stage": "qa", "reason": "fixed since"}),
            json!({"uid": "p", "stage": "render", "reason": "crash after p_000"}),
        ];
        let complete: BTreeSet<String> = ["a_000", "a_180", "q_000", "q_180", "p_000"]
            .iter()
            .map(|s| s.to_string())
            .collect();
        let now = current(&recs, &complete, Some(&theta0s(2)));
        let reasons: Vec<&str> = now.iter().filter_map(|r| r["reason"].as_str()).collect();
        assert_eq!(reasons, ["bad glb", "crash after p_000", "black"]);
        // Not knowing the object's settings, object records stay.
        assert_eq!(current(&recs, &complete, None).len(), 4);
    }

    #[test]
    fn a_record_is_spelled_as_python_json_dumps_spells_it() {
        // Each right-hand side is what Python 3.11's json.dumps writes for the left.
        let cases = [
            (
                json!({"uid": "a", "seconds": 0.5, "attempts": 2}),
                r#"{"attempts": 2, "seconds": 0.5, "uid": "a"}"#,
            ),
            (
                json!({"r": "θ \"x\"\n\u{7f}\u{1f600}"}),
                r#"{"r": "\u03b8 \"x\"\n\u007f\ud83d\ude00"}"#,
            ),
            (
                json!([1.0, 1e-5, 0.0001, 1e16, 123.456, -2.5e-7, null, true, []]),
                "[1.0, 1e-05, 0.0001, 1e+16, 123.456, -2.5e-07, null, true, []]",
            ),
            (
                json!({"s": 12.345, "n": -3, "o": {}}),
                r#"{"n": -3, "o": {}, "s": 12.345}"#,
            ),
        ];
        for (value, python) in cases {
            let mut out = String::new();
            python_json(&value, &mut out);
            assert_eq!(out, python);
        }
    }

    #[test]
    fn torn_and_foreign_lines_are_skipped_and_counted() -> Result<()> {
        let dir = std::env::temp_dir().join(format!("blurset-fail-{}", std::process::id()));
        std::fs::create_dir_all(&dir).map_err(|e| Error::io("mkdir", &dir, e))?;
        let p = dir.join("failures.jsonl");
        std::fs::write(
            &p,
            "{\"uid\":\"a\"}\n{\"uid\":\"b\",\"sta{\"uid\":\"c\"}\n[1]\n\n{\"uid\":\"d\"",
        )
        .map_err(|e| Error::io("write", &p, e))?;
        let (recs, skipped) = read_records(&p)?;
        assert_eq!((recs.len(), skipped), (1, 3));
        assert_eq!(read_records(&dir.join("none.jsonl"))?.0.len(), 0);
        let _ = std::fs::remove_dir_all(&dir);
        Ok(())
    }
}
