//! Reading a linear RGBA EXR frame (a latent render) into an interleaved f32 buffer,
//! as fast as the file's codec allows.
//!
//! The `exr` crate parses the header and the offset table and cuts the chunks. Scan-line
//! files stored without compression or with ZIP/ZIPS (Blender's codecs for latent
//! frames) are decoded here: each block is inflated straight into a per-thread buffer,
//! the ZIP byte predictor is undone in place, and the two byte halves are read back as
//! samples directly into the frame, so no block is copied or re-interleaved on the way.
//! Every other layout (tiles, PIZ, RLE, …) goes through the crate's own decompressor.
//! Blocks are decoded in parallel on the rayon pool; each block also reports whether it
//! held a NaN or inf, so the accumulator needs no second pass to refuse such a frame.
use crate::error::{Error, Result};
use crate::ground::limits::{self, MAX_IMAGE_PIXELS, MAX_IMAGE_SIDE};
use crate::image::CH;
use exr::block::chunk::{Chunk, CompressedBlock};
use exr::block::UncompressedBlock;
use exr::compression::Compression;
use exr::math::Vec2;
use exr::meta::attribute::{ChannelList, SampleType};
use exr::meta::header::Header;
use exr::meta::{BlockDescription, MetaData};
use rayon::prelude::*;
use std::cell::RefCell;
use std::io::Cursor;
use std::path::Path;

/// An RGBA f32 image read from an EXR file: `rgba` is row-major, 4 channels per pixel.
#[derive(Clone, Debug, PartialEq)]
pub struct Frame {
    pub width: u32,
    pub height: u32,
    pub rgba: Vec<f32>,
}

/// [`read_exr`] of a file that must be `want` (width, height) when given: another size
/// is refused from its header ([`check_exr_size`]) before anything is decoded.
pub fn read_exr_sized(path: &Path, want: Option<(u32, u32)>) -> Result<Frame> {
    if let Some(want) = want {
        check_exr_size(path, want)?;
    }
    read_exr(path)
}

/// Read the first RGB(A) layer of an EXR file as RGBA f32 (alpha 1 when the file has none).
///
/// Channels are matched by name (`R`, `G`, `B`, optional `A`; half, float or uint
/// samples); blocks are decompressed in parallel on the rayon pool. Values are returned
/// as stored: no check for NaN or inf (see
/// [`crate::image::accumulate::Accumulator::add_exr`]).
pub fn read_exr(path: &Path) -> Result<Frame> {
    let bytes = std::fs::read(path).map_err(|e| Error::io("cannot open EXR", path, e))?;
    frame_of(&bytes, path)
}

/// Decode an EXR file held in memory (as [`read_exr`]; errors name it `<bytes>`).
/// Arbitrary bytes give a frame or an error, never a panic nor an allocation past
/// [`MAX_IMAGE_PIXELS`], nor more than a few times the frame given or, for an error, a
/// bound proportional to `bytes.len()` (fuzzed: exr, exr_memory).
pub fn decode_exr(bytes: &[u8]) -> Result<Frame> {
    frame_of(bytes, Path::new("<bytes>"))
}

fn frame_of(bytes: &[u8], path: &Path) -> Result<Frame> {
    let mut rgba = Vec::new();
    let d = decode_rgba(bytes, path, &mut rgba)?;
    Ok(Frame {
        width: d.width as u32,
        height: d.height as u32,
        rgba,
    })
}

/// The first layer size (width, height) in `meta` other than `want`.
fn other_size(meta: &MetaData, want: (u32, u32)) -> Option<(u32, u32)> {
    let side = |n: usize| u32::try_from(n).unwrap_or(u32::MAX);
    meta.headers
        .iter()
        .map(|h| (side(h.layer_size.width()), side(h.layer_size.height())))
        .find(|&s| s != want)
}

/// The size of the first layer of the EXR file `bytes` that is not `want` (width,
/// height), read from its headers alone; None when every layer is `want` or the headers
/// do not parse (its decode then says why). A caller that knows the size a file must
/// have (a build's meta.json) refuses one of another size before anything of the size
/// it claims is allocated: a valid 4 MB ZIP file holds a blank 16384² frame of 4 GiB,
/// as blank frames compress that well (issue 60).
pub fn header_size_other_than(bytes: &[u8], want: (u32, u32)) -> Option<(u32, u32)> {
    MetaData::read_from_buffered(Cursor::new(bytes), false)
        .ok()
        .and_then(|meta| other_size(&meta, want))
}

/// The size (width, height) of the first layer of the EXR file at `path`, from its
/// headers alone.
pub fn exr_size(path: &Path) -> Result<(u32, u32)> {
    let meta = MetaData::read_from_file(path, false).map_err(|e| Error::Image {
        reason: exr_reason(e),
        path: path.to_path_buf(),
    })?;
    let side = |n: usize| u32::try_from(n).unwrap_or(u32::MAX);
    Ok(meta.headers.first().map_or((0, 0), |h| {
        (side(h.layer_size.width()), side(h.layer_size.height()))
    }))
}

/// Refuse the EXR file at `path` unless every layer its headers describe is `want`
/// (width, height), from the headers alone: see [`header_size_other_than`].
pub fn check_exr_size(path: &Path, want: (u32, u32)) -> Result<()> {
    let bad = |reason: String| Error::Image {
        reason,
        path: path.to_path_buf(),
    };
    let meta = MetaData::read_from_file(path, false).map_err(|e| bad(exr_reason(e)))?;
    match other_size(&meta, want) {
        None => Ok(()),
        Some((w, h)) => Err(bad(format!(
            "EXR is {w}x{h}, expected {}x{}; refused before decoding it",
            want.0, want.1
        ))),
    }
}

/// Refuse a file whose headers promise a layer past [`MAX_IMAGE_SIDE`] or
/// [`MAX_IMAGE_PIXELS`], or more samples than the file's `file_len` bytes can hold under
/// its codecs ([`max_expansion`]), before anything of that size is allocated: the
/// reason, for the caller to pair with its file. What a decode then allocates is
/// bounded by the file's own size, whether its blocks turn out whole or not.
pub(crate) fn check_sizes(meta: &MetaData, file_len: usize) -> std::result::Result<(), String> {
    for h in &meta.headers {
        let (w, ht) = (h.layer_size.width() as u64, h.layer_size.height() as u64);
        let side = u64::from(MAX_IMAGE_SIDE);
        let what = format!("EXR header promises a {w}x{ht} layer");
        limits::check(&format!("{what}, side"), w.max(ht), side, "MAX_IMAGE_SIDE")?;
        limits::check(
            &format!("{what}, pixels"),
            w * ht,
            MAX_IMAGE_PIXELS,
            "MAX_IMAGE_PIXELS",
        )?;
    }
    check_fits_file(meta, file_len as u64)
}

/// The most bytes a decode of the EXR file at `path` may hold at once: the file, the
/// samples its headers promise and their RGBA f32 frame; a file whose header does not
/// parse or is refused costs its length. For callers that decode many files at once
/// and bound their sum.
pub(crate) fn decode_cost(path: &Path) -> u64 {
    let len = std::fs::metadata(path).map_or(0, |m| m.len());
    let Ok(meta) = MetaData::read_from_file(path, false) else {
        return len;
    };
    if check_sizes(&meta, len as usize).is_err() {
        return len;
    }
    let frame = |h: &Header| (h.layer_size.area() * CH * 4) as u64;
    let held: u64 = meta
        .headers
        .iter()
        .filter(|h| !h.deep)
        .map(|h| level0_bytes(h) + frame(h))
        .sum();
    len + held
}

