//! Bindings of the core's noise plan: the plan of a run, its units and their gains as
//! frozen classes, and a unit's two writers (GIL released).
use crate::config::NoiseConfig;
use crate::run_detached;
use blurset_core as core;
use pyo3::prelude::*;
use std::path::PathBuf;
use std::sync::Arc;

type Levels = (f64, f64, f64, f64);

fn table((log10_read, read_step, log10_shot, shot_step): Levels) -> core::NoiseLevels {
    core::NoiseLevels {
        log10_read,
        read_step,
        log10_shot,
        shot_step,
    }
}

/// One gain of a unit: its folder, key, sigmas and noise.json.
#[pyclass(frozen, name = "NoiseGain", module = "blurset._core")]
pub struct NoiseGain(core::NoiseGain);

#[pymethods]
impl NoiseGain {
    #[getter]
    fn gain(&self) -> f64 {
        self.0.gain
    }
    #[getter]
    fn dir(&self) -> &str {
        &self.0.dir
    }
    #[getter]
    fn key(&self) -> u64 {
        self.0.key
    }
    #[getter]
    fn sigma_read(&self) -> f64 {
        self.0.sigma_read
    }
    #[getter]
    fn sigma_shot(&self) -> f64 {
        self.0.sigma_shot
    }
    /// The gain's noise.json, as written.
    #[getter]
    fn record<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        crate::convert::to_py(py, &self.0.record)
    }
}

/// One scene to noise (a scene, or a level of a build's setting): unit `i` of its plan,
/// which it shares so that a unit's writer can run with the GIL released.
#[pyclass(frozen, name = "NoiseUnit", module = "blurset._core")]
pub struct NoiseUnit {
    plan: Arc<core::NoisePlan>,
    i: usize,
}

impl NoiseUnit {
    fn unit(&self) -> &core::NoiseUnit {
        &self.plan.units[self.i]
    }
}

#[pymethods]
impl NoiseUnit {
    #[getter]
    fn setting(&self) -> Option<&str> {
        self.unit().setting.as_deref()
    }
    #[getter]
    fn level(&self) -> Option<&str> {
        self.unit().level.as_deref()
    }
    #[getter]
    fn dst(&self) -> PathBuf {
        self.unit().dst.clone()
    }
    #[getter]
    fn seed(&self) -> u64 {
        self.unit().seed
    }
    #[getter]
    fn images(&self) -> usize {
        self.unit().names.len()
    }
    #[getter]
    fn clean_views(&self) -> Vec<usize> {
        self.unit().clean_views.clone()
    }
    #[getter]
    fn gains(&self) -> Vec<NoiseGain> {
        self.unit().gains.iter().cloned().map(NoiseGain).collect()
    }

    /// The gains not yet complete in `dst` (indices into `gains`).
    fn pending(&self) -> Vec<usize> {
        self.unit().pending()
    }

    /// The noisy images of the gains `dirs` names, as (gain index, folder).
    fn write_images(&self, py: Python<'_>, dirs: Vec<(usize, PathBuf)>) -> PyResult<()> {
        let (plan, i) = (Arc::clone(&self.plan), self.i);
        run_detached(py, move || plan.units[i].write_images(&dirs))
    }

    /// The clean views' files, the poses, a build's transforms.json and noise.json of
    /// gain `gain` in `dir`.
    fn write_gain_files(&self, py: Python<'_>, gain: usize, dir: PathBuf) -> PyResult<()> {
        let (plan, i) = (Arc::clone(&self.plan), self.i);
        run_detached(py, move || plan.units[i].write_gain_files(gain, &dir))
    }
}

/// The plan of one `blurset noise` run.
#[pyclass(frozen, name = "NoisePlan", module = "blurset._core")]
pub struct NoisePlan(Arc<core::NoisePlan>);

impl From<core::NoisePlan> for NoisePlan {
    fn from(plan: core::NoisePlan) -> Self {
        NoisePlan(Arc::new(plan))
    }
}

#[pymethods]
impl NoisePlan {
    #[getter]
    fn source(&self) -> &str {
        &self.0.source
    }
    #[getter]
    fn gamma(&self) -> &str {
        &self.0.gamma
    }
    #[getter]
    fn downsample(&self) -> Vec<u32> {
        self.0.downsample.clone()
    }
    #[getter]
    fn levels(&self) -> Vec<String> {
        self.0.levels.clone()
    }
    #[getter]
    fn units(&self) -> Vec<NoiseUnit> {
        let unit = |i| NoiseUnit {
            plan: Arc::clone(&self.0),
            i,
        };
        (0..self.0.units.len()).map(unit).collect()
    }
    /// The options the run is made with (noise_dataset.json `params`).
    #[getter]
    fn params<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        crate::convert::to_py(py, &self.0.params)
    }

    /// noise_dataset.json in `out` before any unit: the build and the options.
    fn write_dataset_start(&self, py: Python<'_>, out: PathBuf) -> PyResult<()> {
        let plan = Arc::clone(&self.0);
        run_detached(py, move || plan.write_dataset_start(&out))
    }

    /// noise_dataset.json in `out` over its complete units, stamped `created`; returned.
    fn write_dataset<'py>(
        &self,
        py: Python<'py>,
        out: PathBuf,
        created: String,
    ) -> PyResult<Bound<'py, PyAny>> {
        let plan = Arc::clone(&self.0);
        let doc = run_detached(py, move || plan.write_dataset(&out, &created))?;
        crate::convert::to_py(py, &doc)
    }

    /// noise_scene.json in `out`: the scene, its gain folders, seed and profile; returned.
    fn write_scene_record<'py>(
        &self,
        py: Python<'py>,
        out: PathBuf,
    ) -> PyResult<Bound<'py, PyAny>> {
        let plan = Arc::clone(&self.0);
        let doc = run_detached(py, move || plan.write_scene_record(&out))?;
        crate::convert::to_py(py, &doc)
    }
}

/// The plan of `blurset noise SCENE` (one unit, its gain folders in `out`), the σ table
/// `levels`; bad input is one error naming the file or the option.
#[pyfunction]
fn plan_noise_scene(
    py: Python<'_>,
    scene: PathBuf,
    out: PathBuf,
    config: &NoiseConfig,
    levels: Levels,
) -> PyResult<NoisePlan> {
    let cfg = config.0.clone();
    let plan = run_detached(py, || {
        core::plan_noise_scene(&scene, &out, &cfg, &table(levels))
    })?;
    Ok(plan.into())
}

/// The plan of `blurset noise BUILD` over its complete `settings`, gains under
/// `out/<setting>/<level>/`.
#[pyfunction]
fn plan_noise_build(
    py: Python<'_>,
    build: PathBuf,
    out: PathBuf,
    settings: Vec<String>,
    config: &NoiseConfig,
    levels: Levels,
) -> PyResult<NoisePlan> {
    let cfg = config.0.clone();
    let plan = run_detached(py, || {
        core::plan_noise_build(&build, &out, &settings, &cfg, &table(levels))
    })?;
    Ok(plan.into())
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<NoisePlan>()?;
    m.add_class::<NoiseUnit>()?;
    m.add_class::<NoiseGain>()?;
    add_functions! {
        m,
        plan_noise_scene, plan_noise_build,
    }
    Ok(())
}
