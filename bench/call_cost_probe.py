"""Runs with bpy (bench/bench_call_cost.py starts it): where one render call's fixed cost
goes, frame by frame of one job, as the worker renders it (blender_scene.render_job).

Blender's own render handlers stamp each frame: `render_pre` (its render starts) and
`render_write` (the EXR on disk; Blender runs `render_post` after writing, so the two
cannot part the write from the render). Between them: scene sync, Cycles session set-up,
path tracing, the film read back from the device and the EXR written. The write alone
is timed apart: the last frame's Render Result saved again with the same settings.
Between a frame's write and the next one's start lies the worker's per-frame Python (the
frame-change handler applying camera, samples and seed) and the render pipeline's own
per-frame set-up; after the write, the worker's move of the EXR and its reply. Prints
one JSON object.

argv: GLB DEVICE RES SAMPLES,… FRAMES REPEATS
"""

from __future__ import annotations

import json
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "blender_scripts"))

import blender_scene  # type: ignore[import-not-found]  # noqa: E402
import bpy  # type: ignore[import-untyped]  # noqa: E402
import numpy as np  # noqa: E402


def _frames(info: dict, res: int, work: Path, n: int, tag: int) -> list[dict]:
    """n frames of the first view's sharp camera, as a build plans it, each its own seed."""
    from blurset.plan import BuildConfig, plan_setting

    cfg = BuildConfig(views=1, levels=[1], resolution=res, fov_deg=40.0)
    verts = np.ascontiguousarray(info["vertices"], dtype=np.float32)
    plan = plan_setting(cfg, uid="probe", theta0_deg=0.0, seed=7, bbox_dims=info["bbox_dims"],
                        vertices=verts, backend="CPU")  # fmt: skip
    sharp = plan.renders(str(work / "r"), None)[0]
    return [
        {"c2w": sharp["c2w"], "region": sharp.get("region"), "seed": 1000 * tag + k,
         "out": str(work / f"f{tag}_{k}.exr")}
        for k in range(n)
    ]  # fmt: skip


def _job(frames: list[dict], res: int, samples: int) -> list[dict]:
    """One render_job of `frames`: per frame, the seconds of each stage."""
    stamps: dict[str, list[float]] = {"pre": [], "write": [], "done": []}

    def stamp(key):
        return lambda *_: stamps[key].append(time.perf_counter())

    hooks = [(bpy.app.handlers.render_pre, stamp("pre")),
             (bpy.app.handlers.render_write, stamp("write"))]  # fmt: skip
    for lst, fn in hooks:
        lst.append(fn)  # before render_job's own: stamped before its move and reply
    try:
        blender_scene.render_job(
            frames, res, 40.0, samples,
            lambda *_: stamps["done"].append(time.perf_counter()), crop=True,
        )  # fmt: skip
    finally:
        for lst, fn in hooks:
            lst.remove(fn)
    for f in frames:
        os.unlink(f["out"])
    out = []
    for k in range(1, len(frames)):  # the first frame also pays the job's set-up
        out.append({
            "between_s": stamps["pre"][k] - stamps["write"][k - 1],
            "render_s": stamps["write"][k] - stamps["pre"][k],
            "reply_s": stamps["done"][k] - stamps["write"][k],
        })  # fmt: skip
    return out


def _measure(work: Path) -> dict:
    """The stages' medians per sample count, the frame-change handler and the EXR write,
    every file (the imported GLB's, the frames, the saves) under `work`."""
    glb, device, res, samples, n, repeats = sys.argv[-6:]
    res_i, n_i = int(res), int(n)
    counts = [int(s) for s in samples.split(",")]
    warnings, _, doc = blender_scene.import_glb(glb, str(work), "lit")
    info = blender_scene.normalize(warnings)
    blender_scene.setup_scene(0)
    reported = blender_scene.use_device(device, None)
    blender_scene.set_light_paths(doc, "auto")
    blender_scene.set_exr_codec("NONE")
    blender_scene.set_passes(False, False)
    blender_scene.set_noise_threshold(None)
    _job(_frames(info, res_i, work, 2, 0), res_i, 1)  # warm: kernels, BVH, first session
    per: dict[int, list[dict]] = {s: [] for s in counts}
    for r in range(int(repeats)):
        for s in counts:  # interleaved: the machine's load hits every count alike
            per[s] += _job(_frames(info, res_i, work, n_i, 1 + r * 1000 + s), res_i, s)
    stages = ("between_s", "render_s", "reply_s")
    medians = {s: {k: statistics.median(f[k] for f in per[s]) for k in stages} for s in counts}
    t0 = time.perf_counter()
    for _ in range(50):  # the frame-change handler's own work, alone
        blender_scene.apply_frame(_frames(info, res_i, work, 1, 9)[0], res_i, 40.0, counts[0])
    apply_s = (time.perf_counter() - t0) / 50
    # The EXR write alone: the last Render Result saved again with the scene's settings.
    result, saves = bpy.data.images["Render Result"], []
    for k in range(5):
        t0 = time.perf_counter()
        result.save_render(str(work / f"save{k}.exr"), scene=bpy.context.scene)
        saves.append(time.perf_counter() - t0)
    return {"device": reported, "medians": medians, "apply_frame_s": apply_s,
            "save_exr_s": statistics.median(saves), "frames": n_i, "repeats": int(repeats)}  # fmt: skip


with tempfile.TemporaryDirectory(prefix="blurset-call-cost-") as d:
    print(json.dumps(_measure(Path(d))))
