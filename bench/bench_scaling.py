"""Scaling on one machine (DESIGN §9, issue 8): settings per hour with 1 and 2 local
workers on the same small build, side by side, medians of interleaved runs; and the
machine-hours the paper's 1000 settings take at the paper preset, extrapolated from
render times measured here (a linear fit of Cycles time against samples at 512²).
"""

from __future__ import annotations

import math
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPEATS = 3
# Small enough to repeat, big enough that rendering (not start-up) dominates.
BUILD = (
    "--demo", "--settings-per-object", "2", "--views", "6", "--levels", "1,2",
    "--latents", "6", "--samples", "8", "--resolution", "96", "--seed", "1", "--quiet",
)  # fmt: skip
SETTINGS = 3 * 2
# The paper preset (DESIGN §2): 34 views, levels 1–4, 34 latents, 512², 32 samples per
# latent frame, sharp at samples × latents.
PAPER = {"views": 34, "levels": 4, "latents": 34, "resolution": 512, "samples": 32}


def _build(out: Path, workers: int, threads: int) -> float:
    shutil.rmtree(out, ignore_errors=True)
    t0 = time.perf_counter()
    subprocess.run(
        [sys.executable, "-m", "blurset.cli", "build", *BUILD, "--out", str(out),
         "--workers", str(workers), "--threads", str(threads)],
        check=True, capture_output=True,
    )  # fmt: skip
    return time.perf_counter() - t0


def _render_times(work: Path) -> dict[str, float]:
    """Seconds of one 512² frame at a few sample counts, on a demo object."""
    from blurset.services.demo import make_demo_objects
    from blurset.services.worker_client import Worker

    glb = make_demo_objects(work / "objs", seed=0)[0]
    c2w = [[1, 0, 0, 0], [0, 0.5, -0.866, -2.6], [0, 0.866, 0.5, 1.5], [0, 0, 0, 1]]
    times: dict[str, float] = {}
    with Worker(timeout=900) as w:
        t0 = time.perf_counter()
        w.load(glb, work / "v.npy")
        times["load"] = time.perf_counter() - t0
        for s in (8, 32, 128):
            runs = []
            for k in range(2):
                t0 = time.perf_counter()
                w.render(
                    [{"c2w": c2w, "seed": k, "out": work / f"f{s}_{k}.exr"}],
                    resolution=PAPER["resolution"],
                    fov_deg=40.0,
                    samples=s,
                )
                runs.append(time.perf_counter() - t0)
            times[str(s)] = min(runs)
    return times


def run() -> list[dict]:
    with tempfile.TemporaryDirectory(prefix="blurset-bench-scale-") as tmp:
        d = Path(tmp)
        one, two = [], []
        for _ in range(REPEATS):
            one.append(_build(d / "w1", workers=1, threads=2))
            two.append(_build(d / "w2", workers=2, threads=1))
        t1, t2 = statistics.median(one), statistics.median(two)
        rt = _render_times(d)
    # Cycles time ≈ a + b·samples: least squares over the measured points.
    xs = [8.0, 32.0, 128.0]
    ys = [rt[str(int(x))] for x in xs]
    mx, my = statistics.fmean(xs), statistics.fmean(ys)
    b = sum((x - mx) * (y - my) for x, y in zip(xs, ys, strict=True)) / sum(
        (x - mx) ** 2 for x in xs
    )
    a = my - b * mx
    frame = a + b * PAPER["samples"]
    sharp = a + b * PAPER["samples"] * PAPER["latents"]
    per_setting = PAPER["views"] * (sharp + PAPER["levels"] * PAPER["latents"] * frame)
    paper_hours = 1000 * per_setting / 3600
    return [
        {
            "name": "settings_per_hour_2_vs_1_workers",
            "ratio": t1 / t2,
            "contender": f"2 workers x 1 thread: {3600 * SETTINGS / t2:.0f} settings/h",
            "baseline": f"1 worker x 2 threads: {3600 * SETTINGS / t1:.0f} settings/h",
            "settings": SETTINGS,
            "seconds_1_worker": t1,
            "seconds_2_workers": t2,
            "repeats": REPEATS,
            "build": " ".join(BUILD),
        },
        {
            "name": "paper_1000_settings_machine_hours",
            "ratio": paper_hours,
            "contender": f"{paper_hours:.0f} machine-hours on this 2-core machine",
            "baseline": "paper preset, 1000 settings (extrapolated, not a speed-up)",
            "frame_512_s": {k: round(v, 3) for k, v in rt.items()},
            "fit_seconds": {"a": a, "b_per_sample": b},
            "per_setting_s": per_setting,
            "renders_per_setting": PAPER["views"] * (1 + PAPER["levels"] * PAPER["latents"]),
            "preset": PAPER,
            "days": paper_hours / 24,
            "note": "linear fit t = a + b*samples of 512^2 demo-object frames; "
            + ("valid" if math.isfinite(paper_hours) else "invalid"),
        },
    ]


if __name__ == "__main__":
    for r in run():
        print(r)
