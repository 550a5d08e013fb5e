//! Reading the records blurset writes, checked against their shapes (DESIGN §4, §10).
//!
//! Every reader of meta.json, splits.json, dataset.json, noise_dataset.json,
//! noise.json and export.json goes through [`read_record`]: the file is parsed, then
//! checked against the shape below (the fields readers rely on, with their types;
//! unknown fields are fine, so newer records stay readable). A wrong shape is one
//! [`Error::Input`] naming the file and the field (`splits.json: train: invalid type:
//! integer `5`, expected a sequence`), never a crash further down.
use crate::error::{Error, Result};
use crate::ground::names::files;
use serde::de::DeserializeOwned;
use serde::Deserialize;
use std::collections::BTreeMap;
use std::path::Path;

/// The records blurset writes and reads back.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Record {
    /// `<setting>/meta.json`.
    Meta,
    /// `splits.json` of a build (and its copy in a noise output).
    Splits,
    /// `dataset.json` of a build.
    Dataset,
    /// `noise_dataset.json` of `blurset noise BUILD`.
    NoiseDataset,
    /// `noise.json` of one noisy scene.
    Noise,
    /// `noise_scene.json` of `blurset noise SCENE`.
    NoiseScene,
    /// `export.json` of `blurset export`.
    Export,
    /// `stats.json` of `blurset stats`.
    Stats,
}

impl Record {
    /// The file name of the record.
    pub fn file_name(self) -> &'static str {
        match self {
            Record::Meta => files::META,
            Record::Splits => files::SPLITS,
            Record::Dataset => files::DATASET,
            Record::NoiseDataset => files::NOISE_DATASET,
            Record::Noise => files::NOISE,
            Record::NoiseScene => files::NOISE_SCENE,
            Record::Export => files::EXPORT,
            Record::Stats => files::STATS,
        }
    }

    /// The record of a file name, or None.
    pub fn of_name(name: &str) -> Option<Record> {
        [
            Record::Meta,
            Record::Splits,
            Record::Dataset,
            Record::NoiseDataset,
            Record::Noise,
            Record::NoiseScene,
            Record::Export,
            Record::Stats,
        ]
        .into_iter()
        .find(|r| r.file_name() == name)
    }
}

// -- the shapes (what readers rely on) -------------------------------------------------

#[derive(Deserialize)]
#[allow(dead_code)]
struct LevelShape {
    w_l: f64,
    latents: usize,
}

#[derive(Deserialize)]
#[allow(dead_code)]
struct ViewShape {
    index: usize,
    #[serde(default)]
    levels: BTreeMap<String, LevelShape>,
}

#[derive(Deserialize)]
#[allow(dead_code)]
struct ObjectShape {
    #[serde(default)]
    path: String,
    #[serde(default)]
    sha256: Option<String>,
    #[serde(default)]
    license: Option<String>,
}

#[derive(Deserialize)]
#[allow(dead_code)]
struct RenderShape {
    #[serde(default)]
    background: Option<[f64; 3]>,
    #[serde(default)]
    linear: bool,
}

#[derive(Deserialize)]
#[allow(dead_code)]
struct MetaShape {
    uid: String,
    theta0_deg: f64,
    resolution: [u32; 2],
    views: Vec<ViewShape>,
    levels: Vec<String>,
    #[serde(default)]
    test_views: Vec<usize>,
    #[serde(default)]
    downsample: Vec<u32>,
    #[serde(default)]
    object: Option<ObjectShape>,
    #[serde(default)]
    render: Option<RenderShape>,
}

#[derive(Deserialize)]
#[allow(dead_code)]
struct SplitsShape {
    view_stride: usize,
    train: Vec<String>,
    test: Vec<String>,
    test_views: BTreeMap<String, Vec<usize>>,
    #[serde(default)]
    test_view_images: Option<String>,
}

#[derive(Deserialize)]
#[allow(dead_code)]
struct CountsShape {
    objects: usize,
    settings: usize,
    images: usize,
}

#[derive(Deserialize)]
#[allow(dead_code)]
struct DatasetShape {
    name: String,
    config: serde_json::Map<String, serde_json::Value>,
    #[serde(default)]
    provisional: bool,
    #[serde(default)]
    levels: Option<Vec<String>>,
    #[serde(default)]
    counts: Option<CountsShape>,
    #[serde(default)]
    settings: Option<Vec<String>>,
    #[serde(default)]
    seed: Option<u64>,
}

#[derive(Deserialize)]
#[allow(dead_code)]
struct GainShape {
    gain: f64,
    sigma_read: f64,
    sigma_shot: f64,
}

#[derive(Deserialize)]
#[allow(dead_code)]
struct NoiseCountsShape {
    settings: usize,
    units: usize,
    images: usize,
}

#[derive(Deserialize)]
#[allow(dead_code)]
struct NoiseDatasetShape {
    build: String,
    params: serde_json::Map<String, serde_json::Value>,
    #[serde(default)]
    build_seed: Option<u64>,
    #[serde(default)]
    gains: Vec<GainShape>,
    #[serde(default)]
    levels: Vec<String>,
    #[serde(default)]
    counts: Option<NoiseCountsShape>,
}

#[derive(Deserialize)]
#[allow(dead_code)]
struct NoiseFileShape {
    view: usize,
    frame: usize,
    image: String,
    linear: String,
}

#[derive(Deserialize)]
#[allow(dead_code)]
struct NoiseShape {
    gain: f64,
    seed: u64,
    sigma_read: f64,
    sigma_shot: f64,
    files: Vec<NoiseFileShape>,
    source: serde_json::Map<String, serde_json::Value>,
    #[serde(default)]
    downsample: Vec<u32>,
}

