"""What `build --passes depth,normal,mask` costs (issue 35): seconds and bytes per setting,
the same build with and without it, side by side in one run (alternating, medians).

Two configurations: the demo objects at 128 px (17 views, levels 1–4, the demo's 6
latent frames: a cheap build, where the passes weigh most) and at 512 px (4 views, one
blur level, 8 latent frames of 16 samples). `ratio`: seconds per setting without the
passes / with them (1: free). Bytes are those of the setting folders (the passes'
folders on their own: depth, normals, masks, each with its images_4 size).
"""

from __future__ import annotations

import json
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from blurset import layout

CONFIGS = {
    "128px": ("--views", "17", "--resolution", "128"),
    "512px": ("--views", "4", "--resolution", "512", "--levels", "1", "--latents", "8",
              "--samples", "16", "--sharp-samples", "16"),
}  # fmt: skip
COMMON = ("--demo", "--seed", "5", "--quiet")
PASSES = ("--passes", "depth,normal,mask")
REPEATS = 3


def _build(out: Path, *args: str) -> float:
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-m", "blurset.cli", "build", *COMMON, *args,
                    "--out", str(out)], check=True, capture_output=True)  # fmt: skip
    return time.perf_counter() - t0


def _bytes(root: Path) -> int:
    return sum(p.stat().st_size for p in root.rglob("*") if p.is_file() and not p.is_symlink())


def measure(name: str, args: tuple[str, ...]) -> dict:
    off_s, on_s, geometry_s = [], [], []
    with tempfile.TemporaryDirectory() as d:
        for k in range(REPEATS):
            off, on = Path(d) / f"off{k}", Path(d) / f"on{k}"
            off_s.append(_build(off, *args))
            on_s.append(_build(on, *args, *PASSES))
        settings = layout.complete_settings(on)
        plain = layout.complete_settings(off)
        for s in settings:
            geometry_s.append(json.loads((s / layout.META).read_text())["timings"]["geometry_s"])
        # Every level's own files of a pass (a blur level holds its own masks).
        kinds = {
            k: sum(
                _bytes(s / lv / layout.pass_dir(k, f))
                for s in settings
                for lv in {layout.pass_level(k, lv, True) for lv in layout.setting_levels(s)}
                for f in (1, 4)
            )
            for k in layout.PASSES
        }
        n = len(settings)
        views = len(json.loads((settings[0] / layout.META).read_text())["views"])
        off_b = sum(_bytes(s) for s in plain) / n
    med_off, med_on = statistics.median(off_s), statistics.median(on_s)
    return {
        "name": f"passes_cost_{name}",
        "ratio": round(med_off / med_on, 3),
        "contender": "build --passes depth,normal,mask",
        "baseline": "the same build without --passes",
        "settings": n,
        "views": views,
        "seconds_per_setting_off": round(med_off / n, 2),
        "seconds_per_setting_on": round(med_on / n, 2),
        "geometry_seconds_per_setting": round(statistics.median(geometry_s), 2),
        "bytes_per_setting_off": round(off_b),
        "bytes_per_setting_passes": {k: round(v / n) for k, v in kinds.items()},
        "repeats": REPEATS,
        "runs_s": {"off": [round(x, 1) for x in off_s], "on": [round(x, 1) for x in on_s]},
    }


def run() -> list[dict]:
    return [measure(name, args) for name, args in CONFIGS.items()]


if __name__ == "__main__":
    for r in run():
        print(json.dumps(r))