/// The bytes of samples of a layer's full-resolution level (subsampled channels count
/// their own samples): what a decode of it holds before conversion.
pub(crate) fn level0_bytes(h: &Header) -> u64 {
    let (w, ht) = (h.layer_size.width() as u64, h.layer_size.height() as u64);
    h.channels
        .list
        .iter()
        .map(|c| {
            let (sx, sy) = (c.sampling.x().max(1) as u64, c.sampling.y().max(1) as u64);
            w.div_ceil(sx) * ht.div_ceil(sy) * c.sample_type.bytes_per_sample() as u64
        })
        .sum()
}

/// The most bytes of samples one byte of a block can become under `c`, or `None` for
/// the codecs not read: DWAA/DWAB (lossy DCT; a block of a few bytes can claim a whole
/// layer) and HTJ2K (the crate does not decode it).
fn max_expansion(c: Compression) -> Option<u64> {
    Some(match c {
        Compression::Uncompressed => 1,
        // A count byte and a value byte make at most 128 equal bytes.
        Compression::RLE => 64,
        Compression::ZIP1 | Compression::ZIP16 => limits::ZLIB_MAX_RATIO,
        // Huffman codes of at least one bit, and a run code with an 8-bit count repeats
        // at most 255 values of 2 bytes: under 512 bytes per byte.
        Compression::PIZ => 512,
        // 4-byte samples are deflated as 3 bytes.
        Compression::PXR24 => limits::ZLIB_MAX_RATIO * 4 / 3,
        // A 4x4 block of halves (32 bytes) in at least 3 bytes; other samples raw.
        Compression::B44 | Compression::B44A => 11,
        _ => return None,
    })
}

/// The samples every (flat) header promises must fit the file: at least
/// `bytes / max_expansion` bytes of blocks each, together no more than `file_len`.
/// Checked before the output (or the crate's channels) are allocated, so a header at
/// the pixel limit over a file of tiny blocks is refused at the cost of its own bytes.
fn check_fits_file(meta: &MetaData, file_len: u64) -> std::result::Result<(), String> {
    let mut least = 0u64;
    for h in meta.headers.iter().filter(|h| !h.deep) {
        let ratio = max_expansion(h.compression)
            .ok_or_else(|| format!("EXR {} is not read", h.compression))?;
        let bytes = level0_bytes(h);
        least = least.saturating_add(bytes.div_ceil(ratio));
        if least > file_len {
            let (w, ht) = (h.layer_size.width(), h.layer_size.height());
            return Err(format!(
                "EXR header promises a {w}x{ht} layer of {bytes} bytes of samples, more than \
                 a file of {file_len} bytes can hold under {} (at most {ratio}:1); \
                 refused before reading it",
                h.compression
            ));
        }
    }
    Ok(())
}

/// The blocks of the full-resolution level of a layer (scan-line blocks or tiles).
fn level0_blocks(header: &Header, width: usize, height: usize) -> usize {
    match header.blocks {
        BlockDescription::ScanLines => height.div_ceil(header.compression.scan_lines_per_block()),
        BlockDescription::Tiles(t) => {
            width.div_ceil(t.tile_size.width().max(1))
                * height.div_ceil(t.tile_size.height().max(1))
        }
    }
}

/// Read a whole file into `buf`, reusing its memory; on Unix the two halves are read
/// at once on the rayon pool (the copy out of the page cache is a visible share of a
/// frame's time).
pub(crate) fn read_into(path: &Path, buf: &mut Vec<u8>) -> Result<()> {
    use std::io::Read;
    let err = |e| Error::io("cannot open EXR", path, e);
    let mut f = std::fs::File::open(path).map_err(err)?;
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileExt;
        let len = f.metadata().map_err(err)?.len();
        if let Ok(len) = usize::try_from(len) {
            buf.resize(len, 0);
            let (a, b) = buf.split_at_mut(len / 2);
            let (ra, rb) = rayon::join(
                || f.read_exact_at(a, 0),
                || f.read_exact_at(b, (len / 2) as u64),
            );
            ra.and(rb).map_err(err)?;
            // A file that grew since `metadata` keeps its tail.
            f.read_to_end(buf).map_err(err)?;
            return Ok(());
        }
    }
    buf.clear();
    f.read_to_end(buf).map_err(err)?;
    Ok(())
}

/// A NaN or inf found in a frame: pixel x, y, RGBA channel index, value.
pub(crate) type NonFinite = (usize, usize, usize, f32);

/// Size of a decoded frame and its first non-finite value in row-major order.
pub(crate) struct Decoded {
    pub width: usize,
    pub height: usize,
    pub non_finite: Option<NonFinite>,
}

/// Decode the first flat RGB(A) layer of the EXR file `bytes` into `rgba` (resized to
/// width · height · 4; alpha 1 when the layer has none). `path` only names the file
/// in errors.
pub(crate) fn decode_rgba(bytes: &[u8], path: &Path, rgba: &mut Vec<f32>) -> Result<Decoded> {
    let bad = |reason: String| Error::Image {
        reason,
        path: path.to_path_buf(),
    };
    let reader = exr::block::read(Cursor::new(bytes), false).map_err(|e| bad(exr_reason(e)))?;
    let meta = reader.meta_data().clone();
    // Every header is checked before anything of its size is allocated.
    check_sizes(&meta, bytes.len()).map_err(bad)?;
    let layer = rgb_layer(&meta).map_err(bad)?;
    let header = &meta.headers[layer];
    check_uncropped(header).map_err(bad)?;
    let slots = rgba_slots(header).map_err(bad)?;
    let (width, height) = (header.layer_size.width(), header.layer_size.height());
    if width == 0 || height == 0 {
        return Err(bad("empty image".into()));
    }
    let non_finite = decode_layer(bytes, reader, &meta, layer, &slots, rgba).map_err(bad)?;
    Ok(Decoded {
        width,
        height,
        non_finite,
    })
}

fn exr_reason(e: exr::error::Error) -> String {
    format!("EXR: {e}")
}

/// The first flat layer with R, G and B channels: the rendered colour.
fn rgb_layer(meta: &MetaData) -> std::result::Result<usize, String> {
    let has_rgb = |h: &Header| {
        ["R", "G", "B"]
            .iter()
            .all(|c| h.channels.list.iter().any(|ch| ch.name.eq(c)))
    };
    meta.headers
        .iter()
        .position(|h| !h.deep && has_rgb(h))
        .ok_or_else(|| {
            let names: Vec<String> = meta
                .headers
                .iter()
                .flat_map(|h| h.channels.list.iter().map(|c| c.name.to_string()))
                .collect();
            format!("no flat layer with R, G, B channels (channels: {names:?})")
        })
}

/// A layer's pixels must cover exactly its display window: a crop render would be
/// averaged as if it were the whole frame.
fn check_uncropped(header: &Header) -> std::result::Result<(), String> {
    let display = header.shared_attributes.display_window;
    let (width, height) = (header.layer_size.width(), header.layer_size.height());
    if header.own_attributes.layer_position != display.position || header.layer_size != display.size
    {
        return Err(format!(
            "data window ({width}x{height} at {:?}) differs from the display window ({}x{} at {:?}); crop renders are not supported",
            header.own_attributes.layer_position,
            display.size.width(),
            display.size.height(),
            display.position
        ));
    }
    Ok(())
}

/// Where each of the layer's channels goes in an RGBA pixel (`None`: not read);
/// the channels read must have a sample at every pixel.
fn rgba_slots(header: &Header) -> std::result::Result<Vec<Option<usize>>, String> {
    let slots: Vec<Option<usize>> = header
        .channels
        .list
        .iter()
        .map(|c| ["R", "G", "B", "A"].iter().position(|n| c.name.eq(n)))
        .collect();
    if let Some(c) = header
        .channels
        .list
        .iter()
        .zip(&slots)
        .find(|(c, s)| s.is_some() && c.sampling != Vec2(1, 1))
    {
        return Err(format!("channel {} is subsampled", c.0.name));
    }
    Ok(slots)
}

