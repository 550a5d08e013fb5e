//! Bindings of the core's failures and setting names: the rules of failures.jsonl, for `blurset build`.
use blurset_core as core;
use pyo3::prelude::*;
use std::collections::BTreeSet;
use std::path::PathBuf;

/// The current failures of a failures.jsonl (a list of records), and the number of lines
/// skipped (torn). `complete`: the complete setting names; `theta0s`: an object's
/// azimuths (None keeps every object record).
#[pyfunction]
#[pyo3(signature = (path, *, complete, theta0s = None))]
fn current_failures(
    py: Python<'_>,
    path: PathBuf,
    complete: Vec<String>,
    theta0s: Option<Vec<f64>>,
) -> PyResult<(Bound<'_, PyAny>, usize)> {
    let done: BTreeSet<String> = complete.into_iter().collect();
    let (records, skipped) = crate::run_detached(py, || core::read_failure_records(&path))?;
    let now = core::current_failures(&records, &done, theta0s.as_deref());
    Ok((crate::convert::to_py(py, &now)?, skipped))
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    add_functions! {
        m,
        current_failures,
    }
    Ok(())
}
