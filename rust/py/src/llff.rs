use blurset_core as core;
use numpy::{PyArray2, PyArrayMethods, PyReadonlyArray2};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use std::path::PathBuf;

/// Read `poses_bounds.npy` as an (N, 17) float64 array.
#[pyfunction]
fn read_poses_bounds<'py>(py: Python<'py>, path: PathBuf) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let rows = crate::run_detached(py, || core::read_poses_bounds(&path))?;
    let flat: Vec<f64> = rows.iter().flatten().copied().collect();
    numpy::PyArray1::from_vec(py, flat).reshape([rows.len(), 17])
}

/// Write an (N, 17) array as `poses_bounds.npy` (atomically; refuses non-finite values).
#[pyfunction]
fn write_poses_bounds(
    py: Python<'_>,
    path: PathBuf,
    rows: PyReadonlyArray2<'_, f64>,
) -> PyResult<()> {
    let a = rows.as_array();
    if a.ncols() != 17 {
        return Err(PyValueError::new_err(format!(
            "poses_bounds must have 17 columns, got {}",
            a.ncols()
        )));
    }
    let rows: Vec<core::PoseRow> = a
        .rows()
        .into_iter()
        .map(|r| {
            let mut out = [0.0; 17];
            for (o, v) in out.iter_mut().zip(r.iter()) {
                *o = *v;
            }
            out
        })
        .collect();
    crate::run_detached(py, || core::write_poses_bounds(&path, &rows))
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    add_functions! {
        m,
        read_poses_bounds, write_poses_bounds,
    }
    Ok(())
}
