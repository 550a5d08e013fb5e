//! The JSON Schema of every record blurset writes, from the serde types that write it,
//! and the one typed writer of the records Python assembles (DESIGN §4).
//!
//! `schemas/<record>.schema.json` in the repository are these schemas (a test fails
//! when they differ); tests validate real outputs against them. The reading shapes of
//! `dataset::read` are looser on purpose: they also read records of older versions.
use super::meta::{write_json, Meta};
use super::read::Record;
use super::records::{DatasetRecord, ExportRecord, NoiseDatasetRecord, NoiseDoc, NoiseSceneDoc};
use super::splits::Splits;
use super::stats::BuildStats;
use crate::error::{Error, Result};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// `stats.json`: when and by which blurset, then the statistics.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
pub struct StatsFile {
    pub generated: String,
    pub blurset_version: String,
    #[serde(flatten)]
    pub stats: BuildStats,
}

impl StatsFile {
    /// Write stats.json (compact: it holds every view's numbers) atomically.
    pub fn write(&self, path: &Path) -> Result<()> {
        let mut text = serde_json::to_vec(self).map_err(|e| Error::Value(e.to_string()))?;
        text.push(b'\n');
        crate::ground::atomic::write_atomic(path, &text)
    }
}

/// The records with a schema, in a stable order.
pub const SCHEMA_RECORDS: [Record; 8] = [
    Record::Meta,
    Record::Splits,
    Record::Dataset,
    Record::Noise,
    Record::NoiseDataset,
    Record::NoiseScene,
    Record::Export,
    Record::Stats,
];

/// The JSON Schema (draft 2020-12) of a record.
pub fn schema(record: Record) -> serde_json::Value {
    let s = match record {
        Record::Meta => schemars::schema_for!(Meta),
        Record::Splits => schemars::schema_for!(Splits),
        Record::Dataset => schemars::schema_for!(DatasetRecord),
        Record::Noise => schemars::schema_for!(NoiseDoc),
        Record::NoiseDataset => schemars::schema_for!(NoiseDatasetRecord),
        Record::NoiseScene => schemars::schema_for!(NoiseSceneDoc),
        Record::Export => schemars::schema_for!(ExportRecord),
        Record::Stats => schemars::schema_for!(StatsFile),
    };
    let mut v = s.to_value();
    if let Some(obj) = v.as_object_mut() {
        obj.insert(
            "$id".into(),
            format!("https://blurset.invalid/schemas/{}", schema_file(record)).into(),
        );
    }
    v
}

/// The JSON Schema of each value the bindings give to Python, or take from it, as a
/// dict: the stub's TypedDicts (python/blurset/_records.pyi, `make schemas`) are made
/// from these, so a dict crossing the FFI has the type the core gives it. (The worker
/// contract's messages are typed from its own schemas: [`super::wire::schemas`].)
pub fn value_schemas() -> Vec<(&'static str, serde_json::Value)> {
    use super::meta::{ImageRender, ObjectRecord, Timings};
    use super::records::DatasetDoc;
    use super::stats::BuildStats;
    use crate::plan::motion::LevelPlan;
    use crate::plan::renders::Render;
    use crate::plan::sampling::SettingPlan;
    use crate::plan::sampling_config::SamplingConfig;
    use schemars::schema_for;
    vec![
        ("ImageRender", schema_for!(ImageRender).to_value()),
        ("Spread", schema_for!(crate::metrics::Spread).to_value()),
        ("Render", schema_for!(Render).to_value()),
        ("SettingPlan", schema_for!(SettingPlan).to_value()),
        ("LevelPlan", schema_for!(LevelPlan).to_value()),
        ("SamplingConfig", schema_for!(SamplingConfig).to_value()),
        ("ObjectRecord", schema_for!(ObjectRecord).to_value()),
        ("Timings", schema_for!(Timings).to_value()),
        ("DatasetDoc", schema_for!(DatasetDoc).to_value()),
        ("NoiseDoc", schema_for!(NoiseDoc).to_value()),
        ("Splits", schema_for!(Splits).to_value()),
        ("BuildStats", schema_for!(BuildStats).to_value()),
        (
            "HalfNoise",
            schema_for!(crate::metrics::HalfNoise).to_value(),
        ),
    ]
}

/// The file name of a record's schema: `meta.schema.json` …
pub fn schema_file(record: Record) -> String {
    let name = record.file_name();
    format!("{}.schema.json", name.strip_suffix(".json").unwrap_or(name))
}

fn typed<T: for<'de> Deserialize<'de> + Serialize>(
    record: Record,
    value: serde_json::Value,
) -> Result<T> {
    serde_path_to_error::deserialize::<_, T>(value).map_err(|e| {
        Error::Value(format!(
            "{} does not fit its schema at {}: {}",
            record.file_name(),
            e.path(),
            e.inner()
        ))
    })
}

/// Write a record Python assembled, through its type (an unknown or missing field, a
/// wrong type is an error before anything is written), atomically.
pub fn write_record(path: &Path, record: Record, value: serde_json::Value) -> Result<()> {
    match record {
        Record::Dataset => write_json(path, &typed::<DatasetRecord>(record, value)?),
        Record::NoiseDataset => write_json(path, &typed::<NoiseDatasetRecord>(record, value)?),
        Record::NoiseScene => write_json(path, &typed::<NoiseSceneDoc>(record, value)?),
        Record::Export => write_json(path, &typed::<ExportRecord>(record, value)?),
        Record::Noise => {
            let doc = typed::<NoiseDoc>(record, value)?;
            doc.validate()?;
            write_json(path, &doc)
        }
        Record::Meta | Record::Splits | Record::Stats => Err(Error::Value(format!(
            "{} is written by the core from its own types",
            record.file_name()
        ))),
    }
}

#[allow(clippy::unwrap_used)] // a failing unwrap is a failing test
#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_record_has_a_schema_of_its_name() {
        for r in SCHEMA_RECORDS {
            let s = schema(r);
            assert!(s.get("$schema").is_some(), "{r:?}");
            assert!(s["$id"].as_str().unwrap().ends_with(&schema_file(r)));
        }
        assert_eq!(
            schema_file(Record::NoiseDataset),
            "noise_dataset.schema.json"
        );
    }

    #[test]
    fn a_record_that_does_not_fit_is_not_written() {
        let p = std::env::temp_dir().join(format!("blurset-schema-{}.json", std::process::id()));
        let bad = serde_json::json!({"kind": "blurset noise scene", "scene": "f"});
        let e = write_record(&p, Record::NoiseScene, bad)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("noise_scene.json does not fit its schema"),
            "{e}"
        );
        assert!(!p.exists());
    }
}
