"""device_costs_<res>px: the two unit costs that price any plan on the device a bench runs
on (DESIGN §9, issue 47): the fixed cost of one render call and the cost of one sample.

A job of FRAMES frames of a demo object (the sharp camera of its first view, each frame its
own seed) is rendered through the build's path (worker → EXR → Rust accumulator) at
SAMPLES samples each; per-frame wall time is the job's over FRAMES, median of REPEATS
interleaved repeats. A least-squares line t(s) = call_s + sample_s · s through those
medians gives the two costs. `ratio` is the share of fixed cost in a paper latent frame
(32 samples): call_s / t(32). On a 2-core CPU it is small; on an H200 it was measured at
86 % (tools/DEVICE.md), which is why a plan is priced by calls as well as samples.

`--device` (bench/run.py) or BLURSET_BENCH_DEVICE picks the Cycles device (default CPU);
BLURSET_BENCH_COST_RES the sizes (default 128,512). On a GPU the same node's CPU is measured
beside it (`device_costs_cpu_<res>px`, at BLURSET_BENCH_COST_CPU_RES, default 512; empty:
none): the two rows price the same plan on both devices of one machine.
"""

from __future__ import annotations

import os
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

RESOLUTIONS = [int(r) for r in os.environ.get("BLURSET_BENCH_COST_RES", "128,512").split(",")]
SAMPLES = (1, 8, 32, 128)
FRAMES = int(os.environ.get("BLURSET_BENCH_COST_FRAMES", "6"))
REPEATS = int(os.environ.get("BLURSET_BENCH_REPEATS", "3"))
DEVICE = os.environ.get("BLURSET_BENCH_DEVICE", "CPU")
CPU_RESOLUTIONS = [
    int(r) for r in os.environ.get("BLURSET_BENCH_COST_CPU_RES", "512").split(",") if r
]
PAPER_FRAME_SAMPLES = 32


def fit_costs(samples: list[int], seconds: list[float]) -> tuple[float, float]:
    """(call_s, sample_s) of the least-squares line seconds = call_s + sample_s · samples."""
    a = np.vstack([np.ones(len(samples)), np.asarray(samples, dtype=np.float64)]).T
    (call_s, sample_s), *_ = np.linalg.lstsq(a, np.asarray(seconds), rcond=None)
    return float(call_s), float(sample_s)


def _frame_seconds(w, sharp: dict, work: Path, res: int, samples: int, tag: int) -> float:
    """Seconds per frame of one job of FRAMES renders of the sharp camera (its region)."""
    from harness import render_mean

    keep = {k: v for k, v in sharp.items() if k in ("c2w", "region")}
    frames = [
        dict(keep, seed=1000 * tag + k, out=str(work / f"f{tag}_{k}.exr"), call=0)
        for k in range(FRAMES)
    ]
    t0 = time.perf_counter()
    render_mean(w, frames, samples, res, 40.0)
    return (time.perf_counter() - t0) / FRAMES


def _costs_at(res: int, device: str, name: str) -> dict:
    from blurset.plan import BuildConfig
    from blurset.services.demo import make_demo_objects
    from blurset.services.worker_client import Worker
    from harness import plan_object

    with tempfile.TemporaryDirectory(prefix="blurset-bench-cost-") as d:
        work = Path(d)
        glb = make_demo_objects(work / "objs")[0]
        cfg = BuildConfig(views=1, levels=[1], resolution=res, fov_deg=40.0)
        with Worker(threads=0, timeout=3600, workdir=work / "scratch", device=device) as w:
            sharp = plan_object(cfg, glb, w, work).renders(str(work / "r"), None)[0]
            _frame_seconds(w, sharp, work, res, 1, 0)  # warm: kernels, BVH, first session
            per: dict[int, list[float]] = {s: [] for s in SAMPLES}
            for r in range(REPEATS):
                for s in SAMPLES:  # interleaved: load on the machine hits every count alike
                    per[s].append(_frame_seconds(w, sharp, work, res, s, 1 + r * 1000 + s))
            reported = w.info.get("device", {})
    medians = [statistics.median(per[s]) for s in SAMPLES]
    call_s, sample_s = fit_costs(list(SAMPLES), medians)
    frame_s = call_s + sample_s * PAPER_FRAME_SAMPLES
    return {
        "name": name,
        "ratio": call_s / frame_s,
        "contender": f"the fixed cost of a render call ({res} px)",
        "baseline": f"a {PAPER_FRAME_SAMPLES}-sample frame's time",
        "call_s": call_s,
        "sample_s": sample_s,
        "samples": list(SAMPLES),
        "frame_s": medians,
        "frames_per_call": FRAMES,
        "repeats": REPEATS,
        "device": reported,
    }


def run() -> list[dict]:
    out = [_costs_at(res, DEVICE, f"device_costs_{res}px") for res in RESOLUTIONS]
    if DEVICE != "CPU":
        out += [_costs_at(res, "CPU", f"device_costs_cpu_{res}px") for res in CPU_RESOLUTIONS]
    return out
