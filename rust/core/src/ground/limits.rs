//! What a file handed in (by a user, a worker or an earlier run) may make blurset
//! allocate: every reader checks the sizes a file's header promises against these
//! before it allocates, and refuses a file over one with an error naming the file and
//! the limit (issue 34; image-rs's `Limits` do the same for PNG and JPEG).

/// The most pixels of an image read (EXR frame, PNG, JPEG): 2^28 = 16384², the largest
/// image a build renders (`--resolution` ≤ 16384), and 20 times a 12 MP photo of an
/// LLFF scene. A decoded RGBA f32 frame of this size is 4 GiB.
pub const MAX_IMAGE_PIXELS: u64 = 1 << 28;

/// The longest side of an image read, in pixels: 4 × 16384. A side past it is no
/// image blurset writes or a camera takes.
pub const MAX_IMAGE_SIDE: u32 = 1 << 16;

/// The most bytes the decoder of a PNG or JPEG may allocate: MAX_IMAGE_PIXELS of
/// 16-bit RGBA (8 bytes per pixel), 2 GiB.
pub const MAX_IMAGE_ALLOC: u64 = MAX_IMAGE_PIXELS * 8;

/// The most bytes one byte of a zlib (deflate) stream inflates to: a 258-byte match
/// coded in two bits (zlib's documented bound, 1032:1). EXR's ZIP and PXR24 blocks are
/// zlib streams, and no EXR codec read expands more: an EXR header may not promise more
/// samples than its file's bytes could hold at its codec's bound (issue 48), so a file
/// refused later has cost memory in proportion to its own size, not its header's claim.
pub const ZLIB_MAX_RATIO: u64 = 1032;

/// The most bytes the images a command decodes in parallel (`blurset verify`) may hold
/// together, each counted at the most its decode may hold (its file, its samples and its
/// frame): 1 GiB, or one image alone when it is larger. Decoding a file per thread
/// multiplies the largest image's memory by the threads (issue 48).
pub const MAX_PARALLEL_DECODE_BYTES: u64 = 1 << 30;

/// The most rows of a `poses_bounds.npy`: a million views, 136 MB of float64, where a
/// build has at most 4096 views a setting (`--views`).
pub const MAX_POSE_ROWS: usize = 1 << 20;

/// The largest JSON record read (meta.json, splits.json, dataset.json, …, and
/// failures.jsonl), in bytes: 1 GiB. The largest a build writes is its splits.json
/// or dataset.json, about 200 bytes per setting: 1 GiB is five million settings, past
/// a build of all of Objaverse (800k objects × 3 settings). Parsed, a JSON value takes
/// a few times its text, so this also bounds the memory a record can claim.
pub const MAX_RECORD_BYTES: u64 = 1 << 30;

/// Refuse a decode that would hold `bytes` at once unless the process can take them now
/// (an address-space cap, a small machine): reserved and released at once, before a
/// decoder whose allocations cannot fail (the `exr` and `image` crates') makes them, so
/// a file the machine cannot hold is an error naming it, never an abort part-way
/// (issue 72: a 4 MB file promising 16384² aborted `read_depth` under a 3 GB cap).
pub fn can_hold(bytes: u64, what: &str) -> Result<(), String> {
    usize::try_from(bytes)
        .ok()
        .and_then(|n| Vec::<u8>::new().try_reserve_exact(n).ok())
        .ok_or_else(|| format!("cannot allocate {bytes} bytes for {what}"))
}

/// Refuse `n` (a size a file promises) over `limit`, named: the reason for the
/// caller's error, which names the file.
pub fn check(what: &str, n: u64, limit: u64, name: &str) -> Result<(), String> {
    if n > limit {
        return Err(format!(
            "{what}: {n}, over the limit of {limit} ({name}); refused before reading it"
        ));
    }
    Ok(())
}

#[allow(clippy::unwrap_used)] // a failing unwrap is a failing test
#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_size_over_a_limit_is_named() {
        assert_eq!(check("pixels", 4, 4, "MAX_IMAGE_PIXELS"), Ok(()));
        let e = check("pixels", 5, 4, "MAX_IMAGE_PIXELS").unwrap_err();
        assert_eq!(
            e,
            "pixels: 5, over the limit of 4 (MAX_IMAGE_PIXELS); refused before reading it"
        );
        assert_eq!(can_hold(1 << 20, "a frame"), Ok(()));
        let e = can_hold(u64::MAX, "its 9x9 frame").unwrap_err();
        assert_eq!(
            e,
            format!("cannot allocate {} bytes for its 9x9 frame", u64::MAX)
        );
    }
}
