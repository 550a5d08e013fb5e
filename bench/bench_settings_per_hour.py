"""settings_per_hour: whole `blurset build` runs of the paper preset against faster
presets (issue 6, DESIGN §9), with what the faster ones lose in PSNR.

Each preset builds the same setting of a demo object (same seed: same views, trajectories
and w_l) with `--keep-linear`; builds of the presets are interleaved and repeated, and the
median wall time is taken (the machine is shared). A 34-view setting is extrapolated from
the measured views: settings/hour = 3600 / (34 · render time per view + the rest of the
build, worker start and object load included, divided over the 4 settings an object has).

Quality: every blurry and sharp image of the first build of each preset against a
reference rendered for the same views and trajectories (blurry: the mean of many
stratified latent frames with many samples each; sharp: one render with as many samples);
PSNR of the sRGB images over white, the mean over images. The PSNR loss is the paper
preset's PSNR minus the preset's (negative: the faster preset is closer to the reference).

Sizes (env): BLURSET_BENCH_SPH_RES (128 px), BLURSET_BENCH_SPH_VIEWS (2),
BLURSET_BENCH_REPEATS (2).
"""

from __future__ import annotations

import json
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

RES = int(os.environ.get("BLURSET_BENCH_SPH_RES", "128"))
VIEWS = int(os.environ.get("BLURSET_BENCH_SPH_VIEWS", "2"))
REPEATS = int(os.environ.get("BLURSET_BENCH_REPEATS", "2"))
SEED = 5
REFERENCE = (96, 32)
SALT = 0x5BD1E995  # stratified latent frames x samples each; sharp: their product

PRESETS = {
    # blurset build's defaults: the paper's 34 random latent frames, 32 samples each
    # times the parity factor 34^0.4 (132), the sharp image with the budget (1088).
    "paper": {},
    # One Cycles motion blur render per blurry image at 128 samples; sharp at 256.
    "fast": {"blur_method": "motion_blur", "samples_total": 128, "sharp_samples": 256},
    # Latent averaging kept: per-level m from the 1 px ghost bound (stratified, up to
    # 34), 256 samples split over the frames; sharp at 256.
    "balanced": {
        "latents_auto": True,
        "latent_positions": "stratified",
        "samples_total": 256,
        "sharp_samples": 256,
    },
}


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
        # whose blur levels are copies of its sharp image, which would halve the measured
        # cost of a 2-view run and score sharp copies against blurry references.
        "blurry_test_views": True,
    }
    file_values = {k: v for k, v in kw.items() if k != "latents_auto"}
    if kw.get("latents_auto"):
        flags["latents"] = "auto"
    return make_config(file_values, flags)


def _build(out: Path, glb: Path, preset: dict) -> dict:
    from blurset.build import build

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
    per_view = render / VIEWS
    rest = wall - render
    setting_s = 34 * per_view + rest / 4
    return {
        "wall_s": wall,
        "per_view_s": per_view,
        "rest_s": rest,
        "setting_s": setting_s,
        "settings_per_hour": 3600.0 / setting_s,
        "frames": t["frames"],
        "setting": setting,
    }


def _reference(glb: Path, work: Path) -> dict:
    """Reference images (premultiplied linear RGBA) per (view, level dir)."""
    from blurset.image import Accumulator
    from blurset.plan import plan_setting, seed_for
    from blurset.worker_client import Worker

    cfg = _config(work / "unused", glb, latents=REFERENCE[0], latent_positions="stratified",
                  samples=REFERENCE[1])  # fmt: skip
    refs = {}
    with Worker(timeout=3600, workdir=work / "scratch", device=cfg.device.upper()) as w:
        info = w.load(glb, work / "v.npy")
        verts = np.ascontiguousarray(np.load(work / "v.npy"), dtype=np.float32)
        seed = seed_for(cfg.seed, glb.stem, 0)
        setting = plan_setting(
            cfg,
            uid=glb.stem,
            theta0_deg=0.0,
            seed=seed,
            bbox_dims=info["bbox_dims"],
            vertices=verts,
        )
        for v in setting.to_dict()["views"]:
            # Other Cycles seeds than the builds' (noise they share would flatter them).
            jobs = [("sharp", [{"c2w": v["c2w"], "seed": v["sharp_seed"],
                                "samples": REFERENCE[0] * REFERENCE[1],
                                "out": str(work / "s.exr")}])]  # fmt: skip
            jobs += [
                (f"blur_{lvl}", setting.level_renders(v["index"], int(lvl), str(work / "f")))
                for lvl in v["levels"]
            ]
            for name, frames in jobs:
                for f in frames:
                    f["seed"] = (f["seed"] ^ SALT) & 0x7FFFFFFF
                acc = Accumulator(RES, RES)

                def on_frame(_i: int, path: str, origin, acc=acc) -> None:
                    acc.add_exr(path, origin)
                    os.unlink(path)

                w.render(frames, resolution=RES, fov_deg=cfg.fov_deg, samples=1,
                         on_frame=on_frame, crop=True)  # fmt: skip
                refs[(v["index"], name)] = acc.mean()
    return refs


