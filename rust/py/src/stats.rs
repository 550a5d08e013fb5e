//! Build statistics (`blurset stats`): one core call, the document out as JSON text.
use blurset_core as core;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use std::path::PathBuf;

/// Read every complete setting of the build at `out` → the stats document as JSON.
#[pyfunction]
fn build_stats(py: Python<'_>, out: PathBuf) -> PyResult<String> {
    let doc = crate::run_detached(py, || core::build_stats(&out))?;
    serde_json::to_string(&doc).map_err(|e| PyValueError::new_err(e.to_string()))
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(build_stats, m)?)?;
    Ok(())
}
