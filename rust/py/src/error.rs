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

pub(crate) fn to_pyerr(e: Error) -> PyErr {
    let msg = e.to_string();
    match e {
        Error::Io { source, .. } => match source.kind() {
            std::io::ErrorKind::NotFound => PyFileNotFoundError::new_err(msg),
            std::io::ErrorKind::PermissionDenied => PyPermissionError::new_err(msg),
            _ => BlursetError::new_err(msg),
        },
        Error::PoseFormat { .. } => PoseFormatError::new_err(msg),
        Error::Image { .. } => ImageError::new_err(msg),
        Error::Shape(_) | Error::Value(_) => PyValueError::new_err(msg),
        Error::Input { .. } => InputError::new_err(msg),
        Error::Config { option, detail } => Python::attach(|py| {
            let err = ConfigValueError::new_err(msg);
            let v = err.value(py);
            let set = v.setattr("option", option).and(v.setattr("detail", detail));
            set.err().unwrap_or(err)
        }),
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
