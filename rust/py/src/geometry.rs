//! Bindings of the core's per-view geometry (issue 35): depth, normals, masks.
use crate::run_detached;
use blurset_core as core;
use numpy::{PyArray1, PyArrayMethods, PyUntypedArrayMethods};
use pyo3::prelude::*;
use std::path::PathBuf;

/// From a geometry render (Cycles' Depth and Normal passes) write the view's depth EXR
/// and/or normal EXR.
#[pyfunction]
#[pyo3(signature = (render, *, depth = None, normal = None))]
fn write_geometry(
    py: Python<'_>,
    render: PathBuf,
    depth: Option<PathBuf>,
    normal: Option<PathBuf>,
) -> PyResult<()> {
    run_detached(py, move || {
        core::write_geometry(&render, depth.as_deref(), normal.as_deref())
    })
}

/// A depth EXR as float32 (H, W): world units along the viewing axis, 0 where no surface.
/// With `size` (width, height), a file of another size is refused from its header,
/// before anything of its size is decoded.
#[pyfunction]
#[pyo3(signature = (path, *, size = None))]
fn read_depth(
    py: Python<'_>,
    path: PathBuf,
    size: Option<(u32, u32)>,
) -> PyResult<Bound<'_, numpy::PyArray2<f32>>> {
    let (w, h, depth) = run_detached(py, move || core::read_depth_exr_sized(&path, size))?;
    PyArray1::from_vec(py, depth).reshape([h, w])
}

/// A depth EXR as a 16-bit PNG in millimetres (0: no surface), nerfstudio's default.
#[pyfunction]
fn write_depth_millimetres(py: Python<'_>, depth_exr: PathBuf, png: PathBuf) -> PyResult<()> {
    run_detached(py, move || core::write_depth_millimetres(&depth_exr, &png))
}

/// The circle of confusion (diameter, pixels) of each depth (world units along the
/// viewing axis; 0: no surface, which gets 0) for a lens of `aperture_radius` focused at
/// `focus`, `focal_px` the focal length in pixels: meta.json's defocus levels' model.
#[pyfunction]
fn circle_of_confusion<'py>(
    py: Python<'py>,
    depth: numpy::PyReadonlyArrayDyn<'py, f32>,
    focus: f64,
    aperture_radius: f64,
    focal_px: f64,
) -> PyResult<Bound<'py, numpy::PyArrayDyn<f64>>> {
    let shape = depth.shape().to_vec();
    let out: Vec<f64> = depth
        .as_array()
        .iter()
        .map(|&z| {
            if z > 0.0 {
                core::circle_of_confusion(f64::from(z), focus, aperture_radius, focal_px)
            } else {
                0.0
            }
        })
        .collect();
    PyArray1::from_vec(py, out).reshape(shape)
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("PASSES", core::PASSES.to_vec())?;
    add_functions! {
        m,
        write_geometry, read_depth, write_depth_millimetres, circle_of_confusion,
    }
    Ok(())
}
