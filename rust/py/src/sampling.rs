//! Sampling and the plan of a setting. A plan stays a Rust object: Python asks it for
//! its render list and has it write the poses and meta.json; `to_dict` is for reading.
use crate::config::{BuildConfig, SamplingConfig};
use crate::convert::{from_py, to_py};
use crate::qa::FrameQa;
use blurset_core as core;
use numpy::PyReadonlyArray2;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use std::path::PathBuf;

/// The seed of setting `index` of object `uid` under the build seed.
#[pyfunction]
fn seed_for(seed: u64, uid: &str, index: u64) -> u64 {
    core::seed_for(seed, uid, index)
}

/// The plan of one setting: every view, trajectory, level, latent frame and seed.
#[pyclass(frozen, name = "Plan", module = "blurset._core")]
pub struct Plan(pub core::SettingPlan);

#[pymethods]
impl Plan {
    #[getter]
    fn uid(&self) -> String {
        self.0.uid.clone()
    }
    #[getter]
    fn n_views(&self) -> usize {
        self.0.views.len()
    }
    #[getter]
    fn resolution(&self) -> [u32; 2] {
        self.0.resolution
    }
    #[getter]
    fn fov_deg(&self) -> f64 {
        self.0.fov_deg
    }

    /// The whole plan as a dict (views[].levels["<l>"].latent_frames …), for reading.
    fn to_dict<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        to_py(py, &self.0)
    }

    /// The blurry images latents auto left above its ghost bound (`latents_max` stopped
    /// it): (view, level, largest gap px), none without latents auto.
    fn ghost_overruns(&self) -> Vec<(usize, String, f64)> {
        self.0.ghost_overruns()
    }

    /// One view's plan of one blur level as a dict (w_l, latents, motion_px, …).
    fn level<'py>(&self, py: Python<'py>, view: usize, level: u32) -> PyResult<Bound<'py, PyAny>> {
        to_py(py, self.level_plan(view, level)?)
    }

    /// Every render of the setting in stream order (per view: sharp, then each level),
    /// as the worker takes them: {view, level, kind, phase, c2w, seed, samples?,
    /// sample_offset?, sample_sequence?, out, motion?}; `pin`: BuildConfig.cycles_samples.
    /// The blur renders of `sharp_views` are left out (their levels get the sharp image).
    /// With `sharp_samples` (BuildConfig.effective_sharp_samples) every render carries its
    /// samples.
    #[pyo3(signature = (exr_dir, pin = None, *, sharp_views = Vec::new(), sharp_samples = None))]
    fn renders<'py>(
        &self,
        py: Python<'py>,
        exr_dir: PathBuf,
        pin: Option<u32>,
        sharp_views: Vec<usize>,
        sharp_samples: Option<u32>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let renders = self.0.renders_except(&exr_dir, &sharp_views, pin);
        match sharp_samples {
            Some(s) => to_py(py, &core::with_samples(renders, s)),
            None => to_py(py, &renders),
        }
    }

    /// What `renders` (with the same arguments) cost on `backend` with `cores` cores:
    /// (renders, samples, seconds), `blurset build --dry-run`'s estimate.
    #[pyo3(signature = (pin, *, sharp_views, sharp_samples, backend, cores))]
    fn cost(
        &self,
        pin: Option<u32>,
        sharp_views: Vec<usize>,
        sharp_samples: u32,
        backend: &str,
        cores: usize,
    ) -> PyResult<(u64, u64, f64)> {
        let model = core::CostModel::of_backend(backend).map_err(crate::error::to_pyerr)?;
        let renders = self
            .0
            .renders_except(std::path::Path::new(""), &sharp_views, pin);
        let c = model.renders_cost(
            &core::with_samples(renders, sharp_samples),
            self.0.resolution[0],
            cores,
        );
        Ok((c.renders, c.samples, c.seconds))
    }

    /// The renders of one blurry image (view, level), EXRs named `<prefix>_…`.
    #[pyo3(signature = (view, level, prefix, pin = None))]
    fn level_renders<'py>(
        &self,
        py: Python<'py>,
        view: usize,
        level: u32,
        prefix: &str,
        pin: Option<u32>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let lp = self.level_plan(view, level)?;
        to_py(
            py,
            &self
                .0
                .with_regions(core::level_renders(view, level, lp, prefix, pin)),
        )
    }

    /// Write `<level>/poses_bounds.npy` and `<level>/transforms.json` for each level dir
    /// and the setting's transforms.json; `test_views` hold sharp images in the blur
    /// levels when `sharp_test_views`.
    #[pyo3(signature = (setting_dir, level_dirs, *, test_views = Vec::new(), sharp_test_views = true))]
    fn write_poses(
        &self,
        py: Python<'_>,
        setting_dir: PathBuf,
        level_dirs: Vec<String>,
        test_views: Vec<usize>,
        sharp_test_views: bool,
    ) -> PyResult<()> {
        crate::run_detached(py, || {
            core::write_setting_poses(
                &self.0,
                &setting_dir,
                &level_dirs,
                &test_views,
                sharp_test_views,
            )
        })
    }

    /// Write the setting's meta.json: this plan, the build config, the object as the
    /// worker reported it (dict), the timings (dict), the QA of every view and, with
    /// --check-poses, the COLMAP verdict (dict); `light_paths` and `device` as the worker
    /// reported them, `denoiser` as the driver's denoiser describes itself (dicts).
    #[pyo3(signature = (path, *, config, object, timings, qa, pose_check = None, light_paths = None, device = None, denoiser = None, images = None))]
    #[allow(clippy::too_many_arguments)] // keyword arguments of one Python call
    fn write_meta(
        &self,
        py: Python<'_>,
        path: PathBuf,
        config: PyRef<'_, BuildConfig>,
        object: &Bound<'_, PyAny>,
        timings: &Bound<'_, PyAny>,
        qa: Vec<PyRef<'_, FrameQa>>,
        pose_check: Option<&Bound<'_, PyAny>>,
        light_paths: Option<&Bound<'_, PyAny>>,
        device: Option<&Bound<'_, PyAny>>,
        denoiser: Option<&Bound<'_, PyAny>>,
        images: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<()> {
        let object: core::ObjectRecord = from_py("object", object)?;
        let images: Option<Vec<(usize, String, core::ImageRender)>> = typed("images", images)?;
        let timings: core::Timings = from_py("timings", timings)?;
        let qa: Vec<core::FrameQa> = qa.iter().map(|q| q.0).collect();
        let mut meta = core::Meta::new(&self.0, &config.0, object, timings, &qa)
            .map_err(crate::error::to_pyerr)?;
        meta.pose_check = pose_check
            .map(|p| from_py::<core::PoseCheck>("pose_check", p))
            .transpose()?;
        meta.render.light_paths = typed("light_paths", light_paths)?;
        meta.render.device = typed("device", device)?;
        meta.render.denoiser = typed("denoiser", denoiser)?;
        if let Some(images) = images {
            meta.set_images(images).map_err(crate::error::to_pyerr)?;
        }
        crate::run_detached(py, || meta.write(&path))
    }
}

