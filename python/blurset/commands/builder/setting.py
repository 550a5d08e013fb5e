"""One setting: plan it in blurset-core, render its frames in the worker, stream them
into accumulators, and publish the setting directory (DESIGN §2–4).

The setting is written under `<setting>.partial/` and renamed into place after its
`.complete` marker (blurset.layout), so a rerun skips complete settings and redoes
partial ones.
"""

from __future__ import annotations

import functools
import os
import shutil
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

import numpy as np

from blurset import _core, layout
from blurset.commands.builder.geometry import render_geometry
from blurset.exceptions import BlursetError
from blurset.services.config import BuildConfig, out_dir
from blurset.services.objects import ObjectSpec
from blurset.services.progress import Progress

if TYPE_CHECKING:
    from blurset import _records
    from blurset.commands.builder.ports import RenderWorker
    from blurset.services.worker_client import RenderOptions


@dataclass
class SettingJob:
    obj: ObjectSpec
    index: int
    theta0_deg: float

    @property
    def name(self) -> str:
        return layout.setting_name(self.obj.uid, self.theta0_deg)


@dataclass(frozen=True)
class LoadedObject:
    """An object its worker loaded: the worker's reply as it sent it (the contract's type,
    _records.Loaded) and what the build adds to meta.json's `object` and timings."""

    reply: _records.Loaded
    load_s: float
    # Where the object came from (path relative to its root, sha256, licence …).
    provenance: dict[str, Any]
    blender_version: str


class SettingFailed(BlursetError):
    """One setting cannot be made (render QA); the object's other settings go on."""

    def __init__(self, stage: str, reason: str) -> None:
        super().__init__(reason)
        self.stage = stage


def frames_per_setting(cfg: BuildConfig) -> int:
    """Renders of a setting (an upper bound with --latents auto)."""
    return cfg.frames_per_setting


def _copy_sharp(setting: Path, views: list[int], n_views: int, cfg: BuildConfig) -> None:
    """The sharp files of `views` into every blur level (byte-identical copies): a view
    that holds the sharp image holds its mask too."""
    subdirs = [layout.IMAGES, *(layout.images_dir(f) for f in cfg.downsample)]
    masks = [layout.pass_dir("mask", f) for f in [1, *cfg.downsample]] if _masks(cfg) else []
    for view in views:
        name = layout.image_name(view, n_views)
        files = [(d, name) for d in subdirs]
        if cfg.write_linear:
            files.append((layout.LINEAR, layout.linear_name(name)))
        for level in cfg.level_dirs[1:]:
            own = masks if level in layout.own_mask_levels([level]) else []
            for d, f in [*files, *((m, layout.pass_file("mask", name)) for m in own)]:
                (setting / level / d).mkdir(exist_ok=True)  # linear/: no view rendered
                shutil.copyfile(setting / layout.SHARP / d / f, setting / level / d / f)


def _masks(cfg: BuildConfig) -> bool:
    return "mask" in cfg.passes


# Test-only: the Cycles backend `--blur-method auto` prices a setting's images for,
# whatever the worker renders on (a CPU render of what a GPU would choose, in CI, which
# has no GPU). Never set it for a real build: the choice is then not the device's.
PRICE_BACKEND_ENV = "BLURSET_PRICE_BACKEND"


def pricing_backend(info: _records.Loaded, cfg: BuildConfig) -> str:
    """The backend the core prices `blur_method auto` on: the one the worker reported
    rendering on (its ready reply's `device.backend`), else the configured device."""
    forced = os.environ.get(PRICE_BACKEND_ENV)
    if forced:
        return forced
    return reported_backend(info, cfg)


def reported_backend(info: _records.Loaded, cfg: BuildConfig) -> str:
    """The Cycles backend the worker reported rendering on, else the configured device."""
    device = info.get("device")
    return device["backend"] if device else cfg.device


def _object_record(obj: ObjectSpec, loaded: LoadedObject) -> _records.ObjectRecord:
    """meta.json's `object`: the file and what the worker reported about it (the core
    checks every field when it takes the record)."""
    info = loaded.reply
    record: dict[str, Any] = {
        # path (relative to its root), sha256, title, author, licence, source_url: where
        # the object came from, never the builder's absolute path (issue 19).
        **loaded.provenance,
        "bbox_dims": info["bbox_dims"],
        "scale": info["scale"],
        "center": info["center"],
        "n_vertices": info["n_vertices"],
        "n_triangles": info["n_triangles"],
        "unlit_fixed": info["unlit_fixed"],
        "blender_version": loaded.blender_version,
        "warnings": info["warnings"],
    }
    return cast("_records.ObjectRecord", record)


