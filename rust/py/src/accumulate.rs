//! Bindings of the core's accumulator and EXR reader: numpy/path conversion and one core call each.
use crate::qa::{FrameQa, QaThresholds};
use crate::run_detached;
use blurset_core as core;
use numpy::{
    PyArray1, PyArrayDescrMethods, PyArrayDyn, PyArrayMethods, PyReadonlyArray3,
    PyReadonlyArrayDyn, PyUntypedArray, PyUntypedArrayMethods,
};
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;
use std::path::PathBuf;

/// A float32 numpy array, with messages that say what was wrong and how to fix it.
fn f32_array<'py>(obj: &Bound<'py, PyAny>, what: &str) -> PyResult<Bound<'py, PyUntypedArray>> {
    let arr = obj.cast::<PyUntypedArray>().map_err(|_| {
        PyTypeError::new_err(format!(
            "{what} must be a numpy.ndarray, got {}",
            obj.get_type()
                .name()
                .map(|n| n.to_string())
                .unwrap_or_else(|_| "?".into())
        ))
    })?;
    let dtype = arr.dtype();
    if !dtype.is_equiv_to(&numpy::dtype::<f32>(obj.py())) {
        return Err(PyTypeError::new_err(format!(
            "{what} must have dtype float32, got {dtype}; use arr.astype(np.float32)"
        )));
    }
    Ok(arr.clone())
}

/// A C-contiguous float32 (H, W, 4) frame of the given size.
fn rgba_frame<'py>(
    obj: &Bound<'py, PyAny>,
    width: u32,
    height: u32,
) -> PyResult<PyReadonlyArray3<'py, f32>> {
    let arr = f32_array(obj, "frame")?;
    let shape = arr.shape();
    if shape.len() != 3 || shape[2] != 4 {
        return Err(PyValueError::new_err(format!(
            "frame must have shape (H, W, 4) (premultiplied linear RGBA), got {shape:?}"
        )));
    }
    if (shape[0], shape[1]) != (height as usize, width as usize) {
        return Err(PyValueError::new_err(format!(
            "frame is {}x{} (W x H) but the accumulator is {width}x{height}",
            shape[1], shape[0]
        )));
    }
    if !arr.is_c_contiguous() {
        return Err(PyValueError::new_err(
            "frame must be C-contiguous; use np.ascontiguousarray(frame)",
        ));
    }
    Ok(arr.cast::<numpy::PyArray3<f32>>()?.readonly())
}

