//! What decoding an EXR may allocate (issue 48): a counting global allocator measures
//! the peak above what was held before each input. A file that decodes may cost a few
//! times the image it gives; a file that is refused holds nothing, so its cost must be
//! bounded by its own length (its blocks at the loosest codec's expansion), never by
//! the size its header promises. Both readers `blurset verify` tries are measured: the
//! colour one and the depth one (the `exr` crate's generic reader).
//!
//! A quarter of the inputs are files as they come; half are built from the input as
//! issue 48's file was (a header whose size is drawn up to the pixel limit, a whole
//! offset table, blocks cut from the rest of the input), so the fuzzer reaches valid
//! headers that promise far more than their blocks hold within seconds; a quarter are
//! valid ZIP files as issue 60's (blocks that deflate to exactly their size, up to
//! 1032:1): each must decode, at a cost bounded by its frame. On every file, a caller
//! that knows the size (verify, noise) reads another from the header alone, at a cost
//! bounded by the file.
#![no_main]
use libfuzzer_sys::fuzz_target;
use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering::Relaxed};

/// The system allocator, counting the bytes held now and their peak.
struct Counting;

static NOW: AtomicUsize = AtomicUsize::new(0);
static PEAK: AtomicUsize = AtomicUsize::new(0);

fn grew(n: usize) {
    let now = NOW.fetch_add(n, Relaxed) + n;
    PEAK.fetch_max(now, Relaxed);
}

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, l: Layout) -> *mut u8 {
        let p = unsafe { System.alloc(l) };
        if !p.is_null() {
            grew(l.size());
        }
        p
    }
    unsafe fn alloc_zeroed(&self, l: Layout) -> *mut u8 {
        let p = unsafe { System.alloc_zeroed(l) };
        if !p.is_null() {
            grew(l.size());
        }
        p
    }
    unsafe fn dealloc(&self, p: *mut u8, l: Layout) {
        unsafe { System.dealloc(p, l) };
        NOW.fetch_sub(l.size(), Relaxed);
    }
    unsafe fn realloc(&self, p: *mut u8, l: Layout, new: usize) -> *mut u8 {
        let q = unsafe { System.realloc(p, l, new) };
        if !q.is_null() {
            // Counted as a copy: the new block before the old one is freed.
            grew(new);
            NOW.fetch_sub(l.size(), Relaxed);
        }
        q
    }
}

#[global_allocator]
static ALLOC: Counting = Counting;

/// Bytes a decode may allocate per byte of the file: the loosest codec's expansion
/// (PXR24: 1032 · 4/3 bytes of samples a byte), each byte of samples becoming at most
/// 16/6 bytes of the RGBA f32 frame (a half R, G or B), with the decompressed blocks
/// and the file's chunks held beside it.
const PER_FILE_BYTE: usize = 1376 * 4 + 2;

/// A decode that succeeds may also cost this many times the image it gives.
const PER_IMAGE_BYTE: usize = 4;

/// What does not scale with the file: per-thread inflate states and scratch lines,
/// rayon's pool on first use.
const SLACK: usize = 8 << 20;

/// Run `decode` on `file` and check its peak allocation against the bounds; `held`
/// gives the bytes of the image it returned.
fn measure<T>(
    what: &str,
    file: &[u8],
    decode: impl FnOnce(&[u8]) -> Option<T>,
    held: impl Fn(&T) -> usize,
) -> Option<T> {
    let base = NOW.load(Relaxed);
    PEAK.store(base, Relaxed);
    let got = decode(file);
    let peak = PEAK.load(Relaxed).saturating_sub(base);
    let own = PER_FILE_BYTE * file.len();
    let bound = match &got {
        Some(image) => own.max(PER_IMAGE_BYTE * held(image)),
        None => own,
    } + SLACK;
    assert!(
        peak <= bound,
        "{what} of a {}-byte file ({}) allocated {peak} bytes at its peak, over {bound}",
        file.len(),
        if got.is_some() { "decoded" } else { "refused" }
    );
    got
}

