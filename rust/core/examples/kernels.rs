//! Timing harness for the two measured kernels, without Python in the way:
//! `cargo run --release -p blurset-core --example kernels -- noise FERN_IMAGES_DIR [reps]`
//! `cargo run --release -p blurset-core --example kernels -- accumulate EXR_DIR OUT.png [reps]`
//! Prints wall and process CPU seconds per repeat and a digest of the outputs, so a
//! change can be checked for bit-identical results (the digest must not move).
use blurset_core::{Accumulator, Gamma, NoiseLevels, NoiseModel, Samples};
use std::path::{Path, PathBuf};
use std::time::Instant;

fn cpu_seconds() -> f64 {
    // utime + stime of this process from /proc (no libc dependency).
    let stat = std::fs::read_to_string("/proc/self/stat").unwrap_or_default();
    let fields: Vec<&str> = stat
        .rsplit_once(')')
        .map(|(_, rest)| rest.split_whitespace().collect())
        .unwrap_or_default();
    let ticks = |i: usize| {
        fields
            .get(i)
            .and_then(|v| v.parse::<f64>().ok())
            .unwrap_or(0.0)
    };
    (ticks(11) + ticks(12)) / 100.0
}

fn fnv(h: &mut u64, bytes: &[u8]) {
    for &b in bytes {
        *h ^= b as u64;
        *h = h.wrapping_mul(0x0000_0100_0000_01B3);
    }
}

/// Time and size of the PNG encoder's compression and filter settings on one image.
fn png_settings(rgb: &[u8], w: u32, h: u32) {
    use image::codecs::png::{CompressionType, FilterType, PngEncoder};
    use image::ImageEncoder;
    for (cname, c) in [
        ("default", CompressionType::Default),
        ("fast", CompressionType::Fast),
        ("level1", CompressionType::Level(1)),
        ("uncompressed", CompressionType::Uncompressed),
    ] {
        for (fname, f) in [
            ("adaptive", FilterType::Adaptive),
            ("paeth", FilterType::Paeth),
            ("up", FilterType::Up),
            ("none", FilterType::NoFilter),
        ] {
            let t0 = Instant::now();
            let mut buf = Vec::new();
            let ok = PngEncoder::new_with_quality(&mut buf, c, f)
                .write_image(rgb, w, h, image::ExtendedColorType::Rgb8)
                .is_ok();
            println!(
                "  png {cname:>12} {fname:>8}: {:.2} ms, {} bytes{}",
                t0.elapsed().as_secs_f64() * 1e3,
                buf.len(),
                if ok { "" } else { " (failed)" }
            );
        }
    }
}

fn usage() -> blurset_core::Error {
    blurset_core::Error::Value("usage: kernels noise DIR [reps] | accumulate DIR OUT [reps]".into())
}

fn main() -> blurset_core::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let arg = |i: usize| args.get(i).map(PathBuf::from).ok_or_else(usage);
    let reps = |i: usize| args.get(i).and_then(|s| s.parse().ok()).unwrap_or(5);
    match args.get(1).map(String::as_str) {
        Some("noise") => time_noise(&arg(2)?, reps(3)),
        Some("accumulate") => {
            let dir = arg(2)?;
            time_accumulate(&dir, &arg(3)?, reps(4))
        }
        _ => Err(usage()),
    }
}

/// The files of `dir` ending in `.ext`, sorted.
fn files_with_extension(dir: &Path, ext: &str) -> blurset_core::Result<Vec<PathBuf>> {
    let mut paths: Vec<PathBuf> = std::fs::read_dir(dir)
        .map_err(|e| blurset_core::Error::io("read dir", dir, e))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|e| e == ext))
        .collect();
    paths.sort();
    Ok(paths)
}

/// The noise models of the measured gains (1 to 20), each with its key.
fn noise_models() -> blurset_core::Result<Vec<(u64, NoiseModel)>> {
    let wb = blurset_core::sample_white_balance(11);
    [1.0, 2.0, 4.0, 8.0, 16.0, 20.0]
        .iter()
        .map(|&g| {
            let (sr, ss) = NoiseLevels::DEFAULT.sigmas(g)?;
            Ok((
                blurset_core::noise_key(11, g),
                NoiseModel {
                    sigma_read: sr,
                    sigma_shot: ss,
                    gamma: Gamma::Power22,
                    white_balance: Some(wb),
                    white_level: 1.0,
                },
            ))
        })
        .collect()
}

/// Time noising every PNG of `dir` at every gain, `reps` times; the first repeat's
/// digest covers the linear and the processed values.
fn time_noise(dir: &Path, reps: usize) -> blurset_core::Result<()> {
    let images = files_with_extension(dir, "png")?
        .iter()
        .map(|p| blurset_core::read_image(p))
        .collect::<blurset_core::Result<Vec<_>>>()?;
    let models = noise_models()?;
    let values: usize = images.iter().map(|i| i.samples.len()).sum::<usize>() * models.len();
    for rep in 0..reps {
        let (t0, c0) = (Instant::now(), cpu_seconds());
        let mut h = 0xCBF2_9CE4_8422_2325u64;
        for (key, m) in &models {
            for (i, img) in images.iter().enumerate() {
                let stream = blurset_core::noise_stream_id(i as u32, 0);
                let n = blurset_core::add_noise(img, m, *key, stream)?;
                if rep == 0 {
                    let lin: Vec<u8> = n.linear.iter().flat_map(|v| v.to_le_bytes()).collect();
                    fnv(&mut h, &lin);
                    if let Samples::U8(p) = &n.processed.samples {
                        fnv(&mut h, p);
                    }
                }
            }
        }
        let wall = t0.elapsed().as_secs_f64();
        println!(
            "noise rep {rep}: wall {wall:.4} s cpu {:.3} s  {:.2} ns/value wall{}",
            cpu_seconds() - c0,
            wall / values as f64 * 1e9,
            if rep == 0 {
                format!("  digest {h:016x}")
            } else {
                String::new()
            }
        );
    }
    Ok(())
}

/// Time averaging every EXR of `dir` into the PNG `out`, `reps` times; the first
/// repeat also times the PNG encoder's settings.
fn time_accumulate(dir: &Path, out: &Path, reps: usize) -> blurset_core::Result<()> {
    let paths = files_with_extension(dir, "exr")?;
    let (w, h) = {
        let f = blurset_core::read_exr(&paths[0])?;
        (f.width, f.height)
    };
    for rep in 0..reps {
        let (t0, c0) = (Instant::now(), cpu_seconds());
        let mut acc = Accumulator::new(w, h);
        for p in &paths {
            acc.add_exr(p)?;
        }
        let t_add = t0.elapsed().as_secs_f64();
        acc.write_png(out, [1.0; 3])?;
        let wall = t0.elapsed().as_secs_f64();
        if rep == 0 {
            png_settings(&acc.encode_rgb8([1.0; 3])?, w, h);
        }
        let mut d = 0xCBF2_9CE4_8422_2325u64;
        fnv(&mut d, &acc.encode_rgb8([1.0; 3])?);
        println!(
            "accumulate rep {rep}: wall {wall:.4} s (frames {t_add:.4}, png {:.4}) cpu {:.3} s  digest {d:016x}",
            wall - t_add,
            cpu_seconds() - c0
        );
    }
    Ok(())
}
