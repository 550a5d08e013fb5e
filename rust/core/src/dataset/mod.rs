//! The files of a build: names and layout, LLFF poses, splits, failures, statistics,
//! atomic writes, the checksum manifest and the image check of `blurset verify`.
pub mod atomic;
pub mod failures;
pub mod layout;
pub mod license;
pub mod llff;
pub mod manifest;
pub mod meta;
pub mod outputs;
pub mod read;
pub mod records;
pub mod schema;
pub mod splits;
pub mod stats;
pub mod verify;
