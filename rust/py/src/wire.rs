//! The worker contract (blurset-core's dataset::wire): each request as the line the
//! worker reads, each reply line typed, and the contract's schemas. blurset.worker_client
//! sends what these make and acts on the replies they pass.
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

/// The JSON line of a load request: import, normalize and light the GLB at `glb` (an
/// absolute path), its vertices to `vertices_out`; ValueError for an `unlit` or
/// `light_paths` the contract lacks.
#[pyfunction]
#[pyo3(signature = (glb, vertices_out, *, unlit, light_paths))]
fn load_request(
    glb: String,
    vertices_out: String,
    unlit: &Bound<'_, PyAny>,
    light_paths: &Bound<'_, PyAny>,
) -> PyResult<String> {
    let request = wire::LoadRequest {
        glb,
        vertices_out,
        unlit: Some(from_py("unlit", unlit)?),
        light_paths: Some(from_py("light_paths", light_paths)?),
    };
    request.line().map_err(to_pyerr)
}

/// The JSON line that asks the worker to exit.
#[pyfunction]
fn quit_request() -> PyResult<String> {
    wire::Request::Quit.line().map_err(to_pyerr)
}

/// A reply the worker sent (its JSON line parsed), checked against the contract's reply
/// types and given back as sent (every field, a null kept); ValueError naming the reply
/// and the field that does not fit.
#[pyfunction]
fn worker_reply<'py>(msg: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyAny>> {
    let value: serde_json::Value = from_py("worker reply", msg)?;
    wire::Reply::read(&value).map_err(to_pyerr)?;
    Ok(msg.clone())
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
    m.add_function(wrap_pyfunction!(load_request, m)?)?;
    m.add_function(wrap_pyfunction!(quit_request, m)?)?;
    m.add_function(wrap_pyfunction!(worker_reply, m)?)?;
    m.add_function(wrap_pyfunction!(worker_schemas, m)?)?;
    Ok(())
}
