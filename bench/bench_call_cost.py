"""call_cost_<res>px: where the fixed cost of a render call goes (issue 47 item 2), on the
device a bench runs on (`--device`, BLURSET_BENCH_DEVICE; default CPU).

bench/call_cost_probe.py renders jobs of FRAMES frames of a demo object through the
worker's own path (blender_scene.render_job: one render operator call, persistent data)
at each of SAMPLES, REPEATS interleaved times, and stamps every frame with Blender's render
handlers. Per stage, the median seconds per frame, and a line fitted through the render
stage (render start to EXR on disk) over the sample counts: its intercept is the render's
fixed part, its slope the cost of a sample. The EXR write is timed apart (the probe saves
a Render Result again) and taken out of that intercept: what is left is Cycles' own
(scene sync, session set-up, film read back from the device). A call's fixed cost is the
intercept + the time between frames (the frame-change handler, the pipeline's per-frame
set-up) + the worker's move and reply. `ratio` is Cycles' own share of it.

Sizes (env): BLURSET_BENCH_CALL_RES (128,512), BLURSET_BENCH_CALL_FRAMES (8),
BLURSET_BENCH_REPEATS (3).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_device_costs import fit_costs  # noqa: E402

HERE = Path(__file__).resolve().parent
RESOLUTIONS = [int(r) for r in os.environ.get("BLURSET_BENCH_CALL_RES", "128,512").split(",")]
SAMPLES = (1, 8, 32, 128)
FRAMES = int(os.environ.get("BLURSET_BENCH_CALL_FRAMES", "8"))
REPEATS = int(os.environ.get("BLURSET_BENCH_REPEATS", "3"))
DEVICE = os.environ.get("BLURSET_BENCH_DEVICE", "CPU")


def _probe(glb: Path, res: int) -> dict:
    cmd = [sys.executable, str(HERE / "call_cost_probe.py"), str(glb), DEVICE, str(res),
           ",".join(map(str, SAMPLES)), str(FRAMES), str(REPEATS)]  # fmt: skip
    done = subprocess.run(cmd, capture_output=True, text=True, check=True)
    return json.loads(done.stdout.strip().splitlines()[-1])


def _entry(res: int, p: dict) -> dict:
    med = {int(s): v for s, v in p["medians"].items()}
    counts = sorted(med)
    render_fixed, sample_s = fit_costs(counts, [med[s]["render_s"] for s in counts])
    other = {k: float(np.median([med[s][k] for s in counts])) for k in ("between_s", "reply_s")}
    fixed = float(render_fixed) + sum(other.values())
    cycles = max(0.0, float(render_fixed) - p["save_exr_s"])
    return {
        "name": f"call_cost_{res}px",
        "ratio": cycles / fixed if fixed > 0 else None,
        "ratio_is": "Cycles' own fixed part of a render call (sync, session, read back) over "
        "the call's whole fixed cost",
        "contender": f"Cycles' fixed part {cycles * 1000:.1f} ms",
        "baseline": f"a call's fixed cost {fixed * 1000:.1f} ms",
        "cycles_fixed_s": cycles,
        "render_fixed_s": float(render_fixed),
        "save_exr_s": p["save_exr_s"],
        # An upper bound of the fixed part that no fit can lose in a busy CPU's noise.
        "render_1_sample_s": med[counts[0]]["render_s"],
        "sample_s": float(sample_s),
        **{k: v for k, v in other.items()},
        "apply_frame_s": p["apply_frame_s"],
        "call_s": fixed,
        "per_samples": p["medians"],
        "frames_per_job": p["frames"],
        "repeats": p["repeats"],
        "resolution": res,
        "device": p["device"],
    }


def run() -> list[dict]:
    from blurset.services.demo import make_demo_objects

    with tempfile.TemporaryDirectory(prefix="blurset-bench-call-") as d:
        glb = make_demo_objects(Path(d) / "objs")[0]
        return [_entry(res, _probe(glb, res)) for res in RESOLUTIONS]


if __name__ == "__main__":
    json.dump(run(), sys.stdout, indent=1)
    print()
