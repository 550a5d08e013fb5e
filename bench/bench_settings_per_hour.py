"""settings_per_hour: whole `blurset build` runs of the paper preset against faster and
denoised presets, side by side in one run (issues 6 and 28, DESIGN §8–9), with what
each costs in accuracy.

Objects: the textured GLBs of ../shared/data (MapPin, Mazda, WaterBottle) when present,
else the demo box (BLURSET_BENCH_GLBS: comma-separated paths). Every preset builds the
same setting of each object (same seed: same views, trajectories and w_l) with
`--keep-linear`; every measured view renders its blurry images. Settings/hour: a 34-view
setting extrapolated from the measured views, 3600 / (34 · render time per view + the
rest of the build, worker start and object load included, over the 4 settings of an
object), the time summed over the objects (the median of the repeats).

Accuracy, per image (sharp and each blur level), the mean over images and objects:
- `psnr_*_db`: against the continuous-blur reference (blurry: the mean of many
  stratified latent frames with many samples each; sharp: one render with as many).
- `render_psnr_*_db`: against the preset's own frames (same latent positions) rendered
  undenoised with K times its samples on other Cycles seeds, K ≥ 32 unless that would
  exceed BLURSET_BENCH_REF_CAP samples per view (the paper preset's 34 × 132-sample
  images: then K = cap / samples, at least 1). For an undenoised image the reference's
  own noise (1/K of the image's, the same sampler) is taken out: MSE / (1 + 1/K), so
  K = 1 is the two-seed estimate of the render noise. A denoised image has no such
  model, so its reference's own noise is measured: a group with a denoised member renders
  its reference as two halves on two seed sets (K₁ + K₂ = K), and the noise of their
  weighted mean, MSE(r₁, r₂) · K₁K₂ / K², is taken out of the denoised image's MSE
  (independent seeds: E[MSE(image, ref)] = MSE(image, truth) + that noise). At K = 8 it
  is ≈ 0.6 dB of a 512 px denoised image's score (bench/check_reference_noise.py checks
  it against a K = 32 reference).
- `detail_ratio_*`: the high-frequency energy of the image over its render reference's
  (core `detail_ratio`): < 1 a denoiser smoothed texture, > 1 noise on top.

Sizes (env): BLURSET_BENCH_SPH_RES (128 px), BLURSET_BENCH_SPH_VIEWS (1),
BLURSET_BENCH_REPEATS (1), BLURSET_BENCH_SPH_PRESETS (all), BLURSET_BENCH_REF_CAP
(20000), BLURSET_BENCH_NO_RENDER_REF (none: presets not given a render reference),
BLURSET_BENCH_GLBS (the three textured models).
"""

from __future__ import annotations

import json
import math
import os
import statistics
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from fixed_presets import FRAME_OPTIONS, PRESETS  # noqa: E402
from harness import timed_build  # noqa: E402
from sph_references import (  # noqa: E402
    REF_CAP,
    REF_FACTOR,
    REFERENCE,
    continuous_reference,
    denoised_mse,
    render_reference,
)

HERE = Path(__file__).resolve().parent
RES = int(os.environ.get("BLURSET_BENCH_SPH_RES", "128"))
VIEWS = int(os.environ.get("BLURSET_BENCH_SPH_VIEWS", "1"))
REPEATS = int(os.environ.get("BLURSET_BENCH_REPEATS", "1"))
# Presets whose render reference is not rendered (their render PSNR and detail ratio are
# then None): the paper preset's costs as much as its build, hours at 512 px.
NO_RENDER_REF = set(filter(None, os.environ.get("BLURSET_BENCH_NO_RENDER_REF", "").split(",")))
SEED = 5
FLOOR_DB = 58.9  # 8-bit quantization alone: 1 / (255² · 12) in MSE
TEXTURED = ("sketchfab_MapPin", "sketchfab_MazdaRX7Stylised", "WaterBottle_blender_reexport")