def render_setting(
    job: SettingJob,
    cfg: BuildConfig,
    worker: RenderWorker,
    loaded: LoadedObject,
    verts: np.ndarray,
    progress: Progress,
) -> Path:
    """Plan, render, accumulate and write one setting; returns its final directory."""
    final = out_dir(cfg) / job.name
    partial = layout.partial_dir(final)
    t0 = time.time()
    plan, frames, exr_dir = _plan(job, cfg, loaded.reply, verts, partial)
    _warn_ghosts(plan, cfg, job.name, progress)
    sharp = cfg.sharp_views(plan.n_views)
    den = _denoiser(cfg, loaded.reply)
    session = _core.Session(
        plan, cfg, partial=partial, exr_dir=exr_dir, sharp_views=sharp, denoiser=den
    )
    t_plan = time.time() - t0
    n_rendered, t_sharp, t_blur = _render(session, cfg, worker, len(frames), progress)
    # --latents auto / motion blur render fewer frames than the bar's per-setting bound.
    progress.frame_done(frames_per_setting(cfg) - len(frames))
    t_geometry = render_geometry(cfg, worker, frames, exr_dir, partial / layout.SHARP, plan.n_views)
    shutil.rmtree(exr_dir)
    _copy_sharp(partial, sharp, plan.n_views, cfg)
    test_views = _core.test_views(plan.n_views, cfg.view_stride)
    plan.write_poses(
        partial, cfg.level_dirs, test_views=test_views, sharp_test_views=not cfg.blurry_test_views
    )
    timings: _records.Timings = {
        "plan_s": round(t_plan, 3),
        "sharp_s": round(t_sharp, 3),
        "blur_s": round(t_blur, 3),
        **({"geometry_s": round(t_geometry, 3)} if t_geometry else {}),
        "load_s": loaded.load_s,
        "total_s": round(time.time() - t0, 3),
        "frames": n_rendered,
    }
    _write_records(job, cfg, plan, partial, loaded, session, den, timings, progress)
    layout.publish(partial, final)
    return final


def _warn_ghosts(plan: _core.Plan, cfg: BuildConfig, name: str, progress: Progress) -> None:
    """Say when an image's frames lie further apart than --max-ghost-px (latents auto
    capped by --latents-max, or a rolling shutter's bands at any count): the gaps are in
    meta.json, but a user who asked for the bound should not have to look for them."""
    if over := plan.ghost_overruns():
        view, lvl, gap = max(over, key=lambda o: o[2])
        cap = f"-max {cfg.latents_max} caps" if cfg.latents_auto else f" {cfg.latents} sets"
        progress.write(
            f"{name}: {len(over)} images have frames or bands more than --max-ghost-px "
            f"{cfg.max_ghost_px:g} apart (up to {gap:.1f} px, {lvl} of view {view}): --latents"
            f"{cap} them (--latents auto, more latents or --blur-method motion_blur close them; "
            "meta.json records max_gap_px, max_step_px)"
        )


def _plan(
    job: SettingJob, cfg: BuildConfig, info: _records.Loaded, verts: np.ndarray, partial: Path
) -> tuple[_core.Plan, list[_records.Render], Path]:
    """The setting's plan and its renders, in a fresh partial folder; returns (plan,
    renders, the folder the frames' EXRs land in)."""
    shutil.rmtree(partial, ignore_errors=True)
    exr_dir = partial / ".frames"
    exr_dir.mkdir(parents=True)
    plan = _core.plan_setting(
        cfg,
        uid=job.obj.uid,
        theta0_deg=job.theta0_deg,
        seed=_core.seed_for(cfg.seed, job.obj.uid, job.index),
        bbox_dims=info["bbox_dims"],
        vertices=verts,
        backend=pricing_backend(info, cfg),
    )
    # Under sample subsets every render of the build takes a block of one Cycles sequence
    # length, so no pixel depends on what the worker rendered before (a resume equals an
    # uninterrupted build).
    frames = plan.renders(
        exr_dir,
        cfg.cycles_samples,
        sharp_views=cfg.sharp_views(plan.n_views),
        sharp_samples=cfg.effective_sharp_samples,
    )
    return plan, frames, exr_dir


@functools.cache
def object_geometry(path: Path) -> tuple[list[float], np.ndarray]:
    """A GLB's box and vertices as the worker normalizes them (Blender's Z up, box
    centred, largest side 1), read without Blender: what the dry run plans with."""
    import trimesh

    scene = cast("trimesh.Scene", trimesh.load(path, force="scene"))
    parts = []
    for node in scene.graph.nodes_geometry:
        m, name = scene.graph[node]
        parts.append(trimesh.transform_points(scene.geometry[name].vertices, m))
    v = np.vstack(parts)[:, [0, 2, 1]] * [1.0, -1.0, 1.0]  # glTF's Y up → Blender's Z up
    lo, hi = v.min(axis=0), v.max(axis=0)
    v = (v - (lo + hi) / 2) / float((hi - lo).max())
    return (np.ptp(v, axis=0)).tolist(), np.ascontiguousarray(v, dtype=np.float32)


