//! Binding of the core's render QA: one (H, W, 4) float32 image in, its QA numbers out.
use blurset_core as core;
use numpy::{PyReadonlyArray3, PyUntypedArrayMethods};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

/// QA of a premultiplied linear RGBA image: a JSON object with `coverage`, `luminance`,
/// `saturated`, `border_coverage` and `failure` (the reason, or null when it passes).
/// `thresholds` is a JSON object of `QaThresholds` fields; absent fields take defaults.
#[pyfunction]
#[pyo3(signature = (rgba, *, thresholds = None))]
fn frame_qa(rgba: PyReadonlyArray3<'_, f32>, thresholds: Option<&str>) -> PyResult<String> {
    let shape = rgba.shape();
    if shape[2] != 4 {
        return Err(PyValueError::new_err(format!(
            "QA needs shape (H, W, 4) premultiplied RGBA, got {shape:?}"
        )));
    }
    let t: core::QaThresholds = match thresholds {
        Some(s) => serde_json::from_str(s)
            .map_err(|e| PyValueError::new_err(format!("QA thresholds: {e}")))?,
        None => core::QaThresholds::default(),
    };
    let data = rgba.as_slice()?;
    let r =
        core::frame_qa(shape[1] as u32, shape[0] as u32, data).map_err(crate::error::to_pyerr)?;
    let mut v = serde_json::to_value(r).map_err(|e| PyValueError::new_err(e.to_string()))?;
    v["failure"] = t.verdict(&r).into();
    Ok(v.to_string())
}

/// The default QA thresholds as JSON (one place for the numbers).
#[pyfunction]
fn default_qa_thresholds() -> PyResult<String> {
    serde_json::to_string(&core::QaThresholds::default())
        .map_err(|e| PyValueError::new_err(e.to_string()))
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(frame_qa, m)?)?;
    m.add_function(wrap_pyfunction!(default_qa_thresholds, m)?)?;
    Ok(())
}