fn rgba_to_py(py: Python<'_>, f: core::Frame) -> PyResult<Bound<'_, numpy::PyArray3<f32>>> {
    PyArray1::from_vec(py, f.rgba).reshape([f.height as usize, f.width as usize, 4])
}

/// Running mean of linear RGBA frames of one size (memory: one f64 frame).
#[pyclass(name = "Accumulator", module = "blurset._core")]
pub struct PyAccumulator {
    inner: core::Accumulator,
}

impl From<core::Accumulator> for PyAccumulator {
    fn from(inner: core::Accumulator) -> Self {
        PyAccumulator { inner }
    }
}

#[pymethods]
impl PyAccumulator {
    #[new]
    #[pyo3(signature = (width, height, *, guides = false))]
    fn new(width: u32, height: u32, guides: bool) -> PyResult<Self> {
        if width == 0 || height == 0 {
            return Err(PyValueError::new_err(format!(
                "accumulator size must be positive, got {width}x{height}"
            )));
        }
        Ok(PyAccumulator {
            inner: if guides {
                core::Accumulator::with_guides(width, height)
            } else {
                core::Accumulator::new(width, height)
            },
        })
    }

    /// Whether the denoising guides are averaged.
    #[getter]
    fn guides(&self) -> bool {
        self.inner.has_guides()
    }

    /// Whether the mean has been denoised.
    #[getter]
    fn denoised(&self) -> bool {
        self.inner.is_denoised()
    }

    /// Denoise the mean once with its mean guides (core `Accumulator::denoise`).
    fn denoise(&mut self, py: Python<'_>, denoiser: &PyDenoiser) -> PyResult<()> {
        let inner = &mut self.inner;
        let d = &denoiser.inner;
        run_detached(py, move || inner.denoise(d))
    }

    /// The mean albedo and normal, float32 (H, W, 3) each.
    #[allow(clippy::type_complexity)]
    fn guide_means<'py>(
        &self,
        py: Python<'py>,
    ) -> PyResult<(
        Bound<'py, numpy::PyArray3<f32>>,
        Bound<'py, numpy::PyArray3<f32>>,
    )> {
        let inner = &self.inner;
        let (a, n) = run_detached(py, move || inner.guide_means())?;
        let shape = [inner.height() as usize, inner.width() as usize, 3];
        Ok((
            PyArray1::from_vec(py, a).reshape(shape)?,
            PyArray1::from_vec(py, n).reshape(shape)?,
        ))
    }

    #[getter]
    fn width(&self) -> u32 {
        self.inner.width()
    }

    #[getter]
    fn height(&self) -> u32 {
        self.inner.height()
    }

    /// Number of frames added so far.
    #[getter]
    fn count(&self) -> u32 {
        self.inner.count()
    }

    /// Read a linear RGBA float EXR and add it (alpha 1 when the file has none); with
    /// `origin` = (x0, y0), a render cropped to its region, placed there.
    /// `weight`: how many times the frame counts in the mean (its samples, where the
    /// frames of one image render different counts).
    #[pyo3(signature = (path, origin=None, *, weight=1.0))]
    fn add_exr(
        &mut self,
        py: Python<'_>,
        path: PathBuf,
        origin: Option<(u32, u32)>,
        weight: f64,
    ) -> PyResult<()> {
        let inner = &mut self.inner;
        run_detached(py, move || inner.add_exr_weighted(&path, origin, weight))
    }

    /// Add the frames of `other` (the other half of an image rendered to a target).
    fn merge(&mut self, py: Python<'_>, other: PyRef<'_, Self>) -> PyResult<()> {
        let (inner, other) = (&mut self.inner, &other.inner);
        run_detached(py, move || inner.merge(other))
    }

    /// Add a premultiplied linear RGBA frame, float32 (H, W, 4) C-contiguous.
    fn add(&mut self, py: Python<'_>, frame: &Bound<'_, PyAny>) -> PyResult<()> {
        let arr = rgba_frame(frame, self.inner.width(), self.inner.height())?;
        let data = arr.as_slice()?;
        let inner = &mut self.inner;
        run_detached(py, move || inner.add_frame(data))
    }

    /// The mean so far, premultiplied linear RGBA float32 (H, W, 4).
    fn mean<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, numpy::PyArray3<f32>>> {
        let inner = &self.inner;
        let rgba = run_detached(py, move || inner.mean())?;
        rgba_to_py(
            py,
            core::Frame {
                width: inner.width(),
                height: inner.height(),
                rgba,
            },
        )
    }

    /// Render QA of the mean, judged under `thresholds` (default: the core's); its
    /// pixels stay in the core.
    #[pyo3(signature = (*, thresholds = None))]
    fn qa(&self, py: Python<'_>, thresholds: Option<QaThresholds>) -> PyResult<FrameQa> {
        let inner = &self.inner;
        let r = run_detached(py, move || inner.qa())?;
        Ok(FrameQa::judged(r, thresholds))
    }

    /// Write the mean as an 8-bit sRGB PNG composited over `background` (linear RGB),
    /// area-averaged `downsample` times in linear light first (LLFF's `images_<f>/`).
    #[pyo3(signature = (path, background = (1.0, 1.0, 1.0), *, downsample = 1))]
    fn write_png(
        &self,
        py: Python<'_>,
        path: PathBuf,
        background: (f32, f32, f32),
        downsample: u32,
    ) -> PyResult<()> {
        let bg = [background.0, background.1, background.2];
        if bg.iter().any(|v| !v.is_finite()) {
            return Err(PyValueError::new_err(format!(
                "background must be finite linear RGB, got {background:?}"
            )));
        }
        let inner = &self.inner;
        run_detached(py, move || {
            inner.write_png_downsampled(&path, bg, downsample)
        })
    }

    /// Write the object mask of the mean (255 where coverage is at least one half, area-
    /// averaged `downsample` times first) as an 8-bit PNG.
    #[pyo3(signature = (path, *, downsample = 1))]
    fn write_mask(&self, py: Python<'_>, path: PathBuf, downsample: u32) -> PyResult<()> {
        let inner = &self.inner;
        run_detached(py, move || inner.write_mask(&path, downsample))
    }

    /// Write a blurry image's mask (core `Accumulator::write_exposure_mask`): the pixels
    /// its frames covered, each frame one render of `blur_method`, area-averaged
    /// `downsample` times, with every pixel of the mask PNG `sharp` added.
    #[pyo3(signature = (path, *, blur_method, downsample = 1, sharp = None))]
    fn write_exposure_mask(
        &self,
        py: Python<'_>,
        path: PathBuf,
        blur_method: &str,
        downsample: u32,
        sharp: Option<PathBuf>,
    ) -> PyResult<()> {
        let method = <core::BlurMethod as core::Choice>::from_name(blur_method)
            .ok_or_else(|| PyValueError::new_err(format!("no blur method {blur_method:?}")))?;
        let inner = &self.inner;
        run_detached(py, move || {
            inner.write_exposure_mask(&path, downsample, method, sharp.as_deref())
        })
    }

    /// Write the mean as a linear premultiplied RGBA float32 EXR.
    fn write_exr(&self, py: Python<'_>, path: PathBuf) -> PyResult<()> {
        let inner = &self.inner;
        run_detached(py, move || inner.write_exr(&path))
    }

    fn __repr__(&self) -> String {
        format!(
            "Accumulator(width={}, height={}, count={})",
            self.inner.width(),
            self.inner.height(),
            self.inner.count()
        )
    }
}