def _quality(setting: Path, refs: dict) -> dict:
    from blurset.image import image_error, read_exr

    blur, sharp = [], []
    for (view, level), ref in refs.items():
        img = read_exr(setting / level / "linear" / f"{view:03d}.exr")
        q = image_error(np.ascontiguousarray(img), ref).psnr
        (sharp if level == "sharp" else blur).append(q)
    return {"psnr_blur": float(np.mean(blur)), "psnr_sharp": float(np.mean(sharp))}


def measure() -> dict:
    from blurset.demo import make_demo_objects

    with tempfile.TemporaryDirectory(prefix="blurset-bench-sph-") as tmp:
        work = Path(tmp)
        glb = Path(os.environ.get("BLURSET_BENCH_GLB") or make_demo_objects(work / "obj")[0])
        runs: dict[str, list[dict]] = {k: [] for k in PRESETS}
        quality = {}
        for rep in range(REPEATS):
            for name, preset in PRESETS.items():
                r = _build(work / f"{name}_{rep}", glb, preset)
                runs[name].append(r)
        refs = _reference(glb, work)
        for name in PRESETS:
            quality[name] = _quality(runs[name][0]["setting"], refs)
    out = {}
    for name, rs in runs.items():
        out[name] = {
            k: statistics.median(r[k] for r in rs)
            for k in ("wall_s", "per_view_s", "rest_s", "setting_s", "settings_per_hour")
        }
        out[name]["frames"] = rs[0]["frames"]
        out[name].update(quality[name])
    return {"resolution": RES, "views": VIEWS, "repeats": REPEATS, "presets": out,
            "load_average": os.getloadavg()}  # fmt: skip


def run() -> list[dict]:
    m = measure()
    p = m["presets"]
    paper = p["paper"]
    res = [
        {
            "name": "settings_per_hour_paper",
            # Absolute: settings/hour of the paper preset (34-view settings, extrapolated).
            "ratio": paper["settings_per_hour"],
            "ratio_is": "settings per hour",
            "contender": f"paper preset: {paper['settings_per_hour']:.2f} settings/h at "
            f"{m['resolution']} px",
            "baseline": "—",
            "settings_per_hour": paper["settings_per_hour"],
            "per_view_s": paper["per_view_s"],
            "psnr_blur_db": paper["psnr_blur"],
            "psnr_sharp_db": paper["psnr_sharp"],
            "resolution": m["resolution"],
            "views_measured": m["views"],
            "repeats": m["repeats"],
            "device": os.environ.get("BLURSET_BENCH_DEVICE", "CPU"),
            "load_average": m["load_average"],
        }
    ]
    for name in ("fast", "balanced"):
        q = p[name]
        res.append(
            {
                "name": f"settings_per_hour_{name}",
                "ratio": q["settings_per_hour"] / paper["settings_per_hour"],
                "contender": f"{name} preset {PRESETS[name]}: "
                f"{q['settings_per_hour']:.2f} settings/h at {m['resolution']} px",
                "baseline": f"paper preset: {paper['settings_per_hour']:.2f} settings/h",
                "psnr_loss_blur_db": paper["psnr_blur"] - q["psnr_blur"],
                "psnr_loss_sharp_db": paper["psnr_sharp"] - q["psnr_sharp"],
                "psnr_blur_db": q["psnr_blur"],
                "psnr_sharp_db": q["psnr_sharp"],
                "paper_psnr_blur_db": paper["psnr_blur"],
                "paper_psnr_sharp_db": paper["psnr_sharp"],
                "settings_per_hour": q["settings_per_hour"],
                "paper_settings_per_hour": paper["settings_per_hour"],
                "per_view_s": q["per_view_s"],
                "paper_per_view_s": paper["per_view_s"],
                "resolution": m["resolution"],
                "views_measured": m["views"],
                "repeats": m["repeats"],
                "reference": f"blurry: {REFERENCE[0]} stratified frames x {REFERENCE[1]} "
                f"samples; sharp: {REFERENCE[0] * REFERENCE[1]} samples",
                "load_average": m["load_average"],
            }
        )
    return res


if __name__ == "__main__":
    json.dump(measure(), sys.stdout, indent=1, default=str)
    print()
