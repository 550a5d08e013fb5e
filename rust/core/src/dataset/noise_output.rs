//! The records of a noise output (DESIGN §5): `noise_dataset.json` of `blurset noise
//! BUILD` (first its start, the options only, then the whole record over the complete
//! units on disk) and `noise_scene.json` of `blurset noise SCENE`. Python decides when
//! each is written (under its lock, after the units are published); what they say is
//! assembled here, from the run's [`NoisePlan`] and the units' own noise.json.
use super::layout::is_complete;
use super::meta::write_json;
use super::noise_plan::{NoisePlan, SEED_DERIVATION};
use super::read::{read_record, Record};
use super::records::NoiseSceneDoc;
use super::records::{GainRecord, NoiseCounts, NoiseDatasetDoc, NoiseDatasetStart};
use crate::error::{Error, Result};
use crate::ground::names::files;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

const NAME: &str = "blurset Objaverse-Blur + noise";
const LAYOUT: &str = "<setting>/<level>/gain_<g>/ (images/, linear/, images_<f>/, \
    linear_<f>/, poses_bounds.npy, transforms.json, noise.json)";
const SPLITS: &str = "splits.json (copied from the build)";
const SCENE_KIND: &str = "blurset noise scene";

/// One complete unit on disk, as its noise.json describes it.
#[derive(Clone, Debug, PartialEq)]
struct UnitOnDisk {
    setting: String,
    level: String,
    /// `gain_<g>`.
    dir: String,
    seed: u64,
    gain: GainRecord,
    images: usize,
}

/// The entries of `dir` by name, sorted, hidden ones too: a unit under any folder
/// counts, as it did when Python globbed `*/*/gain_*`.
fn entries(dir: &Path) -> Result<Vec<(String, PathBuf)>> {
    let list = std::fs::read_dir(dir).map_err(|e| Error::io("cannot list", dir, e))?;
    let mut out = Vec::new();
    for entry in list {
        let p = entry.map_err(|e| Error::io("cannot list", dir, e))?.path();
        let name = p.file_name().map(|n| n.to_string_lossy().into_owned());
        out.push((name.unwrap_or_default(), p));
    }
    out.sort();
    Ok(out)
}

/// The complete units of `out` (`<setting>/<level>/gain_*/` with their marker), in the
/// order of their paths.
fn complete_units(out: &Path) -> Result<Vec<UnitOnDisk>> {
    let mut units = Vec::new();
    for (setting, s) in entries(out)?.into_iter().filter(|e| e.1.is_dir()) {
        for (level, l) in entries(&s)?.into_iter().filter(|e| e.1.is_dir()) {
            for (dir, u) in entries(&l)? {
                if dir.starts_with("gain_") && is_complete(&u) {
                    units.push(read_unit(&setting, &level, dir, &u)?);
                }
            }
        }
    }
    Ok(units)
}

fn read_unit(setting: &str, level: &str, dir: String, path: &Path) -> Result<UnitOnDisk> {
    let file = path.join(files::NOISE);
    let doc = read_record(&file, Record::Noise)?;
    // The shape read_record checked holds these; a miss is a file changed under us.
    let bad = || Error::Input {
        reason: "noise.json lacks its gain, seed or sigmas".into(),
        path: file.clone(),
    };
    let number = |k: &str| doc[k].as_number().cloned().ok_or_else(bad);
    let float = |k: &str| doc[k].as_f64().ok_or_else(bad);
    Ok(UnitOnDisk {
        setting: setting.into(),
        level: level.into(),
        dir,
        seed: doc["seed"].as_u64().ok_or_else(bad)?,
        gain: GainRecord {
            gain: number("gain")?,
            sigma_read: float("sigma_read")?,
            sigma_shot: float("sigma_shot")?,
        },
        images: doc["files"].as_array().map_or(0, Vec::len),
    })
}

impl NoisePlan {
    /// noise_dataset.json before any unit: the options only, so that a run killed
    /// before its end resumes (and a rerun with other options is refused).
    pub fn dataset_start(&self) -> NoiseDatasetStart {
        NoiseDatasetStart {
            build: self.input.clone(),
            params: self.params.clone(),
        }
    }

    /// Write [`Self::dataset_start`] as `out`'s noise_dataset.json, atomically.
    pub fn write_dataset_start(&self, out: &Path) -> Result<()> {
        write_json(&out.join(files::NOISE_DATASET), &self.dataset_start())
    }