def estimate_setting(
    job: SettingJob, cfg: BuildConfig, geometry: tuple[list[float], np.ndarray], backend: str
) -> tuple[int, int, float]:
    """(renders, samples, seconds) of a setting on `backend` with this machine's cores,
    priced by the core from the setting's own plan (plan/cost.rs renders_cost)."""
    plan = _core.plan_setting(
        cfg,
        uid=job.obj.uid,
        theta0_deg=job.theta0_deg,
        seed=_core.seed_for(cfg.seed, job.obj.uid, job.index),
        bbox_dims=geometry[0],
        vertices=geometry[1],
        backend=backend if cfg.blur_method == "auto" else None,
    )
    return plan.cost(
        cfg.cycles_samples,
        sharp_views=cfg.sharp_views(plan.n_views),
        sharp_samples=cfg.effective_sharp_samples,
        backend=backend,
        cores=os.cpu_count() or 1,
    )


def frame_samples(
    cfg: BuildConfig, job: SettingJob, geometry: tuple[list[float], np.ndarray]
) -> list[int]:
    """The samples each latent frame of a setting renders, fewest to most (`--samples`
    is a frame's share of a blurry image's budget, which the parity factor raises)."""
    plan = _core.plan_setting(
        cfg, uid=job.obj.uid, theta0_deg=job.theta0_deg, seed=0,
        bbox_dims=geometry[0], vertices=geometry[1],
    )  # fmt: skip
    renders = plan.renders("", cfg.cycles_samples)
    return sorted({int(r.get("samples") or 0) for r in renders if r["kind"]["type"] == "blur"})


def _denoiser(cfg: BuildConfig, info: _records.Loaded) -> _core.Denoiser | None:
    """--denoise oidn: the frames carry their guide passes, and every finished image (a
    blurry mean or the sharp render) is denoised once by the core (issue 28)."""
    if cfg.denoise != "oidn":
        return None
    from blurset.services.denoise import denoiser, device_for

    return denoiser(device_for(reported_backend(info, cfg)))


def _render(
    session: _core.Session, cfg: BuildConfig, worker: RenderWorker, bound: int, progress: Progress
) -> tuple[int, float, float]:
    """Every image of the setting rendered by the core's session (phase by phase, to a
    target or at the fixed counts): (renders made, seconds of the first phase and its QA,
    seconds of the rest). The progress bar counts renders up to the setting's share."""
    # Cropped EXRs: only the pixels the region traced cross the disk.
    common: RenderOptions = {
        "resolution": cfg.resolution,
        "fov_deg": cfg.fov_deg,
        "crop": True,
        "guides": cfg.denoise == "oidn",
    }
    done = 0

    def on_frame(i: int, path: str, origin: tuple[int, int] | None) -> None:
        nonlocal done
        session.add_exr(i, path, origin)
        if done < bound:
            progress.frame_done()
        done += 1

    t1 = time.time()
    t_first: float | None = None
    while renders := session.next_renders():
        if t_first is None and session.phases_started > 1:
            t_first = time.time() - t1
        worker.render(renders, on_frame=on_frame, **common)
    if session.failure:
        # QA before the costly blur renders: a bad sharp view fails this setting only.
        raise SettingFailed("qa", session.failure)
    total = time.time() - t1
    first = total if t_first is None else t_first
    return done, first, total - first


def _write_records(
    job: SettingJob,
    cfg: BuildConfig,
    plan: _core.Plan,
    partial: Path,
    loaded: LoadedObject,
    session: _core.Session,
    den: _core.Denoiser | None,
    timings: _records.Timings,
    progress: Progress,
) -> None:
    """meta.json (with the COLMAP verdict under --check-poses) and the preview."""
    images = sorted(session.records())

    def write_meta(pose_check: _records.PoseCheck | None = None) -> None:
        plan.write_meta(
            partial / layout.META,
            config=cfg,
            object=_object_record(job.obj, loaded),
            timings=timings,
            qa=session.qa(),
            pose_check=pose_check,
            light_paths=loaded.reply["light_paths"],
            device=loaded.reply["device"],
            denoiser=den.record() if den is not None else None,
            images=images or None,
        )

    write_meta()
    if cfg.check_poses:
        write_meta(pose_check=_pose_check(partial))
    if cfg.previews:
        from blurset.commands.preview import write_build_preview

        write_build_preview(partial, warn=progress.write)


def _pose_check(setting_dir: Path) -> _records.PoseCheck:
    """The COLMAP verdict of the sharp level (DESIGN §6), compact for meta.json."""
    from blurset.commands.check_poses import check_setting

    try:
        rep = check_setting(setting_dir, levels=[layout.SHARP])[layout.SHARP]
    except Exception as e:  # the check must never cost the setting itself
        return {"verdict": f"error: {e}", "pass": False}
    return {
        "verdict": rep["verdict"],
        "meaning": rep.get("meaning"),
        "pass": bool(rep["pass"]),
        "registered": rep.get("registered"),
        "total": rep.get("total"),
        "median_rot_err_deg": rep.get("median_rot_err_deg"),
        "median_center_err_rel": rep.get("median_center_err_rel"),
    }
