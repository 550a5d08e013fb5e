//! Bindings of the core's metrics: image error against a reference, Pareto front.
use blurset_core as core;
use numpy::{PyReadonlyArray3, PyUntypedArrayMethods};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

fn rgba<'a>(a: &'a PyReadonlyArray3<'_, f32>, what: &str) -> PyResult<&'a [f32]> {
    if a.shape()[2] != 4 {
        return Err(PyValueError::new_err(format!(
            "{what} must have shape (H, W, 4) premultiplied linear RGBA, got {:?}",
            a.shape()
        )));
    }
    a.as_slice()
        .map_err(|_| PyValueError::new_err(format!("{what} must be C-contiguous")))
}

/// Error of an image against a reference (DESIGN §8): PSNR and MSE, sRGB and linear.
#[pyclass(frozen, get_all, name = "ImageMetrics", module = "blurset._core")]
pub struct ImageMetrics {
    /// PSNR (dB, peak 1) of the sRGB image composited over the background (≤ 200).
    pub psnr: f64,
    /// PSNR (dB, peak 1) of the linear premultiplied RGBA.
    pub psnr_linear: f64,
    pub mse: f64,
    pub mse_linear: f64,
    /// High-frequency energy of the image over the reference's (core `detail_ratio`).
    pub detail_ratio: f64,
}

/// A core figure of two premultiplied RGBA images over a background.
type ObjectFigure = fn(&[f32], &[f32], [f64; 3]) -> core::Result<core::ObjectError>;

