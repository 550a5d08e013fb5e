//! The documents beside the images (DESIGN §4): `dataset.json` of a build and
//! `noise.json` of a noisy scene. Their schema lives here; Python supplies the values
//! (a dict checked against these structs: an unknown or missing field is an error).
use super::meta::{write_json, DeviceRecord, PoseCheck};
use crate::error::{Error, Result};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::Path;

/// Versions of what made a build.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Versions {
    pub blurset: String,
    pub python: String,
    /// Blender of the first complete setting (None before any).
    pub blender: Option<String>,
}

/// What a build holds now.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct DatasetCounts {
    pub objects: usize,
    pub objects_failed: usize,
    pub settings: usize,
    pub settings_failed: usize,
    pub images: usize,
}

/// `dataset.json`: the config, versions, seed and counts of a build.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct DatasetDoc {
    pub name: String,
    pub blurset_version: String,
    pub created: String,
    /// `BuildConfig::record()`.
    pub config: serde_json::Value,
    pub seed: u64,
    /// Level directories of every setting (`sharp`, `blur_1`, …).
    pub levels: Vec<String>,
    pub versions: Versions,
    pub counts: DatasetCounts,
    pub settings: Vec<String>,
    /// What the workers rendered on (meta.json `render.device`: backend, device names,
    /// Cycles kernel), each once.
    #[serde(default)]
    pub render_devices: Vec<DeviceRecord>,
    pub seconds: f64,
    /// The COLMAP verdict per setting, when the build checked poses.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pose_checks: Option<BTreeMap<String, PoseCheck>>,
}

/// The white balance of a noisy scene (one draw per scene).
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct WhiteBalanceRecord {
    pub red: f64,
    pub blue: f64,
}

/// The σ(gain) table a noisy scene was made with.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct NoiseTableRecord {
    /// `kpn` (NAN's, from KPN's file) or `blurset-default`.
    pub source: String,
    pub log10_sigma_read_1: f64,
    pub read_step_per_log2_gain: f64,
    pub log10_sigma_shot_1: f64,
    pub shot_step_per_log2_gain: f64,
    /// KPN's file name, when given.
    pub file: Option<String>,
}

/// What a noisy scene was made from: one LLFF scene, or one level of a build's setting.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
#[serde(untagged, deny_unknown_fields)]
pub enum NoiseSource {
    Scene {
        scene: String,
        images: String,
        factor: u32,
        resolution: [u32; 2],
    },
    Build {
        /// `linear` (the build's EXRs) or `png`.
        kind: String,
        build: String,
        setting: String,
        level: String,
        background: [f64; 3],
        resolution: [u32; 2],
    },
}

/// Where the seed of one level of a build's setting comes from (build mode).
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct BuildNoiseRecord {
    pub seed: u64,
    pub seed_derivation: String,
}

/// One written image: its view, frame, clean source and files.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct NoiseFile {
    pub view: usize,
    pub frame: usize,
    pub source: String,
    pub image: String,
    /// Absent under `--no-linear`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub linear: Option<String>,
    /// Left clean (σ = 0): a held-out target (`--clean-views`, a build's test views);
    /// absent when noisy, so a scene noised without clean views keeps its old record.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub clean: bool,
}

/// `noise.json` of one noisy scene (one gain).
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct NoiseDoc {
    /// An integer when the gain is one (`4`, not `4.0`).
    pub gain: serde_json::Number,
    pub seed: u64,
    pub sigma_read: f64,
    pub sigma_shot: f64,
    /// 2.2, or "srgb".
    pub gamma: serde_json::Value,
    pub white_balance: Option<WhiteBalanceRecord>,
    pub white_level: f64,
    pub frames: usize,
    pub profile: String,
    pub model: String,
    /// How the clean image y is made (build mode).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub clean: Option<String>,
    pub levels: NoiseTableRecord,
    pub source: NoiseSource,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub build_noise: Option<BuildNoiseRecord>,
    /// Factors of the `images_<f>/` (and `linear_<f>/`) copies, noise drawn at each size.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub downsample: Vec<u32>,
    /// The views left clean (every file of them has `clean`).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub clean_views: Vec<usize>,
    pub rng: String,
    /// A camera model's parameters and sources (`--model unprocess`, `eld:<camera>`);
    /// absent for the paper's model.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub raw_model: Option<serde_json::Value>,
    pub blurset_version: String,
    pub files: Vec<NoiseFile>,
}

