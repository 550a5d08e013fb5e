"""One setting: plan it in blurset-core, render its frames in the worker, stream them
into accumulators, and publish the setting directory (DESIGN §2–4).

The setting is written under `<setting>.partial/` and renamed into place after its
`.complete` marker (blurset.layout), so a rerun skips complete settings and redoes
partial ones.
"""

from __future__ import annotations

import json
import os
import shutil
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from blurset import __version__, _core, layout
from blurset.config import BuildConfig
from blurset.exceptions import BlursetError
from blurset.objects import ObjectSpec
from blurset.progress import Progress


@dataclass
class SettingJob:
    obj: ObjectSpec
    index: int
    theta0_deg: float

    @property
    def name(self) -> str:
        return layout.setting_name(self.obj.uid, self.theta0_deg)


class SettingFailed(BlursetError):
    """One setting cannot be made (render QA); the object's other settings go on."""

    def __init__(self, stage: str, reason: str) -> None:
        super().__init__(reason)
        self.stage = stage


def frames_per_setting(cfg: BuildConfig) -> int:
    """Renders of a setting (an upper bound with --latents auto)."""
    return cfg.views * (1 + len(cfg.levels) * cfg.max_latents)


def level_renders(lp: dict, exr_prefix: Path) -> list[dict[str, Any]]:
    """The renders of one blurry image of a plan: its latent frames (average method)
    or its single motion blur render, each with its own Cycles samples."""
    spf = lp["samples_per_frame"]
    mb = lp.get("motion_blur")
    if mb:
        keys = [k["c2w"] for k in mb["keys"]]
        return [
            {
                "c2w": keys[0],
                "seed": mb["seed"],
                "samples": spf,
                "motion": {"steps": mb["motion_steps"], "keys": keys},
                "out": f"{exr_prefix}_mb.exr",
            }
        ]
    return [
        {"c2w": f["c2w"], "seed": f["seed"], "samples": spf, "out": f"{exr_prefix}_{k:04d}.exr"}
        for k, f in enumerate(lp["latent_frames"])
    ]


def _render_frames(plan: dict, exr_dir: Path) -> list[dict[str, Any]]:
    """The render list of a setting in stream order: per view, sharp then each level."""
    frames = []
    for v in plan["views"]:
        i = v["index"]
        frames.append(
            {"c2w": v["c2w"], "seed": v["sharp_seed"], "out": str(exr_dir / f"{i:04d}_s.exr")}
        )
        for lvl, lp in v["levels"].items():
            frames.extend(level_renders(lp, exr_dir / f"{i:04d}_{lvl}"))
    return frames


def _keys(plan: dict) -> list[tuple[int, str]]:
    """(view, level dir) of each rendered frame, aligned with `_render_frames`."""
    keys = []
    for v in plan["views"]:
        keys.append((v["index"], layout.SHARP))
        for lvl, lp in v["levels"].items():
            n = 1 if lp.get("motion_blur") else len(lp["latent_frames"])
            keys.extend([(v["index"], layout.level_dir(int(lvl)))] * n)
    return keys


def _meta(plan: dict, cfg: BuildConfig, obj: ObjectSpec, info: dict, timings: dict) -> dict:
    views = []
    for v in plan["views"]:
        v = dict(v)
        v["levels"] = {
            lvl: {
                **{k: x for k, x in lp.items() if k != "latent_frames"},
                "latent_frames": [
                    {k: x for k, x in f.items() if k != "c2w"} for f in lp["latent_frames"]
                ],
                **(
                    {
                        "motion_blur": {
                            **lp["motion_blur"],
                            "keys": [
                                {k: x for k, x in key.items() if k != "c2w"}
                                for key in lp["motion_blur"]["keys"]
                            ],
                        }
                    }
                    if lp.get("motion_blur")
                    else {}
                ),
            }
            for lvl, lp in v["levels"].items()
        }
        views.append(v)
    return {
        "uid": plan["uid"],
        "theta0_deg": plan["theta0_deg"],
        "seed": plan["seed"],
        "resolution": plan["resolution"],
        "fov_deg": plan["fov_deg"],
        "focal_px": plan["focal_px"],
        "bbox_dims": plan["bbox_dims"],
        "radius": plan["radius"],
        "views": views,
        "test_views": _core.test_views(len(views), cfg.view_stride),
        "levels": cfg.level_dirs,
        "sampling": plan["config"],
        "render": {
            "engine": "CYCLES",
            # Per level in views[].levels[].samples_per_frame; null when a budget splits.
            "samples_per_latent": None if cfg.samples_total else cfg.samples,
            "samples_total": cfg.samples_total,
            "blur_method": cfg.blur_method,
            "latents": "auto" if cfg.latents_auto else cfg.latents,
            "sharp_samples": cfg.effective_sharp_samples,
            "exr_codec": "NONE (intermediate frames, deleted after accumulation)",
            "background": cfg.background,
            "alpha": "premultiplied, averaged with colour, composited over background",
            "encoding": "sRGB (IEC 61966-2-1) of linear radiance, 8-bit PNG",
            # <level>/linear/<view>.exr beside images/ (--keep-linear): blurset verify
            # expects them when true.
            "linear": cfg.write_linear,
        },
        "object": {
            # path (relative to its root), sha256, title, author, licence, source_url:
            # where the object came from, never the builder's absolute path (issue 19).
            **info.get("provenance", {}),
            "bbox_dims": info.get("bbox_dims"),
            "scale": info.get("scale"),
            "center": info.get("center"),
            "n_vertices": info.get("n_vertices"),
            "n_triangles": info.get("n_triangles"),
            "unlit_fixed": info.get("unlit_fixed"),
            "blender_version": info.get("blender_version"),
            "warnings": info.get("warnings", []),
        },
        "timings": timings,
        "blurset_version": __version__,
    }


