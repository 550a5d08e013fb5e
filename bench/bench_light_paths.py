"""light_paths_<glb>: what choosing Cycles bounces from the materials (`--light-paths
auto`, issue 15) saves against the fixed bounces every object had before (`fixed`:
max 6, diffuse 2, glossy 2, transmission 4, transparent 8), on the shared real GLBs.

Per GLB: one view at 256 px, 64 samples, the same seed, rendered with the object loaded
under each mode, interleaved and repeated; the time ratio (auto / fixed, wall and CPU)
and the PSNR of the auto render against the fixed one (inf: identical pixels). The
Mazda's unlit materials are also measured in the worker's `emission` unlit mode (camera-
only emission), where auto renders direct light only.
"""

from __future__ import annotations

import json
import math
import os
import statistics
import sys
import tempfile
from pathlib import Path
from typing import Literal

import numpy as np
from harness import proc_cpu

HERE = Path(__file__).resolve().parent
GLB_DIR = HERE.parent.parent / "shared" / "data" / "glb"
RES = int(os.environ.get("BLURSET_BENCH_LP_RES", "256"))
SAMPLES = 64
REPEATS = int(os.environ.get("BLURSET_BENCH_REPEATS", "3"))
DEVICE = os.environ.get("BLURSET_BENCH_DEVICE", "CPU")
# How a model whose every material is unlit renders (the load request's `unlit`).
Unlit = Literal["lit", "emission"]


def _cases() -> list[tuple[str, Path, Unlit]]:
    if not GLB_DIR.is_dir():
        return []
    cases: list[tuple[str, Path, Unlit]] = [
        (p.stem, p, "lit") for p in sorted(GLB_DIR.glob("*.glb"))
    ]
    mazda = GLB_DIR / "sketchfab_MazdaRX7Stylised.glb"
    if mazda.is_file():
        cases.append((f"{mazda.stem}_emission", mazda, "emission"))
    return cases


def measure() -> dict:
    import time

    from blurset.image import image_error, read_exr
    from blurset.plan import BuildConfig, plan_setting
    from blurset.services.worker_client import Worker, WorkerError

    out: dict = {"resolution": RES, "samples": SAMPLES, "repeats": REPEATS, "objects": {}}
    with tempfile.TemporaryDirectory(prefix="blurset-bench-lp-") as tmp:
        work = Path(tmp)
        with Worker(threads=0, timeout=3600, workdir=work / "scratch", device=DEVICE) as w:
            for name, glb, unlit in _cases():
                try:
                    info = w.load(glb, work / "v.npy", unlit=unlit)
                except WorkerError as e:
                    out["objects"][name] = {"skipped": str(e)}
                    continue
                verts = np.ascontiguousarray(np.load(work / "v.npy"), dtype=np.float32)
                cfg = BuildConfig(views=1, levels=[], resolution=RES)
                view = plan_setting(cfg, uid=name, theta0_deg=30.0, seed=3,
                                    bbox_dims=info["bbox_dims"], vertices=verts
                                    ).to_dict()["views"][0]  # fmt: skip
                frame = {"c2w": view["c2w"], "seed": view["sharp_seed"], "samples": SAMPLES}
                times: dict[str, list[tuple[float, float]]] = {"fixed": [], "auto": []}
                img, paths = {}, {}
                for _ in range(REPEATS):
                    for mode in ("fixed", "auto"):
                        paths[mode] = w.load(glb, work / "v.npy", unlit=unlit, light_paths=mode)[
                            "light_paths"
                        ]
                        f = dict(frame, out=str(work / f"{mode}.exr"))
                        assert w._proc is not None  # loaded: the worker runs
                        c0, t0 = proc_cpu(w._proc.pid), time.perf_counter()
                        w.render([f], resolution=RES, fov_deg=cfg.fov_deg, samples=SAMPLES)
                        times[mode].append((time.perf_counter() - t0, proc_cpu(w._proc.pid) - c0))
                        img[mode] = np.asarray(read_exr(work / f"{mode}.exr"))
                diff = image_error(img["auto"], img["fixed"])
                err = {"psnr": diff.psnr}
                med = {m: [statistics.median(x[i] for x in v) for i in (0, 1)]
                       for m, v in times.items()}  # fmt: skip
                out["objects"][name] = {
                    "unlit_mode": unlit,
                    "needs": {
                        k: paths["auto"][k] for k in ("transmission", "transparency", "unlit_only")
                    },  # fmt: skip
                    "bounces_auto": paths["auto"]["bounces"],
                    "fixed_s": med["fixed"][0],
                    "auto_s": med["auto"][0],
                    "fixed_cpu_s": med["fixed"][1],
                    "auto_cpu_s": med["auto"][1],
                    "identical": bool(np.array_equal(img["auto"], img["fixed"])),
                    "psnr_auto_vs_fixed": err["psnr"]
                    if isinstance(err["psnr"], float) and math.isfinite(err["psnr"])
                    else None,
                }
        out["device"] = w.info.get("device")
    out["load_average"] = os.getloadavg()
    return out


def run() -> list[dict]:
    m = measure()
    rows = []
    for name, o in m["objects"].items():
        if "skipped" in o:
            continue
        rows.append(
            {
                "name": f"light_paths_{name}",
                "ratio": o["auto_s"] / o["fixed_s"],
                "ratio_is": "auto-bounces time / fixed-bounces time",
                "cpu_ratio": o["auto_cpu_s"] / o["fixed_cpu_s"],
                "contender": f"bounces from the materials {o['bounces_auto']}: {o['auto_s']:.2f} s",
                "baseline": f"fixed bounces: {o['fixed_s']:.2f} s",
                "identical_pixels": o["identical"],
                "psnr_auto_vs_fixed": o["psnr_auto_vs_fixed"],
                "needs": o["needs"],
                "resolution": m["resolution"],
                "samples": m["samples"],
                "repeats": m["repeats"],
                "device": m["device"],
                "load_average": m["load_average"],
            }
        )
    return rows


if __name__ == "__main__":
    json.dump(measure(), sys.stdout, indent=1)
    print()
