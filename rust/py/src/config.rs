//! The build config (blurset-core's plan::config) as a frozen Python object. Python's
//! blurset.config maps flags and TOML onto option names; values are converted to the
//! core's `Raw` here and checked there.
use blurset_core as core;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyDict, PyFloat, PyInt, PyList, PyString, PyTuple};
use std::collections::BTreeMap;

/// A Python value as given, before the core checks its type and range.
fn raw(v: &Bound<'_, PyAny>) -> PyResult<core::Raw> {
    Ok(if v.is_none() {
        core::Raw::Null
    } else if let Ok(b) = v.cast::<PyBool>() {
        core::Raw::Bool(b.is_true())
    } else if let Ok(i) = v.cast::<PyInt>() {
        match i.extract::<i128>() {
            Ok(x) => core::Raw::Int(x),
            Err(_) => core::Raw::BigInt(i.str()?.to_string()),
        }
    } else if let Ok(x) = v.cast::<PyFloat>() {
        core::Raw::Float(x.value())
    } else if let Ok(s) = v.cast::<PyString>() {
        core::Raw::Str(s.to_string())
    } else if let Ok(l) = v.cast::<PyList>() {
        core::Raw::List(l.iter().map(|x| raw(&x)).collect::<PyResult<_>>()?)
    } else if let Ok(t) = v.cast::<PyTuple>() {
        core::Raw::List(t.iter().map(|x| raw(&x)).collect::<PyResult<_>>()?)
    } else if v.cast::<PyDict>().is_ok() {
        core::Raw::Table
    } else if v.hasattr("__fspath__")? {
        core::Raw::Str(v.call_method0("__fspath__")?.extract()?)
    } else {
        core::Raw::Str(v.str()?.to_string())
    })
}

fn raw_values(kwargs: Option<&Bound<'_, PyDict>>) -> PyResult<BTreeMap<String, core::Raw>> {
    let mut out = BTreeMap::new();
    if let Some(d) = kwargs {
        for (k, v) in d.iter() {
            out.insert(k.extract::<String>()?, raw(&v)?);
        }
    }
    Ok(out)
}

/// Every option of `blurset build`, validated (frozen: `replace` makes a new one).
///
/// `BuildConfig(**values)` takes option names (`views=8`, `levels=[1, 4]` …) over the
/// defaults; a value out of range raises ConfigValueError naming the option and range.
#[pyclass(
    frozen,
    eq,
    skip_from_py_object,
    name = "BuildConfig",
    module = "blurset._core"
)]
#[derive(Clone, PartialEq)]
pub struct BuildConfig(pub core::BuildConfig);

