//! The files of a build: layout, LLFF poses, splits, failures, statistics, the
//! checksum manifest and the image check of `blurset verify` (names, atomic writes and
//! licence ids are `ground`'s).
pub mod build_tail;
pub mod failures;
pub mod finished;
pub mod layout;
pub mod llff;
pub mod manifest;
pub mod meta;
pub mod noise_output;
pub mod noise_plan;
pub mod outputs;
pub mod read;
pub mod records;
pub mod schema;
pub mod session;
pub mod splits;
pub mod stats;
pub mod target_loop;
pub mod verify;
pub mod wire;
