//! `poses_bounds.npy` from arbitrary bytes: rows or an error, never a panic, and every
//! row it accepts is finite.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(rows) = blurset_core::parse_poses_bounds(data) {
        assert!(rows.iter().flatten().all(|v| v.is_finite()));
    }
});
