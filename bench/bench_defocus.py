"""defocus_parity_level<l>: the render noise of a defocus image against its sharp image's,
and what a defocus image costs (issue 35).

A defocus image is one Cycles render through a thin lens at the sharp image's pose and
sample count; the lens is one more dimension the samples must cover, so at equal
samples its render noise can differ from the sharp image's. Per demo object (96 px,
one view, defocus levels 1–4, 256 samples each):
the render-noise MSE of each defocus image (against a converged render of the same lens,
REF× the samples, another seed) over the sharp image's (against its own converged
render), on the object's pixels, as bench_render_parity measures the motion levels
(parity 1; 0.5 dB is 1.12). `ratio`: sharp seconds / defocus seconds per image (one
render each), medians over the objects.

defocus_cost_128px: the demo build at 128 px (17 views, levels 1–4) with and without
`--defocus 1,2,3,4`, side by side (alternating, medians of REPEATS): seconds and bytes
per setting (`ratio`: seconds without / with).
"""

from __future__ import annotations

import json
import os
import statistics
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

RESOLUTION = int(os.environ.get("BLURSET_BENCH_NOISE_RES", "96"))
REF = 16  # converged renders: REF × the image's samples
SHARP_SAMPLES = 256
LEVELS = (1, 2, 3, 4)
SALT = 0x5EED
DEVICE = os.environ.get("BLURSET_BENCH_DEVICE", "CPU")


def _render(
    w, frames: list[dict], samples: int, work: Path
) -> tuple[list[np.ndarray], list[float]]:
    from blurset.image import read_exr

    images: dict[int, np.ndarray] = {}
    secs: list[float] = []
    t = [time.perf_counter()]

    def done(i: int, path: str, _origin) -> None:
        images[i] = read_exr(path)
        os.unlink(path)
        now = time.perf_counter()
        secs.append(now - t[0])
        t[0] = now

    w.render(frames, resolution=RESOLUTION, fov_deg=40.0, samples=samples, on_frame=done)
    return [images[i] for i in range(len(frames))], secs


def measure() -> dict:
    from blurset.image import object_error
    from blurset.plan import BuildConfig, plan_setting
    from blurset.services.demo import make_demo_objects
    from blurset.services.worker_client import Worker

    rows: dict[str, dict] = {
        f"level{lvl}": {"mse_vs_sharp": [], "seconds_vs_sharp": []} for lvl in LEVELS
    }
    with tempfile.TemporaryDirectory(prefix="blurset-bench-") as tmp:
        work = Path(tmp)
        cfg = BuildConfig(views=1, levels=[], defocus=list(LEVELS), resolution=RESOLUTION,
                          sharp_samples=SHARP_SAMPLES)  # fmt: skip
        for glb in make_demo_objects(work / "objects"):
            with Worker(threads=0, timeout=7200, workdir=work / "s", device=DEVICE) as w:
                info = w.load(glb, work / "v.npy")
                verts = np.ascontiguousarray(np.load(work / "v.npy"), dtype=np.float32)
                p = plan_setting(cfg, uid="bench", theta0_deg=0.0, seed=11,
                                 bbox_dims=info["bbox_dims"], vertices=verts)  # fmt: skip
                frames: list[dict[str, Any]] = [dict(f) for f in p.renders(str(work / "f"))]
                for f in frames:  # whole images, one render call each (view, level)
                    f.pop("region", None)
                    f.pop("call", None)
                images, secs = _render(w, frames, SHARP_SAMPLES, work)
                conv = []
                for f in frames:
                    c = {
                        k: v for k, v in f.items() if k not in ("sample_offset", "sample_sequence")
                    }
                    c["seed"] = (int(f["seed"]) ^ SALT) & 0x7FFFFFFF
                    conv.append(c)
                refs, _ = _render(w, conv, REF * SHARP_SAMPLES, work)
            sharp_mse = object_error(images[0], refs[0]).mse
            for k, lvl in enumerate(LEVELS, start=1):
                assert frames[k]["level"] == f"defocus_{lvl}"
                rows[f"level{lvl}"]["mse_vs_sharp"].append(
                    object_error(images[k], refs[k]).mse / sharp_mse
                )
                rows[f"level{lvl}"]["seconds_vs_sharp"].append(secs[k] / secs[0])
    return rows


def measure_cost() -> dict:
    import sys

    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from bench_passes import REPEATS, _build, _bytes
    from blurset import layout

    args = ("--views", "17", "--resolution", "128")
    off_s, on_s = [], []
    with tempfile.TemporaryDirectory() as d:
        for k in range(REPEATS):
            off, on = Path(d) / f"off{k}", Path(d) / f"on{k}"
            off_s.append(_build(off, *args))
            on_s.append(_build(on, *args, "--defocus", "1,2,3,4"))
        settings = layout.complete_settings(on)
        n = len(settings)
        levels = [f"defocus_{lvl}" for lvl in LEVELS]
        per_level = sum(_bytes(s / lvl) for s in settings for lvl in levels) / n / len(levels)
        off_b = sum(_bytes(s) for s in layout.complete_settings(off)) / n
    med_off, med_on = statistics.median(off_s), statistics.median(on_s)
    return {
        "name": "defocus_cost_128px",
        "ratio": round(med_off / med_on, 3),
        "contender": "build --defocus 1,2,3,4",
        "baseline": "the same build without --defocus",
        "settings": n,
        "seconds_per_setting_off": round(med_off / n, 2),
        "seconds_per_setting_on": round(med_on / n, 2),
        "bytes_per_setting_off": round(off_b),
        "bytes_per_defocus_level": round(per_level),
        "repeats": REPEATS,
        "runs_s": {"off": [round(x, 1) for x in off_s], "on": [round(x, 1) for x in on_s]},
    }


def run() -> list[dict]:
    out = [measure_cost()]
    for key, row in measure().items():
        mse, t = row["mse_vs_sharp"], row["seconds_vs_sharp"]
        out.append(
            {
                "name": f"defocus_parity_{key}",
                "ratio": round(1 / statistics.median(t), 3),
                "contender": f"a defocus image ({key}), one Cycles render through its lens",
                "baseline": "the sharp image of the view at the same samples",
                "mse_vs_sharp": [round(x, 3) for x in mse],
                "mse_vs_sharp_median": round(statistics.median(mse), 3),
                "mse_vs_sharp_max": round(max(mse), 3),
                "seconds_vs_sharp": [round(x, 3) for x in t],
                "objects": len(mse),
                "resolution": RESOLUTION,
                "sharp_samples": SHARP_SAMPLES,
                "reference_factor": REF,
            }
        )
    return out


if __name__ == "__main__":
    print(json.dumps(run(), indent=1))