impl NoiseDoc {
    /// Refuse a document whose numbers cannot describe a noisy scene.
    pub fn validate(&self) -> Result<()> {
        let gain = self.gain.as_f64().unwrap_or(f64::NAN);
        let finite = [gain, self.sigma_read, self.sigma_shot, self.white_level];
        if !(finite.iter().all(|x| x.is_finite()) && gain > 0.0) {
            return Err(Error::Value(format!(
                "noise.json: gain {gain}, sigmas ({}, {}), white level {} must be finite, gain > 0",
                self.sigma_read, self.sigma_shot, self.white_level
            )));
        }
        Ok(())
    }
}

/// Write dataset.json atomically.
pub fn write_dataset(path: &Path, doc: &DatasetDoc) -> Result<()> {
    write_json(path, doc)
}

/// The dataset.json a build's first run writes under its lock before any setting: the
/// options it is made with (a rerun must keep those that shape outputs).
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct DatasetStart {
    pub name: String,
    /// `BuildConfig::record()`.
    pub config: serde_json::Value,
    /// Always true: no run has finished.
    pub provisional: bool,
}

/// dataset.json: a finished run's document, or the first run's start.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
#[serde(untagged)]
pub enum DatasetRecord {
    Done(Box<DatasetDoc>),
    Start(DatasetStart),
}

/// The options a noise output is made with; a rerun into it must match them.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct NoiseParams {
    pub seed: u64,
    /// `linear` (the build's EXRs) or `png`.
    pub source: String,
    /// `paper` or `nan`.
    pub profile: String,
    /// `2.2` or `srgb`.
    pub gamma: String,
    pub white_level: f64,
    pub frames: usize,
    pub levels_table: NoiseTableParams,
    pub downsample: Vec<u32>,
    /// `test_views` (the build's test views stay clean) or `none`.
    pub clean_views: String,
    /// `--no-linear`: absent when the EXRs are written (the records before it).
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub no_linear: bool,
    /// `--model`: absent for `paper` (the records before it).
    #[serde(default = "paper", skip_serializing_if = "is_paper")]
    pub model: String,
}

fn paper() -> String {
    "paper".into()
}

fn is_paper(m: &str) -> bool {
    m == "paper"
}

/// The σ(gain) table a noise output is made with (noise.json's, without KPN's file name).
/// Its fields are in name order: the order noise_dataset.json has held them in since it
/// was a free map, so that a rerun writes the same bytes.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct NoiseTableParams {
    pub log10_sigma_read_1: f64,
    pub log10_sigma_shot_1: f64,
    pub read_step_per_log2_gain: f64,
    pub shot_step_per_log2_gain: f64,
    /// `kpn` (NAN's, from KPN's file) or `blurset-default`.
    pub source: String,
}

/// One gain of a noise output.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct GainRecord {
    pub gain: serde_json::Number,
    pub sigma_read: f64,
    pub sigma_shot: f64,
}

/// What a noise output holds.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct NoiseCounts {
    pub settings: usize,
    pub units: usize,
    pub images: usize,
}

/// `noise_dataset.json` of `blurset noise BUILD` once its run has finished.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct NoiseDatasetDoc {
    pub name: String,
    pub blurset_version: String,
    pub created: String,
    /// The build by its folder's name.
    pub build: String,
    pub build_seed: Option<u64>,
    pub params: NoiseParams,
    pub seed_derivation: String,
    pub gains: Vec<GainRecord>,
    pub levels: Vec<String>,
    /// The seed of every (setting, level).
    pub seeds: BTreeMap<String, BTreeMap<String, u64>>,
    pub layout: String,
    pub splits: String,
    pub counts: NoiseCounts,
}

/// The noise_dataset.json a noise run writes first (the options only), so that a run
/// killed before its end resumes.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct NoiseDatasetStart {
    pub build: String,
    pub params: NoiseParams,
}

