//! What blurset writes and what a command may touch (blurset-core's dataset::outputs),
//! and the typed reading of its records (dataset::read). blurset.outputs wraps these.
use crate::error::to_pyerr;
use blurset_core as core;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pythonize::pythonize;
use std::path::PathBuf;

/// The kinds of output blurset writes into a folder of their own.
#[pyclass(
    eq,
    eq_int,
    frozen,
    from_py_object,
    name = "OutputKind",
    module = "blurset._core"
)]
#[derive(Clone, Copy, PartialEq)]
pub enum PyOutputKind {
    #[pyo3(name = "BUILD")]
    Build,
    #[pyo3(name = "NOISE")]
    Noise,
    #[pyo3(name = "NOISE_SCENE")]
    NoiseScene,
    #[pyo3(name = "EXPORT")]
    Export,
    #[pyo3(name = "STATS")]
    Stats,
}

impl From<PyOutputKind> for core::OutputKind {
    fn from(k: PyOutputKind) -> Self {
        match k {
            PyOutputKind::Build => core::OutputKind::Build,
            PyOutputKind::Noise => core::OutputKind::Noise,
            PyOutputKind::NoiseScene => core::OutputKind::NoiseScene,
            PyOutputKind::Export => core::OutputKind::Export,
            PyOutputKind::Stats => core::OutputKind::Stats,
        }
    }
}

impl From<core::OutputKind> for PyOutputKind {
    fn from(k: core::OutputKind) -> Self {
        match k {
            core::OutputKind::Build => PyOutputKind::Build,
            core::OutputKind::Noise => PyOutputKind::Noise,
            core::OutputKind::NoiseScene => PyOutputKind::NoiseScene,
            core::OutputKind::Export => PyOutputKind::Export,
            core::OutputKind::Stats => PyOutputKind::Stats,
        }
    }
}

#[pymethods]
impl PyOutputKind {
    /// How messages name the kind (`build`, `noise output`, `export` …).
    #[getter]
    fn label(&self) -> &'static str {
        core::OutputKind::from(*self).name()
    }

    /// The file name of the record that says what the folder is.
    #[getter]
    fn record(&self) -> &'static str {
        core::OutputKind::from(*self).record().file_name()
    }

    /// The lock file a writer of this kind holds in its folder.
    #[getter]
    fn lock_name(&self) -> &'static str {
        core::OutputKind::from(*self).lock_name()
    }
}

/// The kind of blurset output `dir` is, from its record; None for none.
#[pyfunction]
fn output_kind(py: Python<'_>, dir: PathBuf) -> PyResult<Option<PyOutputKind>> {
    crate::run_detached(py, || core::output_kind(&dir)).map(|k| k.map(Into::into))
}

/// `new`, `empty`, `same` or `beside`: what a command writing `kind` may do with `dir`;
/// ConfigValueError naming `option` when it may not write there.
#[pyfunction]
fn claim(
    py: Python<'_>,
    dir: PathBuf,
    kind: PyOutputKind,
    option: String,
) -> PyResult<&'static str> {
    let c = crate::run_detached(py, || core::claim(&dir, kind.into(), &option))?;
    Ok(match c {
        core::Claim::New => "new",
        core::Claim::Empty => "empty",
        core::Claim::Same => "same",
        core::Claim::Beside => "beside",
    })
}

/// The entries (relative paths) an output of `kind` in `dir` wrote.
#[pyfunction]
fn owned_entries(py: Python<'_>, dir: PathBuf, kind: PyOutputKind) -> PyResult<Vec<String>> {
    crate::run_detached(py, || core::owned_entries(&dir, kind.into()))
}

/// The entries inside the owned entry `rel` of the output in `dir` that no command of
/// `kind` writes (paths relative to `dir`).
#[pyfunction]
fn not_written(
    py: Python<'_>,
    dir: PathBuf,
    kind: PyOutputKind,
    rel: String,
) -> PyResult<Vec<String>> {
    crate::run_detached(py, || core::not_written(&dir, kind.into(), &rel))
}

/// The first entry on the way to one of `rels` in `dir` that is a link, or None.
#[pyfunction]
fn linked_entry(dir: PathBuf, rels: Vec<String>) -> Option<String> {
    core::linked_entry(&dir, &rels)
}

/// Remove what `owned_entries` lists; returns it. An entry holding a file the command
/// did not write is refused by name (InputError) before anything is removed.
#[pyfunction]
fn remove_owned(py: Python<'_>, dir: PathBuf, kind: PyOutputKind) -> PyResult<Vec<String>> {
    crate::run_detached(py, || core::remove_owned(&dir, kind.into()))
}