// One #[pymethods] block per class: the field getters and the methods below.
macro_rules! build_config_methods {
    (fields { $($f:ident : $t:ty),* $(,)? } $($rest:tt)*) => {
        #[pymethods]
        impl BuildConfig {
            $( #[getter] fn $f(&self) -> $t { self.0.$f.clone() } )*
            $($rest)*
        }
    };
}

build_config_methods!(fields {
    objects: Vec<String>, out: Option<String>, demo: bool, settings_per_object: usize,
    views: usize, levels: Vec<u32>, latents: usize, latents_auto: bool, latents_max: usize,
    max_ghost_px: f64, blur_method: String, samples: u32, samples_total: Option<u32>,
    sharp_samples: Option<u32>, latent_sampling: String, blur_budget: String, denoise: String, light_paths: String, device: String,
    gpus: Option<Vec<u32>>, gpus_per_task: Option<f64>, resolution: u32, seed: u64, fov_deg: f64, phi0_deg: f64,
    window_deg: f64, delta0: f64, radius_margin: f64, level_spread: f64,
    latent_positions: String, trajectory: String, orientation_max: f64, near_floor: f64,
    write_linear: bool, previews: bool, view_stride: usize, test_fraction: f64,
    test_objects: Option<Vec<String>>, test_settings: Option<usize>,
    blurry_test_views: bool, downsample: Vec<u32>, workers: usize, threads: usize, executor: String,
    ray_address: Option<String>, shard: Option<String>, objaverse_dir: Option<String>,
    objaverse_offline: bool, objaverse_count: Option<usize>, timeout: f64,
    object_timeout: f64, retries: u32, max_failure_rate: f64, max_triangles: u64,
    max_texture_pixels: u64, blender: Option<String>, check_poses: bool, allow_mixed: bool,
    licenses: Option<Vec<String>>,
}
    #[new]
    #[pyo3(signature = (**values))]
    fn new(values: Option<&Bound<'_, PyDict>>) -> PyResult<Self> {
        let v = raw_values(values)?;
        core::BuildConfig::from_values(&v)
            .map(BuildConfig)
            .map_err(crate::error::to_pyerr)
    }

    /// A copy with these options replaced, validated.
    #[pyo3(signature = (**values))]
    fn replace(&self, values: Option<&Bound<'_, PyDict>>) -> PyResult<Self> {
        let v = raw_values(values)?;
        self.0
            .with_values(&v)
            .map(BuildConfig)
            .map_err(crate::error::to_pyerr)
    }

    /// ConfigValueError unless the config names an output and objects (or demo).
    fn require_target(&self) -> PyResult<()> {
        self.0.require_target().map_err(crate::error::to_pyerr)
    }

    /// This job's share of the objects, `(i, N)` of `shard` (None: every object).
    #[getter]
    fn shard_index(&self) -> Option<(u64, u64)> {
        self.0.shard_index()
    }

    /// ConfigValueError (option test_objects) naming the listed test objects that are
    /// not among `uids`, every object of the build.
    fn check_test_objects(&self, uids: Vec<String>) -> PyResult<()> {
        self.0
            .check_test_objects(&uids)
            .map_err(crate::error::to_pyerr)
    }

    /// The option names, in declaration order.
    #[staticmethod]
    fn options() -> Vec<&'static str> {
        core::BuildConfig::OPTIONS.to_vec()
    }

    /// Linear RGB the transparent film is composited over.
    #[getter]
    fn background(&self) -> (f64, f64, f64) {
        let [r, g, b] = self.0.background;
        (r, g, b)
    }

    /// The most renders one blurry image can take.
    #[getter]
    fn max_latents(&self) -> usize {
        self.0.max_latents()
    }

    /// Samples one blurry image gets at most (the budget, or samples × its frames).
    #[getter]
    fn blur_samples_total(&self) -> u64 {
        self.0.blur_samples_total()
    }

    /// Samples of the sharp render (`sharp_samples`, or the blurry image's budget).
    #[getter]
    fn effective_sharp_samples(&self) -> u64 {
        self.0.effective_sharp_samples()
    }

    /// The Cycles `samples` every render of a subsets build is pinned to (None: each
    /// render its own), so a pixel never depends on what the worker rendered before it.
    #[getter]
    fn cycles_samples(&self) -> Option<u32> {
        self.0.cycles_samples()
    }

    /// Renders of one setting (an upper bound with latents auto).
    #[getter]
    fn frames_per_setting(&self) -> usize {
        self.0.frames_per_setting()
    }

    /// The views whose blur levels hold a copy of the sharp image (none with
    /// blurry_test_views).
    fn sharp_views(&self, n_views: usize) -> Vec<usize> {
        self.0.sharp_views(n_views)
    }

    /// What the blur levels hold at the test views: "sharp" or "blurry".
    #[getter]
    fn test_view_images(&self) -> &'static str {
        self.0.test_view_images()
    }

    /// `sharp`, then `blur_<l>` of every level.
    #[getter]
    fn level_dirs(&self) -> Vec<String> {
        self.0.level_dirs()
    }

    /// The θ0 of each setting of an object.
    #[getter]
    fn theta0s(&self) -> Vec<f64> {
        self.0.theta0s()
    }

    /// dataset.json's `config` record: every option, `latents` = "auto" under latents
    /// auto, and `effective_sharp_samples`.
    fn record<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        crate::sampling::to_py(py, &self.0.record())
    }

    /// The sampling sub-config every setting's plan is made with.
    fn sampling(&self) -> crate::sampling::SamplingConfig {
        crate::sampling::SamplingConfig(self.0.sampling())
    }

    fn __reduce__<'py>(slf: &Bound<'py, Self>) -> PyResult<(Bound<'py, PyAny>, (String,))> {
        let text = serde_json::to_string(&slf.get().0)
            .map_err(|e| PyValueError::new_err(e.to_string()))?;
        Ok((slf.getattr("_from_json")?, (text,)))
    }

    /// The config a `__reduce__` wrote (pickling, e.g. to Ray tasks).
    #[staticmethod]
    fn _from_json(text: &str) -> PyResult<Self> {
        let cfg: core::BuildConfig =
            serde_json::from_str(text).map_err(|e| PyValueError::new_err(e.to_string()))?;
        cfg.validate().map_err(crate::error::to_pyerr)?;
        Ok(BuildConfig(cfg))
    }

    fn __repr__(&self) -> String {
        format!("{:?}", self.0)
    }
);

/// ConfigValueError unless the factors are distinct integers in 2..=64.
#[pyfunction]
fn check_downsample(factors: Vec<u32>) -> PyResult<()> {
    core::check_downsample(&factors).map_err(crate::error::to_pyerr)
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<BuildConfig>()?;
    m.add_function(wrap_pyfunction!(check_downsample, m)?)?;
    Ok(())
}
