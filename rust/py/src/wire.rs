//! The worker contract (blurset-core's dataset::wire): a render request as the line the
//! worker reads, and the contract's schemas. blurset.worker_client sends what these make.
use crate::convert::{from_py, to_py};
use crate::error::to_pyerr;
use blurset_core::wire;
use blurset_core::Render;
use pyo3::prelude::*;

/// The JSON line of a render request of `frames` (the plan's renders, or a caller's
/// frames of `c2w`, `seed` and `out`): each frame typed as the core's Render and checked,
/// its EXR path made absolute; ValueError naming what is wrong.
#[pyfunction]
#[pyo3(signature = (frames, *, resolution, fov_deg, samples, exr_codec = None,
    noise_threshold = None, batch = true, crop = false, guides = false, geometry = false))]
#[allow(clippy::too_many_arguments)] // the request's fields, each a keyword
fn render_request(
    frames: &Bound<'_, PyAny>,
    resolution: u32,
    fov_deg: f64,
    samples: u32,
    exr_codec: Option<String>,
    noise_threshold: Option<f64>,
    batch: bool,
    crop: bool,
    guides: bool,
    geometry: bool,
) -> PyResult<String> {
    let frames: Vec<Render> = from_py("render frame", frames)?;
    let request = wire::RenderRequest {
        resolution,
        fov_deg,
        samples,
        frames,
        exr_codec,
        noise_threshold,
        batch: (!batch).then_some(false),
        crop: crop.then_some(true),
        guides: guides.then_some(true),
        geometry: geometry.then_some(true),
    };
    request.line().map_err(to_pyerr)
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
    m.add_function(wrap_pyfunction!(render_request, m)?)?;
    m.add_function(wrap_pyfunction!(worker_schemas, m)?)?;
    Ok(())
}
