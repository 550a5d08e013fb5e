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