def _glbs(work: Path) -> list[Path]:
    env = os.environ.get("BLURSET_BENCH_GLBS")
    if env:
        return [Path(p) for p in env.split(",") if p]
    data = HERE.parent.parent / "shared" / "data" / "glb"
    found = [data / f"{n}.glb" for n in TEXTURED if (data / f"{n}.glb").exists()]
    if found:
        return found
    from blurset.services.demo import make_demo_objects

    return [make_demo_objects(work / "obj")[0]]


def _config(out: Path, glb: Path, **kw):
    from blurset.services.config import make_config

    flags = {
        "objects": [str(glb)],
        "out": out,
        "views": VIEWS,
        "resolution": RES,
        "settings_per_object": 1,
        "seed": SEED,
        "write_linear": True,
        "device": os.environ.get("BLURSET_BENCH_DEVICE", "cpu").lower(),
        # Every measured view renders its blurry images: by default view 0 is a test view
        # whose blur levels are copies of its sharp image.
        "blurry_test_views": True,
    }
    file_values = {k: v for k, v in kw.items() if k != "latents_auto"}
    if kw.get("latents_auto"):
        flags["latents"] = "auto"
    return make_config(file_values, flags)


def _build(out: Path, glb: Path, preset: dict) -> dict:
    wall, setting, meta = timed_build(_config(out, glb, **preset))
    t = meta["timings"]
    render = t["plan_s"] + t["sharp_s"] + t["blur_s"]
    samples = {"sharp": meta["render"]["sharp_samples"]}
    for v in meta["views"][:1]:
        for lvl, lp in v["levels"].items():
            samples[f"blur_{lvl}"] = lp["samples_per_frame"] * lp["latents"]
    return {
        "wall_s": wall,
        "render_s": render,
        "rest_s": wall - render,
        "frames": t["frames"],
        "setting": setting,
        "samples": samples,
    }


def _score(
    setting: Path, cont: dict, ref: dict | None, noise: dict, k_of: dict, denoised: bool
) -> dict:
    from blurset.image import image_error, read_exr

    out: dict[str, list[float]] = {}
    for (view, level), c in cont.items():
        img = np.ascontiguousarray(read_exr(setting / level / "linear" / f"{view:03d}.exr"))
        kind = "sharp" if level == "sharp" else "blur"
        q = image_error(img, c)
        out.setdefault(f"psnr_{kind}", []).append(q.psnr)
        if ref is None:  # not rendered (NO_RENDER_REF): NaN, reported as None
            for key in ("render_mse", "detail", "ref_factor", "ref_noise"):
                out.setdefault(f"{key}_{kind}", []).append(float("nan"))
            continue
        r = image_error(img, ref[(view, level)])
        k = k_of[level]
        mse = denoised_mse(r.mse, noise[(view, level)]) if denoised else r.mse / (1.0 + 1.0 / k)
        out.setdefault(f"render_mse_{kind}", []).append(mse)
        out.setdefault(f"detail_{kind}", []).append(r.detail_ratio)
        out.setdefault(f"ref_factor_{kind}", []).append(k)
        out.setdefault(f"ref_noise_{kind}", []).append(noise.get((view, level), 0.0))
    return out


def _db(mse: float) -> float | None:
    if not math.isfinite(mse):
        return None
    return float(-10.0 * np.log10(mse)) if mse > 0 else 200.0


def _mean(xs) -> float | None:
    m = float(np.mean(xs))
    return m if math.isfinite(m) else None


