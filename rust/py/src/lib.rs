//! pyo3 bindings of blurset-core: argument conversion and one core call each.
//! If a loop over pixels or poses appears here, it belongs in blurset-core.
use pyo3::prelude::*;

/// Add each named `#[pyfunction]` to the module: a module's `register` lists its
/// functions once, by name (braces: rustfmt leaves the list as written).
macro_rules! add_functions {
    ($m:expr, $($f:ident),+ $(,)?) => {{
        $($m.add_function(wrap_pyfunction!($f, $m)?)?;)+
    }};
}

mod accumulate;
mod build_tail;
mod config;
mod convert;
mod error;
mod failures;
mod geometry;
mod layout;
mod llff;
mod noise;
mod noise_linear;
mod noise_plan;
mod outputs;
mod publish;
mod qa;
mod sampling;
mod session;
mod stats;
mod tradeoff;
mod wire;

/// Run long core work without the GIL, so Python threads (progress bars, Ray) go on.
pub(crate) fn run_detached<T, F>(py: Python<'_>, f: F) -> PyResult<T>
where
    T: Send,
    F: Send + FnOnce() -> blurset_core::Result<T>,
{
    py.detach(f).map_err(error::to_pyerr)
}

#[pymodule(gil_used = false)]
fn _core(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    error::register(m)?;
    config::register(m)?;
    failures::register(m)?;
    layout::register(m)?;
    llff::register(m)?;
    sampling::register(m)?;
    accumulate::register(m)?;
    build_tail::register(m)?;
    geometry::register(m)?;
    noise::register(m)?;
    noise_linear::register(m)?;
    noise_plan::register(m)?;
    outputs::register(m)?;
    publish::register(m)?;
    qa::register(m)?;
    tradeoff::register(m)?;
    stats::register(m)?;
    session::register(m)?;
    wire::register(m)?;
    Ok(())
}
