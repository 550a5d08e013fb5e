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
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
RES = int(os.environ.get("BLURSET_BENCH_SPH_RES", "128"))
VIEWS = int(os.environ.get("BLURSET_BENCH_SPH_VIEWS", "1"))
REPEATS = int(os.environ.get("BLURSET_BENCH_REPEATS", "1"))
REF_CAP = int(os.environ.get("BLURSET_BENCH_REF_CAP", "20000"))
# Presets whose render reference is not rendered (their render PSNR and detail ratio are
# then None): the paper preset's costs as much as its build, hours at 512 px.
NO_RENDER_REF = set(filter(None, os.environ.get("BLURSET_BENCH_NO_RENDER_REF", "").split(",")))
REF_FACTOR = 32
SEED = 5
REFERENCE = (64, 16)  # continuous blur: stratified frames x samples; sharp: their product
SALT = 0x5BD1E995
SALT2 = 0x27D4EB2F  # the second half of a split reference
FLOOR_DB = 58.9  # 8-bit quantization alone: 1 / (255² · 12) in MSE
TEXTURED = ("sketchfab_MapPin", "sketchfab_MazdaRX7Stylised", "WaterBottle_blender_reexport")

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
_ONLY = os.environ.get("BLURSET_BENCH_SPH_PRESETS")
if _ONLY:
    PRESETS = {k: v for k, v in PRESETS.items() if k in {"paper", *_ONLY.split(",")}}
# Options that move latent frames: presets equal in these share a render reference.
_FRAMES = ("blur_method", "latents_auto", "latent_positions", "max_ghost_px", "latents")


def _glbs(work: Path) -> list[Path]:
    env = os.environ.get("BLURSET_BENCH_GLBS")
    if env:
        return [Path(p) for p in env.split(",") if p]
    data = HERE.parent.parent / "shared" / "data" / "glb"
    found = [data / f"{n}.glb" for n in TEXTURED if (data / f"{n}.glb").exists()]
    if found:
        return found
    from blurset.demo import make_demo_objects

    return [make_demo_objects(work / "obj")[0]]


def _config(out: Path, glb: Path, **kw):
    from blurset.config import make_config

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
    from blurset.builder import build

    cfg = _config(out, glb, **preset)
    t0 = time.perf_counter()
    summary = build(cfg, progress=False)
    wall = time.perf_counter() - t0
    if summary["settings_complete"] != 1:
        raise RuntimeError(f"bench build failed: {summary['failures']}")
    (setting,) = [d for d in out.iterdir() if (d / ".complete").exists()]
    meta = json.loads((setting / "meta.json").read_text())
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


def _plan(cfg, glb: Path, w, work: Path):
    from blurset.plan import plan_setting, seed_for

    info = w.load(glb, work / "v.npy")
    verts = np.ascontiguousarray(np.load(work / "v.npy"), dtype=np.float32)
    return plan_setting(cfg, uid=glb.stem, theta0_deg=0.0, seed=seed_for(cfg.seed, glb.stem, 0),
                        bbox_dims=info["bbox_dims"], vertices=verts)  # fmt: skip


def _render(w, frames: list[dict], samples: int) -> np.ndarray:
    from blurset.image import Accumulator

    acc = Accumulator(RES, RES)

    def on_frame(_i: int, path: str, origin) -> None:
        acc.add_exr(path, origin)
        os.unlink(path)

    w.render(frames, resolution=RES, fov_deg=40.0, samples=samples, on_frame=on_frame, crop=True)
    return acc.mean()


def _continuous_reference(glb: Path, work: Path) -> dict:
    """Reference images (premultiplied linear RGBA) per (view, level dir): the continuous
    blur of each level, and the sharp view with as many samples."""
    from blurset.worker_client import Worker

    cfg = _config(work / "unused", glb, latents=REFERENCE[0], latent_positions="stratified",
                  samples=REFERENCE[1], blur_budget="flat")  # fmt: skip
    refs = {}
    with Worker(timeout=7200, workdir=work / "scratch", device=cfg.device.upper()) as w:
        setting = _plan(cfg, glb, w, work)
        for v in setting.to_dict()["views"]:
            # Other Cycles seeds than the builds' (noise they share would flatter them).
            sharp = [{"c2w": v["c2w"], "seed": v["sharp_seed"] ^ SALT, "out": str(work / "s.exr")}]
            refs[(v["index"], "sharp")] = _render(w, sharp, REFERENCE[0] * REFERENCE[1])
            for lvl in v["levels"]:
                frames = setting.level_renders(v["index"], int(lvl), str(work / "f"))
                for f in frames:
                    f["seed"] = (f["seed"] ^ SALT) & 0x7FFFFFFF
                refs[(v["index"], f"blur_{lvl}")] = _render(w, frames, 1)
    return refs


