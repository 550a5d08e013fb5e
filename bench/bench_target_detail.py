"""target_detail: does a target build keep the texture (issue 37's detail-ratio bar, DESIGN
§8)? Per held-out model, the `--preset balanced --target-psnr T` build of bench_target_speed
(same config, same bytes), T the paper preset's worst image on that model as that bench
recorded it in results.json (`target_speed_<res>px_<model>`), scored against the
continuous blur rendered twice on independent seeds: the detail ratio over the
reference's noise-free part (bench_target_speed.signal_detail_ratio), PSNR against the
mean of the two. Untimed: it measures accuracy only, so it may share the machine.

Sizes (env): BLURSET_BENCH_SPEED_RES (512), BLURSET_BENCH_SPEED_VIEWS (1, as the speed
run), BLURSET_BENCH_GLBS (the held-out models that have a recorded speed row).
"""

from __future__ import annotations

import json
import os
import sys
import tempfile
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
os.environ.setdefault("BLURSET_BENCH_SPEED_RES", "512")
os.environ.setdefault("BLURSET_BENCH_SPEED_VIEWS", "1")
sys.path.insert(0, str(HERE))
import bench_target_speed as speed  # noqa: E402
from bench_target import held_out_glbs  # noqa: E402
from harness import timed_build  # noqa: E402


def recorded_targets() -> dict[str, float]:
    """Per model: the target of its recorded speed row (the paper preset's worst image)."""
    rows = json.loads((HERE / "results.json").read_text())
    prefix = f"target_speed_{speed.RES}px_"
    return {r["name"].removeprefix(prefix): r["at_paper_worst"]["target_db"]
            for r in rows if r["name"].startswith(prefix)}  # fmt: skip


def _keep(model: str, setting: Path, cont: dict) -> None:
    """With BLURSET_BENCH_KEEP=DIR, the build's linear images and the references as
    DIR/<model>.npz, so a later measure can be computed without rendering again."""
    keep = os.environ.get("BLURSET_BENCH_KEEP")
    if not keep:
        return
    from blurset import layout
    from blurset.image import read_exr

    arrays = {}
    for (view, level), (r1, r2) in cont.items():
        name = layout.linear_name(layout.image_name(view, speed.VIEWS))
        arrays[f"{view}_{level}_image"] = read_exr(setting / level / "linear" / name)
        arrays[f"{view}_{level}_r1"], arrays[f"{view}_{level}_r2"] = r1, r2
    Path(keep).mkdir(parents=True, exist_ok=True)
    np.savez_compressed(Path(keep) / f"{model}.npz", **arrays)


def run() -> list[dict]:
    targets = recorded_targets()
    res = []
    with tempfile.TemporaryDirectory(prefix="blurset-bench-detail-") as d:
        for glb in [g for g in held_out_glbs(None) if g.stem in targets]:
            work = Path(d) / glb.stem
            cont = speed._continuous(glb, work)
            cfg = speed._config(work / "target", glb, preset="balanced",
                                target_psnr=targets[glb.stem])  # fmt: skip
            _, setting, meta = timed_build(cfg)
            scores = speed._against_continuous(setting, cont)
            _keep(glb.stem, setting, cont)
            res.append(
                {
                    "name": f"target_detail_{speed.RES}px_{glb.stem}",
                    "ratio": scores["detail_kept_blur"],
                    "ratio_is": "share of the continuous blur's texture the blurry images "
                    "keep (core detail_kept, mean over images; 1: kept, < 1 smoothed)",
                    "contender": f"--preset balanced --target-psnr {targets[glb.stem]}",
                    "baseline": "continuous blur, two renders on independent seeds",
                    "model": glb.stem,
                    "target_db": targets[glb.stem],
                    **scores,
                    "max_gap_px": round(
                        max(lv["max_gap_px"] for v in meta["views"] for lv in v["levels"].values()),
                        2,
                    ),  # fmt: skip
                    "continuous": {
                        "max_gap_px": speed.CONTINUOUS_GHOST_PX,
                        "samples": speed.CONTINUOUS_SAMPLES,
                        "renders": 2,
                        # Its own render noise, out of the PSNR (speed._against_continuous).
                        "reference_noise": "taken out",
                    },  # fmt: skip
                    "resolution": speed.RES,
                    "views_measured": speed.VIEWS,
                }
            )
    return res


if __name__ == "__main__":
    json.dump(run(), sys.stdout, indent=1, default=str)
    print()