/// An optional record given as a dict, read through its core type (None stays None).
fn typed<T: serde::de::DeserializeOwned>(
    what: &str,
    v: Option<&Bound<'_, PyAny>>,
) -> PyResult<Option<T>> {
    v.filter(|x| !x.is_none())
        .map(|x| from_py::<T>(what, x))
        .transpose()
}

impl Plan {
    fn level_plan(&self, view: usize, level: u32) -> PyResult<&core::LevelPlan> {
        self.0
            .views
            .get(view)
            .and_then(|v| v.levels.get(&level.to_string()))
            .ok_or_else(|| {
                PyValueError::new_err(format!("the plan has no view {view} at level {level}"))
            })
    }
}

/// Plan one setting (views, near/far from the vertices, weights, latent frames, seeds).
/// `config` is a SamplingConfig or a BuildConfig (its sampling). `backend`: the Cycles
/// backend the worker reported, which `blur_method auto` (a BuildConfig's) prices each
/// blurry image's method on.
#[pyfunction]
#[pyo3(signature = (config, *, uid, theta0_deg, seed, bbox_dims, vertices, backend = None))]
#[allow(clippy::too_many_arguments)] // keyword arguments of one Python call
fn plan_setting(
    py: Python<'_>,
    config: &Bound<'_, PyAny>,
    uid: &str,
    theta0_deg: f64,
    seed: u64,
    bbox_dims: [f64; 3],
    vertices: PyReadonlyArray2<'_, f32>,
    backend: Option<&str>,
) -> PyResult<Plan> {
    let (cfg, pricing) = if let Ok(b) = config.cast::<BuildConfig>() {
        let b = &b.get().0;
        let pricing = match backend {
            Some(name) => b.pricing(name).map_err(crate::error::to_pyerr)?,
            None => None,
        };
        (b.sampling(), pricing)
    } else {
        (config.cast::<SamplingConfig>()?.get().0.clone(), None)
    };
    let v = vertices.as_array();
    if v.ncols() != 3 {
        return Err(PyValueError::new_err(format!(
            "vertices must be (N, 3), got {:?}",
            v.shape()
        )));
    }
    let pts: Vec<[f32; 3]> = v.rows().into_iter().map(|r| [r[0], r[1], r[2]]).collect();
    let plan = crate::run_detached(py, || {
        core::plan_setting_priced(
            &cfg,
            pricing.as_ref(),
            uid,
            theta0_deg,
            seed,
            bbox_dims,
            &pts,
        )
    })?;
    Ok(Plan(plan))
}

