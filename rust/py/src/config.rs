//! The build config (blurset-core's plan::config) as a frozen Python object. Python's
//! blurset.config maps flags and TOML onto option names; values are converted to the
//! core's `Raw` here and checked there.
use blurset_core as core;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyDict, PyFloat, PyInt, PyList, PyString, PyTuple};
use std::collections::BTreeMap;

use crate::convert::{from_py, to_py};

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

// One #[pymethods] block per config class: a getter per option of the core's
// declaration table (`build_options!`, `noise_options!`; the table names the class, which
// this module defines under the core's name), what every config has (the constructor
// from option values, `options`, `declarations`), and the methods given.
macro_rules! py_config {
    (
        { $($methods:tt)* }
        $(#[doc = $sdoc:expr])*
        $cfg:ident, $command:literal;
        $(
            $(#[doc = $doc:expr])*
            $name:ident : $ty:ty = $default:expr, $spec:expr, $shape:ident
                { $($k:ident : $v:expr),* $(,)? };
        )*
    ) => {
        #[pymethods]
        impl $cfg {
            $(
                #[getter]
                fn $name<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
                    crate::convert::to_py(py, &self.0.$name)
                }
            )*

            #[new]
            #[pyo3(signature = (**values))]
            fn new(values: Option<&Bound<'_, PyDict>>) -> PyResult<Self> {
                let v = raw_values(values)?;
                core::$cfg::from_values(&v)
                    .map($cfg)
                    .map_err(crate::error::to_pyerr)
            }

            /// The option names, in declaration order.
            #[staticmethod]
            fn options() -> Vec<&'static str> {
                core::$cfg::OPTIONS.to_vec()
            }

            /// Every option as the core declares it, in declaration order.
            #[staticmethod]
            fn declarations() -> Vec<OptionDecl> {
                core::$cfg::declarations()
                    .into_iter()
                    .map(OptionDecl)
                    .collect()
            }

            $($methods)*
        }
    };
}

blurset_core::build_options!(py_config {
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
        crate::convert::to_py(py, &self.0.record())
    }

    /// The sampling sub-config every setting's plan is made with.
    fn sampling(&self) -> SamplingConfig {
        SamplingConfig(self.0.sampling())
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
});

/// Every option of `blurset noise`, validated (frozen).
///
/// `NoiseConfig(**values)` takes option names (`gains=["1", "4"]`, `frames=2` …) over
/// the defaults; a bad value raises ConfigValueError naming the option.
#[pyclass(
    frozen,
    eq,
    skip_from_py_object,
    name = "NoiseConfig",
    module = "blurset._core"
)]
#[derive(Clone, PartialEq)]
pub struct NoiseConfig(pub core::NoiseConfig);

blurset_core::noise_options!(py_config {
    /// The gains as numbers, in the order given.
    #[getter]
    fn gain_values(&self) -> PyResult<Vec<f64>> {
        self.0.gain_values().map_err(crate::error::to_pyerr)
    }

    fn __repr__(&self) -> String {
        format!("NoiseConfig({:?})", self.0)
    }
});

/// One option as its declaration in the core states it: the flags, help, TOML keys,
/// range, defaults and whether it shapes the outputs (python/blurset/options.py makes the
/// parsers and the CLI reference from these).
#[pyclass(
    frozen,
    eq,
    skip_from_py_object,
    name = "OptionDecl",
    module = "blurset._core"
)]
#[derive(Clone, PartialEq)]
pub struct OptionDecl(pub core::OptionInfo);

#[pymethods]
impl OptionDecl {
    #[getter]
    fn name(&self) -> &'static str {
        self.0.name
    }
    /// The field's Rust type as the core's table writes it (`Option<Vec<String>>`).
    #[getter]
    fn rust_type(&self) -> &'static str {
        self.0.rust_type
    }
    /// Its flags, the first the one errors name (none: set through `via`, or TOML only).
    #[getter]
    fn flags(&self) -> Vec<String> {
        self.0.flags.clone()
    }
    /// The option whose flag sets this one.
    #[getter]
    fn via(&self) -> Option<&'static str> {
        self.0.via
    }
    /// The keys a TOML file may name it by (dashes or underscores alike).
    #[getter]
    fn keys(&self) -> Vec<String> {
        self.0.keys.clone()
    }
    /// How it reads on the command line: switch, int, float, text, choice, words,
    /// levels, factors, indices, rgb, count_or_auto, fraction_or_ids.
    #[getter]
    fn kind<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        crate::convert::to_py(py, &self.0.kind)
    }
    /// None is a value of it.
    #[getter]
    fn optional(&self) -> bool {
        self.0.optional
    }
    #[getter]
    fn choices(&self) -> Vec<&'static str> {
        self.0.choices.clone()
    }
    /// The accepted values, as an error states them.
    #[getter]
    fn range(&self) -> String {
        self.0.range.clone()
    }
    /// The default, as dataset.json records it.
    #[getter]
    fn default<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        crate::convert::to_py(py, &self.0.default)
    }
    /// What a None default means, in words.
    #[getter]
    fn unset(&self) -> Option<&'static str> {
        self.0.unset
    }
    /// The default under --demo, when it has its own.
    #[getter]
    fn demo<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        crate::convert::to_py(py, &self.0.demo)
    }
    /// The value a recorded config without this option was made with.
    #[getter]
    fn before<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        crate::convert::to_py(py, &self.0.before)
    }
    #[getter]
    fn help(&self) -> &'static str {
        self.0.help
    }
    /// Whether it shapes the files written (a rerun into the same output must keep it).
    #[getter]
    fn shapes_outputs(&self) -> bool {
        self.0.shapes_outputs
    }
    /// Options whose flags exclude each other share a group.
    #[getter]
    fn group(&self) -> Option<&'static str> {
        self.0.group
    }
    #[getter]
    fn metavar(&self) -> Option<&'static str> {
        self.0.metavar
    }
    /// The titled section of the help its flag is listed under (None: the command's).
    #[getter]
    fn section(&self) -> Option<&'static str> {
        self.0.section
    }
    fn __repr__(&self) -> String {
        format!("OptionDecl({:?})", self.0.name)
    }
}

