//! The layout of a build on disk (blurset-core's dataset::layout): names, the marker,
//! what "complete" means, atomic writes. blurset.layout wraps these.
use blurset_core as core;
use pyo3::prelude::*;
use std::path::PathBuf;

/// `<uid>_<theta0>`, the directory name of one setting.
#[pyfunction]
fn setting_name(uid: &str, theta0_deg: f64) -> String {
    core::setting_name(uid, theta0_deg)
}

/// The θ0 of each of an object's `n` settings, evenly spaced from 0°.
#[pyfunction]
fn theta0s(n: usize) -> Vec<f64> {
    core::theta0s(n)
}

/// Image file name of view `index` among `n` views.
#[pyfunction]
fn image_name(index: usize, n: usize) -> String {
    core::image_name(index, n)
}

/// Directory of a blur level (`blur_<l>`); level 0 is `sharp`.
#[pyfunction]
fn level_dir(level: u32) -> String {
    core::level_dir(level)
}

/// `sharp`, then `blur_<l>` of every level.
#[pyfunction]
fn level_dirs(levels: Vec<u32>) -> Vec<String> {
    core::level_dirs(&levels)
}

/// The level of a level directory name (`sharp` → 0, `blur_<l>` → l), or None.
#[pyfunction]
fn parse_level_dir(name: &str) -> Option<u32> {
    core::parse_level_dir(name)
}

/// The kind of a level directory (`sharp`, `blur`, `defocus` …), or None for a name
/// that is no level directory.
#[pyfunction]
fn level_kind(name: &str) -> Option<&'static str> {
    core::ImageKind::parse(name).map(core::ImageKind::name)
}

/// What a level directory's kind is, as a dataset card says it: (its directories'
/// pattern, `blur_<l>`, and its sentence); None for `sharp` and a name that is no level
/// directory.
#[pyfunction]
fn level_means(name: &str) -> Option<(String, &'static str)> {
    let kind = core::ImageKind::parse(name)?;
    Some((kind.dir_pattern(), kind.means()?))
}

/// Whether a name is a level directory a build writes (sharp, blur_<l>, defocus_<l>).
#[pyfunction]
fn is_level_dir(name: &str) -> bool {
    core::is_level_dir(name)
}

/// Where meta.json records a level directory's image in each view: (the key of its
/// kind's map, its level's key), `("levels", "2")` for `blur_2`; None for `sharp` and
/// for a name that is no level directory.
#[pyfunction]
fn level_record(name: &str) -> Option<(&'static str, String)> {
    core::ImageKind::parse(name).and_then(core::ImageKind::record)
}

/// Whether a level directory's images are seen from the written poses (sharp, defocus)
/// rather than being means whose mean latent poses meta.json records; False for a name
/// that is no level directory.
#[pyfunction]
fn written_pose(name: &str) -> bool {
    core::ImageKind::parse(name).is_some_and(core::ImageKind::written_pose)
}

/// Level directory names in level order; other names are dropped.
#[pyfunction]
fn sort_level_dirs(names: Vec<String>) -> Vec<String> {
    core::sort_level_dirs(&names)
}

/// The level directories a setting holds, in level order.
#[pyfunction]
fn setting_levels(py: Python<'_>, setting: PathBuf) -> PyResult<Vec<String>> {
    crate::run_detached(py, || core::setting_levels(&setting))
}

/// The mean latent pose (OpenGL c2w rows) of blur level `level` of every view of a
/// setting's meta.json, or None for a meta.json from before mean poses.
#[pyfunction]
fn read_mean_poses(
    py: Python<'_>,
    meta: PathBuf,
    level: u32,
) -> PyResult<Option<Vec<[[f64; 4]; 4]>>> {
    crate::run_detached(py, || core::read_mean_poses(&meta, level))
}

