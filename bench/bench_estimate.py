"""estimate_<case>: the plan's time estimate (what `blurset build --dry-run` prints)
against the same build rendered, wall time of `build()` from the call to its summary,
worker starts and object loads included. `ratio` is measured / estimated: the promise is
within 2x (0.5-2.0). Cases: the demo (three procedural objects, 96 px) and a 128 px build
of one real model at the paper's defaults (sketchfab_MapPin, one setting of
BLURSET_BENCH_ESTIMATE_VIEWS views, 4 by default). The per-sample cost was fitted on the
recorded 512 px paper preset, not on these builds.
"""

from __future__ import annotations

import os
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from harness import merge_into_results  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
GLB = ROOT.parent / "shared" / "data" / "glb" / "sketchfab_MapPin.glb"
VIEWS = int(os.environ.get("BLURSET_BENCH_ESTIMATE_VIEWS", "4"))


def _case(name: str, values: dict) -> dict:
    from blurset.commands.builder import build, estimate, job_objects
    from blurset.services.config import make_config

    with tempfile.TemporaryDirectory(prefix="blurset-bench-estimate-") as d:
        cfg = make_config({**values, "out": str(Path(d) / "out")}, {})
        est = estimate(cfg, job_objects(cfg), "cpu")
        assert est is not None
        t0 = time.perf_counter()
        summary = build(cfg, progress=False)
        wall = time.perf_counter() - t0
    assert not summary["failures"], summary["failures"]
    return {
        "name": f"estimate_{name}",
        "ratio": round(wall / est[2], 3),
        "ratio_is": "measured wall seconds of the build / the plan's estimate (promise: 0.5-2)",
        "contender": f"the build, measured: {wall:.1f} s",
        "baseline": f"the plan's estimate: {est[2]:.1f} s ({est[0]} renders, {est[1]} samples)",
        "estimate_s": round(est[2], 2),
        "measured_s": round(wall, 2),
        "load_average": list(os.getloadavg()),
        "repeats": 1,
    }


def run() -> list[dict]:
    return [
        _case("demo", {"demo": True}),
        _case(
            "128px",
            {"objects": [str(GLB)], "resolution": 128, "views": VIEWS, "settings_per_object": 1},
        ),
    ]


if __name__ == "__main__":
    rows = run()
    print(merge_into_results(rows))
    for r in rows:
        print(r["name"], r["ratio"], r["baseline"], r["contender"])