/// Whether the layer is one this file decodes itself: scan lines, stored raw or with
/// ZIP, every channel at full resolution (Blender's latent frames).
fn decoded_here(header: &Header) -> bool {
    matches!(
        header.compression,
        Compression::Uncompressed | Compression::ZIP1 | Compression::ZIP16
    ) && matches!(header.blocks, BlockDescription::ScanLines)
        && header
            .channels
            .list
            .iter()
            .all(|c| c.sampling == Vec2(1, 1))
}

/// Decode the layer into `rgba` and find its first non-finite value: here when
/// [`decoded_here`] says so, straight into the frame, else through the crate's
/// decompressor. A file with fewer blocks than its header's size needs is refused
/// before the frame is allocated.
fn decode_layer(
    bytes: &[u8],
    reader: exr::block::reader::Reader<Cursor<&[u8]>>,
    meta: &MetaData,
    layer: usize,
    slots: &[Option<usize>],
    rgba: &mut Vec<f32>,
) -> std::result::Result<Option<NonFinite>, String> {
    let header = &meta.headers[layer];
    let (width, height) = (header.layer_size.width(), header.layer_size.height());
    let need = level0_blocks(header, width, height);
    let too_few = |have: usize, what: &str| {
        format!("{have} {what} for a {width}x{height} image, expected {need}")
    };
    if !decoded_here(header) {
        let chunks = read_chunks(reader, layer).map_err(exr_reason)?;
        if chunks.len() < need {
            return Err(too_few(chunks.len(), "blocks"));
        }
        // Every block is decompressed before the frame is allocated: a file whose
        // blocks do not decode costs what they held, not what its header promised.
        // The crate's allocations cannot fail: the process must hold the blocks first.
        limits::can_hold(
            level0_bytes(header),
            &format!("its {width}x{height} samples"),
        )?;
        let blocks = decompress_chunks(chunks, meta)?;
        // The crate's blocks write the channels the file has: a missing alpha reads 1.
        let has_alpha = slots.contains(&Some(3));
        let fill = if has_alpha { 0.0 } else { 1.0 };
        sized_frame(rgba, width, height, fill)?;
        for b in &blocks {
            place_block(b, &header.channels, slots, rgba, width)?;
        }
        return Ok(first_non_finite(width, rgba));
    }
    // Single-part files: the chunks are sliced out of `bytes` in place; a
    // multi-part file's chunks are cut (copied) by the crate.
    let owned;
    let blocks: Vec<(i32, &[u8])> = match single_part_chunks(bytes, header.chunk_count) {
        Some(blocks) if meta.headers.len() == 1 => blocks,
        _ => {
            owned = read_chunks(reader, layer).map_err(exr_reason)?;
            owned
                .iter()
                .filter_map(|c| match &c.compressed_block {
                    CompressedBlock::ScanLine(b) => {
                        Some((b.y_coordinate, b.compressed_pixels_le.as_slice()))
                    }
                    _ => None,
                })
                .collect()
        }
    };
    if blocks.len() < need {
        return Err(too_few(blocks.len(), "scan-line blocks"));
    }
    // Every value of the frame is written (a missing block is an error), so a
    // buffer of the right size is reused as it is.
    if rgba.len() != width * height * CH {
        sized_frame(rgba, width, height, 0.0)?;
    }
    decode_scanlines(&blocks, header, slots, width, height, rgba)
}

/// `rgba` as a `width` x `height` RGBA frame of `fill`, or the reason it cannot be held:
/// a frame past the memory the process may take (an address-space cap, a small
/// machine) is an error naming the file, not an abort.
fn sized_frame(
    rgba: &mut Vec<f32>,
    width: usize,
    height: usize,
    fill: f32,
) -> std::result::Result<(), String> {
    let n = width * height * CH;
    rgba.clear();
    rgba.try_reserve_exact(n).map_err(|_| {
        format!(
            "cannot allocate {} bytes for its {width}x{height} RGBA frame",
            (n as u64).saturating_mul(4)
        )
    })?;
    rgba.resize(n, fill);
    Ok(())
}

/// The chunks of one layer's full-resolution level, cut (copied) by the `exr` crate.
fn read_chunks(
    reader: exr::block::reader::Reader<Cursor<&[u8]>>,
    layer: usize,
) -> exr::error::Result<Vec<Chunk>> {
    reader
        .filter_chunks(false, |_, tile, block| {
            block.layer == layer && tile.level_index == Vec2(0, 0)
        })?
        .collect()
}

/// The (y, data) chunks of a single-part file, sliced out of its bytes: the header's
/// attributes (`name\0type\0size value`, ended by a null byte), the offset table of
/// `chunk_count` u64, then at each offset `y: i32, size: i32, data`. `None` if the
/// bytes do not have that shape (the caller then lets the crate read them).
fn single_part_chunks(bytes: &[u8], chunk_count: usize) -> Option<Vec<(i32, &[u8])>> {
    let i32_at = |at: usize| -> Option<i32> {
        Some(i32::from_le_bytes(
            bytes.get(at..at.checked_add(4)?)?.try_into().ok()?,
        ))
    };
    // Magic number and version; bit 12 marks multi-part files.
    if i32_at(0)? != 20_000_630 || i32_at(4)? & 0x1000 != 0 {
        return None;
    }
    let mut at = 8;
    while *bytes.get(at)? != 0 {
        for _ in 0..2 {
            at += bytes.get(at..)?.iter().position(|&b| b == 0)? + 1;
        }
        at = at.checked_add(4 + usize::try_from(i32_at(at)?).ok()?)?;
    }
    at += 1;
    let table = bytes.get(at..at.checked_add(chunk_count.checked_mul(8)?)?)?;
    table
        .chunks_exact(8)
        .map(|o| {
            let off = usize::try_from(u64::from_le_bytes(o.try_into().ok()?)).ok()?;
            let data = off.checked_add(8)?;
            let size = usize::try_from(i32_at(off.checked_add(4)?)?).ok()?;
            Some((i32_at(off)?, bytes.get(data..data.checked_add(size)?)?))
        })
        .collect()
}

/// The first non-finite value of an RGBA buffer in row-major order.
pub(crate) fn first_non_finite(width: usize, rgba: &[f32]) -> Option<NonFinite> {
    let row = (width * CH).max(1);
    let (r, i) = rgba.par_chunks(row).enumerate().find_map_first(|(r, s)| {
        if s.iter().all(|v| v.is_finite()) {
            None
        } else {
            s.iter().position(|v| !v.is_finite()).map(|i| (r, i))
        }
    })?;
    Some((i / CH, r, i % CH, rgba[r * row + i]))
}

thread_local! {
    /// Inflated bytes of the block being decoded (one per rayon worker, reused).
    static SCRATCH: RefCell<Vec<u8>> = const { RefCell::new(Vec::new()) };
}