def _render_reference(
    glb: Path, work: Path, preset: dict, samples: dict, split: bool
) -> tuple[dict, int, dict]:
    """The preset's own images, undenoised, at K times its samples on other seeds:
    (images per (view, level dir), K, the noise MSE of each image). `samples`: the sample
    counts of `preset`'s images (the member with the most samples of the presets that share
    these frames). `split`: render each image as two halves on two seed sets and measure
    the noise of their mean (else the noise is not measured: no entry)."""
    from blurset.image import image_error
    from blurset.worker_client import Worker

    per_view = sum(samples.values())
    k = max(2 if split else 1, min(REF_FACTOR, REF_CAP // max(per_view, 1)))
    halves = [(SALT, k // 2), (SALT2, k - k // 2)] if split else [(SALT, k)]
    cfg = _config(work / "unused", glb, **preset)
    refs, noise = {}, {}
    with Worker(timeout=7200, workdir=work / "scratch", device=cfg.device.upper()) as w:
        setting = _plan(cfg, glb, w, work)
        sharp_n = int(cfg.effective_sharp_samples)
        images: dict[tuple[int, str], list[dict]] = {}
        for f in setting.renders(str(work / "r")):
            images.setdefault((f["view"], f["level"]), []).append(f)
        for key, frames in images.items():
            parts = []
            for salt, kh in halves:
                half = [dict(f) for f in frames]
                for f in half:
                    f["seed"] = (f["seed"] ^ salt) & 0x7FFFFFFF
                    n = f.get("samples") or sharp_n
                    f["samples"] = kh * n
                    if f.get("sample_offset") is not None:
                        f["sample_offset"] *= kh
                        f["sample_sequence"] *= kh
                parts.append((kh, _render(w, half, kh * sharp_n)))
            refs[key] = sum(kh * img for kh, img in parts) / k
            if split:
                (k1, r1), (k2, r2) = parts
                noise[key] = image_error(r1, r2).mse * k1 * k2 / k**2
    return refs, k, noise


def denoised_mse(measured: float, reference_noise: float) -> float:
    """A denoised image's MSE against the truth: its MSE against the reference less the
    reference's own noise (independent seeds: the two add)."""
    return max(measured - reference_noise, 0.0)


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


def measure() -> dict:
    with tempfile.TemporaryDirectory(prefix="blurset-bench-sph-") as tmp:
        work = Path(tmp)
        glbs = _glbs(work)
        per: dict[str, dict] = {name: {"objects": {}} for name in PRESETS}
        for glb in glbs:
            runs: dict[str, list[dict]] = {k: [] for k in PRESETS}
            for rep in range(REPEATS):
                for name, preset in PRESETS.items():
                    runs[name].append(_build(work / f"{glb.stem}_{name}_{rep}", glb, preset))
            cont = _continuous_reference(glb, work)
            groups: dict[tuple, list[str]] = {}
            for name, preset in PRESETS.items():
                key = tuple((o, str(preset.get(o))) for o in _FRAMES)
                groups.setdefault(key, []).append(name)
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
                    ref, k, noise = _render_reference(glb, work, plain, samples, split)
                for n in names:
                    own = runs[n][0]["samples"]
                    k_of = {lv: k * samples[lv] / own[lv] for lv in own}
                    denoised = PRESETS[n].get("denoise") == "oidn"
                    sc = _score(runs[n][0]["setting"], cont, ref, noise, k_of, denoised)
                    rs = runs[n]
                    per[n]["objects"][glb.stem] = {
                        "render_s": statistics.median(r["render_s"] for r in rs),
                        "rest_s": statistics.median(r["rest_s"] for r in rs),
                        "frames": rs[0]["frames"],
                        "samples": rs[0]["samples"],
                        **{key: [float(x) for x in v] for key, v in sc.items()},
                    }
    out = {}
    for name, p in per.items():
        objs = p["objects"].values()
        # One setting of each object, in turn: 34 views, the rest over 4 settings.
        setting_s = statistics.mean(34 * o["render_s"] / VIEWS + o["rest_s"] / 4 for o in objs)
        cat = {key: [x for o in objs for x in o[key]] for key in next(iter(objs)) if key.startswith(
            ("psnr_", "render_mse_", "detail_", "ref_factor_", "ref_noise_"))}  # fmt: skip
        out[name] = {
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
            "per_object": {
                u: {
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
                for u, o in p["objects"].items()
            },
        }
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
