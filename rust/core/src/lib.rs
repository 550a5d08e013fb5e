//! blurset-core: every number blurset samples or computes.
//!
//! Pure Rust (glam, rayon, image); the Python bindings in `rust/py` only convert.
//!
//! The modules are private and grouped by concern: `plan` (what a setting renders),
//! `image` (colour, accumulation, image files, QA), `noise` (the sensor noise model
//! and its kernel), `dataset` (the files of a build) and `metrics` (PSNR, Pareto).
//! What the bindings, the examples and the fuzz targets use is re-exported below and
//! nothing else, so the compiler reports whatever nothing uses.
mod dataset;
mod error;
mod ground;
mod image;
mod metrics;
mod noise;
mod plan;
mod rng;

pub use crate::error::{Error, Result};
pub use crate::rng::seed_for;

// What one setting renders: views, trajectories, levels, latent frames.
pub use crate::plan::choices::{BlurMethod, Choice, Preset};
pub use crate::plan::config::BuildConfig;
pub use crate::plan::cost::{BlurChoice, CostModel, Pricing, OBJECT_LOAD_S};
pub use crate::plan::kinds::defocus::{circle_of_confusion, DefocusPlan};
pub use crate::plan::kinds::KIND_STATS;
pub use crate::plan::motion::{level_renders, LevelPlan};
pub use crate::plan::options::OptionInfo;
pub use crate::plan::presets::{preset_values, FLOOR_PSNR_DB};
pub use crate::plan::renders::{with_samples, Motion, Render};
pub use crate::plan::sampling::{plan_setting, plan_setting_priced, SettingPlan};
pub use crate::plan::sampling_config::SamplingConfig;
pub use crate::plan::spec::{check_downsample, check_range, check_theta0, Kind, Raw};
pub use crate::plan::target::{ImageState, TargetRule};

// Linear frames in, encoded images out; image files; render QA.
pub use crate::image::accumulate::Accumulator;
pub use crate::image::color::srgb_encode_slice;
pub use crate::image::denoise::{DenoiseDevice, Denoiser, DenoiserRecord};
pub use crate::image::exr::read::{
    check_exr_size, decode_exr, exr_size, header_size_other_than, read_exr, read_exr_sized, Frame,
};
// The depth reader `verify` tries after the colour one, for the fuzz target exr_memory.
pub use crate::image::geometry::decode_depth_exr;
pub use crate::image::geometry::{
    depth_millimetres, mask_from_coverage, read_depth_exr_sized, read_geometry, write_depth_exr,
    write_depth_millimetres, write_geometry, write_gray16_png, write_gray8_png, write_normal_exr,
    Geometry,
};
pub use crate::image::io::{image_info, read_image, Image, Samples};
pub use crate::image::qa::{
    exr_qa, frame_qa, object as object_qa, thumbnail_qa, FrameQa, QaThresholds,
};

// Sensor noise, from 8/16-bit images or from a build's linear EXRs.
pub use crate::noise::config::NoiseConfig;
pub use crate::noise::kernel::{add_noise, clean_linear};
pub use crate::noise::linear::{add_noise_linear, clean_from_linear, read_linear, LinearRgb};
pub use crate::noise::model::{
    noise_key, sample_white_balance, scene_seed, stream_id as noise_stream_id, Gamma, NoiseLevels,
    NoiseModel, WhiteBalance,
};
pub use crate::noise::raw::raw_frame;
pub use crate::noise::raw_model::{Display as RawDisplay, ModelKind, RawModel};
pub use crate::noise::variants::{write_variants, write_variants_linear, Variant, VariantOptions};

// The files of a build.
pub use crate::dataset::build_tail::{write_build_tail, BuildTail, RunFacts};
pub use crate::dataset::failures::{
    current as current_failures, read_records as read_failure_records,
};
pub use crate::dataset::finished::ImageWriter;
pub use crate::dataset::layout::{
    complete_settings, is_complete, is_image_folder, parse_temp_name, partial_dir, png_fault,
    publish, setting_levels, setting_problem, setting_problems, temp_path, Fault, SettingProblem,
    MARKER, PARTIAL_SUFFIX,
};
pub use crate::dataset::llff::{
    parse_poses_bounds, read_poses_bounds, write_poses_bounds, write_scene_transforms,
    write_setting_poses, PoseRow, SceneFields,
};
pub use crate::dataset::manifest::{
    check_manifest, list_files as manifest_files, manifest_mismatches, rewrite_manifest,
    sha256_file, update_manifest, write_manifest, ManifestProblem, MANIFEST,
};
pub use crate::dataset::meta::{
    read_exposure_ends, read_mean_poses, write_json, DeviceRecord, ImageRender, LightPathsRecord,
    Meta, ObjectRecord, Pose, PoseCheck, Timings,
};
pub use crate::dataset::noise_plan::{
    plan_build as plan_noise_build, plan_scene as plan_noise_scene, NoiseGain, NoisePlan, NoiseUnit,
};
pub use crate::dataset::outputs::{
    build_state, claim, linked_entry, mark_text, not_written, output_kind, owned_entries,
    remove_owned, superseded_settings, text_owner, BuildState, Claim, OutputKind, TextOwner,
};
pub use crate::dataset::read::{check_shape, parse_record, read_record, Record};
pub use crate::dataset::records::{write_dataset, DatasetDoc};
pub use crate::dataset::schema::{
    schema, schema_file, value_schemas, write_record, StatsFile, SCHEMA_RECORDS,
};
pub use crate::dataset::session::{Counts, Session};
pub use crate::dataset::splits::{make_splits, seeded_subset, Holdout, SettingEntry, Splits};
pub use crate::dataset::stats::{build_stats, BuildStats};
pub use crate::dataset::target_loop::{Finished, ImageKey, TargetImages};
pub use crate::dataset::verify::{check_images, ImageCheck};
/// The worker contract: the JSON lines to and from a Blender worker, typed.
pub use crate::dataset::wire;
pub use crate::ground::atomic::{replace_dir, write_atomic};
pub use crate::ground::license::{
    allowed as license_allowed, canonical as canonical_license, spdx_ids, spdx_of,
};
pub use crate::ground::names::test_views;
pub use crate::ground::names::{
    files, gain_name, image_name, images_dir, linear_dir, linear_name, nerfstudio_depth_dir,
    object_lock, pass_dir, pass_file, setting_name, theta0s, work_dir, OBJECT_LOCK_PREFIX, PASSES,
    SHARP, WORK_PREFIX,
};
pub use crate::plan::kind::ImageKind;
pub use crate::plan::kind::{
    is_level_dir, level_dir, level_dirs, parse_level_dir, sort_level_dirs,
};
pub use crate::plan::kinds::pass_level;

// Image error against a reference and the speed/quality front.
pub use crate::metrics::{
    detail_kept, detail_ratio, half_noise, half_noise_bound, image_error, object_error,
    pareto_front, spread, ObjectError, Spread,
};
