//! Property tests of the raw pipeline (issue 61): round trip, variance against signal
//! per CFA channel, row-noise power, the read noise's Tukey-lambda shape, extremes,
//! thread-count independence.
use super::*;
use crate::noise::camera::{eld_camera, EldCamera};
use crate::noise::draws::{tukey_quantile, tukey_variance};
use crate::noise::model::{Gamma, WhiteBalance};
use crate::noise::raw_model::{Display, RawModel};

fn display(gamma: Gamma) -> Display {
    Display {
        gamma,
        white_balance: Some(WhiteBalance {
            red: 2.1,
            blue: 1.7,
        }),
        white_level: 1.0,
    }
}

fn camera(name: &str) -> &'static EldCamera {
    eld_camera(name).expect("an ELD camera")
}

fn eld(name: &str, gain: f64) -> RawModel {
    RawModel::eld(camera(name), gain, display(Gamma::Srgb)).expect("model")
}

/// Every model at one gain: the five ELD cameras and unprocess.
fn all_models(gain: f64, gamma: Gamma) -> Vec<RawModel> {
    let mut out: Vec<RawModel> = crate::noise::camera::ELD_CAMERAS
        .iter()
        .map(|c| RawModel::eld(c, gain, display(gamma)).expect("model"))
        .collect();
    out.push(RawModel::unprocess(7, gain, display(gamma)).expect("model"));
    out
}

fn flat(w: u32, h: u32, v: f32) -> LinearRgb {
    LinearRgb::new(w, h, vec![v; (w * h * 3) as usize]).expect("image")
}

fn moments(v: &[f64]) -> (f64, f64) {
    let n = v.len() as f64;
    let m = v.iter().sum::<f64>() / n;
    (
        m,
        v.iter().map(|x| (x - m) * (x - m)).sum::<f64>() / (n - 1.0),
    )
}

/// The model's variance (DN² for ELD, signal² for Brooks) at clean raw `x`.
fn model_variance(m: &RawModel, x: f64) -> f64 {
    match m.noise {
        RawNoise::Physics {
            k,
            read_scale,
            lambda,
            row_sigma,
        } => {
            let read = read_scale * read_scale * tukey_variance(lambda);
            k * x * (m.white - m.black) + read + row_sigma * row_sigma + 1.0 / 12.0
        }
        RawNoise::Gaussian { shot, read } => shot * x + read,
    }
}

#[test]
fn without_noise_the_round_trip_returns_every_code() -> Result<()> {
    // Every 8-bit code in every channel, decoded as the PNG path decodes it.
    let (w, h) = (64u32, 12u32);
    let codes: Vec<u8> = (0..w * h * 3)
        .map(|i| ((i * 7 + i / 3) % 256) as u8)
        .collect();
    for gamma in [Gamma::Power22, Gamma::Srgb] {
        let lin: Vec<f32> = codes
            .iter()
            .map(|&c| gamma.decode(f64::from(c) / 255.0) as f32)
            .collect();
        let img = LinearRgb::new(w, h, lin)?;
        for m in all_models(4.0, gamma) {
            let out = raw_frame(&img, &m.clean(), 1, 2)?;
            let Samples::U8(got) = &out.processed.samples else {
                panic!("8-bit output");
            };
            let worst = got
                .iter()
                .zip(&codes)
                .map(|(a, b)| (i32::from(*a) - i32::from(*b)).abs())
                .max();
            assert_eq!(worst, Some(0), "{} {gamma:?}", m.name);
        }
    }
    Ok(())
}

/// Per CFA channel (R, G, B) of the noisy mosaic of a flat image at linear `level`:
/// (clean raw x, sample variance) in the model's units (DN for ELD).
fn cfa_variances(m: &RawModel, level: f32, size: u32) -> [(f64, f64); 3] {
    let img = flat(size, size, level);
    let raw = clean_raw(&img, m);
    let w = size as usize;
    let noisy = noisy_mosaic(m, &raw, w, 3, 4);
    let unit = if m.quantize { m.white - m.black } else { 1.0 };
    [0, 1, 2].map(|c| {
        let v: Vec<f64> = noisy
            .iter()
            .enumerate()
            .filter(|(i, _)| cfa_channel(i % w, i / w) == c)
            .map(|(_, v)| v * unit)
            .collect();
        (raw[c], moments(&v).1)
    })
}

