//! Binding of the core's render session (`Session`): the builder asks it for renders and
//! hands back the EXRs the worker wrote; every image's state stays in the core.
use crate::accumulate::PyDenoiser;
use crate::config::BuildConfig;
use crate::convert::to_py;
use crate::qa::FrameQa;
use crate::sampling::Plan;
use blurset_core as core;
use pyo3::prelude::*;
use std::path::PathBuf;

/// One setting's images, rendered phase by phase and written under its partial folder
/// (core `Session`).
#[pyclass(name = "Session", module = "blurset._core")]
pub struct Session(core::Session);

#[pymethods]
impl Session {
    /// The images of `plan` under `config` (fixed counts, or its render target), written
    /// under `partial` (whose image folders it makes), their frames' EXRs in `exr_dir`;
    /// `sharp_views` as for `Plan.renders`; `denoiser`: `--denoise oidn`'s.
    #[new]
    #[pyo3(signature = (plan, config, *, partial, exr_dir, sharp_views, denoiser = None))]
    fn new(
        plan: PyRef<'_, Plan>,
        config: PyRef<'_, BuildConfig>,
        partial: PathBuf,
        exr_dir: PathBuf,
        sharp_views: Vec<usize>,
        denoiser: Option<PyRef<'_, PyDenoiser>>,
    ) -> PyResult<Self> {
        let cfg = &config.0;
        let pin = cfg.cycles_samples();
        let renders = plan.0.renders_except(&exr_dir, &sharp_views, pin);
        let (renders, counts) = match (cfg.target(), pin) {
            (Some(rule), Some(sequence)) => {
                let background = cfg.background;
                (
                    renders,
                    core::Counts::Target {
                        rule,
                        sequence,
                        background,
                    },
                )
            }
            _ => {
                let sharp = u32::try_from(cfg.effective_sharp_samples()).unwrap_or(u32::MAX);
                (core::with_samples(renders, sharp), core::Counts::Fixed)
            }
        };
        let den = denoiser.map(|d| d.inner.clone());
        let guides = den.is_some();
        let n_views = plan.0.views.len();
        let writer = core::ImageWriter::new(&partial, cfg, n_views, &renders, den)
            .map_err(crate::error::to_pyerr)?;
        let size = cfg.resolution;
        Ok(Session(core::Session::new(
            renders, counts, size, guides, writer,
        )))
    }

    /// The renders to make next (dicts, as `Plan.renders`), after taking in the last
    /// ones; an empty list: every image is written, or the sharp images failed render QA
    /// (`failure`).
    fn next_renders<'py>(&mut self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let inner = &mut self.0;
        let renders = crate::run_detached(py, move || inner.next_renders())?;
        to_py(py, &renders)
    }

    /// The EXR of render `i` of the last `next_renders` into its image (deleted once
    /// read); an image that holds all its frames is written. `origin`: where a cropped
    /// render lies.
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

    /// Why the setting failed render QA ("render QA: view 2 is empty: …"), or None.
    #[getter]
    fn failure(&self) -> Option<String> {
        self.0.failure().map(str::to_string)
    }

    /// Render phases started so far: 1 while the sharp images render.
    #[getter]
    fn phases_started(&self) -> u32 {
        self.0.phases_started()
    }

    /// The render QA of every view's sharp image, in view order.
    fn qa(&self) -> Vec<FrameQa> {
        self.0
            .qa()
            .values()
            .map(|&q| FrameQa::judged(q, None))
            .collect()
    }

    /// Under a render target, each image's record (meta.json `views[].images`):
    /// (view, level, record dict); empty at fixed counts.
    fn records<'py>(&self, py: Python<'py>) -> PyResult<Vec<(usize, String, Bound<'py, PyAny>)>> {
        self.0
            .records()
            .iter()
            .map(|((v, l), r)| Ok((*v, l.clone(), to_py(py, r)?)))
            .collect()
    }
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<Session>()?;
    Ok(())
}
