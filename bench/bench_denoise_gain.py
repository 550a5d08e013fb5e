"""denoise_gain: what `--denoise oidn` buys a sharp image, per object and size (issue 28).

For one view of each textured GLB (MapPin, Mazda, WaterBottle from ../shared/data, else
the demo box) at 128 and 512 px, the sharp image is rendered with its guide passes at
64 to 1024 samples, as a `--denoise oidn` build renders it, and scored undenoised and
denoised (the driver's OIDN on the image, as the build) against a render of REF samples
on other Cycles seeds: render PSNR (sRGB over the background, as everywhere in the
bench) and detail ratio (high-frequency energy over the reference's: < 1 smoothed).
An undenoised image's score has the reference's own noise taken out (MSE / (1 + S/REF),
the same sampler); a denoised one is scored as measured (conservative).

The ratio: the samples an undenoised image needs to reach the 8-bit floor (58.9 dB)
over the samples a denoised one needs, each read off its measured curve (log-linear
between the two sample counts around the floor; None when a curve never reaches it).
The time of a render is close to proportional to its samples (the per-frame overhead at
128 px is ≈ 8 ms), so that ratio is what the denoiser saves in render time, before its
own time (`denoise_s`, also reported).

Sizes (env): BLURSET_BENCH_GAIN_RES (128,512), BLURSET_BENCH_GAIN_SAMPLES
(64,128,256,512,1024), BLURSET_BENCH_GAIN_REF (4096).
"""

from __future__ import annotations

import json
import math
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
RESOLUTIONS = tuple(int(x) for x in os.environ.get("BLURSET_BENCH_GAIN_RES", "128,512").split(","))
SAMPLES = tuple(
    int(x) for x in os.environ.get("BLURSET_BENCH_GAIN_SAMPLES", "64,128,256,512,1024").split(",")
)
REF = int(os.environ.get("BLURSET_BENCH_GAIN_REF", "4096"))
FLOOR_DB = 58.9  # 8-bit quantization alone: 1 / (255² · 12) in MSE
SALT = 0x5BD1E995


def samples_at(samples: list[int], psnr: list[float], target: float = FLOOR_DB) -> float | None:
    """The sample count at which a measured PSNR curve reaches `target`: log-linear
    between the two measured counts around it; None when it never does."""
    pts = sorted(zip(samples, psnr, strict=True))
    if pts[0][1] >= target:
        return float(pts[0][0])
    for (s0, p0), (s1, p1) in zip(pts, pts[1:], strict=False):
        if p0 < target <= p1:
            f = (target - p0) / (p1 - p0)
            return float(math.exp(math.log(s0) + f * (math.log(s1) - math.log(s0))))
    return None


def _render(w, work: Path, c2w, seed: int, res: int, fov: float, samples: int, guides: bool):
    """One sharp render, accumulated as a build does: (Accumulator, seconds)."""
    from blurset.image import Accumulator

    acc = Accumulator(res, res, guides=guides)

    def on_frame(_i: int, path: str, origin) -> None:
        acc.add_exr(path, origin)
        os.unlink(path)

    t0 = time.perf_counter()
    frame = {"c2w": c2w, "seed": seed, "out": str(work / "s.exr")}
    w.render([frame], resolution=res, fov_deg=fov, samples=samples, on_frame=on_frame,
             crop=True, guides=guides)  # fmt: skip
    return acc, time.perf_counter() - t0


def measure() -> dict:
    sys.path.insert(0, str(HERE))
    from bench_settings_per_hour import _glbs
    from blurset.image import image_error
    from blurset.plan import BuildConfig, plan_setting
    from blurset.services.denoise import denoiser, device_for
    from blurset.services.worker_client import Worker

    device = os.environ.get("BLURSET_BENCH_DEVICE", "CPU")  # bench/run.py --device
    den = denoiser(device_for(device))  # on the render device, as a build denoises
    out: dict = {"ref_samples": REF, "samples": list(SAMPLES), "objects": {}}
    with tempfile.TemporaryDirectory(prefix="blurset-bench-gain-") as tmp:
        work = Path(tmp)
        with Worker(timeout=7200, workdir=work / "scratch", device=device) as w:
            for glb in _glbs(work):
                info = w.load(glb, work / "v.npy")
                verts = np.ascontiguousarray(np.load(work / "v.npy"), dtype=np.float32)
                for res in RESOLUTIONS:
                    cfg = BuildConfig(views=1, resolution=res)
                    plan = plan_setting(cfg, uid=glb.stem, theta0_deg=0.0, seed=5,
                                        bbox_dims=info["bbox_dims"], vertices=verts)  # fmt: skip
                    v = plan.to_dict()["views"][0]

                    fov = cfg.fov_deg
                    ref_seed = (v["sharp_seed"] ^ SALT) & 0x7FFFFFFF
                    ref_acc, ref_s = _render(w, work, v["c2w"], ref_seed, res, fov, REF, False)
                    ref = ref_acc.mean()
                    row: dict = {"ref_s": ref_s, "render_s": [], "denoise_s": [],
                                 "raw_db": [], "oidn_db": [], "raw_detail": [], "oidn_detail": []}  # fmt: skip
                    for s in SAMPLES:
                        acc, t = _render(w, work, v["c2w"], v["sharp_seed"], res, fov, s, True)
                        raw = acc.mean()
                        t0 = time.perf_counter()
                        acc.denoise(den)
                        row["denoise_s"].append(time.perf_counter() - t0)
                        er, ed = image_error(raw, ref), image_error(acc.mean(), ref)
                        mse = er.mse / (1.0 + s / REF)
                        row["render_s"].append(t)
                        row["raw_db"].append(float(-10.0 * np.log10(mse)) if mse > 0 else 200.0)
                        row["oidn_db"].append(float(ed.psnr))
                        row["raw_detail"].append(float(er.detail_ratio))
                        row["oidn_detail"].append(float(ed.detail_ratio))
                    row["raw_samples_at_floor"] = samples_at(list(SAMPLES), row["raw_db"])
                    row["oidn_samples_at_floor"] = samples_at(list(SAMPLES), row["oidn_db"])
                    out["objects"].setdefault(glb.stem, {})[str(res)] = row
                    print(glb.stem, res, json.dumps(row), file=sys.stderr, flush=True)
            out["device"] = w.info.get("device")
    out["load_average"] = os.getloadavg()
    return out


def run() -> list[dict]:
    m = measure()
    res = []
    for uid, by_res in m["objects"].items():
        for r, row in by_res.items():
            raw_n, oidn_n = row["raw_samples_at_floor"], row["oidn_samples_at_floor"]
            ratio = raw_n / oidn_n if raw_n and oidn_n else float("nan")
            res.append(
                {
                    "name": f"denoise_gain_{uid}_{r}px",
                    "ratio": ratio,
                    "ratio_is": "samples an undenoised sharp image needs for 58.9 dB / "
                    "samples a denoised one needs",
                    "contender": f"OIDN: {_n(oidn_n)} samples for 58.9 dB",
                    "baseline": f"undenoised: {_n(raw_n)} samples",
                    "resolution": int(r),
                    **row,
                    "samples": m["samples"],
                    "ref_samples": m["ref_samples"],
                    "device": m["device"],
                    "load_average": m["load_average"],
                }
            )
    return res


def _n(x: float | None) -> str:
    return "more than measured" if x is None else f"{x:.0f}"


if __name__ == "__main__":
    json.dump(measure(), sys.stdout, indent=1, default=str)
    print()
