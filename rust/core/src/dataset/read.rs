//! Reading the records blurset writes, checked against their shapes (DESIGN §4, §10).
//!
//! Every reader of meta.json, splits.json, dataset.json, noise_dataset.json,
//! noise.json and export.json goes through [`read_record`]: the file is parsed, then
//! checked against the shape below (the fields readers rely on, with their types;
//! unknown fields are fine, so newer records stay readable). A wrong shape is one
//! [`Error::Input`] naming the file and the field (`splits.json: train: invalid type:
//! integer `5`, expected a sequence`), never a crash further down.
use crate::error::{Error, Result};
use crate::ground::limits::{self, MAX_RECORD_BYTES};
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

    /// Every record, in the order of their declaration.
    pub const ALL: [Record; 8] = [
        Record::Meta,
        Record::Splits,
        Record::Dataset,
        Record::NoiseDataset,
        Record::Noise,
        Record::NoiseScene,
        Record::Export,
        Record::Stats,
    ];

    /// The record of a file name, or None.
    pub fn of_name(name: &str) -> Option<Record> {
        Record::ALL.into_iter().find(|r| r.file_name() == name)
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
    #[serde(default)]
    linear: Option<String>,
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
    let Some(text) = read_limited(path, name)? else {
        return Err(bad(format!("{name} not found")));
    };
    parse_record(&text, record).map_err(bad)
}

/// A record held in memory: the JSON value when it has the record's shape, otherwise
/// the reason (for the caller to pair with its file). Arbitrary bytes give an error,
/// never a panic (fuzzed).
pub fn parse_record(
    bytes: &[u8],
    record: Record,
) -> std::result::Result<serde_json::Value, String> {
    let name = record.file_name();
    let value: serde_json::Value =
        serde_json::from_slice(bytes).map_err(|e| format!("{name} is not readable JSON ({e})"))?;
    check_shape(&value, record).map_err(|what| format!("{name} has the wrong shape: {what}"))?;
    Ok(value)
}

/// The bytes of the record file `name` at `path` (None when there is none), refused
/// with an error naming the limit past [`MAX_RECORD_BYTES`], before they are read.
pub(crate) fn read_limited(path: &Path, name: &str) -> Result<Option<Vec<u8>>> {
    use std::io::Read;
    let io = |e| Error::io("cannot read", path, e);
    let f = match std::fs::File::open(path) {
        Ok(f) => f,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(io(e)),
    };
    let too_large = |len: u64| {
        limits::check(
            &format!("{name}: size in bytes"),
            len,
            MAX_RECORD_BYTES,
            "MAX_RECORD_BYTES",
        )
        .map_err(|reason| Error::Input {
            reason,
            path: path.into(),
        })
    };
    let len = f.metadata().map_err(io)?.len();
    too_large(len)?;
    let mut out = Vec::with_capacity(len as usize);
    // A file that grows while it is read stops at the limit too.
    f.take(MAX_RECORD_BYTES + 1)
        .read_to_end(&mut out)
        .map_err(io)?;
    too_large(out.len() as u64)?;
    Ok(Some(out))
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

    #[test]
    fn a_record_over_the_limit_is_refused_named_before_it_is_read() -> Result<()> {
        let dir = std::env::temp_dir().join(format!("blurset-read-big-{}", std::process::id()));
        std::fs::create_dir_all(&dir).map_err(|e| Error::io("mkdir", &dir, e))?;
        let p = dir.join("dataset.json");
        // Sparse: no disk space, and read, 1 GiB of zero bytes.
        let f = std::fs::File::create(&p).map_err(|e| Error::io("create", &p, e))?;
        f.set_len(MAX_RECORD_BYTES + 1)
            .map_err(|e| Error::io("set_len", &p, e))?;
        let e = read_record(&p, Record::Dataset).unwrap_err().to_string();
        assert!(
            e.starts_with("dataset.json: size in bytes: 1073741825, over the limit of 1073741824 (MAX_RECORD_BYTES)")
                && e.contains("dataset.json\""),
            "{e}"
        );
        let e = crate::dataset::failures::read_records(&p)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("(MAX_RECORD_BYTES)") && e.contains("dataset.json"),
            "{e}"
        );
        let _ = std::fs::remove_dir_all(&dir);
        Ok(())
    }

    /// A valid record of each kind, the seeds of the fuzz harness.
    fn seeds() -> Vec<(Record, Vec<u8>)> {
        let docs = [
            (
                Record::Splits,
                json!({"view_stride": 16, "train": ["a_000"], "test": ["b_000"],
                                    "test_views": {"a_000": [0, 16]}}),
            ),
            (
                Record::Meta,
                json!({"uid": "a", "theta0_deg": 0.0, "resolution": [8, 8],
                                  "levels": ["sharp"], "views": [{"index": 0, "levels":
                                  {"blur_3": {"w_l": 0.5, "latents": 6}}}]}),
            ),
            (
                Record::Export,
                json!({"kind": "blurset export", "scenes": {"a": "b"},
                                    "owns": ["x"]}),
            ),
            (
                Record::Noise,
                json!({"gain": 1.0, "seed": 3, "sigma_read": 0.1,
                                   "sigma_shot": 0.2, "source": {}, "files": [
                                   {"view": 0, "frame": 0, "image": "a", "linear": "b"}]}),
            ),
        ];
        docs.into_iter()
            .map(|(r, d)| (r, serde_json::to_vec(&d).unwrap()))
            .collect()
    }

    #[test]
    fn the_seeds_are_valid() {
        for (r, b) in seeds() {
            assert!(parse_record(&b, r).is_ok(), "{r:?}");
        }
    }

    // The reader's fuzz harness in `cargo test` (rust/fuzz/fuzz_targets/records.rs runs
    // it longer): arbitrary bytes and mutations of valid records give a value or an
    // error, never a panic, and a value it gives has the record's shape.
    mod fuzz {
        use super::*;
        use proptest::prelude::*;

        proptest! {
            #![proptest_config(ProptestConfig::with_cases(2000))]
            #[test]
            fn arbitrary_bytes_never_panic(
                r in 0usize..8,
                bytes in proptest::collection::vec(any::<u8>(), 0..300),
            ) {
                let _ = parse_record(&bytes, Record::ALL[r]);
            }

            #[test]
            fn mutated_records_never_panic(
                which in 0usize..4,
                edits in proptest::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 0..6),
                cut in any::<prop::sample::Index>(),
            ) {
                let (r, mut b) = seeds().swap_remove(which);
                for (at, v) in edits {
                    let i = at.index(b.len());
                    b[i] = v;
                }
                let keep = cut.index(b.len() + 1);
                b.truncate(keep);
                if let Ok(v) = parse_record(&b, r) {
                    prop_assert!(check_shape(&v, r).is_ok());
                }
            }
        }
    }
}
