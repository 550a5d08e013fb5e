//! Bindings of the core's noise from linear images: conversion and one core call each.
use crate::noise::{background_rgb, linear_from_py, model, rgb_from_py, rgb_to_py, value_err};
use crate::run_detached;
use blurset_core as core;
use numpy::PyReadonlyArray3;
use pyo3::prelude::*;
use std::path::PathBuf;

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
    let bg = background_rgb(background)?;
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

/// (coverage, object luma, border fraction) of a uint8 (H, W, 3) image over `background`.
#[pyfunction]
#[pyo3(signature = (image, *, background=(1.0, 1.0, 1.0)))]
fn thumbnail_qa(
    image: PyReadonlyArray3<'_, u8>,
    background: (f64, f64, f64),
) -> PyResult<(f64, f64, f64)> {
    let (w, h, data) = rgb_from_py(&image, "image")?;
    let bg = background_rgb(background)?;
    let qa = core::thumbnail_qa(w, h, &data, bg).map_err(value_err)?;
    Ok((qa.coverage, qa.object_luma, qa.border))
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    add_functions! {
        m,
        noise_scene_seed, read_linear_composited, noise_clean_from_linear, thumbnail_qa,
    }
    Ok(())
}
