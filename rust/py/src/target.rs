//! Binding of the core's target loop (`TargetImages`): the builder asks it for renders,
//! hands it the EXRs the worker wrote, and takes each finished image as an Accumulator.
use crate::accumulate::PyAccumulator;
use crate::config::BuildConfig;
use crate::convert::to_py;
use crate::sampling::Plan;
use blurset_core as core;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use std::path::PathBuf;

/// The images of one render phase of a setting, rendered to the config's target: each
/// image's two halves and its rounds stay in the core (core `TargetImages`).
#[pyclass(name = "TargetImages", module = "blurset._core")]
pub struct TargetImages(core::TargetImages);

#[pymethods]
impl TargetImages {
    /// The images `keys` ((view, level), in render order) of `plan`, their EXRs in
    /// `exr_dir`; `sharp_views` as for `Plan.renders`.
    #[new]
    #[pyo3(signature = (plan, config, keys, *, exr_dir, sharp_views))]
    fn new(
        plan: PyRef<'_, Plan>,
        config: PyRef<'_, BuildConfig>,
        keys: Vec<(usize, String)>,
        exr_dir: PathBuf,
        sharp_views: Vec<usize>,
    ) -> PyResult<Self> {
        let cfg = &config.0;
        let (Some(rule), Some(pin)) = (cfg.target(), cfg.cycles_samples()) else {
            return Err(PyValueError::new_err("the config has no target_psnr"));
        };
        let base = plan.0.renders_except(&exr_dir, &sharp_views, Some(pin));
        let size = (cfg.resolution, cfg.resolution);
        core::TargetImages::new(rule, base, &keys, size, cfg.background, pin)
            .map(TargetImages)
            .map_err(crate::error::to_pyerr)
    }

    /// The renders of the next round of every image in flight (dicts, as `Plan.renders`),
    /// after estimating the round just rendered; an empty list: every image is done.
    fn next_renders<'py>(&mut self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let inner = &mut self.0;
        let renders = crate::run_detached(py, move || inner.next_renders())?;
        to_py(py, &renders)
    }

    /// The EXR of render `i` of the last `next_renders` into its image's half; the file
    /// is deleted once read. `origin`: where a cropped render lies.
    #[pyo3(signature = (i, path, origin = None))]
    fn add_exr(
        &mut self,
        py: Python<'_>,
        i: usize,
        path: PathBuf,
        origin: Option<(u32, u32)>,
    ) -> PyResult<()> {
        let inner = &mut self.0;
        crate::run_detached(py, move || inner.add_exr(i, &path, origin))
    }

    /// The images done since the last call: (view, level, the mean of both halves).
    fn take_finished(&mut self) -> Vec<(usize, String, PyAccumulator)> {
        self.0
            .take_finished()
            .into_iter()
            .map(|f| (f.key.0, f.key.1, PyAccumulator::from(f.image)))
            .collect()
    }

    /// The record (meta.json `views[].images`) of every image done so far:
    /// (view, level, record dict).
    fn records<'py>(&self, py: Python<'py>) -> PyResult<Vec<(usize, String, Bound<'py, PyAny>)>> {
        self.0
            .records()
            .iter()
            .map(|((v, l), r)| Ok((*v, l.clone(), to_py(py, r)?)))
            .collect()
    }
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<TargetImages>()?;
    Ok(())
}
