//! The files of a build: LLFF poses, splits, failures, statistics, atomic writes.
pub mod atomic;
pub mod failures;
pub mod llff;
pub mod splits;
pub mod stats;
