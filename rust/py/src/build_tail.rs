//! Binding of the build's tail (core `write_build_tail`): failures.jsonl, splits.json and
//! dataset.json over what is on disk, written by the core.
use crate::config::BuildConfig;
use blurset_core as core;
use pyo3::prelude::*;
use std::path::PathBuf;

/// (settings complete, the failures now as records, test settings, the settings left
/// out because their meta.json does not read: (name, why)).
type Tail<'py> = (usize, Bound<'py, PyAny>, usize, Vec<(String, String)>);

/// Write failures.jsonl, splits.json and dataset.json of the build at `out` made with
/// `config` (call under the build's lock); `name`, the versions, `created` (local time)
/// and `seconds` are what dataset.json says of the run.
#[pyfunction]
#[pyo3(signature = (out, config, *, name, blurset_version, python_version, created, seconds))]
#[allow(clippy::too_many_arguments)] // keyword arguments of one Python call
fn write_build_tail<'py>(
    py: Python<'py>,
    out: PathBuf,
    config: PyRef<'_, BuildConfig>,
    name: String,
    blurset_version: String,
    python_version: String,
    created: String,
    seconds: f64,
) -> PyResult<Tail<'py>> {
    let run = core::RunFacts {
        name,
        blurset_version,
        python_version,
        created,
        seconds,
    };
    let cfg = config.0.clone();
    let t = crate::run_detached(py, move || core::write_build_tail(&out, &cfg, &run))?;
    let failures = crate::convert::to_py(py, &t.failures)?;
    Ok((t.settings_complete, failures, t.test_settings, t.skipped))
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    add_functions! {
        m,
        write_build_tail,
    }
    Ok(())
}
