"""One setting: plan it in blurset-core, render its frames in the worker, stream them
into accumulators, and publish the setting directory (DESIGN §2–4).

The setting is written under `<setting>.partial/` and renamed into place after its
`.complete` marker (blurset.layout), so a rerun skips complete settings and redoes
partial ones.
"""

from __future__ import annotations

import os
import shutil
import time
from collections.abc import Callable
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
    from blurset.services.worker_client import LoadedObject, RenderOptions


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


def pricing_backend(info: LoadedObject, cfg: BuildConfig) -> str:
    """The backend the core prices `blur_method auto` on: the one the worker reported
    rendering on (its ready reply's `device.backend`), else the configured device."""
    forced = os.environ.get(PRICE_BACKEND_ENV)
    if forced:
        return forced
    return reported_backend(info, cfg)


def reported_backend(info: LoadedObject, cfg: BuildConfig) -> str:
    """The Cycles backend the worker reported rendering on, else the configured device."""
    device = info.get("device")
    return device["backend"] if device else cfg.device


def _object_record(obj: ObjectSpec, info: LoadedObject) -> _records.ObjectRecord:
    """meta.json's `object`: the file and what the worker reported about it (free JSON
    from the worker: the core checks every field when it takes the record)."""
    keys = ("bbox_dims", "scale", "center", "n_vertices", "n_triangles", "unlit_fixed")
    record: dict[str, Any] = {
        # path (relative to its root), sha256, title, author, licence, source_url: where
        # the object came from, never the builder's absolute path (issue 19).
        **info.get("provenance", {}),
        **{k: info.get(k) for k in keys},
        "blender_version": info.get("blender_version"),
        "warnings": info.get("warnings", []),
    }
    return cast("_records.ObjectRecord", record)


def render_setting(
    job: SettingJob,
    cfg: BuildConfig,
    worker: RenderWorker,
    info: LoadedObject,
    verts: np.ndarray,
    progress: Progress,
) -> Path:
    """Plan, render, accumulate and write one setting; returns its final directory."""
    final = out_dir(cfg) / job.name
    partial = layout.partial_dir(final)
    t0 = time.time()
    plan, frames, exr_dir = _plan(job, cfg, info, verts, partial)
    _warn_ghosts(plan, cfg, job.name, progress)
    sharp = cfg.sharp_views(plan.n_views)
    images = _Images(partial, plan.n_views, cfg, info, frames, progress)
    t_plan = time.time() - t0
    records, n_rendered, t_sharp, t_blur = _render(
        plan, cfg, worker, exr_dir, sharp, frames, images, progress
    )
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
        "load_s": info.get("load_s"),
        "total_s": round(time.time() - t0, 3),
        "frames": n_rendered,
    }
    _write_records(job, cfg, plan, partial, info, images, timings, records, progress)
    layout.publish(partial, final)
    return final


def _warn_ghosts(plan: _core.Plan, cfg: BuildConfig, name: str, progress: Progress) -> None:
    """Say when --latents-max kept latents auto from its ghost bound: the gaps are in
    meta.json, but a user who asked for the bound should not have to look for them."""
    if over := plan.ghost_overruns():
        view, lvl, gap = max(over, key=lambda o: o[2])
        progress.write(
            f"{name}: {len(over)} blurry images have latent frames more than --max-ghost-px "
            f"{cfg.max_ghost_px:g} apart (up to {gap:.1f} px, level {lvl} of view {view}): "
            f"--latents-max {cfg.latents_max} caps them (meta.json records max_gap_px)"
        )


def _plan(
    job: SettingJob, cfg: BuildConfig, info: LoadedObject, verts: np.ndarray, partial: Path
) -> tuple[_core.Plan, list[_records.Render], Path]:
    """The setting's plan and its renders, in a fresh partial folder with every level's
    image folders; returns (plan, renders, the folder the frames' EXRs land in)."""
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
    for d in cfg.level_dirs:
        for sub in [layout.IMAGES, *(layout.images_dir(f) for f in cfg.downsample)]:
            (partial / d / sub).mkdir(parents=True)
    if _masks(cfg):
        for level in [layout.SHARP, *layout.own_mask_levels(cfg.level_dirs)]:
            for f in [1, *cfg.downsample]:
                (partial / level / layout.pass_dir("mask", f)).mkdir()
    return plan, frames, exr_dir


