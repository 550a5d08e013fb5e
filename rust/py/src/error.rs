//! Core errors → Python exceptions. Guide: a new core variant gets one arm here.
use blurset_core::Error;
use pyo3::exceptions::{PyFileNotFoundError, PyPermissionError, PyValueError};
use pyo3::prelude::*;

pyo3::create_exception!(_core, BlursetError, pyo3::exceptions::PyException);
pyo3::create_exception!(_core, PoseFormatError, BlursetError);
pyo3::create_exception!(_core, ImageError, BlursetError);
pyo3::create_exception!(
    _core,
    InputError,
    BlursetError,
    "Bad input data (missing file, wrong shape, mismatched sizes); the message names the file."
);

pyo3::create_exception!(
    _core,
    ConfigValueError,
    PyValueError,
    "An option out of its range; `option` names it, `detail` holds the value and the range."
);

/// Attach fields to an exception, so callers read `e.path` / `e.reason` instead of
/// parsing the message.
fn with_fields(err: PyErr, fields: &[(&str, String)]) -> PyErr {
    Python::attach(|py| {
        let v = err.value(py);
        for (k, val) in fields {
            if v.setattr(*k, val.as_str()).is_err() {
                return err.clone_ref(py);
            }
        }
        err.clone_ref(py)
    })
}

pub(crate) fn to_pyerr(e: Error) -> PyErr {
    let msg = e.to_string();
    match e {
        Error::Io { source, path, what } => {
            let err = match source.kind() {
                std::io::ErrorKind::NotFound => PyFileNotFoundError::new_err(msg),
                std::io::ErrorKind::PermissionDenied => PyPermissionError::new_err(msg),
                _ => BlursetError::new_err(msg),
            };
            let reason = format!("{what}: {source}");
            with_fields(
                err,
                &[("reason", reason), ("path", path.display().to_string())],
            )
        }
        Error::PoseFormat { reason, path } => with_fields(
            PoseFormatError::new_err(msg),
            &[("reason", reason), ("path", path.display().to_string())],
        ),
        Error::Image { reason, path } => with_fields(
            ImageError::new_err(msg),
            &[("reason", reason), ("path", path.display().to_string())],
        ),
        Error::Shape(_) | Error::Value(_) => PyValueError::new_err(msg),
        Error::Input { reason, path } => with_fields(
            InputError::new_err(msg),
            &[("reason", reason), ("path", path.display().to_string())],
        ),
        Error::Config { option, detail } => with_fields(
            ConfigValueError::new_err(msg),
            &[("option", option), ("detail", detail)],
        ),
    }
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add("BlursetError", py.get_type::<BlursetError>())?;
    m.add("PoseFormatError", py.get_type::<PoseFormatError>())?;
    m.add("ImageError", py.get_type::<ImageError>())?;
    m.add("InputError", py.get_type::<InputError>())?;
    m.add("ConfigValueError", py.get_type::<ConfigValueError>())?;
    Ok(())
}