#[derive(Deserialize)]
#[allow(dead_code)]
struct NoiseSceneShape {
    kind: String,
    gains: Vec<String>,
}

#[derive(Deserialize)]
#[allow(dead_code)]
struct ExportShape {
    kind: String,
    #[serde(default)]
    scenes_dir: Option<String>,
    #[serde(default)]
    scenes: BTreeMap<String, String>,
    #[serde(default)]
    owns: Vec<String>,
    #[serde(default)]
    train: Vec<String>,
    #[serde(default)]
    test: Vec<String>,
    #[serde(default)]
    build: Option<String>,
}

#[derive(Deserialize)]
#[allow(dead_code)]
struct StatsShape {
    blurset_version: String,
    counts: serde_json::Map<String, serde_json::Value>,
}

fn check<T: DeserializeOwned>(value: &serde_json::Value) -> std::result::Result<(), String> {
    match serde_path_to_error::deserialize::<_, T>(value) {
        Ok(_) => Ok(()),
        Err(e) => {
            let at = e.path().to_string();
            let what = e.into_inner().to_string();
            Err(if at == "." {
                what
            } else {
                format!("{at}: {what}")
            })
        }
    }
}

/// Check a parsed record against its shape: Err(field: what is wrong).
pub fn check_shape(value: &serde_json::Value, record: Record) -> std::result::Result<(), String> {
    if !value.is_object() {
        return Err(format!("not a JSON object ({})", json_type(value)));
    }
    match record {
        Record::Meta => check::<MetaShape>(value),
        Record::Splits => check::<SplitsShape>(value),
        Record::Dataset => check::<DatasetShape>(value),
        Record::NoiseDataset => check::<NoiseDatasetShape>(value),
        Record::Noise => check::<NoiseShape>(value),
        Record::NoiseScene => check::<NoiseSceneShape>(value),
        Record::Export => check::<ExportShape>(value),
        Record::Stats => check::<StatsShape>(value),
    }
}

fn json_type(v: &serde_json::Value) -> &'static str {
    match v {
        serde_json::Value::Null => "null",
        serde_json::Value::Bool(_) => "a boolean",
        serde_json::Value::Number(_) => "a number",
        serde_json::Value::String(_) => "a string",
        serde_json::Value::Array(_) => "an array",
        serde_json::Value::Object(_) => "an object",
    }
}

/// Read `path` as `record`: the JSON value when it has the record's shape; otherwise
/// one Input error naming the file and the field.
pub fn read_record(path: &Path, record: Record) -> Result<serde_json::Value> {
    let name = record.file_name();
    let bad = |reason: String| Error::Input {
        reason,
        path: path.into(),
    };
    let text = match std::fs::read(path) {
        Ok(t) => t,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            return Err(bad(format!("{name} not found")))
        }
        Err(e) => return Err(Error::io("cannot read", path, e)),
    };
    let value: serde_json::Value = serde_json::from_slice(&text)
        .map_err(|e| bad(format!("{name} is not readable JSON ({e})")))?;
    check_shape(&value, record)
        .map_err(|what| bad(format!("{name} has the wrong shape: {what}")))?;
    Ok(value)
}

#[allow(clippy::unwrap_used)] // a failing unwrap is a failing test
#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    #[test]
    fn a_wrong_shape_names_the_field() {
        let e = check_shape(&json!([]), Record::Splits).unwrap_err();
        assert!(e.contains("not a JSON object (an array)"), "{e}");
        let e = check_shape(&json!([1, 2]), Record::Meta).unwrap_err();
        assert!(e.contains("an array"), "{e}");
        let e = check_shape(
            &json!({"view_stride": 16, "train": 5, "test": [], "test_views": {}}),
            Record::Splits,
        )
        .unwrap_err();
        assert!(e.starts_with("train: invalid type: integer `5`"), "{e}");
        let e = check_shape(
            &json!({"uid": "a", "theta0_deg": 0.0, "resolution": [8, 8], "levels": ["sharp"],
                    "views": [{"index": 0}, {"index": "1"}]}),
            Record::Meta,
        )
        .unwrap_err();
        assert!(e.starts_with("views[1].index: invalid type: string"), "{e}");
    }

    #[test]
    fn unknown_fields_and_defaults_are_fine() {
        let ok = json!({"view_stride": 16, "train": ["a_000"], "test": [], "extra": 1,
                        "test_views": {"a_000": [0, 16]}});
        assert_eq!(check_shape(&ok, Record::Splits), Ok(()));
        let provisional =
            json!({"name": "blurset Objaverse-Blur", "config": {}, "provisional": true});
        assert_eq!(check_shape(&provisional, Record::Dataset), Ok(()));
    }

    #[test]
    fn read_record_names_the_file() -> Result<()> {
        let dir = std::env::temp_dir().join(format!("blurset-read-{}", std::process::id()));
        std::fs::create_dir_all(&dir).map_err(|e| Error::io("mkdir", &dir, e))?;
        let p = dir.join("splits.json");
        std::fs::write(&p, b"{\"train\": 5}").map_err(|e| Error::io("write", &p, e))?;
        let e = read_record(&p, Record::Splits).unwrap_err().to_string();
        assert!(e.starts_with("splits.json has the wrong shape: "), "{e}");
        assert!(e.ends_with(&format!("{:?}", p)), "{e}");
        std::fs::write(&p, b"{").map_err(|e| Error::io("write", &p, e))?;
        let e = read_record(&p, Record::Splits).unwrap_err().to_string();
        assert!(e.contains("not readable JSON"), "{e}");
        let e = read_record(&dir.join("none.json"), Record::Splits)
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("splits.json not found"), "{e}");
        let _ = std::fs::remove_dir_all(&dir);
        Ok(())
    }
}