    /// noise_dataset.json over the complete units of `out` (those of earlier runs
    /// too), stamped `created`; written atomically, and returned.
    pub fn write_dataset(&self, out: &Path, created: &str) -> Result<NoiseDatasetDoc> {
        let doc = self.dataset_doc(&complete_units(out)?, created);
        write_json(&out.join(files::NOISE_DATASET), &doc)?;
        Ok(doc)
    }

    fn dataset_doc(&self, units: &[UnitOnDisk], created: &str) -> NoiseDatasetDoc {
        let mut seeds: BTreeMap<String, BTreeMap<String, u64>> = BTreeMap::new();
        // Each gain once, by its folder (every unit of a gain has the same σ).
        let mut gains: BTreeMap<&str, GainRecord> = BTreeMap::new();
        for u in units {
            let of_setting = seeds.entry(u.setting.clone()).or_default();
            of_setting.insert(u.level.clone(), u.seed);
            gains.insert(&u.dir, u.gain.clone());
        }
        let mut gains: Vec<GainRecord> = gains.into_values().collect();
        let value = |g: &GainRecord| g.gain.as_f64().unwrap_or(f64::NAN);
        gains.sort_by(|a, b| value(a).total_cmp(&value(b)));
        let on_disk = |l: &&String| seeds.values().any(|s| s.contains_key(*l));
        let levels = self.build_levels.iter().filter(on_disk).cloned().collect();
        NoiseDatasetDoc {
            name: NAME.into(),
            blurset_version: env!("CARGO_PKG_VERSION").into(),
            created: created.into(),
            build: self.input.clone(),
            build_seed: self.build_seed,
            params: self.params.clone(),
            seed_derivation: SEED_DERIVATION.into(),
            gains,
            levels,
            counts: NoiseCounts {
                settings: seeds.len(),
                units: units.len(),
                images: units.iter().map(|u| u.images).sum(),
            },
            seeds,
            layout: LAYOUT.into(),
            splits: SPLITS.into(),
        }
    }

    /// noise_scene.json of a scene's run: the scene, its gain folders, seed and profile.
    pub fn scene_doc(&self) -> NoiseSceneDoc {
        let gains = self.units.first().map(|u| &u.gains[..]).unwrap_or_default();
        NoiseSceneDoc {
            kind: SCENE_KIND.into(),
            blurset_version: env!("CARGO_PKG_VERSION").into(),
            scene: self.input.clone(),
            gains: gains.iter().map(|g| g.dir.clone()).collect(),
            seed: self.params.seed,
            profile: self.params.profile.clone(),
            model: self.params.model.clone(),
            llffhold: self.llffhold,
        }
    }

    /// Write [`Self::scene_doc`] as `out`'s noise_scene.json (the last file of a scene's
    /// run), atomically; returns it.
    pub fn write_scene_record(&self, out: &Path) -> Result<NoiseSceneDoc> {
        let doc = self.scene_doc();
        write_json(&out.join(files::NOISE_SCENE), &doc)?;
        Ok(doc)
    }
}

#[allow(clippy::unwrap_used)] // a failing unwrap is a failing test
#[cfg(test)]
mod tests {
    use super::*;
    use crate::dataset::records::{NoiseParams, NoiseTableParams};
    use serde_json::json;

    fn plan(build_levels: &[&str]) -> NoisePlan {
        NoisePlan {
            source: "png".into(),
            gamma: "srgb".into(),
            downsample: vec![2],
            levels: Vec::new(),
            units: Vec::new(),
            input: "build".into(),
            params: NoiseParams {
                seed: 3,
                source: "png".into(),
                profile: "paper".into(),
                gamma: "srgb".into(),
                white_level: 1.0,
                frames: 1,
                levels_table: NoiseTableParams {
                    log10_sigma_read_1: -2.25,
                    log10_sigma_shot_1: -3.0,
                    read_step_per_log2_gain: 0.375,
                    shot_step_per_log2_gain: 0.5,
                    source: "blurset-default".into(),
                },
                downsample: vec![2],
                clean_views: "test_views".into(),
                no_linear: false,
                model: "paper".into(),
            },
            build_levels: build_levels.iter().map(|l| l.to_string()).collect(),
            build_seed: Some(11),
            llffhold: None,
        }
    }

    /// A unit folder with its noise.json of `images` files, complete when `done`.
    fn unit(out: &Path, at: &str, gain: serde_json::Value, seed: u64, images: usize, done: bool) {
        let dir = out.join(at);
        std::fs::create_dir_all(&dir).unwrap();
        let file =
            json!({"view": 0, "frame": 0, "image": "images/a.png", "linear": "linear/a.exr"});
        let doc = json!({"gain": gain, "seed": seed, "sigma_read": 0.5, "sigma_shot": 0.25,
                         "files": vec![file; images], "source": {"kind": "png"}});
        std::fs::write(dir.join(files::NOISE), doc.to_string()).unwrap();
        if done {
            std::fs::write(dir.join(crate::dataset::layout::MARKER), "t\n").unwrap();
        }
    }

