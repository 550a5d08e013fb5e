//! Bindings of the core's failures and setting names: the rules of failures.jsonl, for `blurset build`.
use blurset_core as core;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use std::collections::BTreeSet;
use std::path::PathBuf;

/// The current failures of a failures.jsonl as a JSON list, and the number of lines
/// skipped (torn). `complete`: the complete setting names; `theta0s`: an object's
/// azimuths (None keeps every object record).
#[pyfunction]
#[pyo3(signature = (path, *, complete, theta0s = None))]
fn current_failures(
    py: Python<'_>,
    path: PathBuf,
    complete: Vec<String>,
    theta0s: Option<Vec<f64>>,
) -> PyResult<(String, usize)> {
    let done: BTreeSet<String> = complete.into_iter().collect();
    let (records, skipped) = crate::run_detached(py, || core::read_failure_records(&path))?;
    let now = core::current_failures(&records, &done, theta0s.as_deref());
    let text = serde_json::to_string(&now).map_err(|e| PyValueError::new_err(e.to_string()))?;
    Ok((text, skipped))
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(current_failures, m)?)?;
    Ok(())
}
