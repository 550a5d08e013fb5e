//! What decoding an EXR may allocate (issue 48): a counting global allocator measures
//! the peak above what was held before each input. A file that decodes may cost a few
//! times the image it gives; a file that is refused holds nothing, so its cost must be
//! bounded by its own length (its blocks at the loosest codec's expansion), never by
//! the size its header promises. Both readers `blurset verify` tries are measured: the
//! colour one and the depth one (the `exr` crate's generic reader).
//!
//! Half the inputs are files as they come; the other half are built from the input as
//! issue 48's file was (a header whose size is drawn up to the pixel limit, a whole
//! offset table, blocks cut from the rest of the input), so the fuzzer reaches valid
//! headers that promise far more than their blocks hold within seconds.
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
) {
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
    let n = ((h + lines - 1) / lines) as usize;
    // Each block gets an equal share of `rest` (at most the bytes `p` allows).
    let share = (rest.len() / n).min(usize::from(u16::from_le_bytes([p[4], p[5]])));
    let first = (out.len() + 8 * n) as u64;
    for i in 0..n as u64 {
        out.extend_from_slice(&(first + i * (8 + share as u64)).to_le_bytes());
    }
    for i in 0..n {
        let block = &rest[i * share..(i + 1) * share];
        out.extend(ints(&[i as i32 * lines, block.len() as i32]));
        out.extend_from_slice(block);
    }
    out
}

fuzz_target!(|data: &[u8]| {
    let built;
    let file = match data.split_first() {
        Some((&pick, rest)) if pick & 1 == 1 && rest.len() >= 6 => {
            let (p, rest) = rest.split_at(6);
            built = crafted(&p.try_into().unwrap_or([0; 6]), rest);
            &built[..]
        }
        _ => data,
    };
    measure(
        "decode_exr",
        file,
        |b| blurset_core::decode_exr(b).ok(),
        |f| f.rgba.len() * 4,
    );
    measure(
        "decode_depth_exr",
        file,
        |b| blurset_core::decode_depth_exr(b, std::path::Path::new("fuzz.exr")).ok(),
        |d| d.2.len() * 4,
    );
});
