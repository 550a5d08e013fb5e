//! Serde values to and from Python objects, for every binding that hands a record or a
//! config across (one conversion, one error wording).
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pythonize::{depythonize, pythonize};

pub(crate) fn to_py<'py, T: serde::Serialize>(
    py: Python<'py>,
    value: &T,
) -> PyResult<Bound<'py, PyAny>> {
    pythonize(py, value).map_err(|e| PyValueError::new_err(e.to_string()))
}

pub(crate) fn from_py<T: serde::de::DeserializeOwned>(
    what: &str,
    obj: &Bound<'_, PyAny>,
) -> PyResult<T> {
    depythonize(obj).map_err(|e| PyValueError::new_err(format!("{what}: {e}")))
}