/// Scan-line blocks, uncompressed or ZIP/ZIPS, decoded block-parallel into `rgba`.
fn decode_scanlines(
    chunks: &[(i32, &[u8])],
    header: &Header,
    slots: &[Option<usize>],
    width: usize,
    height: usize,
    rgba: &mut [f32],
) -> std::result::Result<Option<NonFinite>, String> {
    let row = width * CH;
    let lines = header.compression.scan_lines_per_block();
    let line_bytes: usize = header
        .channels
        .list
        .iter()
        .map(|c| width * c.sample_type.bytes_per_sample())
        .sum();
    // Each block owns its rows of the frame; a file that repeats a block is refused.
    let mut dst_rows: Vec<Option<&mut [f32]>> = rgba.chunks_mut(lines * row).map(Some).collect();
    let mut parts: Vec<Option<(&[u8], &mut [f32])>> = Vec::new();
    parts.resize_with(dst_rows.len(), || None);
    for &(y, data) in chunks {
        let y = i64::from(y) - i64::from(header.own_attributes.layer_position.y());
        let index = usize::try_from(y)
            .ok()
            .filter(|y| y % lines == 0 && *y < height)
            .map(|y| y / lines)
            .ok_or_else(|| format!("scan-line block at y = {y} lies outside the image"))?;
        let dst = dst_rows[index]
            .take()
            .ok_or_else(|| format!("scan-line block at y = {y} appears twice"))?;
        parts[index] = Some((data, dst));
    }
    if let Some(missing) = parts.iter().position(Option::is_none) {
        return Err(format!(
            "scan-line block at y = {} is missing",
            missing * lines
        ));
    }
    let compression = header.compression;
    let found = parts
        .into_par_iter()
        .enumerate()
        .filter_map(|(i, p)| p.map(|p| (i, p)))
        .map(|(i, (data, dst))| {
            let n_lines = dst.len() / row.max(1);
            let expected = n_lines * line_bytes;
            let bad = decode_block(compression, data, expected, header, slots, width, dst)?;
            // The first non-finite value of the block, row-major (channel lines come
            // in name order, so look again in pixel order).
            Ok(bad
                .then(|| {
                    dst.iter()
                        .position(|v| !v.is_finite())
                        .map(|k| ((k % row) / CH, i * lines + k / row, k % CH, dst[k]))
                })
                .flatten())
        })
        .collect::<std::result::Result<Vec<Option<NonFinite>>, String>>()?;
    Ok(found.into_iter().flatten().next())
}

/// Decode one scan-line block into its rows; true if it held a NaN or inf in R, G, B or A.
fn decode_block(
    compression: Compression,
    data: &[u8],
    expected: usize,
    header: &Header,
    slots: &[Option<usize>],
    width: usize,
    dst: &mut [f32],
) -> std::result::Result<bool, String> {
    // A block whose compressed form would not be smaller is stored raw (OpenEXR rule).
    if compression == Compression::Uncompressed || data.len() == expected {
        if data.len() != expected {
            return Err(format!(
                "uncompressed block holds {} bytes, expected {expected}",
                data.len()
            ));
        }
        return Ok(scatter(
            &header.channels,
            slots,
            width,
            dst,
            Bytes::Raw(data),
        ));
    }
    SCRATCH.with(|s| {
        let mut buf = s.borrow_mut();
        let more = expected.saturating_sub(buf.len());
        buf.try_reserve(more)
            .map_err(|_| format!("cannot allocate {expected} bytes for a block"))?;
        buf.resize(expected, 0);
        inflate_zlib(data, &mut buf)?;
        undo_predictor(&mut buf);
        let (lo, hi) = buf.split_at(expected.div_ceil(2));
        Ok(scatter(
            &header.channels,
            slots,
            width,
            dst,
            Bytes::Split(lo, hi),
        ))
    })
}

thread_local! {
    /// One inflate state per rayon worker, reset between blocks (its window is
    /// allocated once instead of once per block).
    static INFLATE: RefCell<Option<zlib_rs::Inflate>> = const { RefCell::new(None) };
}

/// Inflate a zlib stream into exactly `out.len()` bytes.
fn inflate_zlib(data: &[u8], out: &mut [u8]) -> std::result::Result<(), String> {
    INFLATE.with(|cell| {
        let mut slot = cell.borrow_mut();
        let inflate = match slot.as_mut() {
            Some(i) => {
                i.reset(true);
                i
            }
            None => slot.insert(zlib_rs::Inflate::new(true, 15)),
        };
        let want = out.len();
        let status = inflate.decompress(data, out, zlib_rs::InflateFlush::Finish);
        match status {
            Ok(zlib_rs::Status::StreamEnd) if inflate.total_out() == want as u64 => Ok(()),
            other => Err(format!(
                "ZIP block does not inflate to {want} bytes ({other:?}, {} bytes)",
                inflate.total_out()
            )),
        }
    })
}

/// Undo OpenEXR's ZIP predictor: each byte was stored as the difference to the one
/// before it, plus 128 (mod 256), so the data is a running sum.
fn undo_predictor(buf: &mut [u8]) {
    #[cfg(target_arch = "x86_64")]
    {
        // SAFETY: SSE2 is part of the x86_64 baseline.
        unsafe { undo_predictor_sse2(buf) }
    }
    #[cfg(not(target_arch = "x86_64"))]
    undo_predictor_swar(buf)
}

/// The running sum 16 bytes at a time: a log-step prefix sum inside the register plus
/// the carry-in byte broadcast from the block before.
///
/// # Safety
/// The CPU must support SSE2 (every x86_64 CPU does).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "sse2")]
unsafe fn undo_predictor_sse2(buf: &mut [u8]) {
    use std::arch::x86_64::*;
    let Some(&first) = buf.first() else {
        return;
    };
    let rest = &mut buf[1..];
    let bias = _mm_set1_epi8(-128);
    let mut prev = _mm_set1_epi8(first as i8);
    let mut chunks = rest.chunks_exact_mut(16);
    for c in &mut chunks {
        let p = c.as_mut_ptr() as *mut __m128i;
        let mut x = _mm_xor_si128(_mm_loadu_si128(p), bias);
        x = _mm_add_epi8(x, _mm_slli_si128::<1>(x));
        x = _mm_add_epi8(x, _mm_slli_si128::<2>(x));
        x = _mm_add_epi8(x, _mm_slli_si128::<4>(x));
        x = _mm_add_epi8(x, _mm_slli_si128::<8>(x));
        x = _mm_add_epi8(x, prev);
        _mm_storeu_si128(p, x);
        // Broadcast byte 15 for the next block.
        let hi = _mm_shufflehi_epi16::<0xFF>(_mm_unpackhi_epi8(x, x));
        prev = _mm_shuffle_epi32::<0xFF>(hi);
    }
    let mut last = _mm_cvtsi128_si32(prev) as u8;
    for v in chunks.into_remainder() {
        last = last.wrapping_add(*v ^ 0x80);
        *v = last;
    }
}

/// The running sum without SIMD intrinsics, eight bytes per step: the even and odd
/// bytes go to 16-bit lanes, where one multiplication forms the prefix sums of the
/// byte pairs (at most 4 · 510 per lane, so no lane overflows), and only the carry-in
/// byte waits for the step before.
#[cfg_attr(target_arch = "x86_64", allow(dead_code))]
fn undo_predictor_swar(buf: &mut [u8]) {
    const LOW: u64 = 0x00FF_00FF_00FF_00FF;
    let Some((first, rest)) = buf.split_first_mut() else {
        return;
    };
    let mut prev = u64::from(*first);
    let mut words = rest.chunks_exact_mut(8);
    for w in &mut words {
        let mut le = [0u8; 8];
        le.copy_from_slice(w);
        let x = u64::from_le_bytes(le) ^ 0x8080_8080_8080_8080;
        let even = x & LOW;
        let odd = (x >> 8) & LOW;
        // Lane i holds the sum of bytes 0 ..= 2i + 1 (mod 2^16).
        let pairs = (even + odd).wrapping_mul(0x0001_0001_0001_0001);
        let carry = prev * 0x0001_0001_0001_0001;
        let at_odd = pairs + carry;
        let at_even = at_odd - odd;
        let y = (at_even & LOW) | ((at_odd & LOW) << 8);
        w.copy_from_slice(&y.to_le_bytes());
        prev = y >> 56;
    }
    let mut prev = prev as u8;
    for v in words.into_remainder() {
        prev = prev.wrapping_add(*v ^ 0x80);
        *v = prev;
    }
}