/// A figure of two images (each with its name for errors) on the object's pixels over
/// `background`: their shapes checked, `figure` run with the GIL released.
fn object_figure(
    py: Python<'_>,
    [(a, a_name), (b, b_name)]: [(&PyReadonlyArray3<'_, f32>, &str); 2],
    background: (f64, f64, f64),
    figure: ObjectFigure,
) -> PyResult<ObjectError> {
    same_shape(a, b)?;
    let (a, b) = (rgba(a, a_name)?, rgba(b, b_name)?);
    let bg = [background.0, background.1, background.2];
    Ok(crate::run_detached(py, || figure(a, b, bg))?.into())
}

/// Error of `image` against `reference` (float32 (H, W, 4), premultiplied linear RGBA):
/// JSON with `psnr` (sRGB over the background), `psnr_linear`, `mse`, `mse_linear`.
#[pyfunction]
#[pyo3(signature = (image, reference, *, background = (1.0, 1.0, 1.0)))]
fn image_error(
    py: Python<'_>,
    image: PyReadonlyArray3<'_, f32>,
    reference: PyReadonlyArray3<'_, f32>,
    background: (f64, f64, f64),
) -> PyResult<ImageMetrics> {
    if image.shape() != reference.shape() {
        return Err(PyValueError::new_err(format!(
            "image {:?} and reference {:?} differ in shape",
            image.shape(),
            reference.shape()
        )));
    }
    let (a, b) = (rgba(&image, "image")?, rgba(&reference, "reference")?);
    let bg = [background.0, background.1, background.2];
    let width = image.shape()[1];
    let (e, detail) = crate::run_detached(py, || {
        Ok((
            core::image_error(a, b, bg)?,
            core::detail_ratio(a, b, width, bg)?,
        ))
    })?;
    Ok(ImageMetrics {
        psnr: e.psnr,
        psnr_linear: e.psnr_linear,
        mse: e.mse,
        mse_linear: e.mse_linear,
        detail_ratio: detail,
    })
}

/// The share of the reference's texture `image` keeps (core `detail_kept`): `reference`
/// rendered twice on independent seeds, `r1` and `r2`; all float32 (H, W, 4)
/// premultiplied linear RGBA. Render noise on either side does not read as detail.
#[pyfunction]
#[pyo3(signature = (image, r1, r2, *, background = (1.0, 1.0, 1.0)))]
fn detail_kept(
    py: Python<'_>,
    image: PyReadonlyArray3<'_, f32>,
    r1: PyReadonlyArray3<'_, f32>,
    r2: PyReadonlyArray3<'_, f32>,
    background: (f64, f64, f64),
) -> PyResult<f64> {
    same_shape(&image, &r1)?;
    same_shape(&image, &r2)?;
    let (a, b, c) = (rgba(&image, "image")?, rgba(&r1, "r1")?, rgba(&r2, "r2")?);
    let bg = [background.0, background.1, background.2];
    let width = image.shape()[1];
    crate::run_detached(py, || core::detail_kept(a, [b, c], width, bg))
}

/// Error on the object's pixels (alpha over 1e-6, Cycles' rounding, in either image;
/// DESIGN §8).
#[pyclass(frozen, get_all, name = "ObjectError", module = "blurset._core")]
pub struct ObjectError {
    /// PSNR (dB, peak 1) of the sRGB image over the background, on object pixels (≤ 200).
    pub psnr: f64,
    pub mse: f64,
    /// Fraction of the frame that is object pixels.
    pub coverage: f64,
    pub object_px: u64,
}

impl From<core::ObjectError> for ObjectError {
    fn from(e: core::ObjectError) -> Self {
        ObjectError {
            psnr: e.psnr,
            mse: e.mse,
            coverage: e.coverage,
            object_px: e.object_px,
        }
    }
}

fn same_shape(a: &PyReadonlyArray3<'_, f32>, b: &PyReadonlyArray3<'_, f32>) -> PyResult<()> {
    if a.shape() != b.shape() {
        return Err(PyValueError::new_err(format!(
            "images {:?} and {:?} differ in shape",
            a.shape(),
            b.shape()
        )));
    }
    Ok(())
}

/// Error of `image` against `reference` (float32 (H, W, 4), premultiplied linear RGBA) on
/// the object's pixels (core `object_error`).
#[pyfunction]
#[pyo3(signature = (image, reference, *, background = (1.0, 1.0, 1.0)))]
fn object_error(
    py: Python<'_>,
    image: PyReadonlyArray3<'_, f32>,
    reference: PyReadonlyArray3<'_, f32>,
    background: (f64, f64, f64),
) -> PyResult<ObjectError> {
    let pair = [(&image, "image"), (&reference, "reference")];
    object_figure(py, pair, background, core::object_error)
}

/// The render noise of the mean of two independent halves of an image, estimated from
/// them on object pixels: MSE(half_a, half_b) / 4 where sRGB is straight over their
/// spread, each half's distance from their merged image where it bends (core `half_noise`).
#[pyfunction]
#[pyo3(signature = (half_a, half_b, *, background = (1.0, 1.0, 1.0)))]
fn half_noise(
    py: Python<'_>,
    half_a: PyReadonlyArray3<'_, f32>,
    half_b: PyReadonlyArray3<'_, f32>,
    background: (f64, f64, f64),
) -> PyResult<ObjectError> {
    let pair = [(&half_a, "half_a"), (&half_b, "half_b")];
    object_figure(py, pair, background, core::half_noise)
}

/// [`half_noise`] with its bound where the noise is heavy-tailed (core
/// `half_noise_bound`): a dict with `estimate` (psnr, mse, coverage, object_px),
/// `mse_bound`, `psnr_bound` and `n_eff`.
#[pyfunction]
#[pyo3(signature = (half_a, half_b, *, background = (1.0, 1.0, 1.0)))]
fn half_noise_bound<'py>(
    py: Python<'py>,
    half_a: PyReadonlyArray3<'py, f32>,
    half_b: PyReadonlyArray3<'py, f32>,
    background: (f64, f64, f64),
) -> PyResult<Bound<'py, PyAny>> {
    same_shape(&half_a, &half_b)?;
    let (a, b) = (rgba(&half_a, "half_a")?, rgba(&half_b, "half_b")?);
    let bg = [background.0, background.1, background.2];
    let h = crate::run_detached(py, || core::half_noise_bound(a, b, bg))?;
    crate::convert::to_py(py, &h)
}

/// The worst value, the 5th percentile and the mean of per-image figures (core `spread`):
/// a dict with worst, p5, mean, n.
#[pyfunction]
fn spread(py: Python<'_>, values: Vec<f64>) -> PyResult<Bound<'_, PyAny>> {
    let s = core::spread(&values).map_err(crate::error::to_pyerr)?;
    crate::convert::to_py(py, &s)
}

/// Which points (seconds, psnr) are Pareto-optimal (faster or better than every other).
#[pyfunction]
fn pareto_front(seconds: Vec<f64>, psnr: Vec<f64>) -> PyResult<Vec<bool>> {
    core::pareto_front(&seconds, &psnr).map_err(crate::error::to_pyerr)
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<ImageMetrics>()?;
    m.add_class::<ObjectError>()?;
    m.add_function(wrap_pyfunction!(object_error, m)?)?;
    m.add_function(wrap_pyfunction!(half_noise, m)?)?;
    m.add_function(wrap_pyfunction!(half_noise_bound, m)?)?;
    m.add_function(wrap_pyfunction!(spread, m)?)?;
    m.add_function(wrap_pyfunction!(image_error, m)?)?;
    m.add_function(wrap_pyfunction!(detail_kept, m)?)?;
    m.add_function(wrap_pyfunction!(pareto_front, m)?)?;
    Ok(())
}
