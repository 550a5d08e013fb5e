"""The two references bench_settings_per_hour scores a preset's images against: the
continuous blur (many stratified latent frames, many samples each) and the preset's own
frames rendered at K times its samples on other Cycles seeds (its render noise)."""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path

from harness import plan_object, render_mean

REF_FACTOR = 32
REF_CAP = int(os.environ.get("BLURSET_BENCH_REF_CAP", "20000"))
REFERENCE = (64, 16)  # continuous blur: stratified frames x samples; sharp: their product
SALT = 0x5BD1E995
SALT2 = 0x27D4EB2F  # the second half of a split reference
FOV_DEG = 40.0


def continuous_reference(config: Callable, glb: Path, work: Path, res: int) -> dict:
    """Reference images (premultiplied linear RGBA) per (view, level dir): the continuous
    blur of each level, and the sharp view with as many samples. `config(out, glb,
    **flags)` makes the bench's build config."""
    from blurset.services.worker_client import Worker

    cfg = config(work / "unused", glb, latents=REFERENCE[0], latent_positions="stratified",
                 samples=REFERENCE[1], blur_budget="flat")  # fmt: skip
    refs = {}
    with Worker(timeout=7200, workdir=work / "scratch", device=cfg.device.upper()) as w:
        setting = plan_object(cfg, glb, w, work)
        for v in setting.to_dict()["views"]:
            # Other Cycles seeds than the builds' (noise they share would flatter them).
            sharp = [{"c2w": v["c2w"], "seed": v["sharp_seed"] ^ SALT, "out": str(work / "s.exr")}]
            refs[(v["index"], "sharp")] = render_mean(
                w, sharp, REFERENCE[0] * REFERENCE[1], res, FOV_DEG
            )
            for lvl in v["levels"]:
                frames = setting.level_renders(v["index"], int(lvl), str(work / "f"))
                for f in frames:
                    f["seed"] = (f["seed"] ^ SALT) & 0x7FFFFFFF
                refs[(v["index"], f"blur_{lvl}")] = render_mean(w, frames, 1, res, FOV_DEG)
    return refs


def _scaled(frames: list[dict], salt: int, kh: int, sharp_n: int) -> list[dict]:
    """`frames` on other seeds at `kh` times their samples (and sample offsets)."""
    half = [dict(f) for f in frames]
    for f in half:
        f["seed"] = (f["seed"] ^ salt) & 0x7FFFFFFF
        n = f.get("samples") or sharp_n
        f["samples"] = kh * n
        if f.get("sample_offset") is not None:
            f["sample_offset"] *= kh
            f["sample_sequence"] *= kh
    return half


def render_reference(
    config: Callable, glb: Path, work: Path, res: int, preset: dict, samples: dict, split: bool
) -> tuple[dict, int, dict]:
    """The preset's own images, undenoised, at K times its samples on other seeds:
    (images per (view, level dir), K, the noise MSE of each image). `samples`: the sample
    counts of `preset`'s images (the member with the most samples of the presets that share
    these frames). `split`: render each image as two halves on two seed sets and measure
    the noise of their mean (else the noise is not measured: no entry)."""
    from blurset.image import image_error
    from blurset.services.worker_client import Worker

    per_view = sum(samples.values())
    k = max(2 if split else 1, min(REF_FACTOR, REF_CAP // max(per_view, 1)))
    halves = [(SALT, k // 2), (SALT2, k - k // 2)] if split else [(SALT, k)]
    cfg = config(work / "unused", glb, **preset)
    refs, noise = {}, {}
    with Worker(timeout=7200, workdir=work / "scratch", device=cfg.device.upper()) as w:
        setting = plan_object(cfg, glb, w, work)
        sharp_n = int(cfg.effective_sharp_samples)
        images: dict[tuple[int, str], list[dict]] = {}
        for f in setting.renders(str(work / "r")):
            images.setdefault((f["view"], f["level"]), []).append(f)
        for key, frames in images.items():
            parts = [
                (kh, render_mean(w, _scaled(frames, salt, kh, sharp_n), kh * sharp_n, res, FOV_DEG))
                for salt, kh in halves
            ]
            refs[key] = sum(kh * img for kh, img in parts) / k
            if split:
                (k1, r1), (k2, r2) = parts
                noise[key] = image_error(r1, r2).mse * k1 * k2 / k**2
    return refs, k, noise


def denoised_mse(measured: float, reference_noise: float) -> float:
    """A denoised image's MSE against the truth: its MSE against the reference less the
    reference's own noise (independent seeds: the two add)."""
    return max(measured - reference_noise, 0.0)
