"""What the benches share: timing two sides side by side (or several, round by round), a
process's CPU time, the steps of a rendering bench (one setting's plan, a mean of
rendered frames, a timed build), and merging a part's rows into bench/results.json.

Not a bench itself (bench/run.py runs `bench_*.py` only)."""

from __future__ import annotations

import json
import os
import statistics
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np


def median_times(
    a: Callable[[], object], b: Callable[[], object], repeats: int, cpu: dict | None = None
) -> tuple[float, float]:
    """Medians of `repeats` interleaved runs of two thunks, so load from other processes
    on a shared machine hits both sides alike. If `cpu` is given, the medians of the
    process CPU time (all threads) of each side go to cpu["a"], cpu["b"]."""
    ta: list[float] = []
    tb: list[float] = []
    ca: list[float] = []
    cb: list[float] = []
    for _ in range(repeats):
        for fn, times, cpus in ((a, ta, ca), (b, tb, cb)):
            c0, t0 = time.process_time(), time.perf_counter()
            fn()
            times.append(time.perf_counter() - t0)
            cpus.append(time.process_time() - c0)
    if cpu is not None:
        cpu["a"], cpu["b"] = statistics.median(ca), statistics.median(cb)
    return statistics.median(ta), statistics.median(tb)


def interleaved_times(
    thunks: dict[str, Callable[[], object]], repeats: int
) -> dict[str, list[float]]:
    """Wall seconds of `repeats` rounds of several thunks, each round running every thunk
    once in turn (as median_times does for two), so load from other processes hits them
    alike: per name, its time in each round."""
    times: dict[str, list[float]] = {k: [] for k in thunks}
    for _ in range(repeats):
        for name, fn in thunks.items():
            t0 = time.perf_counter()
            fn()
            times[name].append(time.perf_counter() - t0)
    return times


RESULTS = Path(__file__).resolve().parent / "results.json"


def merge_into_results(rows: list[dict], out: Path = RESULTS) -> Path:
    """`rows` into bench/results.json, replacing entries of the same name (as bench/run.py
    does for a partial run), each with the machine it was measured on."""
    from run import machine

    new = {r["name"] for r in rows}
    kept = [r for r in json.loads(out.read_text()) if r["name"] not in new]
    rows = [{**r, "machine": r.get("machine", machine())} for r in rows]
    out.write_text(json.dumps(kept + rows, indent=2) + "\n")
    return out


def proc_cpu(pid: int) -> float:
    """CPU seconds (user + system) another process has used: a Blender worker's."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def plan_object(cfg, glb: Path, w, work: Path):
    """The plan of `glb`'s first setting under `cfg`, as a build makes it (its vertices
    loaded by the worker `w`)."""
    from blurset.commands.builder.setting import pricing_backend
    from blurset.plan import plan_setting, seed_for

    info = w.load(glb, work / "v.npy")
    verts = np.ascontiguousarray(np.load(work / "v.npy"), dtype=np.float32)
    # blur_method auto is priced on the device the worker renders on (its load reply's),
    # as a build's is.
    backend = pricing_backend(info, cfg)
    return plan_setting(cfg, uid=glb.stem, theta0_deg=0.0, seed=seed_for(cfg.seed, glb.stem, 0),
                        bbox_dims=info["bbox_dims"], vertices=verts, backend=backend)  # fmt: skip


def render_mean(w, frames: list, samples: int, res: int, fov_deg: float) -> np.ndarray:
    """The mean of `frames` rendered by the worker `w` (premultiplied linear RGBA), as the
    build accumulates them; each frame's EXR removed once added."""
    from blurset.image import Accumulator

    acc = Accumulator(res, res)

    def on_frame(_i: int, path: str, origin) -> None:
        acc.add_exr(path, origin)
        os.unlink(path)

    w.render(frames, resolution=res, fov_deg=fov_deg, samples=samples,
             on_frame=on_frame, crop=True)  # fmt: skip
    return acc.mean()


def timed_build(cfg) -> tuple[float, Path, dict[str, Any]]:
    """One `blurset build` of one setting: (wall seconds, the setting's folder, its meta)."""
    from blurset.commands.builder import build

    t0 = time.perf_counter()
    summary = build(cfg, progress=False)
    wall = time.perf_counter() - t0
    if summary["settings_complete"] != 1:
        raise RuntimeError(f"bench build failed: {summary['failures']}")
    out = Path(cfg.out)
    (setting,) = [d for d in out.iterdir() if (d / ".complete").exists()]
    return wall, setting, json.loads((setting / "meta.json").read_text())