/// A build as its readers see it.
#[pyclass(frozen, get_all, name = "BuildState", module = "blurset._core")]
pub struct PyBuildState {
    /// Complete setting directory names, sorted.
    complete: Vec<String>,
    /// Why the build is provisional; empty when it is finished.
    provisional: Vec<String>,
}

/// Whether `out` is a finished build, and its complete settings.
#[pyfunction]
fn build_state(py: Python<'_>, out: PathBuf) -> PyResult<PyBuildState> {
    let s = crate::run_detached(py, || core::build_state(&out))?;
    Ok(PyBuildState {
        complete: s.complete,
        provisional: s.provisional,
    })
}

/// (setting, source path, the source's id now) of complete settings whose source file
/// now has another id; `current` holds (uid, source path) of every object of the build.
#[pyfunction]
fn superseded_settings(
    py: Python<'_>,
    out: PathBuf,
    current: Vec<(String, String)>,
) -> PyResult<Vec<(String, String, String)>> {
    crate::run_detached(py, || core::superseded_settings(&out, &current))
}

/// `text` with its last line marking it as written by `command` (and its checksum).
#[pyfunction]
fn mark_text(text: &str, command: &str) -> String {
    core::mark_text(text, command)
}

/// `absent`, `ours`, `edited` or `foreign`: who the text file at `path` belongs to.
#[pyfunction]
fn text_owner(path: PathBuf, command: &str) -> PyResult<&'static str> {
    Ok(match core::text_owner(&path, command).map_err(to_pyerr)? {
        core::TextOwner::Absent => "absent",
        core::TextOwner::Ours => "ours",
        core::TextOwner::Edited => "edited",
        core::TextOwner::Foreign => "foreign",
    })
}

/// A record blurset wrote (meta.json, splits.json, dataset.json, noise_dataset.json,
/// noise.json, noise_scene.json, export.json, stats.json), checked against its shape:
/// the parsed JSON. `record` names the record when the file is named otherwise.
/// InputError naming the file and the field when the shape is wrong.
#[pyfunction]
#[pyo3(signature = (path, record = None))]
fn read_record<'py>(
    py: Python<'py>,
    path: PathBuf,
    record: Option<&str>,
) -> PyResult<Bound<'py, PyAny>> {
    let name = match record {
        Some(r) => r.to_string(),
        None => path
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default(),
    };
    let kind = core::Record::of_name(&name)
        .ok_or_else(|| PyValueError::new_err(format!("not a blurset record: {name:?}")))?;
    let value = crate::run_detached(py, || core::read_record(&path, kind))?;
    pythonize(py, &value).map_err(|e| PyValueError::new_err(e.to_string()))
}

fn record_of(name: &str) -> PyResult<core::Record> {
    core::Record::of_name(name)
        .ok_or_else(|| PyValueError::new_err(format!("not a blurset record: {name:?}")))
}

/// Write a record assembled in Python (`record` its file name: dataset.json,
/// noise_dataset.json, noise_scene.json, export.json, noise.json) through the core's
/// type: a field it does not know, a missing one or a wrong type is a ValueError before
/// anything is written.
#[pyfunction]
fn write_record(
    py: Python<'_>,
    path: PathBuf,
    record: &str,
    value: &Bound<'_, PyAny>,
) -> PyResult<()> {
    let kind = record_of(record)?;
    let value: serde_json::Value = crate::convert::from_py(record, value)?;
    crate::run_detached(py, || core::write_record(&path, kind, value))
}

/// (schema file name, JSON Schema) of every record blurset writes.
#[pyfunction]
fn record_schemas(py: Python<'_>) -> PyResult<Vec<(String, Bound<'_, PyAny>)>> {
    core::SCHEMA_RECORDS
        .iter()
        .map(|r| {
            let s = pythonize(py, &core::schema(*r))
                .map_err(|e| PyValueError::new_err(e.to_string()))?;
            Ok((core::schema_file(*r), s))
        })
        .collect()
}

/// (type name, JSON Schema) of every value the bindings hand across as a dict.
#[pyfunction]
fn value_schemas(py: Python<'_>) -> PyResult<Vec<(&'static str, Bound<'_, PyAny>)>> {
    core::value_schemas()
        .into_iter()
        .map(|(name, s)| {
            let s = pythonize(py, &s).map_err(|e| PyValueError::new_err(e.to_string()))?;
            Ok((name, s))
        })
        .collect()
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyOutputKind>()?;
    m.add_class::<PyBuildState>()?;
    add_functions! {
        m,
        write_record, value_schemas, record_schemas, output_kind, claim, owned_entries,
        not_written, linked_entry, remove_owned, build_state, superseded_settings, mark_text,
        text_owner, read_record,
    }
    Ok(())
}