/// The first and last latent camera (OpenGL c2w rows) of each view's exposure in blur level
/// `level` (None: a sharp copy or under two frames), or None for a meta.json from before
/// mean poses.
#[pyfunction]
#[allow(clippy::type_complexity)]
fn read_exposure_ends(
    py: Python<'_>,
    meta: PathBuf,
    level: u32,
) -> PyResult<Option<Vec<Option<[core::Pose; 2]>>>> {
    crate::run_detached(py, || core::read_exposure_ends(&meta, level))
}

/// The image folder at downsampling factor `factor` (`images`, `images_4`).
#[pyfunction]
fn images_dir(factor: u32) -> String {
    core::images_dir(factor)
}

/// The sharp level's folder of a pass at downsampling factor `factor` (`depth`,
/// `normals_4`, `masks`).
#[pyfunction]
fn pass_dir(kind: &str, factor: u32) -> String {
    core::pass_dir(kind, factor)
}

/// nerfstudio's depth folder in an exported scene at downsampling factor `factor`
/// (`depths`, `depths_4`).
#[pyfunction]
fn nerfstudio_depth_dir(factor: u32) -> String {
    core::nerfstudio_depth_dir(factor)
}

/// The level folder that holds `level`'s files of pass `kind` (a moving exposure's
/// own masks where the setting records them; everything else the sharp level's).
#[pyfunction]
fn pass_level(kind: &str, level: &str, level_masks: bool) -> String {
    core::pass_level(kind, level, level_masks).to_string()
}

/// The file of an image's view in a pass's folder (`007.png` → `007.exr` or `007.png`).
#[pyfunction]
fn pass_file(kind: &str, image: &str) -> String {
    core::pass_file(kind, image)
}

/// The linear EXR folder at downsampling factor `factor` (`linear`, `linear_4`).
#[pyfunction]
fn linear_dir(factor: u32) -> String {
    core::linear_dir(factor)
}

/// Directory name of a noise gain (`gain_4`, `gain_2.5`).
#[pyfunction]
fn gain_name(gain: f64) -> String {
    core::gain_name(gain)
}

/// Where a setting or noise unit is written before it is published.
#[pyfunction]
fn partial_dir(final_dir: PathBuf) -> PathBuf {
    core::partial_dir(&final_dir)
}

/// A final (not `*.partial`) directory holding its marker.
#[pyfunction]
fn is_complete(dir: PathBuf) -> bool {
    core::is_complete(&dir)
}

/// Whether a level's folder `name` holds per-view files (images, linear, passes).
#[pyfunction]
fn is_image_folder(name: &str) -> bool {
    core::is_image_folder(name)
}

/// The private folder an object's worker writes its scratch in (`.work-<uid>`).
#[pyfunction]
fn work_dir(uid: &str) -> String {
    core::work_dir(uid)
}

/// The lock a build holds while it builds one object (`.lock-<uid>`).
#[pyfunction]
fn object_lock(uid: &str) -> String {
    core::object_lock(uid)
}

/// The linear EXR of an image (`007.png` → `007.exr`).
#[pyfunction]
fn linear_name(image: &str) -> String {
    core::linear_name(image)
}

/// What is missing or damaged in a complete setting (checked cheaply), or None.
#[pyfunction]
fn setting_problem(py: Python<'_>, setting: PathBuf) -> Option<String> {
    py.detach(|| core::setting_problem(&setting))
}

/// Every problem of a complete setting the cheap check finds: (path relative to the
/// setting, its kind, what is wrong in words), in the order the check meets them.
#[pyfunction]
fn setting_problems(py: Python<'_>, setting: PathBuf) -> Vec<(String, &'static str, String)> {
    py.detach(|| core::setting_problems(&setting))
        .into_iter()
        .map(|p| (p.path, p.fault.kind(), p.fault.what()))
        .collect()
}

/// What is wrong with a PNG read without decoding (signature, end chunk), or None.
#[pyfunction]
fn png_problem(path: PathBuf) -> Option<String> {
    core::png_fault(&path).map(|f| f.what())
}