def _scored_presets(glb: Path, work: Path, runs: dict[str, list[dict]]) -> dict[str, dict]:
    """Each preset's images of `glb` scored against the continuous blur and, per group of
    presets that share latent frames, one render reference."""
    cont = continuous_reference(_config, glb, work, RES)
    groups: dict[tuple, list[str]] = {}
    for name, preset in PRESETS.items():
        key = tuple((o, str(preset.get(o))) for o in FRAME_OPTIONS)
        groups.setdefault(key, []).append(name)
    scored = {}
    for names in groups.values():
        # The reference renders the frames of the member with the most samples, K
        # times each image's samples in that member: a member's factor is K times
        # that member's samples over its own (the most in one image need not be the
        # top member's).
        top = max(names, key=lambda n: sum(runs[n][0]["samples"].values()))
        samples = runs[top][0]["samples"]
        plain = {k: v for k, v in PRESETS[top].items() if k != "denoise"}
        split = any(PRESETS[n].get("denoise") == "oidn" for n in names)
        noise: dict  # the reference's noise per image: none without a reference
        if set(names) <= NO_RENDER_REF:
            ref, k, noise = None, 1, {}
        else:
            ref, k, noise = render_reference(_config, glb, work, RES, plain, samples, split)
        for n in names:
            own = runs[n][0]["samples"]
            k_of = {lv: k * samples[lv] / own[lv] for lv in own}
            denoised = PRESETS[n].get("denoise") == "oidn"
            sc = _score(runs[n][0]["setting"], cont, ref, noise, k_of, denoised)
            rs = runs[n]
            scored[n] = {
                "render_s": statistics.median(r["render_s"] for r in rs),
                "rest_s": statistics.median(r["rest_s"] for r in rs),
                "frames": rs[0]["frames"],
                "samples": rs[0]["samples"],
                **{key: [float(x) for x in v] for key, v in sc.items()},
            }
    return scored


def _object_summary(o: dict) -> dict:
    return {
        "settings_per_hour": 3600.0 / (34 * o["render_s"] / VIEWS + o["rest_s"] / 4),
        "render_psnr_blur_db": _db(float(np.mean(o["render_mse_blur"]))),
        "render_psnr_sharp_db": _db(float(np.mean(o["render_mse_sharp"]))),
        "detail_ratio_blur": _mean(o["detail_blur"]),
        "detail_ratio_sharp": _mean(o["detail_sharp"]),
        "psnr_blur_db": float(np.mean(o["psnr_blur"])),
        "psnr_sharp_db": float(np.mean(o["psnr_sharp"])),
        "samples": o["samples"],
        "frames": o["frames"],
    }


def _preset_summary(objects: dict[str, dict]) -> dict:
    """One preset over every object: settings per hour and the pooled accuracy."""
    objs = objects.values()
    # One setting of each object, in turn: 34 views, the rest over 4 settings.
    setting_s = statistics.mean(34 * o["render_s"] / VIEWS + o["rest_s"] / 4 for o in objs)
    cat = {key: [x for o in objs for x in o[key]] for key in next(iter(objs)) if key.startswith(
        ("psnr_", "render_mse_", "detail_", "ref_factor_", "ref_noise_"))}  # fmt: skip
    return {
        "settings_per_hour": 3600.0 / setting_s,
        "setting_s": setting_s,
        "psnr_blur_db": float(np.mean(cat["psnr_blur"])),
        "psnr_sharp_db": float(np.mean(cat["psnr_sharp"])),
        # PSNR of the mean render-noise MSE over the images.
        "render_psnr_blur_db": _db(float(np.mean(cat["render_mse_blur"]))),
        "render_psnr_sharp_db": _db(float(np.mean(cat["render_mse_sharp"]))),
        "render_psnr_blur_min_db": _db(float(np.max(cat["render_mse_blur"]))),
        "render_psnr_sharp_min_db": _db(float(np.max(cat["render_mse_sharp"]))),
        "detail_ratio_blur": _mean(cat["detail_blur"]),
        "detail_ratio_sharp": _mean(cat["detail_sharp"]),
        "reference_factor_min": _mean([min(cat["ref_factor_blur"] + cat["ref_factor_sharp"])]),
        # The reference's own noise taken out of denoised images' MSE (None: not
        # measured, no denoised member).
        "reference_noise_psnr_blur_db": _db(float(np.mean(cat["ref_noise_blur"])))
        if any(cat["ref_noise_blur"])
        else None,
        "reference_noise_psnr_sharp_db": _db(float(np.mean(cat["ref_noise_sharp"])))
        if any(cat["ref_noise_sharp"])
        else None,
        "per_object": {u: _object_summary(o) for u, o in objects.items()},
    }