/// noise_dataset.json: a finished run's document, or the start of one.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
#[serde(untagged)]
pub enum NoiseDatasetRecord {
    Done(Box<NoiseDatasetDoc>),
    Start(Box<NoiseDatasetStart>),
}

/// `noise_scene.json` of `blurset noise SCENE`: what the folder is, written last.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct NoiseSceneDoc {
    /// Always `blurset noise scene`.
    pub kind: String,
    pub blurset_version: String,
    /// The scene by its folder's name.
    pub scene: String,
    /// The gain folders (`gain_4` …); each holds its noise.json.
    pub gains: Vec<String>,
    pub seed: u64,
    pub profile: String,
    /// `--model`: absent for `paper` (the records before it).
    #[serde(default = "paper", skip_serializing_if = "is_paper")]
    pub model: String,
    /// Views i with i % llffhold == 0 are clean in every gain; absent: none.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub llffhold: Option<u32>,
}

/// The loader layout an export is made for, `blurset export --for`: one module of
/// python/blurset/exports/ each, which declares it (that module's name is this name).
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq, Eq, schemars::JsonSchema)]
pub enum ExportTarget {
    /// `nerf_llff_data/<scene>/`: IBRNet, NAN, GNT, Deblur-NeRF.
    #[serde(rename = "llff")]
    Llff,
    /// `<scene>/` with transforms.json: nerfstudio.
    #[serde(rename = "nerfstudio")]
    Nerfstudio,
    /// `geonerf/train/<scene>/` and `geonerf/test/<scene>__v<view>/`: GeoNeRF.
    #[serde(rename = "geonerf")]
    Geonerf,
    /// Parquet shards `data/<config>/<split>-*.parquet`: `datasets`, the Hugging Face Hub.
    #[serde(rename = "hub")]
    Hub,
}

/// `export.json` of `blurset export`: what was exported and how to read it.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ExportDoc {
    /// Always `blurset export`.
    pub kind: String,
    pub blurset_version: String,
    #[serde(rename = "for")]
    pub target: ExportTarget,
    /// The build, and the noise output, by their folders' names.
    pub build: String,
    pub noise: Option<String>,
    pub levels: Vec<String>,
    pub gains: Vec<String>,
    pub copy: bool,
    pub llffhold: usize,
    pub factors: Vec<u32>,
    pub test_view_images: String,
    /// The folder of the scenes, relative to the export (`.` for nerfstudio).
    pub scenes_dir: String,
    /// Scene (a path relative to scenes_dir) → its source, relative to the build or the
    /// noise output.
    pub scenes: BTreeMap<String, String>,
    pub train: Vec<String>,
    pub test: Vec<String>,
    /// GeoNeRF scenes: the views each holds, in order (a test scene's first is its target).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub views: Option<BTreeMap<String, Vec<usize>>>,
    /// Where a GeoNeRF test scene's target image comes from (`sharp`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub target_images: Option<String>,
    /// The build's `--passes` every scene carries beside its images (issue 35): the
    /// sharp level's files at the written pose, which every level and gain shares
    /// (without `mask` under `export --no-masks`).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub passes: Vec<String>,
    /// `--for hub` (issue 50): the size a Parquet shard is cut at, in bytes.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub shard_bytes: Option<u64>,
    /// `--for hub`: every shard (a path relative to scenes_dir, also a key of `scenes`)
    /// and what it holds.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub shards: Option<BTreeMap<String, HubShard>>,
}

/// One Parquet shard of `export --for hub`: the rows of whole settings of one config.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct HubShard {
    /// The config (`sharp`, `blur_4`, `blur_4_gain_4` …): one level, or one gain of it.
    pub config: String,
    /// `train` or `test`: the split of the settings it holds.
    pub split: String,
    /// The settings whose rows it holds, in order (a setting's rows are never split).
    pub settings: Vec<String>,
    /// Rows (one per image) and the file's size and sha256.
    pub rows: usize,
    pub bytes: u64,
    pub sha256: String,
}