def _render(
    plan: _core.Plan,
    cfg: BuildConfig,
    worker: RenderWorker,
    exr_dir: Path,
    sharp: list[int],
    frames: list[_records.Render],
    images: _Images,
    progress: Progress,
) -> tuple[dict[tuple[int, str], _records.ImageRender], int, float, float]:
    """Every image of the setting rendered into `images`, to a target or at the fixed
    counts: (the images' target records, renders made, sharp seconds, blurry seconds)."""
    # Cropped EXRs: only the pixels the region traced cross the disk.
    common: RenderOptions = {
        "resolution": cfg.resolution,
        "fov_deg": cfg.fov_deg,
        "crop": True,
        "guides": images.guides,
    }
    records: dict[tuple[int, str], _records.ImageRender] = {}
    n_rendered = len(frames)
    if cfg.target_psnr is not None:
        records, n_rendered, t_sharp, t_blur = _render_targeted(
            plan, cfg, worker, exr_dir, sharp, images.keys, images.finish, images.qa,
            progress, common, len(frames),
        )  # fmt: skip
    else:
        t_sharp, t_blur = _render_fixed(cfg, worker, frames, images, common)
    if images.open:
        raise BlursetError(f"{len(images.open)} view/level images incomplete after rendering")
    return records, n_rendered, t_sharp, t_blur


class _Images:
    """The images of a setting as their frames arrive: each view/level's accumulator,
    written (and denoised, and QA'd if sharp) once it holds all its frames."""

    def __init__(
        self,
        partial: Path,
        n_views: int,
        cfg: BuildConfig,
        info: LoadedObject,
        frames: list[_records.Render],
        progress: Progress,
    ) -> None:
        self.partial, self.n_views, self.cfg, self.progress = partial, n_views, cfg, progress
        self.keys: list[tuple[int, str]] = [(f["view"], f["level"]) for f in frames]
        # Each image's method (under blur_method auto, the plan's per image): a motion
        # blur render carries its camera's motion.
        self.motion_blur = {(f["view"], f["level"]) for f in frames if f.get("motion")}
        # The images of the plan's first phase (the sharp images): QA'd before any other
        # phase renders, their coverage the mask the other images of their view share.
        self.first = {(f["view"], f["level"]) for f in frames if f["phase"] == 0}
        self.need: dict[tuple[int, str], int] = {}
        for k in self.keys:
            self.need[k] = self.need.get(k, 0) + 1
        self.open: dict[tuple[int, str], _core.Accumulator] = {}
        self.qa: dict[int, _core.FrameQa] = {}
        # --denoise oidn: the frames carry their guide passes, every finished image (a
        # blurry mean or the sharp render) is denoised once by the driver (issue 28).
        self.guides = cfg.denoise == "oidn"
        self.den = None
        if self.guides:
            from blurset.services.denoise import denoiser, device_for

            self.den = denoiser(device_for(reported_backend(info, cfg)))

    def finish(self, key: tuple[int, str], a: _core.Accumulator) -> None:
        """Write a finished image (the mean of its frames) and its copies; QA a sharp one."""
        if self.den is not None:
            a.denoise(self.den)
        view, level = key
        name = layout.image_name(view, self.n_views)
        level_dir, bg = self.partial / level, self.cfg.background
        a.write_png(level_dir / layout.IMAGES / name, background=bg)
        for f in self.cfg.downsample:
            a.write_png(level_dir / layout.images_dir(f) / name, background=bg, downsample=f)
        if self.cfg.write_linear:
            a.write_exr(level_dir / layout.LINEAR / layout.linear_name(name))
        if _masks(self.cfg):
            self._write_masks(key, name, a)
        if key in self.first:
            self.qa[view] = a.qa()

    def _write_masks(self, key: tuple[int, str], name: str, a: _core.Accumulator) -> None:
        """The image's masks at every size: the sharp image's coverage; a blurry image's
        own, the pixels its exposure covered plus the sharp mask of its view (written
        first: every sharp image is done before a blurry one starts)."""
        level = key[1]
        for f in [1, *self.cfg.downsample]:
            sub, file = layout.pass_dir("mask", f), layout.pass_file("mask", name)
            if key in self.first:
                a.write_mask(self.partial / level / sub / file, downsample=f)
            elif level in layout.own_mask_levels([level]):
                a.write_exposure_mask(
                    self.partial / level / sub / file,
                    blur_method="motion_blur" if key in self.motion_blur else "average",
                    downsample=f,
                    sharp=self.partial / layout.SHARP / sub / file,
                )

    def on_frame(self, i: int, path: str, origin: tuple[int, int] | None) -> None:
        key = self.keys[i]
        a = self.open.get(key)
        if a is None:
            res = self.cfg.resolution
            a = self.open[key] = _core.Accumulator(res, res, guides=self.guides)
        a.add_exr(path, origin)
        os.unlink(path)
        if a.count == self.need[key]:
            self.finish(key, a)
            del self.open[key]
        self.progress.frame_done()


