//! The worker contract (blurset-core's dataset::wire): a render's frame as the worker
//! reads it, and the contract's schemas. blurset.worker_client sends what these make.
use crate::convert::{from_py, to_py};
use crate::error::to_pyerr;
use blurset_core::wire;
use pyo3::prelude::*;

/// A render (a plan's, or a caller's dict) as one frame of a worker's render request:
/// its wire fields, typed and checked; ValueError naming what is wrong.
#[pyfunction]
fn wire_frame<'py>(py: Python<'py>, render: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyAny>> {
    let loose: wire::LooseFrame = from_py("render frame", render)?;
    let frame = wire::wire_frame(loose).map_err(to_pyerr)?;
    to_py(py, &frame)
}

/// (file stem, JSON Schema) of the worker's requests and replies.
#[pyfunction]
fn worker_schemas(py: Python<'_>) -> PyResult<Vec<(&'static str, Bound<'_, PyAny>)>> {
    wire::schemas()
        .into_iter()
        .map(|(stem, s)| Ok((stem, to_py(py, &s)?)))
        .collect()
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(wire_frame, m)?)?;
    m.add_function(wrap_pyfunction!(worker_schemas, m)?)?;
    Ok(())
}
