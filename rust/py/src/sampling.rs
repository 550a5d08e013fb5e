//! Sampling, setting poses and splits. Structured values cross the boundary as JSON
//! text (serde on this side, `json` on the other): one schema, defined in blurset-core.
use blurset_core as core;
use numpy::PyReadonlyArray2;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use std::path::PathBuf;

fn from_json<T: serde::de::DeserializeOwned>(what: &str, text: &str) -> PyResult<T> {
    serde_json::from_str(text).map_err(|e| PyValueError::new_err(format!("{what}: {e}")))
}

fn to_json<T: serde::Serialize>(value: &T) -> PyResult<String> {
    serde_json::to_string(value).map_err(|e| PyValueError::new_err(e.to_string()))
}

/// The default sampling configuration (the paper's settings) as JSON.
#[pyfunction]
fn default_sampling_config() -> PyResult<String> {
    to_json(&core::SamplingConfig::default())
}

/// Check a sampling configuration; raises ValueError naming the bad option.
#[pyfunction]
fn validate_sampling_config(config_json: &str) -> PyResult<()> {
    let cfg: core::SamplingConfig = from_json("sampling config", config_json)?;
    cfg.validate().map_err(crate::error::to_pyerr)
}

/// The seed of setting `index` of object `uid` under the build seed.
#[pyfunction]
fn seed_for(seed: u64, uid: &str, index: u64) -> u64 {
    core::seed_for(seed, uid, index)
}

/// Plan one setting (views, near/far from the vertices, weights, latent frames, seeds) → JSON.
#[pyfunction]
#[pyo3(signature = (config_json, *, uid, theta0_deg, seed, bbox_dims, vertices))]
fn plan_setting(
    py: Python<'_>,
    config_json: &str,
    uid: &str,
    theta0_deg: f64,
    seed: u64,
    bbox_dims: [f64; 3],
    vertices: PyReadonlyArray2<'_, f32>,
) -> PyResult<String> {
    let cfg: core::SamplingConfig = from_json("sampling config", config_json)?;
    let v = vertices.as_array();
    if v.ncols() != 3 {
        return Err(PyValueError::new_err(format!(
            "vertices must be (N, 3), got {:?}",
            v.shape()
        )));
    }
    let pts: Vec<[f32; 3]> = v.rows().into_iter().map(|r| [r[0], r[1], r[2]]).collect();
    let plan = crate::run_detached(py, || {
        core::plan_setting(&cfg, uid, theta0_deg, seed, bbox_dims, &pts)
    })?;
    to_json(&plan)
}

/// Write `<level>/poses_bounds.npy` for each level dir and `transforms.json` of a setting.
#[pyfunction]
fn write_setting_poses(
    py: Python<'_>,
    plan_json: &str,
    setting_dir: PathBuf,
    level_dirs: Vec<String>,
) -> PyResult<()> {
    let plan: core::SettingPlan = from_json("setting plan", plan_json)?;
    crate::run_detached(py, || {
        core::write_setting_poses(&plan, &setting_dir, &level_dirs)
    })
}

/// Every `stride`-th view index below `views` (the held-out views of a setting).
#[pyfunction]
fn test_views(views: usize, stride: usize) -> Vec<usize> {
    core::test_views(views, stride)
}

/// Train/test splits by object → JSON (the `splits.json` document).
#[pyfunction]
#[pyo3(signature = (entries_json, *, view_stride, test_fraction, test_objects, seed))]
fn make_splits(
    entries_json: &str,
    view_stride: usize,
    test_fraction: f64,
    test_objects: Option<Vec<String>>,
    seed: u64,
) -> PyResult<String> {
    let entries: Vec<core::SettingEntry> = from_json("split entries", entries_json)?;
    let s = core::make_splits(
        &entries,
        view_stride,
        test_fraction,
        test_objects.as_deref(),
        seed,
    )
    .map_err(crate::error::to_pyerr)?;
    to_json(&s)
}

/// A seeded random subset of `k` ids, sorted (it depends on the set of ids, not their order).
#[pyfunction]
fn seeded_subset(ids: Vec<String>, k: usize, seed: u64) -> Vec<String> {
    core::seeded_subset(&ids, k, seed)
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(seeded_subset, m)?)?;
    m.add_function(wrap_pyfunction!(default_sampling_config, m)?)?;
    m.add_function(wrap_pyfunction!(validate_sampling_config, m)?)?;
    m.add_function(wrap_pyfunction!(seed_for, m)?)?;
    m.add_function(wrap_pyfunction!(plan_setting, m)?)?;
    m.add_function(wrap_pyfunction!(write_setting_poses, m)?)?;
    m.add_function(wrap_pyfunction!(test_views, m)?)?;
    m.add_function(wrap_pyfunction!(make_splits, m)?)?;
    Ok(())
}