/// The export.json an export writes before it moves its scenes into place: everything
/// it may own by then, so a rerun after a stop replaces those entries.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ExportReplacing {
    pub kind: String,
    /// Always `replacing`.
    pub state: String,
    pub build: String,
    pub scenes_dir: String,
    pub scenes: BTreeMap<String, String>,
    /// Entries (relative paths) the export owns while it replaces them.
    pub owns: Vec<String>,
    /// `--for hub`: the shards this run has written, or checked against the record
    /// before keeping them, so far: a rerun after a kill keeps a shard only when its
    /// bytes are these (a shard no record vouches for is written again).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub shards: Option<BTreeMap<String, HubShard>>,
}

/// export.json: a finished export, or one replacing its entries.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
#[serde(untagged)]
pub enum ExportRecord {
    Done(Box<ExportDoc>),
    Replacing(ExportReplacing),
}

/// Write noise.json atomically, after checking it.
pub fn write_noise(path: &Path, doc: &NoiseDoc) -> Result<()> {
    doc.validate()?;
    write_json(path, doc)
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    fn noise(source: serde_json::Value) -> serde_json::Value {
        json!({
            "gain": 4, "seed": 1, "sigma_read": 0.01, "sigma_shot": 0.02, "gamma": "srgb",
            "white_balance": {"red": 2.0, "blue": 1.6}, "white_level": 1.0, "frames": 1,
            "profile": "paper", "model": "m",
            "levels": {"source": "blurset-default", "log10_sigma_read_1": -3.0,
                       "read_step_per_log2_gain": 0.3, "log10_sigma_shot_1": -2.0,
                       "shot_step_per_log2_gain": 0.25, "file": null},
            "source": source, "rng": "philox", "blurset_version": "0",
            "files": [{"view": 0, "frame": 0, "source": "a.png", "image": "images/a.png",
                       "linear": "linear/a.exr"}]
        })
    }

    #[test]
    fn both_noise_sources_and_the_schema_is_strict() -> Result<()> {
        let e = |e: serde_json::Error| Error::Value(e.to_string());
        let scene = noise(json!({"scene": "fern", "images": "images_8", "factor": 8,
                                 "resolution": [504, 378]}));
        let doc: NoiseDoc = serde_json::from_value(scene.clone()).map_err(e)?;
        assert!(matches!(doc.source, NoiseSource::Scene { factor: 8, .. }));
        assert_eq!(serde_json::to_value(&doc).map_err(e)?, scene);
        let build = noise(json!({"kind": "linear", "build": "/b", "setting": "a_000",
                                 "level": "blur_1", "background": [1.0, 1.0, 1.0],
                                 "resolution": [96, 96]}));
        let doc: NoiseDoc = serde_json::from_value(build).map_err(e)?;
        assert!(matches!(doc.source, NoiseSource::Build { .. }));
        let mut extra =
            noise(json!({"scene": "f", "images": "i", "factor": 1, "resolution": [1, 1]}));
        extra["colour"] = json!(1);
        assert!(serde_json::from_value::<NoiseDoc>(extra).is_err());
        let mut bad = doc.clone();
        bad.sigma_read = f64::NAN;
        assert!(bad.validate().is_err());
        Ok(())
    }

    #[test]
    fn an_export_names_its_target_as_it_always_did_and_no_other() -> Result<()> {
        let e = |e: serde_json::Error| Error::Value(e.to_string());
        let export = |target: &str| {
            json!({"kind": "blurset export", "blurset_version": "0", "for": target,
                   "build": "b", "noise": null, "levels": ["sharp"], "gains": [],
                   "copy": false, "llffhold": 16, "factors": [4], "test_view_images": "sharp",
                   "scenes_dir": "geonerf", "scenes": {}, "train": [], "test": []})
        };
        for (name, target) in [
            ("llff", ExportTarget::Llff),
            ("nerfstudio", ExportTarget::Nerfstudio),
            ("geonerf", ExportTarget::Geonerf),
            ("hub", ExportTarget::Hub),
        ] {
            let doc: ExportDoc = serde_json::from_value(export(name)).map_err(e)?;
            assert_eq!(doc.target, target);
            assert_eq!(serde_json::to_value(&doc).map_err(e)?, export(name));
        }
        for bad in ["zarr", "LLFF", ""] {
            assert!(
                serde_json::from_value::<ExportDoc>(export(bad)).is_err(),
                "{bad}"
            );
        }
        Ok(())
    }
}