def render_setting(
    job: SettingJob,
    cfg: BuildConfig,
    worker: Any,
    info: dict,
    verts: np.ndarray,
    progress: Progress,
) -> Path:
    """Plan, render, accumulate and write one setting; returns its final directory."""
    out = Path(cfg.out)
    final = out / job.name
    partial = layout.partial_dir(final)
    shutil.rmtree(partial, ignore_errors=True)
    exr_dir = partial / ".frames"
    exr_dir.mkdir(parents=True)
    t0 = time.time()
    seed = _core.seed_for(cfg.seed, job.obj.uid, job.index)
    plan = json.loads(
        _core.plan_setting(
            cfg.sampling_json(),
            uid=job.obj.uid,
            theta0_deg=job.theta0_deg,
            seed=seed,
            bbox_dims=info["bbox_dims"],
            vertices=verts,
        )
    )
    n_views = len(plan["views"])
    frames = _render_frames(plan, exr_dir)
    keys = _keys(plan)
    need: dict[tuple[int, str], int] = {}
    for k in keys:
        need[k] = need.get(k, 0) + 1
    for d in cfg.level_dirs:
        (partial / d / "images").mkdir(parents=True)
    acc: dict[tuple[int, str], Any] = {}
    res = cfg.resolution
    qa: dict[int, dict] = {}

    def on_frame(i: int, path: str) -> None:
        key = keys[i]
        a = acc.get(key)
        if a is None:
            a = acc[key] = _core.Accumulator(res, res)
        a.add_exr(path)
        os.unlink(path)
        if a.count == need[key]:
            view, level = key
            name = layout.image_name(view, n_views)
            a.write_png(partial / level / "images" / name, background=tuple(cfg.background))
            if cfg.write_linear:
                a.write_exr(partial / level / "linear" / name.replace(".png", ".exr"))
            if level == layout.SHARP:
                qa[view] = json.loads(_core.frame_qa(a.mean()))
            del acc[key]
        progress.frame_done()

    t_plan = time.time() - t0
    # The sharp render gets its own (larger) sample count: render it separately.
    sharp_idx = [i for i, k in enumerate(keys) if k[1] == layout.SHARP]
    blur_idx = [i for i, k in enumerate(keys) if k[1] != layout.SHARP]
    t1 = time.time()
    common = {"resolution": res, "fov_deg": cfg.fov_deg}
    worker.render(
        [frames[i] for i in sharp_idx],
        samples=cfg.effective_sharp_samples,
        on_frame=lambda j, p: on_frame(sharp_idx[j], p),
        **common,
    )
    # QA before the costly blur renders: a bad sharp view fails this setting only.
    for view in sorted(qa):
        if qa[view]["failure"]:
            raise SettingFailed("qa", f"render QA: view {view} is {qa[view]['failure']}")
    t_sharp = time.time() - t1
    if blur_idx:
        worker.render(
            [frames[i] for i in blur_idx],
            samples=cfg.samples,
            on_frame=lambda j, p: on_frame(blur_idx[j], p),
            **common,
        )
    t_blur = time.time() - t1 - t_sharp
    if acc:
        raise BlursetError(f"{len(acc)} view/level images incomplete after rendering")
    # --latents auto / motion blur render fewer frames than the bar's per-setting bound.
    progress.frame_done(frames_per_setting(cfg) - len(frames))
    shutil.rmtree(exr_dir)
    _core.write_setting_poses(json.dumps(plan), partial, cfg.level_dirs)
    timings = {
        "plan_s": round(t_plan, 3),
        "sharp_s": round(t_sharp, 3),
        "blur_s": round(t_blur, 3),
        "load_s": info.get("load_s"),
        "total_s": round(time.time() - t0, 3),
        "frames": len(frames),
    }
    meta = _meta(plan, cfg, job.obj, info, timings)
    for v in meta["views"]:
        v["qa"] = {k: x for k, x in qa[v["index"]].items() if k != "failure"}
    layout.write_json(partial / "meta.json", meta)
    if cfg.check_poses:
        meta["pose_check"] = _pose_check(partial)
        layout.write_json(partial / "meta.json", meta)
    if cfg.previews:
        from blurset.preview import write_build_preview

        write_build_preview(partial, warn=progress.write)
    layout.publish(partial, final)
    return final


def _pose_check(setting_dir: Path) -> dict:
    """The COLMAP verdict of the sharp level (DESIGN §6), compact for meta.json."""
    from blurset.check_poses import check_setting

    try:
        rep = check_setting(setting_dir, levels=[layout.SHARP])[layout.SHARP]
    except Exception as e:  # the check must never cost the setting itself
        return {"verdict": f"error: {e}", "pass": False}
    keep = ("verdict", "pass", "registered", "total", "median_rot_err_deg", "median_center_err_rel")
    return {k: rep.get(k) for k in keep}