/// ConfigValueError unless the factors are distinct integers in 2..=64.
#[pyfunction]
fn check_downsample(factors: Vec<u32>) -> PyResult<()> {
    core::check_downsample(&factors).map_err(crate::error::to_pyerr)
}

/// ConfigValueError naming `option` unless `value` is in lo..=hi (above lo with lo_open),
/// an integer unless `integer` is false: the words of every declared range.
#[pyfunction]
#[pyo3(signature = (option, value, lo, hi=u32::MAX as f64, *, lo_open=false, integer=true))]
fn check_range(
    option: &str,
    value: &Bound<'_, PyAny>,
    lo: f64,
    hi: f64,
    lo_open: bool,
    integer: bool,
) -> PyResult<()> {
    core::check_range(option, &raw(value)?, (lo, hi), lo_open, integer)
        .map_err(crate::error::to_pyerr)
}

/// What preset `name` sets: option name → value (core `preset_values`).
#[pyfunction]
fn preset_values<'py>(py: Python<'py>, name: &str) -> PyResult<Bound<'py, PyDict>> {
    use core::Raw;
    let preset = <core::Preset as core::Choice>::from_name(name)
        .ok_or_else(|| PyValueError::new_err(format!("no preset {name:?}")))?;
    let out = PyDict::new(py);
    for (k, v) in core::preset_values(preset) {
        match v {
            Raw::Bool(b) => out.set_item(k, b)?,
            Raw::Float(x) => out.set_item(k, x)?,
            Raw::Int(i) => out.set_item(k, i)?,
            Raw::Str(t) => out.set_item(k, t)?,
            other => {
                return Err(PyValueError::new_err(format!(
                    "preset {name}: {k} = {other} has no Python value"
                )))
            }
        }
    }
    Ok(out)
}

/// Samples per frame and half of an image's next round under the config's target, or
/// None when the image is done (core `TargetRule::next_round`; `mse`: the last estimate,
/// None before the pilot; `previous`: (samples per frame and half, MSE) of the estimate
/// before it).
#[pyfunction]
#[pyo3(signature = (config, *, frames, spent_per_frame, rounds, mse = None, previous = None))]
fn target_next_round(
    config: PyRef<'_, BuildConfig>,
    frames: u32,
    spent_per_frame: u32,
    rounds: u32,
    mse: Option<f64>,
    previous: Option<(u32, f64)>,
) -> PyResult<Option<u32>> {
    let rule = config
        .0
        .target()
        .ok_or_else(|| PyValueError::new_err("the config has no target_psnr"))?;
    Ok(rule.next_round(&core::ImageState {
        frames,
        spent_per_frame,
        rounds,
        mse,
        previous,
    }))
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<BuildConfig>()?;
    m.add_class::<SamplingConfig>()?;
    m.add_class::<NoiseConfig>()?;
    m.add_class::<OptionDecl>()?;
    add_functions! {
        m,
        preset_values, target_next_round, default_sampling_config, check_downsample,
        check_range,
    }
    Ok(())
}

/// The sampling of a setting's plan (views, trajectory, levels, latents, samples).
///
/// `SamplingConfig(**values)` takes the fields of `to_dict()` over the paper's defaults;
/// ConfigValueError names an option out of range.
#[pyclass(
    frozen,
    eq,
    skip_from_py_object,
    name = "SamplingConfig",
    module = "blurset._core"
)]
#[derive(Clone, PartialEq)]
pub struct SamplingConfig(pub core::SamplingConfig);

#[pymethods]
impl SamplingConfig {
    #[new]
    #[pyo3(signature = (**values))]
    fn new(values: Option<&Bound<'_, PyDict>>) -> PyResult<Self> {
        let cfg: core::SamplingConfig = match values {
            Some(d) => from_py("sampling config", d.as_any())?,
            None => core::SamplingConfig::default(),
        };
        cfg.validate().map_err(crate::error::to_pyerr)?;
        Ok(SamplingConfig(cfg))
    }

    /// The fields as a dict (what meta.json records as `sampling`).
    fn to_dict<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        to_py(py, &self.0)
    }

    /// The most latent frames one blurry image can have.
    #[getter]
    fn max_latents(&self) -> usize {
        self.0.max_latents()
    }
}

/// The paper's sampling settings.
#[pyfunction]
fn default_sampling_config() -> SamplingConfig {
    SamplingConfig(core::SamplingConfig::default())
}