    fn out(tag: &str) -> PathBuf {
        let dir =
            std::env::temp_dir().join(format!("blurset-noise-out-{tag}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        dir
    }

    #[test]
    fn the_dataset_record_counts_the_complete_units_on_disk() {
        let out = out("dataset");
        unit(&out, "b_000/sharp/gain_20", json!(20), 5, 4, true);
        unit(&out, "b_000/sharp/gain_4", json!(4), 5, 4, true);
        unit(&out, "a_000/blur_2/gain_4", json!(4), 7, 3, true);
        unit(&out, "a_000/sharp/gain_2.5", json!(2.5), 8, 2, true);
        // Not complete: a partial folder, a folder without its marker.
        unit(&out, "a_000/sharp/gain_8.partial", json!(8), 8, 2, true);
        unit(&out, "a_000/blur_1/gain_8", json!(8), 9, 2, false);
        let p = plan(&["sharp", "blur_1", "blur_2"]);
        let doc = p.write_dataset(&out, "2026-01-02T03:04:05").unwrap();
        let gains: Vec<String> = doc.gains.iter().map(|g| g.gain.to_string()).collect();
        assert_eq!(gains, ["2.5", "4", "20"]);
        assert_eq!(
            (doc.gains[0].sigma_read, doc.gains[0].sigma_shot),
            (0.5, 0.25)
        );
        // The build's order, and only levels with a unit on disk.
        assert_eq!(doc.levels, ["sharp", "blur_2"]);
        assert_eq!(
            doc.seeds["a_000"],
            BTreeMap::from([("blur_2".into(), 7), ("sharp".into(), 8)])
        );
        assert_eq!(doc.seeds["b_000"], BTreeMap::from([("sharp".into(), 5)]));
        assert_eq!(
            (doc.counts.settings, doc.counts.units, doc.counts.images),
            (2, 4, 13)
        );
        assert_eq!(
            (doc.build.as_str(), doc.build_seed, doc.params.seed),
            ("build", Some(11), 3)
        );
        assert_eq!(
            (doc.created.as_str(), doc.seed_derivation.as_str()),
            ("2026-01-02T03:04:05", SEED_DERIVATION)
        );
        let written = read_record(&out.join(files::NOISE_DATASET), Record::NoiseDataset).unwrap();
        assert_eq!(written, serde_json::to_value(&doc).unwrap());
        let _ = std::fs::remove_dir_all(&out);
    }

    #[test]
    fn the_start_holds_the_options_and_the_params_keep_their_order() {
        let out = out("start");
        let p = plan(&["sharp"]);
        p.write_dataset_start(&out).unwrap();
        let text = std::fs::read_to_string(out.join(files::NOISE_DATASET)).unwrap();
        let v: serde_json::Value = serde_json::from_str(&text).unwrap();
        assert_eq!(
            v,
            json!({"build": "build", "params": serde_json::to_value(&p.params).unwrap()})
        );
        // The table's keys in name order, as noise_dataset.json has always held them.
        let keys = [
            "log10_sigma_read_1",
            "log10_sigma_shot_1",
            "read_step_per_log2_gain",
        ];
        let at: Vec<usize> = keys.iter().map(|k| text.find(k).unwrap()).collect();
        assert!(
            at.windows(2).all(|w| w[0] < w[1])
                && text.find("\"source\": \"blurset-default\"").unwrap() > at[2]
        );
        // No unit yet: an empty record, not an error.
        let doc = p.write_dataset(&out, "t").unwrap();
        assert_eq!(
            (doc.counts.units, doc.levels.len(), doc.gains.len()),
            (0, 0, 0)
        );
        let _ = std::fs::remove_dir_all(&out);
    }

    #[test]
    fn the_scene_record_names_the_scene_its_gains_seed_and_profile() {
        let p = plan(&[]);
        let doc = p.scene_doc();
        assert_eq!(
            (doc.kind.as_str(), doc.scene.as_str(), doc.seed),
            (SCENE_KIND, "build", 3)
        );
        assert_eq!((doc.profile.as_str(), doc.gains.len()), ("paper", 0));
        assert_eq!(doc.blurset_version, env!("CARGO_PKG_VERSION"));
    }
}