/// A scan-line EXR as issue 48's: `p` picks the compression, the channels (R, G, B or
/// Z, half or float) and a size up to 16384 x 16384; the offset table is whole and its
/// blocks share the bytes of `rest`.
fn crafted(p: &[u8; 6], rest: &[u8]) -> Vec<u8> {
    // (OpenEXR's number, scan lines a block): none, RLE, ZIPS, ZIP, PIZ, PXR24, B44, B44A.
    const CODECS: [(u8, i32); 8] = [
        (0, 1),
        (1, 1),
        (2, 1),
        (3, 16),
        (4, 32),
        (5, 16),
        (6, 32),
        (7, 32),
    ];
    let (code, lines) = CODECS[p[0] as usize % CODECS.len()];
    let ty = 1 + i32::from(p[1] & 1); // half or float
    let names: &[&str] = if p[1] & 2 == 0 {
        &["B", "G", "R"]
    } else {
        &["Z"]
    };
    let side = |b: u8| 1i32 << (b % 15); // 1 to 16384
    let (w, h) = (side(p[2]), side(p[3]));
    let n = ((h + lines - 1) / lines) as usize;
    // Each block gets an equal share of `rest` (at most the bytes `p` allows).
    let share = (rest.len() / n).min(usize::from(u16::from_le_bytes([p[4], p[5]])));
    let blocks = (0..n).map(|i| rest[i * share..(i + 1) * share].to_vec());
    with_blocks(header(names, ty, code, w, h), lines, blocks.collect())
}

/// A valid scan-line EXR as issue 60's: `p` picks ZIP or ZIPS, the channels (R, G, B,
/// optional A; half or float), a size up to 511 x 511 and the deflate level; each
/// block is `rest` repeated to the block's bytes and deflated whole (any bytes are the
/// split, predicted form of some samples). Returns the file and its size.
fn valid_zip(p: &[u8; 6], rest: &[u8]) -> (Vec<u8>, (usize, usize)) {
    let (code, lines) = if p[0] & 1 == 0 { (2, 1) } else { (3, 16) };
    let (ty, bytes) = if p[1] & 1 == 0 { (1, 2) } else { (2, 4) };
    let names: &[&str] = if p[1] & 2 == 0 {
        &["B", "G", "R"]
    } else {
        &["A", "B", "G", "R"]
    };
    let (w, h) = (1 + 2 * usize::from(p[2]), 1 + 2 * usize::from(p[3]));
    let level = i32::from(p[4] % 10);
    let pattern: &[u8] = if rest.is_empty() { &[0] } else { rest };
    let blocks = (0..h.div_ceil(lines)).map(|i| {
        let rows = lines.min(h - i * lines);
        let raw: Vec<u8> = pattern
            .iter()
            .cycle()
            .take(rows * w * names.len() * bytes)
            .copied()
            .collect();
        let mut out = vec![0u8; zlib_rs::compress_bound(raw.len())];
        let (z, _) = zlib_rs::compress_slice(&mut out, &raw, zlib_rs::DeflateConfig::new(level));
        z.to_vec()
    });
    let head = header(names, ty, code, w as i32, h as i32);
    (with_blocks(head, lines as i32, blocks.collect()), (w, h))
}

