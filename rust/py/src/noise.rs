//! Bindings of the core's noise kernel and image files: conversion and
//! one core call each.
use crate::run_detached;
use blurset_core::{
    self as core, Gamma, Image, LinearRgb, NoiseLevels, NoiseModel, Samples, WhiteBalance,
};
use numpy::{
    PyArray1, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray3, PyReadonlyArrayDyn,
    PyUntypedArrayMethods,
};
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::IntoPyObjectExt;
use std::path::PathBuf;

type Levels = (f64, f64, f64, f64);

fn levels_to_py(l: NoiseLevels) -> Levels {
    (l.log10_read, l.read_step, l.log10_shot, l.shot_step)
}

pub(crate) fn value_err(e: blurset_core::Error) -> PyErr {
    PyValueError::new_err(e.to_string())
}

/// A validated noise model from the bindings' arguments.
pub(crate) fn model(
    sigma_read: f64,
    sigma_shot: f64,
    gamma: &str,
    white_balance: Option<(f64, f64)>,
    white_level: f64,
) -> PyResult<NoiseModel> {
    let m = NoiseModel {
        sigma_read,
        sigma_shot,
        gamma: Gamma::parse(gamma).map_err(value_err)?,
        white_balance: white_balance.map(|(red, blue)| WhiteBalance { red, blue }),
        white_level,
    };
    m.validate().map_err(value_err)?;
    Ok(m)
}

/// The variants of a scene from (out_dir, sigma_read, sigma_shot, key) per gain.
pub(crate) fn variants_from_py(
    variants: Vec<(PathBuf, f64, f64, u64)>,
    gamma: &str,
    white_balance: Option<(f64, f64)>,
    white_level: f64,
) -> PyResult<Vec<core::Variant>> {
    variants
        .into_iter()
        .map(|(out_dir, sr, ss, key)| {
            Ok(core::Variant {
                out_dir,
                model: model(sr, ss, gamma, white_balance, white_level)?,
                key,
                raw: None,
            })
        })
        .collect()
}

/// An (H, W) or (H, W, C) uint8 / uint16 array as a core image (copied).
fn image_from_py(obj: &Bound<'_, PyAny>) -> PyResult<Image> {
    fn layout(shape: &[usize]) -> PyResult<(u32, u32, usize)> {
        match shape {
            [h, w] => Ok((*w as u32, *h as u32, 1)),
            [h, w, c] if (1..=4).contains(c) => Ok((*w as u32, *h as u32, *c)),
            s => Err(PyValueError::new_err(format!(
                "image must have shape (H, W) or (H, W, C) with C in 1..4, got {s:?}"
            ))),
        }
    }
    let (w, h, c, samples) = if let Ok(a) = obj.extract::<PyReadonlyArrayDyn<'_, u8>>() {
        let (w, h, c) = layout(a.shape())?;
        (
            w,
            h,
            c,
            Samples::U8(match a.as_slice() {
                Ok(s) => s.to_vec(),
                Err(_) => a.as_array().iter().copied().collect(),
            }),
        )
    } else if let Ok(a) = obj.extract::<PyReadonlyArrayDyn<'_, u16>>() {
        let (w, h, c) = layout(a.shape())?;
        (
            w,
            h,
            c,
            Samples::U16(match a.as_slice() {
                Ok(s) => s.to_vec(),
                Err(_) => a.as_array().iter().copied().collect(),
            }),
        )
    } else {
        return Err(PyTypeError::new_err(
            "image must be a numpy array of dtype uint8 or uint16 (codes), or float32 of \
             shape (H, W, 3) (linear light)",
        ));
    };
    Image::new(w, h, c, samples).map_err(value_err)
}

fn image_to_py(py: Python<'_>, img: Image) -> PyResult<Py<PyAny>> {
    let shape = [img.height as usize, img.width as usize, img.channels];
    match img.samples {
        Samples::U8(v) => PyArray1::from_vec(py, v).reshape(shape)?.into_py_any(py),
        Samples::U16(v) => PyArray1::from_vec(py, v).reshape(shape)?.into_py_any(py),
    }
}

pub(crate) fn background_rgb(bg: (f64, f64, f64)) -> PyResult<[f64; 3]> {
    let b = [bg.0, bg.1, bg.2];
    if b.iter().any(|v| !v.is_finite()) {
        return Err(PyValueError::new_err(format!(
            "background must be finite linear RGB, got {bg:?}"
        )));
    }
    Ok(b)
}

/// (width, height, pixels) of an (H, W, 3) array (copied); `what` names it in the error.
pub(crate) fn rgb_from_py<T: numpy::Element + Copy>(
    image: &PyReadonlyArray3<'_, T>,
    what: &str,
) -> PyResult<(u32, u32, Vec<T>)> {
    let shape = image.shape();
    if shape[2] != 3 {
        return Err(PyValueError::new_err(format!(
            "{what} must have shape (H, W, 3), got {shape:?}"
        )));
    }
    let data = match image.as_slice() {
        Ok(s) => s.to_vec(),
        Err(_) => image.as_array().iter().copied().collect(),
    };
    Ok((shape[1] as u32, shape[0] as u32, data))
}

