//! Bindings of the core's noise from linear images: conversion and one core call each.
use crate::noise::{model, value_err, variants_from_py};
use crate::run_detached;
use blurset_core::{self as core, LinearRgb, Samples};
use numpy::{PyArray1, PyArrayMethods, PyReadonlyArray3, PyUntypedArrayMethods};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::IntoPyObjectExt;
use std::path::PathBuf;

fn background(bg: (f64, f64, f64)) -> PyResult<[f64; 3]> {
    let b = [bg.0, bg.1, bg.2];
    if b.iter().any(|v| !v.is_finite()) {
        return Err(PyValueError::new_err(format!(
            "background must be finite linear RGB, got {bg:?}"
        )));
    }
    Ok(b)
}

/// A float32 (H, W, 3) array as a core linear image (copied).
fn linear_from_py(image: PyReadonlyArray3<'_, f32>) -> PyResult<LinearRgb> {
    let shape = image.shape();
    if shape[2] != 3 {
        return Err(PyValueError::new_err(format!(
            "linear image must have shape (H, W, 3), got {shape:?}"
        )));
    }
    let data = match image.as_slice() {
        Ok(s) => s.to_vec(),
        Err(_) => image.as_array().iter().copied().collect(),
    };
    LinearRgb::new(shape[1] as u32, shape[0] as u32, data).map_err(value_err)
}

fn rgb_to_py(py: Python<'_>, width: u32, height: u32, v: Vec<f32>) -> PyResult<Py<PyAny>> {
    PyArray1::from_vec(py, v)
        .reshape([height as usize, width as usize, 3])?
        .into_py_any(py)
}

/// The noise seed of one level of one setting of a build.
#[pyfunction]
fn noise_scene_seed(seed: u64, setting: &str, level: &str) -> u64 {
    core::scene_seed(seed, setting, level)
}

/// A build's linear EXR composited over `background`: float32 (H, W, 3), unclipped.
#[pyfunction]
#[pyo3(signature = (path, *, background=(1.0, 1.0, 1.0)))]
fn read_linear_composited(
    py: Python<'_>,
    path: PathBuf,
    background: (f64, f64, f64),
) -> PyResult<Py<PyAny>> {
    let bg = self::background(background)?;
    let img = run_detached(py, || core::read_linear(&path, bg))?;
    rgb_to_py(py, img.width, img.height, img.rgb)
}

/// The clean values `y` the linear path adds noise to: float32 (H, W, 3).
#[pyfunction]
#[pyo3(signature = (image, *, white_balance=None, white_level=1.0))]
fn noise_clean_from_linear(
    py: Python<'_>,
    image: PyReadonlyArray3<'_, f32>,
    white_balance: Option<(f64, f64)>,
    white_level: f64,
) -> PyResult<Py<PyAny>> {
    let img = linear_from_py(image)?;
    let m = model(0.0, 0.0, "2.2", white_balance, white_level)?;
    let y = run_detached(py, || core::clean_from_linear(&img, &m))?;
    rgb_to_py(py, img.width, img.height, y)
}

/// One noisy frame from a linear float32 (H, W, 3) image: (linear float32 (H, W, 3),
/// processed uint8 (H, W, 3)); the draws of `noise_image` for the same key/view/frame.
#[pyfunction]
#[pyo3(signature = (image, *, sigma_read, sigma_shot, key, view=0, frame=0, gamma="2.2", white_balance=None, white_level=1.0))]
#[allow(clippy::too_many_arguments)]
fn noise_image_linear(
    py: Python<'_>,
    image: PyReadonlyArray3<'_, f32>,
    sigma_read: f64,
    sigma_shot: f64,
    key: u64,
    view: u32,
    frame: u32,
    gamma: &str,
    white_balance: Option<(f64, f64)>,
    white_level: f64,
) -> PyResult<(Py<PyAny>, Py<PyAny>)> {
    let img = linear_from_py(image)?;
    let m = model(sigma_read, sigma_shot, gamma, white_balance, white_level)?;
    let stream = core::noise_stream_id(view, frame);
    let noisy = run_detached(py, || core::add_noise_linear(&img, &m, key, stream))?;
    let Samples::U8(codes) = noisy.processed.samples else {
        return Err(PyValueError::new_err("processed image is not 8-bit"));
    };
    let (w, h) = (img.width as usize, img.height as usize);
    let processed = PyArray1::from_vec(py, codes)
        .reshape([h, w, 3])?
        .into_py_any(py)?;
    Ok((
        rgb_to_py(py, img.width, img.height, noisy.linear)?,
        processed,
    ))
}

/// Write every variant from linear EXRs: `variants` holds (out_dir, sigma_read,
/// sigma_shot, key) per gain; `names` the `len(sources) * frames` stems, view-major.
#[pyfunction]
#[pyo3(signature = (sources, names, variants, *, frames=1, gamma="2.2", white_balance=None, white_level=1.0, background=(1.0, 1.0, 1.0), downsample=Vec::new(), clean_views=Vec::new()))]
#[allow(clippy::too_many_arguments)]
fn noise_write_variants_linear(
    py: Python<'_>,
    sources: Vec<PathBuf>,
    names: Vec<String>,
    variants: Vec<(PathBuf, f64, f64, u64)>,
    frames: u32,
    gamma: &str,
    white_balance: Option<(f64, f64)>,
    white_level: f64,
    background: (f64, f64, f64),
    downsample: Vec<u32>,
    clean_views: Vec<usize>,
) -> PyResult<()> {
    let bg = self::background(background)?;
    let variants = variants_from_py(variants, gamma, white_balance, white_level)?;
    let opts = core::VariantOptions {
        downsample,
        clean_views: clean_views.into_iter().collect(),
    };
    run_detached(py, || {
        core::write_variants_linear(&sources, &names, frames, &variants, bg, &opts)
    })
}

/// (coverage, object luma, border fraction) of a uint8 (H, W, 3) image over `background`.
#[pyfunction]
#[pyo3(signature = (image, *, background=(1.0, 1.0, 1.0)))]
fn thumbnail_qa(
    image: PyReadonlyArray3<'_, u8>,
    background: (f64, f64, f64),
) -> PyResult<(f64, f64, f64)> {
    let shape = image.shape();
    if shape[2] != 3 {
        return Err(PyValueError::new_err(format!(
            "image must have shape (H, W, 3), got {shape:?}"
        )));
    }
    let data = match image.as_slice() {
        Ok(s) => s.to_vec(),
        Err(_) => image.as_array().iter().copied().collect(),
    };
    let bg = self::background(background)?;
    let qa = core::thumbnail_qa(shape[1] as u32, shape[0] as u32, &data, bg).map_err(value_err)?;
    Ok((qa.coverage, qa.object_luma, qa.border))
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(noise_scene_seed, m)?)?;
    m.add_function(wrap_pyfunction!(read_linear_composited, m)?)?;
    m.add_function(wrap_pyfunction!(noise_clean_from_linear, m)?)?;
    m.add_function(wrap_pyfunction!(noise_image_linear, m)?)?;
    m.add_function(wrap_pyfunction!(noise_write_variants_linear, m)?)?;
    m.add_function(wrap_pyfunction!(thumbnail_qa, m)?)?;
    Ok(())
}