/// The bytes of one block in file order: stored as they are, or (ZIP) split into the
/// even-indexed bytes followed by the odd-indexed ones.
#[derive(Clone, Copy)]
enum Bytes<'a> {
    Raw(&'a [u8]),
    Split(&'a [u8], &'a [u8]),
}

/// Write the R, G, B, A lines of a block into interleaved RGBA rows; true if any
/// written value is NaN or inf. Lines are `for y { for channel (name order) { width
/// samples } }`, little-endian; every channel line starts at an even byte offset.
/// Each line is first decoded into a contiguous plane, then the four planes are
/// interleaved: both loops are plain enough for the compiler to vectorize.
fn scatter(
    channels: &ChannelList,
    slots: &[Option<usize>],
    width: usize,
    dst: &mut [f32],
    bytes: Bytes<'_>,
) -> bool {
    PLANES.with(|p| {
        let (planes, line) = &mut *p.borrow_mut();
        planes.clear();
        // A missing alpha plane reads as 1 (opaque).
        planes.resize(width * CH, 1.0);
        let (r, rest) = planes.split_at_mut(width);
        let (g, rest) = rest.split_at_mut(width);
        let (b, a) = rest.split_at_mut(width);
        let mut offset = 0;
        let mut non_finite = 0u32;
        for dst_row in dst.chunks_exact_mut((width * CH).max(1)) {
            for (c, slot) in channels.list.iter().zip(slots) {
                let ty = c.sample_type;
                let len = width * ty.bytes_per_sample();
                let plane: &mut [f32] = match slot {
                    Some(0) => r,
                    Some(1) => g,
                    Some(2) => b,
                    Some(_) => a,
                    None => {
                        offset += len;
                        continue;
                    }
                };
                match bytes {
                    Bytes::Raw(src) => line_raw(ty, &src[offset..offset + len], plane),
                    Bytes::Split(lo, hi) => {
                        let h = offset / 2;
                        line.resize(len, 0);
                        interleave(&lo[h..h + len / 2], &hi[h..h + len / 2], line);
                        line_raw(ty, line, plane)
                    }
                }
                offset += len;
            }
            for ((((d, &r), &g), &b), &a) in dst_row
                .chunks_exact_mut(CH)
                .zip(&*r)
                .zip(&*g)
                .zip(&*b)
                .zip(&*a)
            {
                d.copy_from_slice(&[r, g, b, a]);
            }
            // No early exit, so the check vectorizes.
            non_finite |= dst_row
                .iter()
                .fold(0, |acc, v| acc | u32::from(!v.is_finite()));
        }
        non_finite != 0
    })
}

thread_local! {
    /// One row of R, G, B and A planes and one channel line of bytes (one per rayon
    /// worker, reused).
    static PLANES: RefCell<(Vec<f32>, Vec<u8>)> = const { RefCell::new((Vec::new(), Vec::new())) };
}

fn sample_f32(ty: SampleType, b: [u8; 4]) -> f32 {
    match ty {
        SampleType::F32 => f32::from_le_bytes(b),
        SampleType::F16 => exr::prelude::f16::from_bits(u16::from_le_bytes([b[0], b[1]])).to_f32(),
        SampleType::U32 => u32::from_le_bytes(b) as f32,
    }
}

/// One channel line from file-order bytes into a plane (one loop per sample type, so
/// each is a plain conversion the compiler can vectorize).
fn line_raw(ty: SampleType, b: &[u8], out: &mut [f32]) {
    match ty {
        SampleType::F32 => {
            for (d, s) in out.iter_mut().zip(b.chunks_exact(4)) {
                *d = f32::from_le_bytes([s[0], s[1], s[2], s[3]]);
            }
        }
        SampleType::F16 => {
            for (d, s) in out.iter_mut().zip(b.chunks_exact(2)) {
                *d = exr::prelude::f16::from_bits(u16::from_le_bytes([s[0], s[1]])).to_f32();
            }
        }
        SampleType::U32 => {
            for (d, s) in out.iter_mut().zip(b.chunks_exact(4)) {
                *d = u32::from_le_bytes([s[0], s[1], s[2], s[3]]) as f32;
            }
        }
    }
}

/// Bytes in file order from ZIP's split halves: `lo` the even bytes, `hi` the odd ones.
fn interleave(lo: &[u8], hi: &[u8], out: &mut [u8]) {
    for ((o, &l), &h) in out.chunks_exact_mut(2).zip(lo).zip(hi) {
        o[0] = l;
        o[1] = h;
    }
}

/// Any other layout: the `exr` crate decompresses each block (in parallel); the
/// caller then places their lines.
fn decompress_chunks(
    chunks: Vec<Chunk>,
    meta: &MetaData,
) -> std::result::Result<Vec<UncompressedBlock>, String> {
    chunks
        .into_par_iter()
        .map(|chunk| UncompressedBlock::decompress_chunk(chunk, meta, false))
        .collect::<std::result::Result<Vec<_>, _>>()
        .map_err(|e| format!("EXR: {e}"))
}