#[test]
fn variance_against_signal_per_cfa_channel_is_the_models() {
    let mut worst: f64 = 0.0;
    let models = [
        eld("SonyA7S2", 8.0),
        eld("CanonEOS70D", 20.0),
        eld("NikonD850", 1.0),
    ];
    let unprocess = RawModel::unprocess(3, 4.0, display(Gamma::Srgb)).expect("model");
    for m in models.iter().chain([&unprocess]) {
        for level in [0.0f32, 0.02, 0.2, 0.6] {
            for (c, (x, var)) in cfa_variances(m, level, 512).into_iter().enumerate() {
                let want = model_variance(m, x);
                let ratio = var / want;
                worst = worst.max((ratio - 1.0).abs());
                assert!(
                    (ratio - 1.0).abs() < 0.05,
                    "{} level {level} channel {c}: {ratio}",
                    m.name
                );
            }
        }
    }
    eprintln!("variance / model: worst |ratio - 1| = {worst:.4}");
}

#[test]
fn row_noise_has_the_calibrated_power() {
    // Canon 70D at gain 20: row σ ≈ 1.8 DN beside ≈ 12 DN of Tukey read noise.
    let m = eld("CanonEOS70D", 20.0);
    let RawNoise::Physics { row_sigma, .. } = m.noise else {
        panic!("physics");
    };
    let (w, h) = (1024usize, 1024usize);
    let raw = clean_raw(&flat(w as u32, h as u32, 0.0), &m);
    let noisy = noisy_mosaic(&m, &raw, w, 5, 6);
    let range = m.white - m.black;
    let rows: Vec<(f64, f64)> = noisy
        .chunks_exact(w)
        .map(|r| moments(&r.iter().map(|v| v * range).collect::<Vec<_>>()))
        .collect();
    let (_, var_of_means) = moments(&rows.iter().map(|r| r.0).collect::<Vec<_>>());
    let within = rows.iter().map(|r| r.1).sum::<f64>() / h as f64;
    let row_power = var_of_means - within / w as f64;
    let ratio = row_power / (row_sigma * row_sigma);
    eprintln!(
        "row power {row_power:.4} DN^2, model {:.4}: ratio {ratio:.4}",
        row_sigma * row_sigma
    );
    assert!((ratio - 1.0).abs() < 0.15, "{ratio}");
}

#[test]
fn read_noise_has_the_published_tukey_lambda_shape() {
    // Canon 70D at gain 20: λ < 0 (heavier tails than a normal), scale ≈ 12 DN.
    let m = eld("CanonEOS70D", 20.0);
    let RawNoise::Physics {
        read_scale, lambda, ..
    } = m.noise
    else {
        panic!("physics");
    };
    assert!(lambda < -0.1, "{lambda}");
    let (w, h) = (2048usize, 512usize);
    let raw = clean_raw(&flat(w as u32, h as u32, 0.0), &m);
    let noisy = noisy_mosaic(&m, &raw, w, 8, 9);
    let range = m.white - m.black;
    // Minus each row's mean (its row noise), in DN.
    let mut read: Vec<f64> = noisy
        .chunks_exact(w)
        .flat_map(|r| {
            let mean = r.iter().sum::<f64>() / w as f64;
            r.iter().map(move |v| (v - mean) * range)
        })
        .collect();
    read.sort_by(f64::total_cmp);
    let n = read.len() as f64;
    for p in [0.001, 0.01, 0.1, 0.25, 0.75, 0.9, 0.99, 0.999] {
        let got = read[(p * n) as usize];
        let want = read_scale * tukey_quantile(p, lambda);
        assert!(
            (got - want).abs() < 0.05 * want.abs() + 0.6,
            "p {p}: {got} vs {want}"
        );
    }
    // The tails are the Tukey's, heavier than a normal of the same variance.
    let sd = read_scale * tukey_variance(lambda).sqrt();
    assert!(read[(0.999 * n) as usize] > 3.09 * sd * 1.05);
}

#[test]
fn black_saturated_and_largest_gain_stay_finite_and_bounded() -> Result<()> {
    for gain in [1.0, 20.0, 64.0, 1.0e4] {
        for m in all_models(gain, Gamma::Srgb) {
            for level in [0.0f32, 1.0] {
                let out = raw_frame(&flat(16, 8, level), &m, 1, 1)?;
                assert!(
                    out.linear.iter().all(|v| v.is_finite()),
                    "{} {gain}",
                    m.name
                );
                if m.quantize {
                    // Raw clipped to [0, white]: linear stays within the matrices' reach.
                    let bound = 4.0 * m.wb.iter().fold(1.0f64, |a, b| a.max(*b));
                    let big = out.linear.iter().map(|v| v.abs()).fold(0.0f32, f32::max);
                    assert!(f64::from(big) <= bound, "{} {gain}: {big}", m.name);
                }
            }
        }
    }
    // A saturated white stays white at the base gain (the raw clips at the white level).
    let out = raw_frame(&flat(16, 8, 1.0), &eld("SonyA7S2", 1.0), 1, 1)?;
    let Samples::U8(codes) = &out.processed.samples else {
        panic!("8-bit");
    };
    assert!(codes.iter().all(|&c| c >= 250), "{:?}", &codes[..6]);
    Ok(())
}