/// A float32 (H, W, 3) array as a core linear image (copied).
pub(crate) fn linear_from_py(image: PyReadonlyArray3<'_, f32>) -> PyResult<LinearRgb> {
    let (w, h, data) = rgb_from_py(&image, "linear image")?;
    LinearRgb::new(w, h, data).map_err(value_err)
}

pub(crate) fn rgb_to_py(
    py: Python<'_>,
    width: u32,
    height: u32,
    v: Vec<f32>,
) -> PyResult<Py<PyAny>> {
    PyArray1::from_vec(py, v)
        .reshape([height as usize, width as usize, 3])?
        .into_py_any(py)
}

/// One noisy frame from a linear float32 (H, W, 3) image (`noise_image` on linear light):
/// (linear float32 (H, W, 3), processed uint8 (H, W, 3)).
pub(crate) fn noise_frame_linear(
    py: Python<'_>,
    image: PyReadonlyArray3<'_, f32>,
    m: &core::NoiseModel,
    key: u64,
    stream: u64,
) -> PyResult<(Py<PyAny>, Py<PyAny>)> {
    let img = linear_from_py(image)?;
    let noisy = run_detached(py, || core::add_noise_linear(&img, m, key, stream))?;
    Ok((
        rgb_to_py(py, img.width, img.height, noisy.linear)?,
        image_to_py(py, noisy.processed)?,
    ))
}

/// (log10 σ_read(1), read step, log10 σ_shot(1), shot step) of blurset's default table.
#[pyfunction]
fn noise_default_levels() -> Levels {
    levels_to_py(NoiseLevels::DEFAULT)
}

/// NAN's levels from the `sig_read` and `sig_shot` arrays of KPN's test file.
#[pyfunction]
fn noise_levels_from_kpn(
    sig_read: PyReadonlyArray1<'_, f64>,
    sig_shot: PyReadonlyArray1<'_, f64>,
) -> PyResult<Levels> {
    let r: Vec<f64> = sig_read.as_array().to_vec();
    let s: Vec<f64> = sig_shot.as_array().to_vec();
    NoiseLevels::from_kpn(&r, &s)
        .map(levels_to_py)
        .map_err(value_err)
}

/// (σ_read, σ_shot) at `gain` under `levels`.
#[pyfunction]
fn noise_sigmas(gain: f64, levels: Levels) -> PyResult<(f64, f64)> {
    let l = NoiseLevels {
        log10_read: levels.0,
        read_step: levels.1,
        log10_shot: levels.2,
        shot_step: levels.3,
    };
    l.sigmas(gain).map_err(value_err)
}

/// The scene's (red, blue) white-balance gains drawn from `seed`.
#[pyfunction]
fn noise_white_balance(seed: u64) -> (f64, f64) {
    let wb = core::sample_white_balance(seed);
    (wb.red, wb.blue)
}

/// The Philox key of one gain of one seed.
#[pyfunction]
fn noise_key(seed: u64, gain: f64) -> u64 {
    core::noise_key(seed, gain)
}

/// (width, height, channels, bits per sample) from an image file's header.
#[pyfunction]
fn image_info(py: Python<'_>, path: PathBuf) -> PyResult<(u32, u32, usize, u32)> {
    run_detached(py, || core::image_info(&path))
}

/// Decode an image file to an (H, W, C) uint8 or uint16 array.
#[pyfunction]
fn read_image(py: Python<'_>, path: PathBuf) -> PyResult<Py<PyAny>> {
    let img = run_detached(py, || core::read_image(&path))?;
    image_to_py(py, img)
}

/// One noisy frame of one view: (linear float32 (H, W, 3|4), processed array of the
/// input's dtype and shape with alpha copied). A float32 (H, W, 3) image is composited
/// linear light (a build's EXR): the same draws, processed to uint8.
#[pyfunction]
#[pyo3(signature = (image, *, sigma_read, sigma_shot, key, view=0, frame=0, gamma="2.2", white_balance=None, white_level=1.0))]
#[allow(clippy::too_many_arguments)]
fn noise_image(
    py: Python<'_>,
    image: &Bound<'_, PyAny>,
    sigma_read: f64,
    sigma_shot: f64,
    key: u64,
    view: u32,
    frame: u32,
    gamma: &str,
    white_balance: Option<(f64, f64)>,
    white_level: f64,
) -> PyResult<(Py<PyAny>, Py<PyAny>)> {
    let m = model(sigma_read, sigma_shot, gamma, white_balance, white_level)?;
    let stream = core::noise_stream_id(view, frame);
    if let Ok(linear) = image.extract::<PyReadonlyArray3<'_, f32>>() {
        return noise_frame_linear(py, linear, &m, key, stream);
    }
    let img = image_from_py(image)?;
    let noisy = run_detached(py, || core::add_noise(&img, &m, key, stream))?;
    let (h, w) = (img.height as usize, img.width as usize);
    let linear = PyArray1::from_vec(py, noisy.linear)
        .reshape([h, w, noisy.linear_channels])?
        .into_py_any(py)?;
    Ok((linear, image_to_py(py, noisy.processed)?))
}

