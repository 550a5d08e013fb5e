//! Build statistics (`blurset stats`): one core call, the document as a frozen object.
use crate::convert::to_py;
use blurset_core as core;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use std::path::PathBuf;

/// The statistics of a build (the `stats.json` document, schema "blurset-stats/1").
#[pyclass(frozen, name = "BuildStats", module = "blurset._core")]
pub struct BuildStats(core::BuildStats);

#[pymethods]
impl BuildStats {
    /// Objects, settings, views, images, test counts, failures, skipped settings.
    #[getter]
    fn counts<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        to_py(py, &self.0.counts)
    }

    /// The complete settings read (name, uid, θ0, views, level dirs, images …).
    #[getter]
    fn settings<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        to_py(py, &self.0.settings)
    }

    /// The whole document as a dict (per-view arrays, per-level maps keyed "1" … as in
    /// stats.json, summaries).
    fn to_dict<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let doc =
            serde_json::to_value(&self.0).map_err(|e| PyValueError::new_err(e.to_string()))?;
        to_py(py, &doc)
    }

    /// Write stats.json (compact), `generated` and `blurset_version` first, atomically.
    fn write(&self, py: Python<'_>, path: PathBuf, generated: &str) -> PyResult<()> {
        let file = core::StatsFile {
            generated: generated.into(),
            blurset_version: env!("CARGO_PKG_VERSION").into(),
            stats: self.0.clone(),
        };
        crate::run_detached(py, || file.write(&path))
    }
}

/// Read every complete setting of the build at `out` and compute its statistics.
///
/// Raises InputError naming the file: no such directory, not a build, unreadable or
/// corrupt meta.json of a complete setting, corrupt splits.json or failures.jsonl.
#[pyfunction]
fn build_stats(py: Python<'_>, out: PathBuf) -> PyResult<BuildStats> {
    crate::run_detached(py, || core::build_stats(&out)).map(BuildStats)
}

/// Each degradation kind beside motion blur, in level order, as its histogram shows it:
/// (kind, its statistic's name in stats.json, figure title, x axis label).
#[pyfunction]
fn kind_figures() -> Vec<(&'static str, &'static str, &'static str, &'static str)> {
    core::KIND_STATS
        .iter()
        .map(|k| (k.name, k.stat.0, k.figure.0, k.figure.1))
        .collect()
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<BuildStats>()?;
    add_functions! {
        m,
        build_stats, kind_figures,
    }
    Ok(())
}
