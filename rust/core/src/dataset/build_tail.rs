//! The build's tail (DESIGN §4, §10): once a run's objects are done, failures.jsonl,
//! splits.json and dataset.json are written over what is on disk (the settings of every
//! run and shard), from the meta.json the core wrote for each setting. The builder calls
//! it under the build's lock and then rewrites the manifest.
use super::failures::{current, is_license_skip, read_records, write_records};
use super::layout::complete_settings;
use super::meta::{round_to, write_json, DeviceRecord, PoseCheck};
use super::records::{write_dataset, DatasetCounts, DatasetDoc, Versions};
use super::splits::{make_splits, Holdout, SettingEntry};
use crate::error::{Error, Result};
use crate::ground::names::files;
use crate::plan::config::BuildConfig;
use serde_json::Value;
use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

/// What dataset.json says of the run that the core cannot know: the dataset's name, the
/// package's and Python's versions, when, and how long the run took.
#[derive(Clone, Debug, PartialEq)]
pub struct RunFacts {
    pub name: String,
    pub blurset_version: String,
    pub python_version: String,
    /// Local time, `%Y-%m-%dT%H:%M:%S`.
    pub created: String,
    pub seconds: f64,
}

/// What the tail found: the complete settings, the failures now (failures.jsonl's
/// records), the test settings, and the settings left out because their meta.json does
/// not read (name, why).
#[derive(Clone, Debug, PartialEq)]
pub struct BuildTail {
    pub settings_complete: usize,
    pub failures: Vec<Value>,
    pub test_settings: usize,
    pub skipped: Vec<Unreadable>,
}

/// A complete setting left out of the tail: its name, and why its meta.json does not read.
pub type Unreadable = (String, String);

/// A complete setting's meta.json, as the tail reads it.
struct Setting {
    name: String,
    meta: Value,
}

impl Setting {
    fn uid(&self) -> &str {
        self.meta["uid"].as_str().unwrap_or_default()
    }

    fn views(&self) -> usize {
        self.meta["views"].as_array().map_or(0, Vec::len)
    }

    fn levels(&self) -> usize {
        match &self.meta["levels"] {
            Value::Array(a) => a.len(),
            Value::Object(o) => o.len(),
            _ => 0,
        }
    }
}

/// The complete settings whose meta.json reads (an object with `uid` and a `views`
/// list); the others are named with why (their object's next run redoes them).
fn read_settings(out: &Path) -> Result<(Vec<Setting>, Vec<Unreadable>)> {
    let (mut found, mut skipped) = (Vec::new(), Vec::new());
    for name in complete_settings(out)? {
        let path = out.join(&name).join(files::META);
        let meta = std::fs::read(&path)
            .map_err(|e| e.to_string())
            .and_then(|b| serde_json::from_slice::<Value>(&b).map_err(|e| e.to_string()))
            .and_then(|m| {
                let ok = m["views"].is_array() && m["uid"].is_string();
                ok.then_some(m)
                    .ok_or_else(|| "not a setting's meta.json".to_string())
            });
        match meta {
            Ok(meta) => found.push(Setting { name, meta }),
            Err(why) => skipped.push((name, why)),
        }
    }
    Ok((found, skipped))
}

/// A field of a meta.json read through its core type (absent or null: None).
fn field<T: serde::de::DeserializeOwned>(s: &Setting, v: &Value, what: &str) -> Result<Option<T>> {
    if v.is_null() {
        return Ok(None);
    }
    serde_json::from_value(v.clone())
        .map(Some)
        .map_err(|e| Error::Value(format!("{}/meta.json: {what}: {e}", s.name)))
}

/// failures.jsonl (the latest record of each object or setting whose work is still not
/// complete), splits.json and dataset.json of the build at `out` made with `cfg`.
pub fn write_build_tail(out: &Path, cfg: &BuildConfig, run: &RunFacts) -> Result<BuildTail> {
    let (settings, skipped) = read_settings(out)?;
    let names: BTreeSet<String> = settings.iter().map(|s| s.name.clone()).collect();
    let fpath = out.join(files::FAILURES);
    let (records, _) = read_records(&fpath)?;
    let kept = current(&records, &names, Some(&cfg.theta0s()));
    write_records(&fpath, &kept)?;

    let entries: Vec<SettingEntry> = settings
        .iter()
        .map(|s| SettingEntry {
            setting: s.name.clone(),
            object: s.uid().into(),
            views: s.views(),
        })
        .collect();
    let holdout = match cfg.test_settings {
        Some(n) => Holdout::Settings(n),
        None => Holdout::Objects {
            fraction: cfg.test_fraction,
            list: cfg.test_objects.as_deref(),
        },
    };
    let splits = make_splits(
        &entries,
        cfg.view_stride,
        &holdout,
        !cfg.blurry_test_views,
        cfg.seed,
    )?;
    write_json(&out.join(files::SPLITS), &splits)?;

    let doc = dataset_doc(cfg, run, &settings, &kept)?;
    write_dataset(&out.join(files::DATASET), &doc)?;
    Ok(BuildTail {
        settings_complete: settings.len(),
        failures: kept,
        test_settings: splits.test.len(),
        skipped,
    })
}

fn dataset_doc(
    cfg: &BuildConfig,
    run: &RunFacts,
    settings: &[Setting],
    failures: &[Value],
) -> Result<DatasetDoc> {
    let mut pose_checks = BTreeMap::new();
    // What the workers rendered on (backend, device names, Cycles kernel), once each.
    let mut render_devices: Vec<DeviceRecord> = Vec::new();
    for s in settings {
        if let Some(c) = field::<PoseCheck>(s, &s.meta["pose_check"], "pose_check")? {
            pose_checks.insert(s.name.clone(), c);
        }
        let d = field::<DeviceRecord>(s, &s.meta["render"]["device"], "render.device")?;
        if let Some(d) = d.filter(|d| !render_devices.contains(d)) {
            render_devices.push(d);
        }
    }
    // Blender of the first setting that records its object.
    let object = settings
        .iter()
        .map(|s| &s.meta["object"])
        .find(|o| o.as_object().is_some_and(|o| !o.is_empty()));
    let blender = object.and_then(|o| o["blender_version"].as_str().map(str::to_owned));
    let str_of = |r: &Value, k: &str| r[k].as_str().map(str::to_owned);
    let uids = |it: &mut dyn Iterator<Item = String>| it.collect::<BTreeSet<String>>().len();
    Ok(DatasetDoc {
        name: run.name.clone(),
        blurset_version: run.blurset_version.clone(),
        created: run.created.clone(),
        config: cfg.record(),
        seed: cfg.seed,
        levels: cfg.level_dirs(),
        versions: Versions {
            blurset: run.blurset_version.clone(),
            python: run.python_version.clone(),
            blender,
        },
        counts: DatasetCounts {
            objects: uids(&mut settings.iter().map(|s| s.uid().to_owned())),
            // An object --licenses leaves out is skipped by request, not a failure (its
            // record in failures.jsonl says stage "license").
            objects_failed: uids(&mut failures.iter().filter_map(|r| {
                (!is_license_skip(r["stage"].as_str())).then(|| str_of(r, "uid"))?
            })),
            settings: settings.len(),
            settings_failed: failures
                .iter()
                .filter(|r| r["setting"].as_str().is_some_and(|s| !s.is_empty()))
                .count(),
            images: settings.iter().map(|s| s.views() * s.levels()).sum(),
        },
        settings: settings.iter().map(|s| s.name.clone()).collect(),
        render_devices,
        seconds: round_to(run.seconds, 1),
        pose_checks: (!pose_checks.is_empty()).then_some(pose_checks),
    })
}
