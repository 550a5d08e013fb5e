"""denoise_process: which process runs Open Image Denoise (issue 28).

A blurry image is denoised once, after averaging, so the denoiser must see the mean of
the latent frames and of their guides, which only the driver holds. Two candidates:
- the driver: blurset-core loads the bpy wheel's OIDN and denoises the mean in memory
  (what `--denoise oidn` does);
- the Blender worker: Cycles' own denoiser (`use_denoising`, OIDN, Cycles' defaults)
  runs inside each render; for a blurry image the mean would have to travel back to the
  worker (EXR out and in) to be denoised there.

Measured on one view of a textured GLB (MapPin from ../shared/data, else the demo box) at
128 and 512 px, 64 samples, median of 3: a render without guides, with guide passes
(multi-layer EXR), with Cycles' denoiser; the driver's denoise of the render with guides
(3 OIDN filter runs: albedo, normal, colour); and how close the driver's result is to
Cycles' own denoised render of the same samples (PSNR: both are OIDN 2.3.3 with the same
settings, so they should agree to float rounding).
"""

from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
RESOLUTIONS = (128, 512)
SAMPLES = 64
REPEATS = 3

_BPY = r"""
import json, math, sys, time
sys.path.insert(0, sys.argv[1])
import bpy, numpy as np
import blender_scene as bs
glb, work, res, samples, repeats = sys.argv[2], sys.argv[3], int(sys.argv[4]), int(sys.argv[5]), int(sys.argv[6])
w, _, doc = bs.import_glb(glb, work, "lit")
bs.normalize(w)
bs.setup_scene(0)
bs.set_light_paths(doc, "auto")
r, phi, th = 2.2, math.radians(60), math.radians(30)
pos = np.array([r*math.sin(phi)*math.cos(th), r*math.sin(phi)*math.sin(th), r*math.cos(phi)])
f = -pos/np.linalg.norm(pos); x = np.cross(f, [0, 0, 1.0]); x /= np.linalg.norm(x); y = np.cross(x, f)
c2w = np.eye(4); c2w[:3, 0], c2w[:3, 1], c2w[:3, 2], c2w[:3, 3] = x, y, -f, pos
bs.set_camera(c2w.tolist(), res, 40.0, samples)
sc = bpy.context.scene
out = {}
def timed(name, path):
    ts = []
    for _ in range(repeats + 1):  # the first render warms the kernel and OIDN up
        t0 = time.perf_counter(); bs.render_frame(path, 7); ts.append(time.perf_counter() - t0)
    out[name] = sorted(ts[1:])[len(ts[1:]) // 2]
bs.set_guides(False); timed("plain_s", f"{work}/plain.exr")
bs.set_guides(True); timed("guides_s", f"{work}/guides.exr")
bs.set_guides(False)
sc.cycles.use_denoising = True
sc.cycles.denoiser = "OPENIMAGEDENOISE"
sc.cycles.denoising_use_gpu = False
out["cycles_settings"] = {"prefilter": sc.cycles.denoising_prefilter,
                          "quality": sc.cycles.denoising_quality,
                          "input_passes": sc.cycles.denoising_input_passes}
timed("cycles_denoise_s", f"{work}/cycles.exr")
print("RESULT " + json.dumps(out), flush=True)
"""


def _glb(work: Path) -> Path:
    p = HERE.parent.parent / "shared" / "data" / "glb" / "sketchfab_MapPin.glb"
    if p.exists():
        return p
    from blurset.services.demo import make_demo_objects

    return make_demo_objects(work / "obj")[0]


def measure() -> dict:
    from blurset.image import Accumulator, image_error, read_exr
    from blurset.services.denoise import denoiser

    den = denoiser("cpu")
    out = {}
    with tempfile.TemporaryDirectory(prefix="blurset-bench-denoise-") as tmp:
        work = Path(tmp)
        glb = _glb(work)
        scripts = HERE.parent / "blender_scripts"
        for res in RESOLUTIONS:
            p = subprocess.run(
                [sys.executable, "-c", _BPY, str(scripts), str(glb), str(work), str(res),
                 str(SAMPLES), str(REPEATS)],
                capture_output=True, text=True, check=True,
            )  # fmt: skip
            line = next(x for x in p.stdout.splitlines() if x.startswith("RESULT "))
            r = json.loads(line[len("RESULT ") :])
            ts = []
            for _ in range(REPEATS):
                acc = Accumulator(res, res, guides=True)
                acc.add_exr(work / "guides.exr")
                t0 = time.perf_counter()
                acc.denoise(den)
                ts.append(time.perf_counter() - t0)
            ours = acc.mean()
            cycles = np.ascontiguousarray(read_exr(work / "cycles.exr"))
            raw = np.ascontiguousarray(read_exr(work / "plain.exr"))
            r["driver_denoise_s"] = statistics.median(ts)
            r["driver_vs_cycles_psnr_db"] = image_error(ours, cycles).psnr
            r["raw_vs_cycles_psnr_db"] = image_error(raw, cycles).psnr
            r["exr_bytes_plain"] = (work / "plain.exr").stat().st_size
            r["exr_bytes_guides"] = (work / "guides.exr").stat().st_size
            out[res] = r
    return {"glb": glb.stem, "samples": SAMPLES, "repeats": REPEATS, "by_res": out,
            "oidn": den.record(), "load_average": os.getloadavg()}  # fmt: skip


def run() -> list[dict]:
    m = measure()
    rows = []
    for res, r in m["by_res"].items():
        worker_cost = r["cycles_denoise_s"] - r["plain_s"]
        driver_cost = r["driver_denoise_s"] + (r["guides_s"] - r["plain_s"])
        rows.append(
            {
                "name": f"denoise_process_{res}px",
                "ratio": worker_cost / driver_cost if driver_cost > 0 else float("inf"),
                "ratio_is": "seconds one image's denoise adds in the worker (Cycles' own, "
                "in the render) / in the driver (guide passes + core OIDN on the mean)",
                "contender": f"driver: guide passes {r['guides_s'] - r['plain_s']:+.3f} s + "
                f"OIDN {r['driver_denoise_s']:.3f} s",
                "baseline": f"worker: Cycles denoiser {worker_cost:+.3f} s per render",
                **r,
                "glb": m["glb"],
                "samples": m["samples"],
                "oidn": m["oidn"],
                "load_average": m["load_average"],
            }
        )
    return rows


if __name__ == "__main__":
    for r in run():
        print(json.dumps(r, indent=1, default=str))
