//! Binding of the core's render QA: one (H, W, 4) float32 image in, its QA numbers out.
use blurset_core as core;
use numpy::{PyReadonlyArray3, PyUntypedArrayMethods};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

/// When a view fails render QA (the core's defaults unless given).
#[pyclass(
    frozen,
    get_all,
    from_py_object,
    name = "QaThresholds",
    module = "blurset._core"
)]
#[derive(Clone, Copy)]
pub struct QaThresholds {
    /// Least mean alpha (fraction of the image the object covers).
    pub min_coverage: f64,
    /// Least mean unpremultiplied luminance of the object.
    pub min_luminance: f64,
    /// Largest fraction of the object's pixels clipped in sRGB.
    pub max_saturated: f64,
}

impl From<QaThresholds> for core::QaThresholds {
    fn from(t: QaThresholds) -> Self {
        core::QaThresholds {
            min_coverage: t.min_coverage,
            min_luminance: t.min_luminance,
            max_saturated: t.max_saturated,
        }
    }
}

#[pymethods]
impl QaThresholds {
    #[new]
    #[pyo3(signature = (*, min_coverage = None, min_luminance = None, max_saturated = None))]
    fn new(
        min_coverage: Option<f64>,
        min_luminance: Option<f64>,
        max_saturated: Option<f64>,
    ) -> Self {
        let d = core::QaThresholds::default();
        QaThresholds {
            min_coverage: min_coverage.unwrap_or(d.min_coverage),
            min_luminance: min_luminance.unwrap_or(d.min_luminance),
            max_saturated: max_saturated.unwrap_or(d.max_saturated),
        }
    }
}

/// What one view looks like in numbers, and its verdict under the thresholds.
#[pyclass(
    frozen,
    skip_from_py_object,
    name = "FrameQa",
    module = "blurset._core"
)]
#[derive(Clone)]
pub struct FrameQa(pub core::FrameQa, pub Option<String>);

impl FrameQa {
    /// The numbers with their verdict under `thresholds` (default: the core's).
    pub(crate) fn judged(r: core::FrameQa, thresholds: Option<QaThresholds>) -> Self {
        let t: core::QaThresholds = thresholds.map(Into::into).unwrap_or_default();
        FrameQa(r, t.verdict(&r))
    }
}

#[pymethods]
impl FrameQa {
    /// Mean alpha: the fraction of the image the object covers.
    #[getter]
    fn coverage(&self) -> f64 {
        self.0.coverage
    }
    /// Mean unpremultiplied luminance of the object (Σ premultiplied Y / Σ alpha).
    #[getter]
    fn luminance(&self) -> f64 {
        self.0.luminance
    }
    /// Fraction of covered pixels with a colour channel at or above 1.
    #[getter]
    fn saturated(&self) -> f64 {
        self.0.saturated
    }
    /// Fraction of the border pixels the object covers.
    #[getter]
    fn border_coverage(&self) -> f64 {
        self.0.border_coverage
    }
    /// The reason the view fails, or None when it passes.
    #[getter]
    fn failure(&self) -> Option<String> {
        self.1.clone()
    }
}

fn rgba<'a>(a: &'a PyReadonlyArray3<'_, f32>) -> PyResult<&'a [f32]> {
    if a.shape()[2] != 4 {
        return Err(PyValueError::new_err(format!(
            "QA needs shape (H, W, 4) premultiplied RGBA, got {:?}",
            a.shape()
        )));
    }
    Ok(a.as_slice()?)
}

/// QA of a premultiplied linear RGBA image (H, W, 4) under `thresholds` (default: the core's).
#[pyfunction]
#[pyo3(signature = (rgba_, *, thresholds = None))]
fn frame_qa(
    rgba_: PyReadonlyArray3<'_, f32>,
    thresholds: Option<QaThresholds>,
) -> PyResult<FrameQa> {
    let shape = rgba_.shape();
    let r = core::frame_qa(shape[1] as u32, shape[0] as u32, rgba(&rgba_)?)
        .map_err(crate::error::to_pyerr)?;
    Ok(FrameQa::judged(r, thresholds))
}

/// QA of an EXR (premultiplied linear RGBA), read and judged in the core.
#[pyfunction]
#[pyo3(signature = (path, *, thresholds = None))]
fn frame_qa_exr(
    py: Python<'_>,
    path: std::path::PathBuf,
    thresholds: Option<QaThresholds>,
) -> PyResult<FrameQa> {
    let r = crate::run_detached(py, move || core::exr_qa(&path))?;
    Ok(FrameQa::judged(r, thresholds))
}

/// The default QA thresholds (one place for the numbers).
#[pyfunction]
fn default_qa_thresholds() -> QaThresholds {
    QaThresholds::new(None, None, None)
}

/// OpenGL camera-to-world (row-major) of each load-time QA view of an object of this box.
#[pyfunction]
fn object_qa_cameras(bbox_dims: [f64; 3]) -> Vec<[[f64; 4]; 4]> {
    core::object_qa::cameras(bbox_dims)
}

/// The reason an object fails its load-time QA (invisible or black in every view), or None.
#[pyfunction]
#[pyo3(signature = (views, *, thresholds = None))]
fn object_qa_verdict(
    views: Vec<PyRef<'_, FrameQa>>,
    thresholds: Option<QaThresholds>,
) -> Option<String> {
    let t: core::QaThresholds = thresholds.map(Into::into).unwrap_or_default();
    let v: Vec<core::FrameQa> = views.iter().map(|q| q.0).collect();
    core::object_qa::verdict(&v, &t)
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<QaThresholds>()?;
    m.add_class::<FrameQa>()?;
    m.add("OBJECT_QA_RESOLUTION", core::object_qa::RESOLUTION)?;
    m.add("OBJECT_QA_SAMPLES", core::object_qa::SAMPLES)?;
    m.add("OBJECT_QA_FOV_DEG", core::object_qa::FOV_DEG)?;
    add_functions! {
        m,
        frame_qa, frame_qa_exr, default_qa_thresholds, object_qa_cameras, object_qa_verdict,
    }
    Ok(())
}
