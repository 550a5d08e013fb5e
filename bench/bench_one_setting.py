"""one_setting_<res>px_<preset>: one whole setting, as a user builds it, timed end to end
(issue 47: a 34-view 512 px setting of the balanced preset in at most 5 minutes on an H200).

`blurset build --preset P --resolution RES --views 34` of one held-out model (the first of
BLURSET_BENCH_GLBS, else ../shared/data's held-out panel), every view's blurry images
rendered; wall time from the call to the setting's `.complete`, worker start, object load
and the device's first render included. `ratio` is BUDGET_S over that time: at least 1
within the budget.

Sizes (env): BLURSET_BENCH_ONE_RES (512), BLURSET_BENCH_ONE_VIEWS (34),
BLURSET_BENCH_ONE_PRESET (balanced), BLURSET_BENCH_ONE_BUDGET_S (300).
"""

from __future__ import annotations

import json
import os
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_target import config, held_out_glbs  # noqa: E402
from harness import timed_build  # noqa: E402

RES = int(os.environ.get("BLURSET_BENCH_ONE_RES", "512"))
VIEWS = int(os.environ.get("BLURSET_BENCH_ONE_VIEWS", "34"))
PRESET = os.environ.get("BLURSET_BENCH_ONE_PRESET", "balanced")
BUDGET_S = float(os.environ.get("BLURSET_BENCH_ONE_BUDGET_S", "300"))


def run() -> list[dict]:
    with tempfile.TemporaryDirectory(prefix="blurset-bench-one-") as d:
        glb = held_out_glbs(Path(d))[0]
        wall, _, meta = timed_build(config(Path(d) / "out", glb, RES, VIEWS, preset=PRESET))
    images = [im for v in meta["views"] for im in v["images"].values()]
    return [
        {
            "name": f"one_setting_{RES}px_{PRESET}",
            "ratio": round(BUDGET_S / wall, 3),
            "ratio_is": f"{BUDGET_S:.0f} s over one {VIEWS}-view setting's wall time (>= 1: "
            "within the budget)",
            "contender": f"--preset {PRESET}, {VIEWS} views at {RES} px of {glb.stem}: {wall:.1f} s",
            "baseline": f"{BUDGET_S:.0f} s",
            "model": glb.stem,
            "build_s": round(wall, 2),
            "views": VIEWS,
            "resolution": RES,
            "images": len(images),
            "worst_render_psnr_db": min(im["render_psnr_db"] for im in images),
            "blur_choice": meta["render"].get("blur_choice", {}).get("images", {}),
            "device": meta["render"].get("device", {}),
            "timings": meta.get("timings", {}),
        }
    ]


if __name__ == "__main__":
    json.dump(run(), sys.stdout, indent=1)
    print()