/// Convert the lines of one decompressed block (native-endian samples) into
/// interleaved RGBA.
fn place_block(
    block: &UncompressedBlock,
    channels: &ChannelList,
    slots: &[Option<usize>],
    dst: &mut [f32],
    width: usize,
) -> std::result::Result<(), String> {
    for line in block.lines(channels) {
        let Some(slot) = slots[line.location.channel] else {
            continue;
        };
        let (x0, y) = (line.location.position.x(), line.location.position.y());
        let n = line.location.sample_count;
        let start = Some((y * width + x0) * CH)
            .filter(|&s| x0 + n <= width && s + n * CH <= dst.len())
            .ok_or_else(|| format!("block line at ({x0}, {y}) lies outside the image"))?;
        let out = dst[start..start + n * CH].iter_mut().skip(slot).step_by(CH);
        let ty = channels.list[line.location.channel].sample_type;
        match ty {
            SampleType::F16 => {
                for (d, b) in out.zip(line.value.chunks_exact(2)) {
                    let v = u16::from_ne_bytes([b[0], b[1]]).to_le_bytes();
                    *d = sample_f32(ty, [v[0], v[1], 0, 0]);
                }
            }
            _ => {
                for (d, b) in out.zip(line.value.chunks_exact(4)) {
                    let v = u32::from_ne_bytes([b[0], b[1], b[2], b[3]]).to_le_bytes();
                    *d = sample_f32(ty, v);
                }
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use exr::prelude::{
        AnyChannel, AnyChannels, Blocks, Encoding, FlatSamples, Image, Layer, LayerAttributes,
        LineOrder, SmallVec, WritableImage,
    };

    #[test]
    fn predictor_matches_the_reference_loop() {
        let mut s = crate::rng::Stream::new(5, 0);
        for n in [0usize, 1, 2, 3, 8, 9, 17, 1000, 4099] {
            let src: Vec<u8> = (0..n).map(|_| s.next_u64() as u8).collect();
            let mut want = src.clone();
            for i in 1..want.len() {
                want[i] = (want[i - 1] as i32 + want[i] as i32 - 128) as u8;
            }
            let mut got = src.clone();
            undo_predictor(&mut got);
            assert_eq!(got, want, "n = {n}");
            let mut got = src;
            undo_predictor_swar(&mut got);
            assert_eq!(got, want, "swar, n = {n}");
        }
    }

    /// Every codec and block layout the reader is tested on.
    const CODECS: [Compression; 5] = [
        Compression::Uncompressed,
        Compression::ZIP1,
        Compression::ZIP16,
        Compression::RLE,
        Compression::PIZ,
    ];
    const LAYOUTS: [Blocks; 2] = [Blocks::ScanLines, Blocks::Tiles(Vec2(16, 8))];

    /// A file with every sample type, an extra channel, a ragged last block and a NaN.
    fn sample_file(compression: Compression, blocks: Blocks, nan: bool) -> Result<Vec<u8>> {
        let (w, h) = (37usize, 23usize);
        let v = |c: usize, i: usize| ((i * 7 + c * 13) % 97) as f32 / 8.0 - 2.0;
        let n = w * h;
        let mut b: Vec<f32> = (0..n).map(|i| v(2, i)).collect();
        if nan {
            b[5 * w + 7] = f32::NAN;
        }
        let channels = AnyChannels::sort(SmallVec::from_vec(vec![
            AnyChannel::new(
                "A",
                FlatSamples::F16(
                    (0..n)
                        .map(|i| exr::prelude::f16::from_f32(v(3, i)))
                        .collect(),
                ),
            ),
            AnyChannel::new("B", FlatSamples::F32(b)),
            AnyChannel::new(
                "G",
                FlatSamples::U32((0..n).map(|i| (i % 1000) as u32).collect()),
            ),
            AnyChannel::new("R", FlatSamples::F32((0..n).map(|i| v(0, i)).collect())),
            AnyChannel::new("Z", FlatSamples::F32(vec![f32::NAN; n])),
        ]));
        let encoding = Encoding {
            compression,
            blocks,
            line_order: LineOrder::Increasing,
        };
        let layer = Layer::new((w, h), LayerAttributes::default(), encoding, channels);
        let mut out = Cursor::new(Vec::new());
        Image::from_layer(layer)
            .write()
            .non_parallel()
            .to_buffered(&mut out)
            .map_err(|e| Error::Value(e.to_string()))?;
        Ok(out.into_inner())
    }

    #[test]
    fn every_codec_and_sample_type_decodes_alike() -> Result<()> {
        let (w, h) = (37usize, 23usize);
        let v = |c: usize, i: usize| ((i * 7 + c * 13) % 97) as f32 / 8.0 - 2.0;
        let want: Vec<f32> = (0..w * h)
            .flat_map(|i| [v(0, i), (i % 1000) as f32, v(2, i), v(3, i)])
            .collect();
        let path = Path::new("sample.exr");
        for compression in CODECS {
            for blocks in LAYOUTS {
                let mut got = Vec::new();
                let d = decode_rgba(&sample_file(compression, blocks, false)?, path, &mut got)?;
                assert_eq!((d.width, d.height), (w, h));
                assert_eq!(d.non_finite, None, "{compression:?} {blocks:?}");
                assert_eq!(got, want, "{compression:?} {blocks:?}");
                let d = decode_rgba(&sample_file(compression, blocks, true)?, path, &mut got)?;
                let (x, y, c, value) = d.non_finite.ok_or(Error::Value("no NaN found".into()))?;
                assert_eq!((x, y, c), (7, 5, 2), "{compression:?} {blocks:?}");
                assert!(value.is_nan());
            }
        }
        Ok(())
    }

    #[test]
    fn truncated_and_garbage_files_are_errors() -> Result<()> {
        let file = sample_file(Compression::ZIP16, Blocks::ScanLines, false)?;
        let mut out = Vec::new();
        for bad in [
            &file[..file.len() - 10],
            &file[..file.len() / 2],
            b"v/1\x01 junk",
        ] {
            assert!(decode_rgba(bad, Path::new("bad.exr"), &mut out).is_err());
        }
        // A corrupt ZIP stream is an error, not a panic or a silent zero block.
        let mut flipped = file.clone();
        let k = file.len() - 200;
        flipped[k] ^= 0xFF;
        flipped[k + 1] ^= 0x5A;
        let e = decode_rgba(&flipped, Path::new("bad.exr"), &mut out)
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
        assert!(e.contains("bad.exr") && e.contains("ZIP block"), "{e}");
        Ok(())
    }

    /// `file` (scan lines, `lines` a block) with its data and display windows set to
    /// `w` x `h` and the chunk count to match: the header's size.
    fn resized(file: &[u8], lines: i32, w: i32, h: i32) -> Vec<u8> {
        let mut out = file.to_vec();
        let name = b"chunkCount\0int\0";
        if let Some(i) = out.windows(name.len()).position(|x| x == name) {
            let at = i + name.len() + 4;
            out[at..at + 4].copy_from_slice(&((h + lines - 1) / lines).to_le_bytes());
        }
        for name in [&b"dataWindow\0box2i\0"[..], &b"displayWindow\0box2i\0"[..]] {
            let at = out
                .windows(name.len())
                .position(|x| x == name)
                .map(|i| i + name.len() + 4)
                .unwrap_or_else(|| panic!("no {name:?}"));
            out[at + 8..at + 12].copy_from_slice(&(w - 1).to_le_bytes());
            out[at + 12..at + 16].copy_from_slice(&(h - 1).to_le_bytes());
        }
        out
    }

    #[test]
    fn a_header_promising_more_than_the_limit_is_refused_named() -> Result<()> {
        let path = Path::new("huge.exr");
        let mut out = Vec::new();
        for compression in [Compression::ZIP16, Compression::PIZ] {
            let file = sample_file(compression, Blocks::ScanLines, false)?;
            let lines = compression.scan_lines_per_block() as i32;
            let resized = |w, h| resized(&file, lines, w, h);
            // 20000 x 20000 = 4e8 pixels (6.4 GB as RGBA f32) from a file of a few KB.
            let e = decode_rgba(&resized(20000, 20000), path, &mut out)
                .err()
                .map(|e| e.to_string())
                .unwrap_or_default();
            assert!(
                e.contains("EXR header promises a 20000x20000 layer, pixels: 400000000, over the limit of 268435456 (MAX_IMAGE_PIXELS)")
                    && e.contains("huge.exr"),
                "{e}"
            );
            assert!(out.capacity() < 1 << 20, "allocated before refusing");
            let e = decode_rgba(&resized(70000, 1), path, &mut out)
                .err()
                .map(|e| e.to_string())
                .unwrap_or_default();
            assert!(
                e.contains("(MAX_IMAGE_SIDE)") && e.contains("huge.exr"),
                "{e}"
            );
            // Under the limits, a header larger than the file's blocks is refused before
            // the frame is allocated (16384 x 16384 would be 4 GiB).
            let e = decode_rgba(&resized(16384, 16384), path, &mut out)
                .err()
                .map(|e| e.to_string())
                .unwrap_or_default();
            assert!(e.contains("huge.exr"), "{e}");
            assert!(out.capacity() < 1 << 20, "allocated before refusing");
        }
        // The guide-pass reader refuses it too, before the crate allocates its channels.
        let file = sample_file(Compression::ZIP16, Blocks::ScanLines, false)?;
        let e = super::super::passes::decode_passes(&resized(&file, 16, 20000, 20000), path)
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
        assert!(
            e.contains("(MAX_IMAGE_PIXELS)") && e.contains("huge.exr"),
            "{e}"
        );
        Ok(())
    }

    /// A scan-line EXR written by hand, as issue 48's was: half channels `names`,
    /// OpenEXR compression number `code` (`lines` a block), a `w` x `h` data and display
    /// window and a whole offset table of blocks of `block` bytes each (zeros): a valid
    /// frame of the file, far fewer bytes than its header's size needs.
    fn tiny_blocks(names: &[&str], code: u8, lines: i32, w: i32, h: i32, block: i32) -> Vec<u8> {
        fn attr(out: &mut Vec<u8>, name: &str, ty: &str, value: &[u8]) {
            for s in [name, ty] {
                out.extend_from_slice(s.as_bytes());
                out.push(0);
            }
            out.extend_from_slice(&(value.len() as i32).to_le_bytes());
            out.extend_from_slice(value);
        }
        let ints = |v: &[i32]| -> Vec<u8> { v.iter().flat_map(|x| x.to_le_bytes()).collect() };
        let mut out = ints(&[20_000_630, 2]);
        let mut chlist = Vec::new();
        for n in names {
            chlist.extend_from_slice(n.as_bytes());
            chlist.push(0);
            chlist.extend(ints(&[1, 0, 1, 1])); // half, pLinear + reserved, sampling 1x1
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
        let n = (h + lines - 1) / lines;
        let first = out.len() as u64 + 8 * n as u64;
        let chunk = 8 + block as u64;
        for i in 0..n as u64 {
            out.extend_from_slice(&(first + i * chunk).to_le_bytes());
        }
        for i in 0..n {
            out.extend(ints(&[i * lines, block]));
            out.resize(out.len() + block as usize, 0);
        }
        out
    }

    #[test]
    fn a_header_at_the_limit_over_tiny_blocks_is_refused_before_allocating() -> Result<()> {
        let path = Path::new("tiny.exr");
        let words = |r: Result<()>| r.err().map(|e| e.to_string()).unwrap_or_default();
        // 4096^2 first: without the check it costs 256 MiB and fails later, on a block.
        for (w, h) in [(4096, 4096), (16384, 16384)] {
            // ZIP, uncompressed, PIZ (the crate's decompressor).
            for (code, lines) in [(3, 16), (0, 1), (4, 32)] {
                let rgb = tiny_blocks(&["B", "G", "R"], code, lines, w, h, 8);
                let mut out = Vec::new();
                let e = words(decode_rgba(&rgb, path, &mut out).map(|_| ()));
                assert!(
                    e.contains(&format!("EXR header promises a {w}x{h} layer"))
                        && e.contains(&format!("more than a file of {} bytes", rgb.len()))
                        && e.contains("tiny.exr"),
                    "{e}"
                );
                assert!(out.capacity() < 1 << 20, "allocated before refusing");
                // The depth and guide readers (verify tries depth after colour) too.
                let z = tiny_blocks(&["Z"], code, lines, w, h, 8);
                let e = words(crate::image::geometry::decode_depth_exr(&z, path).map(|_| ()));
                assert!(
                    e.contains("more than a file of") && e.contains("tiny.exr"),
                    "{e}"
                );
                let e = words(super::super::passes::decode_passes(&rgb, path).map(|_| ()));
                assert!(
                    e.contains("more than a file of") && e.contains("tiny.exr"),
                    "{e}"
                );
            }
        }
        // Lossy DCT blocks may claim any size from a few bytes: not read.
        let dwa = tiny_blocks(&["B", "G", "R"], 8, 32, 64, 64, 8);
        let e = words(decode_exr(&dwa).map(|_| ()));
        assert!(e.contains("EXR dwaa compression is not read"), "{e}");
        Ok(())
    }

    #[test]
    fn a_size_the_caller_knows_is_checked_from_the_header_alone() -> Result<()> {
        // 16384² over ZIP blocks of 8 bytes: its decode is refused, its size read.
        let big = tiny_blocks(&["B", "G", "R"], 3, 16, 16384, 16384, 8);
        assert_eq!(header_size_other_than(&big, (48, 48)), Some((16384, 16384)));
        assert_eq!(header_size_other_than(&big, (16384, 16384)), None);
        assert_eq!(header_size_other_than(b"not an EXR", (48, 48)), None);
        // Every part counts: the normal's part is 3 px wider than the others.
        let parts = passes_file(true, 3)?;
        assert_eq!(header_size_other_than(&parts, (19, 11)), Some((22, 11)));
        assert_eq!(
            header_size_other_than(&passes_file(true, 0)?, (19, 11)),
            None
        );
        let d = std::env::temp_dir().join(format!("blurset-exr-size-{}", std::process::id()));
        std::fs::create_dir_all(&d).map_err(|e| Error::io("mkdir", &d, e))?;
        let p = d.join("big.exr");
        std::fs::write(&p, &big).map_err(|e| Error::io("write", &p, e))?;
        assert_eq!(exr_size(&p)?, (16384, 16384));
        check_exr_size(&p, (16384, 16384))?;
        let e = check_exr_size(&p, (48, 48)).err().map(|e| e.to_string());
        let e = e.unwrap_or_default();
        assert!(
            e.contains("EXR is 16384x16384, expected 48x48; refused before decoding it")
                && e.contains("big.exr"),
            "{e}"
        );
        let _ = std::fs::remove_dir_all(&d);
        Ok(())
    }

    #[test]
    fn a_frame_past_what_can_be_allocated_is_an_error() {
        let mut rgba = vec![1.0f32; 8];
        let e = sized_frame(&mut rgba, 1 << 30, 1 << 30, 0.0)
            .err()
            .unwrap_or_default();
        assert!(
            e.contains("cannot allocate") && e.contains("1073741824x1073741824"),
            "{e}"
        );
        assert_eq!(sized_frame(&mut rgba, 3, 2, 0.5), Ok(()));
        assert_eq!(rgba, vec![0.5; 24]);
    }

    /// A multi-layer render as Blender writes one: the combined pass and the guides in
    /// one part (`ViewLayer.<pass>.<channel>`), or, with `parts`, one part a pass whose
    /// last (the normal) is `odd` pixels wider than the others.
    fn passes_file(parts: bool, odd: usize) -> Result<Vec<u8>> {
        let (w, h) = (19usize, 11usize);
        // (pass, its letters, the first value pattern, width)
        let all = [
            ("Combined", "RGBA", 0, w),
            ("Denoising Albedo", "RGB", 4, w),
            ("Denoising Normal", "XYZ", 7, w + odd),
            ("Depth", "Z", 10, w),
        ];
        let encoding = Encoding {
            compression: Compression::ZIP16,
            blocks: Blocks::ScanLines,
            line_order: LineOrder::Increasing,
        };
        let layers: Vec<_> = if parts {
            all.iter()
                .map(|p| {
                    let name = format!("ViewLayer.{}", p.0);
                    let channels = pass_channels(&[*p], h, true);
                    Layer::new((p.3, h), LayerAttributes::named(&*name), encoding, channels)
                })
                .collect()
        } else {
            let channels = pass_channels(&all, h, false);
            let named = LayerAttributes::named("ViewLayer");
            vec![Layer::new((w, h), named, encoding, channels)]
        };
        let mut out = Cursor::new(Vec::new());
        let bounds = exr::meta::attribute::IntegerBounds::from_dimensions((w, h));
        Image::from_layers(exr::prelude::ImageAttributes::new(bounds), layers)
            .write()
            .non_parallel()
            .to_buffered(&mut out)
            .map_err(|e| Error::Value(e.to_string()))?;
        Ok(out.into_inner())
    }

    /// The channels of `passes` (pass, letters, first value pattern, width) in a layer
    /// `h` rows high, named `<pass>.<letter>`, or by the letter alone when `bare`.
    fn pass_channels(
        passes: &[(&str, &str, usize, usize)],
        h: usize,
        bare: bool,
    ) -> AnyChannels<FlatSamples> {
        let v = |c: usize, i: usize| ((i * 5 + c * 11) % 89) as f32 / 16.0 - 1.0;
        let list = passes
            .iter()
            .flat_map(|&(pass, letters, first, w)| {
                letters.chars().enumerate().map(move |(k, l)| {
                    let name = if bare {
                        l.to_string()
                    } else {
                        format!("{pass}.{l}")
                    };
                    let values = (0..w * h).map(|i| v(first + k, i)).collect();
                    AnyChannel::new(name.as_str(), FlatSamples::F32(values))
                })
            })
            .collect();
        AnyChannels::sort(SmallVec::from_vec(list))
    }

    /// Every codec and block layout with and without a NaN, and multi-layer renders.
    fn pinned_files() -> Result<Vec<Vec<u8>>> {
        let mut files = Vec::new();
        for compression in CODECS {
            for blocks in LAYOUTS {
                for nan in [false, true] {
                    files.push(sample_file(compression, blocks, nan)?);
                }
            }
        }
        for (parts, odd) in [(false, 0), (true, 0), (true, 3)] {
            files.push(passes_file(parts, odd)?);
        }
        Ok(files)
    }

    /// `files`, then 24 seeded edits of each: a few bytes changed (half of them in the
    /// header's first 400 bytes), and half of those cut short by up to a third.
    fn with_edits(files: Vec<Vec<u8>>) -> Vec<Vec<u8>> {
        let mut s = crate::rng::Stream::new(36, 0);
        let mut inputs = files.clone();
        for f in &files {
            for _ in 0..24 {
                let mut b = f.clone();
                for _ in 0..1 + s.next_u64() % 4 {
                    let at = s.next_u64() as usize;
                    let within = if s.next_u64() & 1 == 0 {
                        400
                    } else {
                        usize::MAX
                    };
                    let i = at % b.len().min(within);
                    b[i] = s.next_u64() as u8;
                }
                if s.next_u64() & 1 == 0 {
                    let keep = b.len() - (s.next_u64() as usize) % (b.len() / 3 + 1);
                    b.truncate(keep);
                }
                inputs.push(b);
            }
        }
        inputs
    }

    /// An FNV-1a digest.
    struct Fnv(u64);
    impl Fnv {
        fn add(&mut self, bytes: &[u8]) {
            for &b in bytes {
                self.0 ^= u64::from(b);
                self.0 = self.0.wrapping_mul(0x0000_0100_0000_01B3);
            }
        }
        fn add_values(&mut self, values: &[f32]) {
            values
                .iter()
                .for_each(|v| self.add(&v.to_bits().to_le_bytes()));
        }
    }

    /// Fold what `decode_rgba` makes of `b` (into the reused `rgba`) into `h`; whether
    /// it was an error.
    fn fold_rgba(h: &mut Fnv, b: &[u8], rgba: &mut Vec<f32>) -> bool {
        match decode_rgba(b, Path::new("pinned.exr"), rgba) {
            Ok(d) => {
                let non_finite = d.non_finite.map(|(x, y, c, v)| (x, y, c, v.to_bits()));
                h.add(format!("{}x{} {non_finite:?}", d.width, d.height).as_bytes());
                h.add_values(rgba);
                false
            }
            Err(e) => {
                h.add(e.to_string().as_bytes());
                true
            }
        }
    }

    /// Fold what `decode_named` makes of `b` with `spec` into `h`; whether it was an
    /// error.
    fn fold_named(h: &mut Fnv, b: &[u8], spec: &[super::super::passes::PassSpec]) -> bool {
        match super::super::passes::decode_named(b, Path::new("pinned.exr"), spec) {
            Ok(d) => {
                h.add(format!("{}x{}", d.width, d.height).as_bytes());
                for (buf, seen) in &d.passes {
                    h.add(format!("{seen:?}").as_bytes());
                    h.add_values(buf);
                }
                false
            }
            // Which block's error the crate's parallel reader reports first varies
            // with the threads: its own words are left out.
            Err(e) => {
                let text = e.to_string();
                h.add(
                    text.split_once("(EXR: ")
                        .map_or(&*text, |(a, _)| a)
                        .as_bytes(),
                );
                true
            }
        }
    }

    /// The decoders' results on a fixed set of files (every codec and block layout, a
    /// NaN, multi-layer renders, and seeded truncations and byte edits of each), folded
    /// into one FNV-1a digest of the pixels, sizes, non-finite reports and error texts,
    /// with the count of frames and errors of `decode_rgba`, then of `decode_named`.
    /// The digest moves only when what a file decodes to (or the error it gives) does.
    fn decoding_digest() -> Result<(u64, [usize; 4])> {
        let mut outcomes = [0usize; 4];
        let mut h = Fnv(0xCBF2_9CE4_8422_2325);
        let mut rgba = Vec::new();
        let specs: [&[super::super::passes::PassSpec]; 3] = [
            &[
                ("Combined", "RGBA"),
                ("Denoising Albedo", "RGB"),
                ("Denoising Normal", "XYZ"),
            ],
            &[("Depth", "Z"), ("Normal", "XYZ")],
            &[("Combined", "RGB")],
        ];
        for b in &with_edits(pinned_files()?) {
            outcomes[usize::from(fold_rgba(&mut h, b, &mut rgba))] += 1;
            for spec in specs {
                outcomes[2 + usize::from(fold_named(&mut h, b, spec))] += 1;
            }
        }
        Ok((h.0, outcomes))
    }

    #[test]
    fn decoding_is_pinned() -> Result<()> {
        let (digest, outcomes) = decoding_digest()?;
        assert_eq!(outcomes, [98, 477, 189, 1536]);
        assert_eq!(digest, 0x4f71_bff0_8eb5_4429, "{digest:#018x}");
        Ok(())
    }

    // The reader's fuzz harness in `cargo test` (rust/fuzz/fuzz_targets/exr.rs runs it
    // longer): arbitrary bytes and mutations of valid files of each codec give a frame
    // or an error, never a panic.
    mod fuzz {
        use super::*;
        use proptest::prelude::*;

        fn seeds() -> &'static [Vec<u8>] {
            static SEEDS: std::sync::OnceLock<Vec<Vec<u8>>> = std::sync::OnceLock::new();
            SEEDS.get_or_init(|| {
                let mut v = Vec::new();
                for c in [
                    Compression::Uncompressed,
                    Compression::ZIP16,
                    Compression::RLE,
                ] {
                    for b in [Blocks::ScanLines, Blocks::Tiles(Vec2(16, 8))] {
                        v.extend(sample_file(c, b, false).ok());
                    }
                }
                v
            })
        }

        proptest! {
            #![proptest_config(ProptestConfig::with_cases(1000))]
            #[test]
            fn arbitrary_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..600)) {
                let mut prefixed = 20_000_630i32.to_le_bytes().to_vec();
                prefixed.extend_from_slice(&[2, 0, 0, 0]);
                prefixed.extend_from_slice(&bytes);
                let _ = decode_exr(&bytes);
                let _ = decode_exr(&prefixed);
            }

            #[test]
            fn mutated_files_never_panic(
                which in 0usize..6,
                edits in proptest::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 1..6),
                cut in any::<prop::sample::Index>(),
            ) {
                let seeds = seeds();
                let mut b = seeds[which % seeds.len()].clone();
                // Most edits land in the header, where the sizes are.
                for (at, v) in edits {
                    let i = at.index(b.len().min(400));
                    b[i] = v;
                }
                let keep = b.len() - cut.index(b.len() / 4 + 1);
                b.truncate(keep);
                if let Ok(f) = decode_exr(&b) {
                    prop_assert_eq!(f.rgba.len(), f.width as usize * f.height as usize * CH);
                }
            }
        }
    }
}
