"""Statistics benchmark (issue 5): aggregate 10,000 settings' meta.json.

Files: a synthetic build (tests.conftest.write_synthetic_build) of 10,000 complete
settings × 34 views × 4 levels with the full meta.json structure `blurset build`
writes, latent-frame records included (m = 4 per level, ~100 KB per file, ~1 GB in all;
the paper's m = 34 makes files ~8× larger). Contender: `blurset.commands.stats.build_stats`
(Rust, rayon, serde) plus `to_dict` of its document, i.e. what `blurset stats`
holds in Python before drawing. Baseline: the same aggregation in plain Python (json
per file, the same per-view lists, min / median / max / mean, counts). Medians of
interleaved runs; both read the same files from the page cache after a warm-up.
"""

from __future__ import annotations

import functools
import json
import operator
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from collections import defaultdict
from pathlib import Path
from typing import TYPE_CHECKING

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from blurset.commands.stats import build_stats  # noqa: E402
from harness import median_times  # noqa: E402

from tests.conftest import write_synthetic_build  # noqa: E402

if TYPE_CHECKING:
    from blurset import _records

SETTINGS = 10_000
REPEATS = 3


def python_aggregate(build: Path) -> dict:
    """Plain Python: what one would write without blurset-core."""
    names = sorted(
        e.name
        for e in os.scandir(build)
        if e.is_dir()
        and not e.name.startswith(".")
        and not e.name.endswith(".partial")
        and os.path.isfile(os.path.join(e.path, ".complete"))
    )
    cols: defaultdict[str, list[float]] = defaultdict(list)
    per_level: defaultdict[str, defaultdict[str, list[float]]] = defaultdict(
        lambda: defaultdict(list)
    )
    uids, images = set(), 0
    for n in names:
        with open(build / n / "meta.json", "rb") as f:
            m = json.load(f)
        uids.add(m["uid"])
        d = m["bbox_dims"]
        cols["scene_dimension"].append((d[0] * d[1] * d[2]) ** (1 / 3))
        images += len(m["views"]) * len(m["levels"])
        for v in m["views"]:
            cols["scene_range"].append(v["far"] / v["near"])
            for q in ("flatness", "depth_range", "orientation", "w_u"):
                cols[q].append(v[q])
            for lvl, lp in v["levels"].items():
                per_level["blur_weight"][lvl].append(lp["w_l"])
                per_level["latent_frames"][lvl].append(lp["latents"])
                per_level["motion_px"][lvl].append(lp["motion_px"])
    flat = dict(cols)
    for q, by in per_level.items():
        flat.update({f"{q}_{lvl}": v for lvl, v in by.items()})
    summary = {
        q: (min(v), statistics.median(v), max(v), functools.reduce(operator.add, v) / len(v))
        for q, v in flat.items()
    }
    return {
        "cols": flat,
        "summary": summary,
        "counts": {"objects": len(uids), "settings": len(names), "images": images},
    }


def rust_aggregate(build: Path) -> _records.BuildStats:
    return build_stats(build).to_dict()


def run() -> list[dict]:
    tmp = Path(tempfile.mkdtemp(prefix="blurset-bench-stats-"))
    try:
        build = tmp / "build"
        t0 = time.perf_counter()
        write_synthetic_build(build, SETTINGS, latents=4, latent_frames=True)
        t_gen = time.perf_counter() - t0
        size = sum(f.stat().st_size for f in build.glob("*/meta.json"))
        # warm-up, and both sides computing the same numbers
        py, rs = python_aggregate(build), rust_aggregate(build)
        assert py["cols"]["scene_range"] == rs["scene_range"]
        assert py["cols"]["blur_weight_4"] == rs["blur_weight"]["4"]
        assert py["counts"]["images"] == rs["counts"]["images"]
        for s in rs["summary"]:  # (scene dimension: x ** (1/3) here, a correct cbrt there)
            if s["quantity"] != "scene_dimension":
                assert py["summary"][s["quantity"]][1] == s["median"], s["quantity"]
        t_rust_only = statistics.median(
            _timed(lambda: build_stats(build).to_dict()) for _ in range(REPEATS)
        )
        t_py, t_rs = median_times(
            lambda: python_aggregate(build), lambda: rust_aggregate(build), REPEATS
        )
        t0 = time.perf_counter()
        subprocess.run(
            [sys.executable, "-m", "blurset.cli", "stats", str(build), "--out",
             str(tmp / "stats"), "--quiet"],
            check=True, capture_output=True,
        )  # fmt: skip
        t_cli = time.perf_counter() - t0
        return [
            {
                "name": "stats_10k_settings_vs_python",
                "ratio": t_py / t_rs,
                "contender": f"blurset build_stats + to_dict {t_rs:.2f} s",
                "baseline": f"plain Python json {t_py:.2f} s",
                "contender_s": t_rs,
                "baseline_s": t_py,
                "rust_only_s": t_rust_only,
                "settings": SETTINGS,
                "views": rs["counts"]["views"],
                "meta_json_mb": size / 1e6,
                "threads": os.cpu_count(),
                "repeats": REPEATS,
                "synthetic_build_s": t_gen,
                "cli_end_to_end_s": t_cli,
            }
        ]
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def _timed(fn) -> float:
    t0 = time.perf_counter()
    fn()
    return time.perf_counter() - t0


if __name__ == "__main__":
    for r in run():
        print(r)