#[test]
fn identical_for_any_thread_count_and_keyed() -> Result<()> {
    let img = LinearRgb::new(
        33,
        17,
        (0..33 * 17 * 3).map(|i| (i % 97) as f32 / 97.0).collect(),
    )?;
    for m in all_models(8.0, Gamma::Srgb) {
        let run = |threads: usize| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .expect("pool")
                .install(|| raw_frame(&img, &m, 42, 7))
        };
        let (a, b) = (run(1)?, run(4)?);
        assert_eq!(a.linear, b.linear, "{}", m.name);
        assert_eq!(a.processed, b.processed);
        assert_ne!(a.linear, raw_frame(&img, &m, 42, 8)?.linear);
        assert_ne!(a.linear, raw_frame(&img, &m, 43, 7)?.linear);
    }
    Ok(())
}

#[test]
fn demosaicked_noise_is_correlated_in_space_and_across_channels() -> Result<()> {
    // The paper's noise is independent per pixel and channel (correlation 0); a
    // demosaicked raw's is not.
    let m = eld("SonyA7S2", 20.0);
    let (w, h) = (256usize, 256usize);
    let img = flat(w as u32, h as u32, 0.2);
    let clean = raw_frame(&img, &m.clean(), 1, 1)?.linear;
    let noisy = raw_frame(&img, &m, 1, 1)?.linear;
    let n: Vec<f64> = noisy
        .iter()
        .zip(&clean)
        .map(|(a, b)| f64::from(a - b))
        .collect();
    let corr = |a: &[f64], b: &[f64]| {
        let (ma, va) = moments(a);
        let (mb, vb) = moments(b);
        let cov = a
            .iter()
            .zip(b)
            .map(|(x, y)| (x - ma) * (y - mb))
            .sum::<f64>()
            / a.len() as f64;
        cov / (va * vb).sqrt()
    };
    let chan = |c: usize| -> Vec<f64> { n.iter().skip(c).step_by(3).copied().collect() };
    let (r, g) = (chan(0), chan(1));
    let pairs: Vec<usize> = (0..h)
        .flat_map(|y| (0..w - 1).map(move |x| y * w + x))
        .collect();
    let right: Vec<f64> = pairs.iter().map(|&i| g[i + 1]).collect();
    let left: Vec<f64> = pairs.iter().map(|&i| g[i]).collect();
    let (space, across) = (corr(&left, &right), corr(&r, &g));
    eprintln!("green neighbour correlation {space:.3}, red-green {across:.3}");
    assert!(space > 0.2, "{space}");
    assert!(across.abs() > 0.05, "{across}");
    // The paper's model on the same image: both near zero.
    let paper = crate::noise::model::NoiseModel {
        sigma_read: 0.02,
        sigma_shot: 0.05,
        gamma: Gamma::Srgb,
        white_balance: None,
        white_level: 1.0,
    };
    let p = crate::noise::linear::add_noise_linear(&img, &paper, 1, 1)?.linear;
    let n: Vec<f64> = p.iter().map(|v| f64::from(*v) - 0.2).collect();
    let chan = |c: usize| -> Vec<f64> { n.iter().skip(c).step_by(3).copied().collect() };
    let (r, g) = (chan(0), chan(1));
    let right: Vec<f64> = pairs.iter().map(|&i| g[i + 1]).collect();
    let left: Vec<f64> = pairs.iter().map(|&i| g[i]).collect();
    let (space, across) = (corr(&left, &right), corr(&r, &g));
    eprintln!("paper: green neighbour correlation {space:.4}, red-green {across:.4}");
    assert!(
        space.abs() < 0.02 && across.abs() < 0.02,
        "{space} {across}"
    );
    Ok(())
}

#[test]
fn code_steps_round_the_forward_curve() {
    for gamma in [Gamma::Power22, Gamma::Srgb] {
        for m in all_models(2.0, gamma) {
            let steps = code_steps(&m);
            for i in 0..20_000 {
                let s = -0.1 + 1.2 * f64::from(i) / 20_000.0;
                let by_steps = steps.partition_point(|t| s >= *t);
                let by_curve = libm::round(to_code(&m, s) * 255.0) as usize;
                assert_eq!(by_steps, by_curve, "{} {gamma:?} at {s}", m.name);
            }
        }
    }
}