def _render_fixed(
    cfg: BuildConfig,
    worker: RenderWorker,
    frames: list[_records.Render],
    images: _Images,
    common: RenderOptions,
) -> tuple[float, float]:
    """The plan's frames at their sample counts, phase by phase as the plan orders them:
    the first phase (the sharp images) then its QA, then the others. The seconds of the
    first phase and of the rest."""
    t1 = time.time()
    t_first = 0.0
    for n, phase in enumerate(sorted({f["phase"] for f in frames})):
        idx = [i for i, f in enumerate(frames) if f["phase"] == phase]

        def on_frame(j: int, p: str, o: tuple[int, int] | None, idx: list[int] = idx) -> None:
            images.on_frame(idx[j], p, o)

        worker.render([frames[i] for i in idx], on_frame=on_frame, **common)
        if n == 0:
            _raise_on_qa(images.qa)
            t_first = time.time() - t1
    return t_first, time.time() - t1 - t_first


def _write_records(
    job: SettingJob,
    cfg: BuildConfig,
    plan: _core.Plan,
    partial: Path,
    info: LoadedObject,
    images: _Images,
    timings: _records.Timings,
    records: dict[tuple[int, str], _records.ImageRender],
    progress: Progress,
) -> None:
    """meta.json (with the COLMAP verdict under --check-poses) and the preview."""

    def write_meta(pose_check: _records.PoseCheck | None = None) -> None:
        plan.write_meta(
            partial / layout.META,
            config=cfg,
            object=_object_record(job.obj, info),
            timings=timings,
            qa=[images.qa[v] for v in range(images.n_views)],
            pose_check=pose_check,
            light_paths=info.get("light_paths"),
            device=info.get("device"),
            denoiser=images.den.record() if images.den is not None else None,
            images=[(v, level, r) for (v, level), r in sorted(records.items())] or None,
        )

    write_meta()
    if cfg.check_poses:
        write_meta(pose_check=_pose_check(partial))
    if cfg.previews:
        from blurset.commands.preview import write_build_preview

        write_build_preview(partial, warn=progress.write)


def _raise_on_qa(qa: dict[int, _core.FrameQa]) -> None:
    """QA before the costly blur renders: a bad sharp view fails this setting only."""
    for view in sorted(qa):
        if qa[view].failure:
            raise SettingFailed("qa", f"render QA: view {view} is {qa[view].failure}")


def _render_targeted(
    plan: _core.Plan,
    cfg: BuildConfig,
    worker: RenderWorker,
    exr_dir: Path,
    sharp: list[int],
    keys: list[tuple[int, str]],
    finish: Callable[[tuple[int, str], _core.Accumulator], None],
    qa: dict[int, _core.FrameQa],
    progress: Progress,
    common: RenderOptions,
    bound: int,
) -> tuple[dict[tuple[int, str], _records.ImageRender], int, float, float]:
    """Every image to the config's target (builder/target.py): the sharp images first, QA,
    then the blurry ones. The progress bar counts renders up to the setting's share.
    Returns each image's record, the renders, and the seconds of each phase."""
    from blurset.commands.builder.target import render_to_target

    order = list(dict.fromkeys(keys))
    done = [0]

    def on_render() -> None:
        if done[0] < bound:
            progress.frame_done()
        done[0] += 1

    t1 = time.time()
    args = (plan, cfg, worker, exr_dir, sharp)
    sharp_keys = [k for k in order if k[1] == layout.SHARP]
    images, n = render_to_target(*args, sharp_keys, finish, on_render, common)
    _raise_on_qa(qa)
    t_sharp = time.time() - t1
    blur_keys = [k for k in order if k[1] != layout.SHARP]
    blur, n_blur = render_to_target(*args, blur_keys, finish, on_render, common)
    images.update(blur)
    return images, n + n_blur, t_sharp, time.time() - t1 - t_sharp


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