/// The complete setting directory names of a build, sorted.
#[pyfunction]
fn complete_settings(py: Python<'_>, build: PathBuf) -> PyResult<Vec<String>> {
    crate::run_detached(py, || core::complete_settings(&build))
}

/// Write the marker (holding `stamp`) into `partial` and put it at `final_dir`.
#[pyfunction]
fn publish(py: Python<'_>, partial: PathBuf, final_dir: PathBuf, stamp: &str) -> PyResult<()> {
    crate::run_detached(py, || core::publish(&partial, &final_dir, stamp))
}

/// Put the folder `new` at `dst`, the old one renamed aside, then removed.
#[pyfunction]
fn replace_dir(py: Python<'_>, new: PathBuf, dst: PathBuf) -> PyResult<()> {
    crate::run_detached(py, || core::replace_dir(&new, &dst))
}

/// The temp path an atomic write of `path` goes through (`.<name>.tmp<pid>`).
#[pyfunction]
fn temp_path(path: PathBuf) -> PathBuf {
    core::temp_path(&path)
}

/// (target name, pid) of a temp file name, or None.
#[pyfunction]
fn parse_temp_name(name: &str) -> Option<(String, u32)> {
    core::parse_temp_name(name)
}

/// Write `data` through a synced temp file and a rename (parents created).
#[pyfunction]
fn write_atomic(py: Python<'_>, path: PathBuf, data: &[u8]) -> PyResult<()> {
    let data = data.to_vec();
    crate::run_detached(py, || core::write_atomic(&path, &data))
}

/// Write a build's dataset.json; `doc` must match the core's DatasetDoc (unknown or
/// missing fields are errors).
#[pyfunction]
fn write_dataset_json(py: Python<'_>, path: PathBuf, doc: &Bound<'_, PyAny>) -> PyResult<()> {
    let doc: core::DatasetDoc = crate::convert::from_py("dataset.json", doc)?;
    crate::run_detached(py, || core::write_dataset(&path, &doc))
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    register_names(m)?;
    register_functions(m)
}

/// The module's names of markers, folders and files.
fn register_names(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("MARKER", core::MARKER)?;
    m.add("PARTIAL_SUFFIX", core::PARTIAL_SUFFIX)?;
    m.add("SHARP", core::SHARP)?;
    use core::files;
    for (name, value) in [
        ("META", files::META),
        ("DATASET", files::DATASET),
        ("SPLITS", files::SPLITS),
        ("FAILURES", files::FAILURES),
        ("POSES_BOUNDS", files::POSES_BOUNDS),
        ("TRANSFORMS", files::TRANSFORMS),
        ("NOISE", files::NOISE),
        ("NOISE_DATASET", files::NOISE_DATASET),
        ("NOISE_SCENE", files::NOISE_SCENE),
        ("EXPORT", files::EXPORT),
        ("STATS", files::STATS),
        ("IMAGES", files::IMAGES),
        ("LINEAR", files::LINEAR),
        ("DEMO_OBJECTS", files::DEMO_OBJECTS),
    ] {
        m.add(name, value)?;
    }
    Ok(())
}

/// The module's functions.
fn register_functions(m: &Bound<'_, PyModule>) -> PyResult<()> {
    add_functions! {
        m,
        images_dir, work_dir, object_lock, linear_name, linear_dir, pass_dir,
        nerfstudio_depth_dir, pass_file, pass_level, setting_name, theta0s, image_name,
        level_dir, level_dirs, parse_level_dir, level_kind, level_means, level_record,
        written_pose, is_level_dir, sort_level_dirs, setting_levels, read_mean_poses,
        read_exposure_ends, gain_name, partial_dir, is_complete, is_image_folder,
        complete_settings, setting_problem, setting_problems, png_problem, publish, replace_dir,
        temp_path, parse_temp_name, write_atomic, write_dataset_json,
    }
    Ok(())
}
