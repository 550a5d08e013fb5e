//! LLFF-N style sensor noise (DESIGN §5): inverse gamma, inverse white balance,
//! heteroscedastic read + shot noise, forward processing back to an sRGB code.
//!
//! Per colour value, with x the clean code / max code:
//! `y = white_level * decode(x) / wb[c]`, `y' = y + sqrt(σ_r² + σ_s²·y) · n`,
//! `processed = round(max · encode(clip(y' · wb[c] / white_level, 0, 1)))`.
//! `y'` is what `linear/*.exr` holds (unclipped, negative values included).
//!
//! Randomness: value `v = pixel · colour_channels + c` of view `i`, frame `k` takes
//! 32-bit word `v % 4` of Philox block `v / 4` in stream `i << 32 | k` under
//! `noise_key(seed, gain)`; the normal comes from a 128-layer ziggurat fed by that
//! word. The rare rejected draws (≈1.2 %) continue in a second Philox stream indexed
//! by `v`, so every value is a pure function of (seed, gain, view, frame, v) and the
//! output is bit-identical for any thread count.
//!
//! `model` holds the model and the addressing of draws, `ziggurat` the normals,
//! `kernel` the per-image kernel (AVX2 where the CPU has it, bit for bit the scalar
//! path), `linear` the same noise from a build's linear EXRs, and `variants` the files
//! of a scene's variants. `raw_model`, `raw` and their helpers (`camera`, `draws`,
//! `matrix`, `mosaic`) are the camera models of `--model` (issue 61).
pub mod camera;
pub mod config;
pub mod draws;
pub mod kernel;
pub mod linear;
pub mod matrix;
pub mod model;
pub mod mosaic;
pub mod raw;
pub mod raw_model;
pub mod variants;
mod ziggurat;
