"""need_budget_saving: what `--blur-budget need` saves per blur level against parity
(issue 28), from the plans of real objects (no render: the rule is the core's
`need_factor`, measured in bench_render_parity.py).

For the paper's construction (34 random latent frames per blurry image, 32 samples per
frame before the factor) on the textured GLBs of ../shared/data (else the demo box), 34
views of one setting, at 128 and 512 px: per level the Cycles samples a blurry image
renders under parity (m^0.4 times the budget) and under need (the factor its measured
screen motion between frames buys), summed over views and objects. ratio = parity / need.
"""

from __future__ import annotations

import os
import sys
import tempfile
from pathlib import Path

import numpy as np

RESOLUTIONS = (128, 512)
LEVELS = (1, 2, 3, 4)


def measure() -> dict:
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from bench_settings_per_hour import _glbs
    from blurset.plan import BuildConfig, plan_setting
    from blurset.services.worker_client import Worker

    out: dict = {}
    with tempfile.TemporaryDirectory(prefix="blurset-bench-need-") as tmp:
        work = Path(tmp)
        glbs = _glbs(work)
        loaded = []
        with Worker(timeout=600, workdir=work / "scratch") as w:
            for glb in glbs:
                info = w.load(glb, work / "v.npy")
                verts = np.ascontiguousarray(np.load(work / "v.npy"), dtype=np.float32)
                loaded.append((glb.stem, info["bbox_dims"], verts))
        for res in RESOLUTIONS:
            for level in LEVELS:
                tot = {"parity": 0, "need": 0}
                motion, gap = [], []
                for uid, dims, verts in loaded:
                    for budget in tot:
                        cfg = BuildConfig(resolution=res, levels=[level], blur_budget=budget)
                        p = plan_setting(cfg, uid=uid, theta0_deg=0.0, seed=5,
                                         bbox_dims=dims, vertices=verts)  # fmt: skip
                        for v in p.to_dict()["views"]:
                            lp = v["levels"][str(level)]
                            tot[budget] += lp["samples_per_frame"] * lp["latents"]
                            if budget == "need":
                                motion.append(lp["motion_px"])
                                gap.append(lp["motion_px"] / lp["latents"])
                out[(res, level)] = {
                    "parity_samples": tot["parity"],
                    "need_samples": tot["need"],
                    "median_motion_px": float(np.median(motion)),
                    "median_px_between_frames": float(np.median(gap)),
                    "objects": [u for u, _, _ in loaded],
                }
    return out


def run() -> list[dict]:
    m = measure()
    rows = []
    for (res, level), r in m.items():
        rows.append(
            {
                "name": f"need_budget_saving_level{level}_{res}px",
                "ratio": r["parity_samples"] / r["need_samples"],
                "ratio_is": "samples of a blurry image under parity / under need",
                "contender": f"--blur-budget need, level {level} at {res} px: "
                f"{r['need_samples'] / 34 / len(r['objects']):.0f} samples per image",
                "baseline": f"parity: {r['parity_samples'] / 34 / len(r['objects']):.0f}",
                **r,
                "construction": "paper: 34 random latent frames, 32 samples per frame",
                "load_average": os.getloadavg(),
            }
        )
    return rows


if __name__ == "__main__":
    for r in run():
        print(r["name"], round(r["ratio"], 2), r["contender"], r["baseline"])
