//! Checksums and the image check of a published build (issue 19, `blurset verify`):
//! one core call each.
use blurset_core as core;
use pyo3::prelude::*;
use std::path::PathBuf;

/// sha256 of a file's bytes, lowercase hex.
#[pyfunction]
fn sha256_file(py: Python<'_>, path: PathBuf) -> PyResult<String> {
    crate::run_detached(py, || core::sha256_file(&path))
}

/// The files MANIFEST.sha256 of `root` lists (relative, sorted).
#[pyfunction]
fn manifest_files(py: Python<'_>, root: PathBuf) -> PyResult<Vec<String>> {
    crate::run_detached(py, || core::manifest_files(&root))
}

/// Hash every listed file of `root` (in parallel) into root/MANIFEST.sha256; the count.
#[pyfunction]
fn write_manifest(py: Python<'_>, root: PathBuf) -> PyResult<usize> {
    crate::run_detached(py, || core::write_manifest(&root))
}

/// Rehash these files (relative to `root`) into its existing manifest; the count.
#[pyfunction]
fn update_manifest(py: Python<'_>, root: PathBuf, rels: Vec<String>) -> PyResult<usize> {
    crate::run_detached(py, || core::update_manifest(&root, &rels))
}

/// Write root/MANIFEST.sha256 at the end of a run that vouches for `vouched` (files or
/// folders it wrote or checked, relative): those hashed; with `keep_old` every other
/// file the old manifest lists keeps its line; nothing else is listed. The count.
#[pyfunction]
#[pyo3(signature = (root, vouched, keep_old=true))]
fn rewrite_manifest(
    py: Python<'_>,
    root: PathBuf,
    vouched: Vec<String>,
    keep_old: bool,
) -> PyResult<usize> {
    crate::run_detached(py, || core::rewrite_manifest(&root, &vouched, keep_old))
}

/// [(relative path, kind, what is wrong)] of the files root/MANIFEST.sha256 lists under
/// the folder `dir` that are gone or hold other bytes (none without a manifest).
#[pyfunction]
fn manifest_mismatches(
    py: Python<'_>,
    root: PathBuf,
    dir: String,
) -> PyResult<Vec<(String, &'static str, &'static str)>> {
    let problems = crate::run_detached(py, || core::manifest_mismatches(&root, &dir))?;
    Ok(problems
        .into_iter()
        .map(|(p, what)| (p, what.kind(), what.as_str()))
        .collect())
}

/// [(relative path, kind, what is wrong)] of the files that do not match
/// root/MANIFEST.sha256 (kinds: missing, mismatch, unlisted).
#[pyfunction]
fn check_manifest(
    py: Python<'_>,
    root: PathBuf,
) -> PyResult<Vec<(String, &'static str, &'static str)>> {
    let problems = crate::run_detached(py, || core::check_manifest(&root))?;
    Ok(problems
        .into_iter()
        .map(|(p, what)| (p, what.kind(), what.as_str()))
        .collect())
}

/// For each (path, width, height): None when the image decodes whole at that size,
/// else what is wrong. Decoded in parallel.
#[pyfunction]
fn check_images(py: Python<'_>, items: Vec<(PathBuf, u32, u32)>) -> Vec<Option<String>> {
    let items: Vec<core::ImageCheck> = items
        .into_iter()
        .map(|(path, width, height)| core::ImageCheck {
            path,
            width,
            height,
        })
        .collect();
    py.detach(|| core::check_images(&items))
}

/// The SPDX id a licence text names, `other` when it maps to none, `unknown` for none.
#[pyfunction]
#[pyo3(signature = (text))]
fn spdx_of(text: Option<&str>) -> String {
    core::spdx_of(text)
}

/// The canonical spelling of a licence id (SPDX, `other`, `unknown`), or None.
#[pyfunction]
fn canonical_license(id: &str) -> Option<String> {
    core::canonical_license(id)
}

/// Whether an object under licence `id` passes a `--licenses` filter (None: all pass).
#[pyfunction]
#[pyo3(signature = (id, licenses))]
fn license_allowed(id: &str, licenses: Option<Vec<String>>) -> bool {
    core::license_allowed(id, licenses.as_deref())
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("MANIFEST", core::MANIFEST)?;
    m.add("SPDX_IDS", core::spdx_ids())?;
    add_functions! {
        m,
        sha256_file, manifest_files, write_manifest, update_manifest, check_manifest,
        rewrite_manifest, manifest_mismatches, check_images, spdx_of, canonical_license,
        license_allowed,
    }
    Ok(())
}