/// Open Image Denoise loaded at run time (core `Denoiser`).
#[pyclass(frozen, name = "Denoiser", module = "blurset._core")]
pub struct PyDenoiser {
    /// Shared with the render sessions that denoise with it.
    pub(crate) inner: std::sync::Arc<core::Denoiser>,
}

/// A C-contiguous float32 (H, W, 3) image.
fn rgb_image<'py>(obj: &Bound<'py, PyAny>, what: &str) -> PyResult<PyReadonlyArray3<'py, f32>> {
    let arr = f32_array(obj, what)?;
    let shape = arr.shape();
    if shape.len() != 3 || shape[2] != 3 {
        return Err(PyValueError::new_err(format!(
            "{what} must have shape (H, W, 3), got {shape:?}"
        )));
    }
    if !arr.is_c_contiguous() {
        return Err(PyValueError::new_err(format!(
            "{what} must be C-contiguous; use np.ascontiguousarray({what})"
        )));
    }
    Ok(arr.cast::<numpy::PyArray3<f32>>()?.readonly())
}

#[pymethods]
impl PyDenoiser {
    #[new]
    #[pyo3(signature = (library, device = "auto"))]
    fn new(py: Python<'_>, library: PathBuf, device: &str) -> PyResult<Self> {
        let device = match device {
            "auto" => core::DenoiseDevice::Auto,
            "cpu" => core::DenoiseDevice::Cpu,
            other => {
                return Err(PyValueError::new_err(format!(
                    "denoiser device must be auto or cpu, got {other:?}"
                )))
            }
        };
        let inner = run_detached(py, move || core::Denoiser::open(&library, device))?;
        Ok(PyDenoiser {
            inner: std::sync::Arc::new(inner),
        })
    }

    #[getter]
    fn library(&self) -> String {
        self.inner.library().display().to_string()
    }

    #[getter]
    fn version(&self) -> String {
        self.inner.version()
    }

    #[getter]
    fn device_type(&self) -> &'static str {
        self.inner.device_type()
    }

    /// What meta.json records of this denoiser.
    fn record<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        crate::convert::to_py(py, &self.inner.record())
    }

    /// Denoise a float32 (H, W, 3) colour image with its (H, W, 3) albedo and normal.
    fn denoise<'py>(
        &self,
        py: Python<'py>,
        color: &Bound<'py, PyAny>,
        albedo: &Bound<'py, PyAny>,
        normal: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, numpy::PyArray3<f32>>> {
        let (c, a, n) = (
            rgb_image(color, "color")?,
            rgb_image(albedo, "albedo")?,
            rgb_image(normal, "normal")?,
        );
        let shape = c.shape().to_vec();
        for (what, x) in [("albedo", &a), ("normal", &n)] {
            if x.shape() != shape.as_slice() {
                return Err(PyValueError::new_err(format!(
                    "{what} has shape {:?}, color {shape:?}",
                    x.shape()
                )));
            }
        }
        let (h, w) = (shape[0] as u32, shape[1] as u32);
        let (c, a, n) = (c.as_slice()?, a.as_slice()?, n.as_slice()?);
        let inner = &self.inner;
        let out = run_detached(py, move || inner.denoise(w, h, c, a, n))?;
        PyArray1::from_vec(py, out).reshape([h as usize, w as usize, 3])
    }

    fn __repr__(&self) -> String {
        format!("{:?}", self.inner)
    }
}

/// Exact IEC 61966-2-1 encoding of linear float32 values, clamped to [0, 1]; same shape.
#[pyfunction]
fn srgb_encode<'py>(
    py: Python<'py>,
    linear: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyArrayDyn<f32>>> {
    let arr = f32_array(linear, "linear")?;
    let arr: PyReadonlyArrayDyn<'py, f32> = arr.cast::<PyArrayDyn<f32>>()?.readonly();
    let shape = arr.shape().to_vec();
    let owned;
    let data = match arr.as_slice() {
        Ok(s) => s,
        Err(_) => {
            // A strided view: copy it into logical order first.
            owned = arr.as_array().iter().copied().collect::<Vec<f32>>();
            &owned
        }
    };
    let out = run_detached(py, move || Ok(core::srgb_encode_slice(data)))?;
    PyArray1::from_vec(py, out).reshape(shape)
}

/// Read an EXR as premultiplied linear RGBA float32 (H, W, 4), values as stored. With
/// `size` (width, height), a file of another size is refused from its header, before
/// anything of its size is decoded.
#[pyfunction]
#[pyo3(signature = (path, *, size = None))]
fn read_exr(
    py: Python<'_>,
    path: PathBuf,
    size: Option<(u32, u32)>,
) -> PyResult<Bound<'_, numpy::PyArray3<f32>>> {
    let frame = run_detached(py, move || core::read_exr_sized(&path, size))?;
    rgba_to_py(py, frame)
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyAccumulator>()?;
    m.add_class::<PyDenoiser>()?;
    add_functions! {
        m,
        srgb_encode, read_exr,
    }
    Ok(())
}