/// Write the `transforms.json` of one scene of a setting (a noisy copy of a level) at
/// `path`: the cameras of the setting's transforms.json at `setting`, one frame per (view,
/// file path), the train/val/test file lists, its level, gain and what its held-out
/// views hold.
#[pyfunction]
#[pyo3(signature = (path, setting, files, *, test_views, level, gain = None, test_view_images = None))]
#[allow(clippy::too_many_arguments)] // keyword arguments of one Python call
fn write_scene_transforms(
    py: Python<'_>,
    path: PathBuf,
    setting: PathBuf,
    files: Vec<(usize, String)>,
    test_views: Vec<usize>,
    level: String,
    gain: Option<f64>,
    test_view_images: Option<String>,
) -> PyResult<()> {
    let fields = core::SceneFields {
        level,
        gain,
        test_view_images,
    };
    crate::run_detached(py, || {
        core::write_scene_transforms(&path, &setting, &files, &test_views, &fields)
    })
}

/// ConfigValueError unless θ0 is a finite number of degrees.
#[pyfunction]
fn check_theta0_deg(theta0_deg: f64) -> PyResult<()> {
    core::check_theta0(theta0_deg).map_err(crate::error::to_pyerr)
}

/// Every `stride`-th view index below `views` (the held-out views of a setting).
#[pyfunction]
fn test_views(views: usize, stride: usize) -> Vec<usize> {
    core::test_views(views, stride)
}

/// The train/test splits of a build (the `splits.json` document).
#[pyclass(frozen, name = "Splits", module = "blurset._core")]
pub struct Splits(core::Splits);

#[pymethods]
impl Splits {
    #[getter]
    fn train(&self) -> Vec<String> {
        self.0.train.clone()
    }
    #[getter]
    fn test(&self) -> Vec<String> {
        self.0.test.clone()
    }
    #[getter]
    fn test_objects(&self) -> Vec<String> {
        self.0.test_objects.clone()
    }
    #[getter]
    fn view_stride(&self) -> usize {
        self.0.view_stride
    }
    /// Held-out view indices per test setting.
    #[getter]
    fn test_views(&self) -> std::collections::BTreeMap<String, Vec<usize>> {
        self.0.test_views.clone()
    }
    /// Write splits.json atomically.
    fn write(&self, py: Python<'_>, path: PathBuf) -> PyResult<()> {
        crate::run_detached(py, || core::write_json(&path, &self.0))
    }
    /// The document as a dict.
    fn to_dict<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        to_py(py, &self.0)
    }
}

/// Train/test splits of setting entries (setting dir, object uid, views): whole
/// objects, or `test_settings` random settings; `sharp_test_views` records what the
/// blur levels hold at the held-out views.
#[pyfunction]
#[pyo3(signature = (entries, *, view_stride, test_fraction, test_objects, seed, test_settings = None, sharp_test_views = true))]
fn make_splits(
    entries: Vec<(String, String, usize)>,
    view_stride: usize,
    test_fraction: f64,
    test_objects: Option<Vec<String>>,
    seed: u64,
    test_settings: Option<usize>,
    sharp_test_views: bool,
) -> PyResult<Splits> {
    let entries: Vec<core::SettingEntry> = entries
        .into_iter()
        .map(|(setting, object, views)| core::SettingEntry {
            setting,
            object,
            views,
        })
        .collect();
    let holdout = match test_settings {
        Some(n) => core::Holdout::Settings(n),
        None => core::Holdout::Objects {
            fraction: test_fraction,
            list: test_objects.as_deref(),
        },
    };
    core::make_splits(&entries, view_stride, &holdout, sharp_test_views, seed)
        .map(Splits)
        .map_err(crate::error::to_pyerr)
}

/// A seeded random subset of `k` ids, sorted (it depends on the set of ids, not their order).
#[pyfunction]
fn seeded_subset(ids: Vec<String>, k: usize, seed: u64) -> Vec<String> {
    core::seeded_subset(&ids, k, seed)
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<Plan>()?;
    m.add_class::<Splits>()?;
    m.add("OBJECT_LOAD_S", core::OBJECT_LOAD_S)?;
    add_functions! {
        m,
        seeded_subset, seed_for, plan_setting, write_scene_transforms, test_views,
        check_theta0_deg, make_splits,
    }
    Ok(())
}
