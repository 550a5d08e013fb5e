"""The fixed-count presets that bench_settings_per_hour compares with the paper preset:
the record of the approach that target-driven presets replaced (issue 37). Each is the
flags a build gets; the comments say what each was fitted to."""

from __future__ import annotations

import os

_AUTO = {"latents_auto": True, "latent_positions": "stratified"}
PRESETS = {
    # blurset build's defaults: the paper's 34 random latent frames, 32 samples each
    # times the parity factor 34^0.4 (132), the sharp image with the budget (1088).
    "paper": {},
    # Latent averaging, per-level m from the 1 px ghost bound (stratified, up to 34),
    # 256 samples times the parity factor; sharp at 256 (issue 6 / 15).
    "balanced": {**_AUTO, "samples_total": 256, "sharp_samples": 256},
    "balanced_oidn": {**_AUTO, "samples_total": 256, "sharp_samples": 256, "denoise": "oidn"},
    # Re-derived (issue 28) from the first run's measurements on the three textured
    # models: m from a 2 px ghost bound and the need budget; floor: the samples at which
    # the mean render noise of the sharp and of the blurry images reaches the 8-bit floor
    # (192 gave 55.0 / 56.9 dB: 2.2x and 1.5x that); floor_oidn: half of it, denoised.
    # fast: a quarter of the old 192, the sharp image at 1.5x its blurry base, because at
    # 48 / 48 its blurry images were 2.0 dB cleaner than its sharp ones (not a pair at
    # parity); fast_oidn: the same, denoised.
    "floor": {
        **_AUTO,
        "max_ghost_px": 2.0,
        "samples_total": 320,
        "sharp_samples": 448,
        "blur_budget": "need",
    },  # fmt: skip
    "floor_oidn": {
        **_AUTO,
        "max_ghost_px": 2.0,
        "samples_total": 160,
        "sharp_samples": 224,
        "blur_budget": "need",
        "denoise": "oidn",
    },  # fmt: skip
    "fast": {
        **_AUTO,
        "max_ghost_px": 2.0,
        "samples_total": 48,
        "sharp_samples": 72,
        "blur_budget": "need",
    },  # fmt: skip
    "fast_oidn": {
        **_AUTO,
        "max_ghost_px": 2.0,
        "samples_total": 48,
        "sharp_samples": 72,
        "blur_budget": "need",
        "denoise": "oidn",
    },  # fmt: skip
    # For 512 px (the paper's size), from bench_denoise_gain: there a sharp image reaches
    # the floor at ≈ 240–420 samples undenoised and ≈ 120–270 denoised (Mazda the most),
    # and the blurry images' budget is the need factor (saturated: m^0.4) times
    # samples_total. floor512: undenoised; floor512_oidn: denoised at 2/3 of it;
    # floor512_lean_oidn: the blurry base at a third of the sharp samples.
    "floor512": {
        **_AUTO,
        "max_ghost_px": 2.0,
        "samples_total": 208,
        "sharp_samples": 416,
        "blur_budget": "need",
    },  # fmt: skip
    "floor512_oidn": {
        **_AUTO,
        "max_ghost_px": 2.0,
        "samples_total": 144,
        "sharp_samples": 288,
        "blur_budget": "need",
        "denoise": "oidn",
    },  # fmt: skip
    "floor512_lean_oidn": {
        **_AUTO,
        "max_ghost_px": 2.0,
        "samples_total": 96,
        "sharp_samples": 288,
        "blur_budget": "need",
        "denoise": "oidn",
    },  # fmt: skip
    # floor512_fit_oidn: fitted to the first 512 px run (Mazda): there the lean preset's
    # blurry images were 2.4 dB above its sharp ones (61.0 / 58.6 dB): fewer blurry
    # samples, a few more sharp ones.
    "floor512_fit_oidn": {
        **_AUTO,
        "max_ghost_px": 2.0,
        "samples_total": 72,
        "sharp_samples": 336,
        "blur_budget": "need",
        "denoise": "oidn",
    },  # fmt: skip
    # floor512_wide_oidn: the fit preset's samples with latent frames up to 3 px apart (2
    # at 512 px is 4 times finer than at 128): fewer frames, and the need budget
    # (m^0.4 once saturated) buys fewer blurry samples for the same render noise.
    # floor512_wide64_oidn: the same at samples_total 64.
    "floor512_wide_oidn": {
        **_AUTO,
        "max_ghost_px": 3.0,
        "samples_total": 72,
        "sharp_samples": 336,
        "blur_budget": "need",
        "denoise": "oidn",
    },  # fmt: skip
    "floor512_wide64_oidn": {
        **_AUTO,
        "max_ghost_px": 3.0,
        "samples_total": 64,
        "sharp_samples": 336,
        "blur_budget": "need",
        "denoise": "oidn",
    },  # fmt: skip
    # Denoised Cycles motion blur: one render per blurry image (the old fast preset's
    # method, denoised).
    "motion_blur_oidn": {
        "blur_method": "motion_blur",
        "samples_total": 128,
        "sharp_samples": 128,
        "denoise": "oidn",
    },  # fmt: skip
}
ONLY = os.environ.get("BLURSET_BENCH_SPH_PRESETS")
if ONLY:
    PRESETS = {k: v for k, v in PRESETS.items() if k in {"paper", *ONLY.split(",")}}
# Options that move latent frames: presets equal in these share a render reference.
FRAME_OPTIONS = ("blur_method", "latents_auto", "latent_positions", "max_ghost_px", "latents")
