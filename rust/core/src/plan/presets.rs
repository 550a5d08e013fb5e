//! The named presets of `blurset build --preset` (DESIGN §8), declared once: what each
//! sets, applied under the options given beside it (flags and TOML keys override a
//! preset). A preset that promises accuracy says it as targets — a render PSNR every image
//! is rendered to on its object's pixels and a ghost bound between latent frames — never
//! as sample counts, which fit only the objects they were chosen on.
use super::choices::Preset;
use super::spec::{Raw, MAX_COUNT};

/// The 8-bit floor: a PNG's own quantization error, 1/(255²·12) in MSE (DESIGN §8).
pub const FLOOR_PSNR_DB: f64 = 58.92;

/// What `preset` sets, option by option (the paper preset: nothing, the defaults).
pub fn preset_values(preset: Preset) -> Vec<(&'static str, Raw)> {
    // The ghost bound is the promise, so no frame cap below it: 34 frames (latents auto's
    // own cap) leave 9 px gaps at level 4 of a 512 px view.
    let by_motion = |ghost_px: f64| {
        vec![
            ("latents_auto", Raw::Bool(true)),
            ("latent_positions", Raw::Str("stratified".into())),
            ("max_ghost_px", Raw::Float(ghost_px)),
            ("latents_max", Raw::Int(MAX_COUNT as i128)),
            // Each image by the method its device renders for less (`plan/cost.rs`): the
            // frames the ghost bound plans on a CPU, one motion-blur render on a GPU.
            ("blur_method", Raw::Str("auto".into())),
        ]
    };
    let target = |db: f64| ("target_psnr", Raw::Float(db));
    match preset {
        Preset::Paper => Vec::new(),
        Preset::Balanced => [by_motion(1.0), vec![target(50.0)]].concat(),
        Preset::Floor => [by_motion(1.0), vec![target(FLOOR_PSNR_DB)]].concat(),
        Preset::Fast => [by_motion(2.0), vec![target(40.0)]].concat(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plan::choices::Choice;

    #[test]
    fn floor_is_the_quantization_error_of_8_bits() {
        let mse = 1.0 / (255f64.powi(2) * 12.0);
        assert!((-10.0 * mse.log10() - FLOOR_PSNR_DB).abs() < 0.005);
    }

    #[test]
    fn accuracy_presets_are_targets_not_sample_counts() {
        for p in Preset::ALL {
            let v = preset_values(*p);
            assert!(v.iter().all(|(k, _)| !k.contains("samples")), "{p}");
            if *p != Preset::Paper {
                assert!(v.iter().any(|(k, _)| *k == "target_psnr"), "{p}");
            }
        }
    }
}