/// A single-part scan-line EXR header: `names` channels of sample type `ty` (1 half,
/// 2 float), OpenEXR compression number `code`, a `w` x `h` data and display window.
fn header(names: &[&str], ty: i32, code: u8, w: i32, h: i32) -> Vec<u8> {
    let ints = |v: &[i32]| -> Vec<u8> { v.iter().flat_map(|x| x.to_le_bytes()).collect() };
    let attr = |out: &mut Vec<u8>, name: &str, ty: &str, value: &[u8]| {
        for s in [name, ty] {
            out.extend_from_slice(s.as_bytes());
            out.push(0);
        }
        out.extend_from_slice(&(value.len() as i32).to_le_bytes());
        out.extend_from_slice(value);
    };
    let mut out = ints(&[20_000_630, 2]);
    let mut chlist = Vec::new();
    for n in names {
        chlist.extend_from_slice(n.as_bytes());
        chlist.push(0);
        chlist.extend(ints(&[ty, 0, 1, 1]));
    }
    chlist.push(0);
    attr(&mut out, "channels", "chlist", &chlist);
    attr(&mut out, "compression", "compression", &[code]);
    let window = ints(&[0, 0, w - 1, h - 1]);
    attr(&mut out, "dataWindow", "box2i", &window);
    attr(&mut out, "displayWindow", "box2i", &window);
    attr(&mut out, "lineOrder", "lineOrder", &[0]);
    attr(&mut out, "pixelAspectRatio", "float", &1f32.to_le_bytes());
    attr(&mut out, "screenWindowCenter", "v2f", &[0; 8]);
    attr(&mut out, "screenWindowWidth", "float", &1f32.to_le_bytes());
    out.push(0);
    out
}

/// `head` followed by a whole offset table and `blocks` (`lines` scan lines each).
fn with_blocks(mut out: Vec<u8>, lines: i32, blocks: Vec<Vec<u8>>) -> Vec<u8> {
    let mut at = (out.len() + 8 * blocks.len()) as u64;
    for b in &blocks {
        out.extend_from_slice(&at.to_le_bytes());
        at += 8 + b.len() as u64;
    }
    for (i, b) in blocks.iter().enumerate() {
        out.extend_from_slice(&(i as i32 * lines).to_le_bytes());
        out.extend_from_slice(&(b.len() as i32).to_le_bytes());
        out.extend_from_slice(b);
    }
    out
}

/// The size a caller expects, other than the file's: read from the header alone, at a
/// cost bounded by the file.
fn other_size_is_named(file: &[u8]) {
    let Ok(size) = exr_size_of(file) else {
        return;
    };
    let want = (size.0.wrapping_add(1), size.1);
    let got = measure(
        "header_size_other_than",
        file,
        |b| blurset_core::header_size_other_than(b, want),
        |_| 0,
    );
    assert_eq!(got, Some(size), "the header's size is not named");
}

/// The first layer's size by the `exr` crate's header reader.
fn exr_size_of(file: &[u8]) -> Result<(u32, u32), ()> {
    let meta = exr::meta::MetaData::read_from_buffered(file, false).map_err(|_| ())?;
    let h = meta.headers.first().ok_or(())?;
    let side = |n: usize| u32::try_from(n).map_err(|_| ());
    Ok((side(h.layer_size.width())?, side(h.layer_size.height())?))
}

fuzz_target!(|data: &[u8]| {
    let built;
    let mut size = None;
    let file = match data.split_first() {
        Some((&pick, rest)) if pick & 1 == 1 && rest.len() >= 6 => {
            let (p, rest) = rest.split_at(6);
            built = crafted(&p.try_into().unwrap_or([0; 6]), rest);
            &built[..]
        }
        Some((&pick, rest)) if pick & 3 == 2 && rest.len() >= 6 => {
            let (p, rest) = rest.split_at(6);
            let (file, wh) = valid_zip(&p.try_into().unwrap_or([0; 6]), rest);
            (built, size) = (file, Some(wh));
            &built[..]
        }
        _ => data,
    };
    let frame = measure(
        "decode_exr",
        file,
        |b| blurset_core::decode_exr(b).ok(),
        |f| f.rgba.len() * 4,
    );
    if let Some((w, h)) = size {
        // A valid file decodes whole, however well it compresses.
        let got = frame.map(|f| (f.width as usize, f.height as usize));
        assert_eq!(got, Some((w, h)), "a valid ZIP file did not decode");
    }
    measure(
        "decode_depth_exr",
        file,
        |b| blurset_core::decode_depth_exr(b, std::path::Path::new("fuzz.exr")).ok(),
        |d| d.2.len() * 4,
    );
    other_size_is_named(file);
});
