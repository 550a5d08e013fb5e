//! An EXR frame from arbitrary bytes: a frame or an error, never a panic, and never an
//! allocation past the limits a header may promise (`ground/limits.rs`); a frame it
//! gives holds width · height RGBA pixels.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(f) = blurset_core::decode_exr(data) {
        assert_eq!(f.rgba.len(), f.width as usize * f.height as usize * 4);
    }
});
