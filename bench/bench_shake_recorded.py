"""Shake levels beside recorded hand shake (issue 61): the image centre's paths of the
core's shake model at each level, measured as kernels, beside Levin et al. 2009's eight
recorded camera-shake kernels measured by the same code (bench/shake_paths.py).

The recordings are read from a copy of `Levin09.mat` (the eight kernels as the cell array
`kernels`, MATLAB v5) at the path in BLURSET_SHAKE_RECORDINGS; without it the bench is
skipped, saying so. Nothing of the file is kept but the summary numbers below (no pixel).
One public copy in v5: the repository xiuheng-wang/ADMM_3DDnCNN_HSI_deconvolution,
`data/Levin09.mat` (commit c9a20eee); cszn/KAIR's `kernels/Levin09.mat` is MATLAB 7.3
(HDF5), which this reader refuses.

Rows:

- `shake_recorded_levin09`: per recorded kernel its size, extent (px, as a share of the
  data set's 255 px images and of the kernel's size) and shape statistics, and their
  medians;
- `shake_paths_level<l>`: over VIEWS views of one setting planned by the core (frames no
  more than GHOST_PX apart at 512 px), the image centre's path drawn into a kernel at the
  recordings' median extent and measured as they are (medians and quartiles), its own
  drift and length, its extent as a share of the image width, and three example views'
  path lengths (what docs/gen/shake_guide.py checks when it draws the figure again).
  `ratio`: the level's extent over the recordings' median, both as shares of the image
  width.

`bench/run.py bench_shake_recorded` writes them into bench/results.json; the build
guide's shake figure and its numbers are generated from them (`make docs`).
"""

from __future__ import annotations

import hashlib
import os
import sys
from pathlib import Path

import numpy as np
import shake_paths as sp

ENV = "BLURSET_SHAKE_RECORDINGS"
# The side of the sharp images of Levin et al. 2009's data set (255 × 255 px), which the
# kernels blur: a kernel's extent as a share of the image width is over this.
LEVIN_IMAGE_PX = 255
LEVELS = [1, 2, 3, 4]
VIEWS = int(os.environ.get("BLURSET_BENCH_SHAKE_VIEWS", "60"))
GHOST_PX = 0.25
SEED = 5
# The views whose paths the figure draws.
EXAMPLES = (0, 1, 2)
STATS = ("length_over_extent", "ends_share", "dwell_share", "width_px")
OWN = ("drift_share", "path_over_extent")


def recorded_row(path: Path) -> dict:
    kernels = sp.recorded_kernels(path)
    per = []
    for k in kernels:
        s = sp.kernel_stats(k)
        per.append({
            "size_px": int(k.shape[0]),
            "extent_share_of_image": s["extent_px"] / LEVIN_IMAGE_PX,
            "extent_share_of_kernel": s["extent_px"] / k.shape[0],
            **s,
        })  # fmt: skip
    med = {
        f"{k}_{name}": float(fn([p[k] for p in per]))
        for k in per[0]
        for name, fn in (("median", np.median), ("min", np.min), ("max", np.max))
    }
    return {
        "name": "shake_recorded_levin09",
        "ratio": med["extent_share_of_image_median"],
        "ratio_is": "the recorded kernels' median extent over their images' width",
        "contender": f"Levin et al. 2009's {len(per)} recorded kernels, "
        f"{min(p['size_px'] for p in per)}-{max(p['size_px'] for p in per)} px",
        "baseline": f"their {LEVIN_IMAGE_PX} px images",
        "kernels": per,
        "count": len(per),
        "image_px": LEVIN_IMAGE_PX,
        "file_sha256": hashlib.sha256(Path(path).read_bytes()).hexdigest(),
        **med,
    }


def _quartiles(values: list[float]) -> dict[str, float]:
    q1, q2, q3 = np.percentile(values, [25, 50, 75])
    return {"median": float(q2), "q1": float(q1), "q3": float(q3)}


def model_rows(recorded: dict) -> list[dict]:
    draw_at = recorded["extent_px_median"]
    paths = sp.model_paths(VIEWS, LEVELS, resolution=sp.REFERENCE_PX, ghost_px=GHOST_PX,
                           seed=SEED)  # fmt: skip
    rows = []
    for lv in LEVELS:
        stats = [sp.path_stats(v["path"], draw_at) for v in paths[lv]]
        share = 2.0 ** (lv + 2) / sp.REFERENCE_PX
        row: dict = {
            "name": f"shake_paths_level{lv}",
            "ratio": share / recorded["extent_share_of_image_median"],
            "ratio_is": "the level's extent over the recorded kernels' median, as shares of "
            "the image width",
            "contender": f"shake level {lv}: extent {share:.1%} of the image width",
            "baseline": f"Levin et al. 2009's kernels: median "
            f"{recorded['extent_share_of_image_median']:.1%}",
            "level": lv,
            "views": VIEWS,
            "resolution": sp.REFERENCE_PX,
            "ghost_px": GHOST_PX,
            "seed": SEED,
            "extent_px": 2.0 ** (lv + 2),
            "extent_share_of_image": share,
            "drawn_at_extent_px": draw_at,
            "frames_median": float(np.median([len(v["record"]["poses"]) for v in paths[lv]])),
            "examples": [
                {"view": i, "path_px": paths[lv][i]["record"]["path_px"]} for i in EXAMPLES
            ],
        }
        for k in (*STATS, *OWN):
            for q, v in _quartiles([s[k] for s in stats]).items():
                row[f"{k}_{q}"] = v
        rows.append(row)
    return rows


def run() -> list[dict]:
    where = os.environ.get(ENV)
    if not where or not Path(where).is_file():
        print(
            f"bench_shake_recorded: skipped, {ENV} names no file ({where!r}); set it to a "
            "MATLAB v5 copy of Levin09.mat (Levin et al. 2009's eight recorded kernels)",
            file=sys.stderr,
        )
        return []
    recorded = recorded_row(Path(where))
    return [recorded, *model_rows(recorded)]


if __name__ == "__main__":
    for r in run():
        print({k: v for k, v in r.items() if k not in ("kernels", "examples")})
