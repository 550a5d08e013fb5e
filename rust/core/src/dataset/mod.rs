//! The files of a build: names and layout, LLFF poses, splits, failures, statistics,
//! atomic writes.
pub mod atomic;
pub mod failures;
pub mod layout;
pub mod llff;
pub mod meta;
pub mod records;
pub mod splits;
pub mod stats;
