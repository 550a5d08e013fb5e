//! blurset-core: every number blurset samples or computes.
//!
//! Pure Rust (glam, rayon, image); the Python bindings in `rust/py` only convert.
pub mod accumulate;
pub mod atomic;
pub mod camera;
pub mod error;
mod exr_frame;
pub mod failures;
pub mod image_io;
pub mod llff;
pub mod noise;
pub mod noise_linear;
pub mod qa;
pub mod rng;
pub mod sampling;
pub mod splits;
pub mod stats;
pub mod tradeoff;
pub mod weights;

pub use error::{Error, Result};