/// The clean linear values the noise is added to: float32 (H, W, 1|3).
#[pyfunction]
#[pyo3(signature = (image, *, gamma="2.2", white_balance=None, white_level=1.0))]
fn noise_clean_linear(
    py: Python<'_>,
    image: &Bound<'_, PyAny>,
    gamma: &str,
    white_balance: Option<(f64, f64)>,
    white_level: f64,
) -> PyResult<Py<PyAny>> {
    let img = image_from_py(image)?;
    let m = model(0.0, 0.0, gamma, white_balance, white_level)?;
    let y = run_detached(py, || core::clean_linear(&img, &m))?;
    PyArray1::from_vec(py, y)
        .reshape([
            img.height as usize,
            img.width as usize,
            img.color_channels(),
        ])?
        .into_py_any(py)
}

/// Write every variant of a scene: `variants` holds (out_dir, sigma_read, sigma_shot,
/// key) per gain; `names` the `len(sources) * frames` output stems, view-major;
/// `downsample` the factors of `images_<f>/` copies; `clean_views` the views left clean.
/// With a `background` the sources are a build's linear EXRs, composited over it.
#[pyfunction]
#[pyo3(signature = (sources, names, variants, *, frames=1, gamma="2.2", white_balance=None, white_level=1.0, background=None, downsample=Vec::new(), clean_views=Vec::new()))]
#[allow(clippy::too_many_arguments)]
fn noise_write_variants(
    py: Python<'_>,
    sources: Vec<PathBuf>,
    names: Vec<String>,
    variants: Vec<(PathBuf, f64, f64, u64)>,
    frames: u32,
    gamma: &str,
    white_balance: Option<(f64, f64)>,
    white_level: f64,
    background: Option<(f64, f64, f64)>,
    downsample: Vec<u32>,
    clean_views: Vec<usize>,
) -> PyResult<()> {
    let bg = background.map(background_rgb).transpose()?;
    let variants = variants_from_py(variants, gamma, white_balance, white_level)?;
    let opts = core::VariantOptions {
        downsample,
        clean_views: clean_views.into_iter().collect(),
        ..Default::default()
    };
    run_detached(py, || match bg {
        Some(bg) => {
            core::write_variants_linear(&sources, &names, frames, &variants, bg, None, &opts)
        }
        None => core::write_variants(&sources, &names, frames, &variants, &opts),
    })
}

/// One noisy frame of a camera model (`unprocess`, `eld:<camera>`) from a linear
/// float32 (H, W, 3) image: (linear float32 (H, W, 3), processed uint8 (H, W, 3), the
/// model's noise.json `raw_model` as JSON text). `seed` is the scene's (unprocess draws
/// its colour matrix and noise levels from it), `key` the gain's Philox key.
#[pyfunction]
#[pyo3(signature = (image, *, model, gain, seed, key, view=0, frame=0, gamma="srgb", white_balance=None, white_level=1.0, clean=false))]
#[allow(clippy::too_many_arguments)]
fn noise_image_model(
    py: Python<'_>,
    image: PyReadonlyArray3<'_, f32>,
    model: &str,
    gain: f64,
    seed: u64,
    key: u64,
    view: u32,
    frame: u32,
    gamma: &str,
    white_balance: Option<(f64, f64)>,
    white_level: f64,
    clean: bool,
) -> PyResult<(Py<PyAny>, Py<PyAny>, String)> {
    let kind = core::ModelKind::parse(model).map_err(value_err)?;
    let display = core::RawDisplay {
        gamma: Gamma::parse(gamma).map_err(value_err)?,
        white_balance: white_balance.map(|(red, blue)| WhiteBalance { red, blue }),
        white_level,
    };
    let raw = core::RawModel::of(kind, seed, gain, display)
        .map_err(value_err)?
        .ok_or_else(|| PyValueError::new_err("model paper: use noise_image"))?;
    let raw = if clean { raw.clean() } else { raw };
    let img = linear_from_py(image)?;
    let stream = core::noise_stream_id(view, frame);
    let noisy = run_detached(py, || core::raw_frame(&img, &raw, key, stream))?;
    Ok((
        rgb_to_py(py, img.width, img.height, noisy.linear)?,
        image_to_py(py, noisy.processed)?,
        raw.record.to_string(),
    ))
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    add_functions! {
        m,
        noise_image_model, noise_default_levels, noise_levels_from_kpn, noise_sigmas,
        noise_white_balance, noise_key, image_info, read_image, noise_image, noise_clean_linear,
        noise_write_variants,
    }
    Ok(())
}