def measure() -> dict:
    with tempfile.TemporaryDirectory(prefix="blurset-bench-sph-") as tmp:
        work = Path(tmp)
        glbs = _glbs(work)
        per: dict[str, dict] = {name: {} for name in PRESETS}
        for glb in glbs:
            runs: dict[str, list[dict]] = {k: [] for k in PRESETS}
            for rep in range(REPEATS):
                for name, preset in PRESETS.items():
                    runs[name].append(_build(work / f"{glb.stem}_{name}_{rep}", glb, preset))
            for name, scored in _scored_presets(glb, work, runs).items():
                per[name][glb.stem] = scored
    out = {name: _preset_summary(objects) for name, objects in per.items()}
    return {"resolution": RES, "views": VIEWS, "repeats": REPEATS, "presets": out,
            "objects": [g.stem for g in glbs], "load_average": os.getloadavg()}  # fmt: skip


def verdict(q: dict, paper: dict) -> dict:
    """Issue 28's bar for a preset against the paper preset of the same run."""
    # A paper preset without render reference (NO_RENDER_REF) is taken to be above the
    # floor: its 1088 / 4488 samples are, at 128 and 512 px (bench_denoise_gain).
    floor_s = min(paper["render_psnr_sharp_db"] or FLOOR_DB, FLOOR_DB)
    floor_b = min(paper["render_psnr_blur_db"] or FLOOR_DB, FLOOR_DB)
    rb, rs = q["render_psnr_blur_db"], q["render_psnr_sharp_db"]
    checks = {
        "sharp_accurate": rs >= floor_s,
        "blur_accurate": rb >= floor_b,
        "blur_vs_continuous": q["psnr_blur_db"] >= paper["psnr_blur_db"],
        "parity": abs(rb - rs) <= 0.5 or (rb >= FLOOR_DB and rs >= FLOOR_DB),
        "detail": all(0.95 <= q[k] <= 1.05 for k in ("detail_ratio_blur", "detail_ratio_sharp")),
        "speed_10x": q["settings_per_hour"] >= 10.0 * paper["settings_per_hour"],
    }
    return {**checks, "all": all(checks.values())}


def run() -> list[dict]:
    m = measure()
    p = m["presets"]
    paper = p["paper"]
    device = os.environ.get("BLURSET_BENCH_DEVICE", "CPU")
    res = []
    for name, q in p.items():
        res.append(
            {
                # Another size is another table: its ratios are to its own paper preset.
                "name": f"settings_per_hour_{name}"
                if RES == 128
                else f"settings_per_hour_{RES}px_{name}",
                "ratio": q["settings_per_hour"] / paper["settings_per_hour"],
                "ratio_is": "settings per hour over the paper preset's, same run",
                "contender": f"{name} preset {PRESETS[name]}: "
                f"{q['settings_per_hour']:.2f} settings/h at {m['resolution']} px",
                "baseline": f"paper preset: {paper['settings_per_hour']:.2f} settings/h",
                **{k: v for k, v in q.items() if k != "setting_s"},
                "verdict": None
                if name == "paper" or q["render_psnr_sharp_db"] is None
                else verdict(q, paper),
                "resolution": m["resolution"],
                "views_measured": m["views"],
                "repeats": m["repeats"],
                "objects": m["objects"],
                "reference": f"continuous blur: {REFERENCE[0]} stratified frames x "
                f"{REFERENCE[1]} samples, sharp {REFERENCE[0] * REFERENCE[1]}; render: the "
                f"preset's own frames at >= {REF_FACTOR}x its samples, capped at {REF_CAP} "
                "samples per view (reference_factor_min); a denoised image's MSE less its "
                "reference's own noise, measured from two half references on two seed sets",
                "device": device,
                "load_average": m["load_average"],
            }
        )
    return res


if __name__ == "__main__":
    json.dump(measure(), sys.stdout, indent=1, default=str)
    print()
