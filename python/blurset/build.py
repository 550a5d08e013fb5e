"""`blurset build`: GLB objects → Objaverse-Blur style dataset (DESIGN §1–4, §10).

Per object: one Blender worker process loads and normalizes the GLB once; per setting,
blurset-core plans every view, trajectory, level and latent frame (seeded); the worker
renders the frames to linear EXR while this process streams each one into a Rust
accumulator (memory of one frame per open view/level), deletes it, and writes the sRGB
PNG when a view/level is complete. A setting is written under `<setting>.partial/`
and renamed into place after its `.complete` marker: a rerun skips complete settings
and redoes partial ones. A failing object is logged in `failures.jsonl`; the build
goes on.
"""

from __future__ import annotations

import argparse
import concurrent.futures as cf
import contextlib
import dataclasses
import fcntl
import json
import os
import platform
import queue
import shutil
import sys
import threading
import time
import traceback
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from blurset import __version__, _core, devices, objaverse_cache, preflight
from blurset.config import BuildConfig, load_toml, make_config, parse_levels
from blurset.devices import Device
from blurset.exceptions import BlursetError
from blurset.objects import ObjectSpec, resolve_objects, setting_name
from blurset.progress import Progress

MARKER = ".complete"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--config", type=Path, help="TOML file of options (flags override it)")
    p.add_argument(
        "--objects", nargs="+", help="GLB files, folders of GLBs, or text files listing them"
    )
    p.add_argument("--out", type=Path, help="output directory")
    p.add_argument("--demo", action="store_true", default=None, help="built-in procedural objects")
    p.add_argument("--settings-per-object", type=int, help="azimuth settings per object (4)")
    p.add_argument("--views", type=int, help="views per setting (34)")
    p.add_argument("--levels", type=str, help="blur levels, e.g. 1,2,3,4 or none (sharp only)")
    p.add_argument(
        "--latents",
        type=str,
        help="latent frames averaged per blurry image (34), or auto: per view and level, "
        "the fewest that leave no gap over --max-ghost-px on screen",
    )
    p.add_argument("--latents-max", type=int, help="cap of --latents auto (34)")
    p.add_argument(
        "--max-ghost-px",
        type=float,
        help="--latents auto: largest screen gap between latent frames, px (1)",
    )
    p.add_argument("--samples", type=int, help="Cycles samples per latent frame (32)")
    p.add_argument(
        "--samples-total",
        type=int,
        help="sample budget of one blurry image: ceil(S/m) samples per latent frame",
    )
    p.add_argument(
        "--blur-method",
        choices=["average", "motion_blur"],
        help="average of latent renders (the paper; default) or one Cycles motion blur render",
    )
    p.add_argument("--sharp-samples", type=int, help="Cycles samples of the sharp image")
    p.add_argument(
        "--latent-sampling",
        choices=["subsets", "independent"],
        help="subsets: a blurry image's latent frames render the blocks of one sample "
        "sequence on the view's seed, which the sharp image renders too (default); "
        "independent: a seed per frame (builds before issue 15)",
    )
    p.add_argument(
        "--light-paths",
        choices=["auto", "fixed"],
        help="bounces from the object's materials (auto, default) or the same for every object",
    )
    p.add_argument(
        "--device",
        choices=["auto", "cpu", "optix", "cuda", "hip", "oneapi", "metal"],
        help="Cycles device; auto: the best backend Cycles reports "
        "(OptiX > CUDA > HIP > oneAPI > Metal > CPU)",
    )
    p.add_argument("--gpus", help="GPU indices of the backend, e.g. 0,2 (default: all)")
    p.add_argument(
        "--gpus-per-task", type=float, help="GPUs each Ray task reserves (1 with a GPU device)"
    )
    p.add_argument("--resolution", type=int, help="image side in pixels, square (512)")
    p.add_argument("--seed", type=int, help="build seed (0)")
    p.add_argument("--fov-deg", type=float, help="field of view in degrees (40)")
    p.add_argument(
        "--latent-positions", choices=["random", "stratified"], help="latent positions (random)"
    )
    p.add_argument(
        "--keep-linear",
        "--write-linear",
        dest="write_linear",
        action="store_true",
        default=None,
        help="also store the linear float image (EXR) of every view and level; "
        "`blurset noise BUILD` then starts from it",
    )
    p.add_argument(
        "--previews", action="store_true", default=None, help="write <setting>/preview.png"
    )
    p.add_argument("--workers", type=int, help="objects rendered in parallel (1)")
    p.add_argument("--threads", type=int, help="Cycles threads per worker (0 = all cores)")
    p.add_argument("--executor", choices=["local", "ray"], help="local process pool or Ray")
    p.add_argument(
        "--ray-address", help="Ray cluster to join (ray://host:10001 or auto); default: local"
    )
    p.add_argument(
        "--shard", help="i/N: this job's share of the objects (0 ≤ i < N), for job arrays"
    )
    p.add_argument("--objaverse-dir", help="the objaverse package's cache directory (~/.objaverse)")
    p.add_argument(
        "--objaverse-offline",
        action="store_true",
        default=None,
        help="never download: objects missing from the cache fail",
    )
    p.add_argument(
        "--objaverse-count", type=int, help="a seeded random subset of N objaverse objects"
    )
    p.add_argument(
        "--timeout", type=float, help="seconds without a worker reply before it is killed (600)"
    )
    p.add_argument(
        "--object-timeout", type=float, help="wall-clock budget of one object, s (0 = none)"
    )
    p.add_argument("--retries", type=int, help="extra attempts after a worker crash or hang (1)")
    p.add_argument(
        "--max-failure-rate",
        type=float,
        help="exit 1 when more than this fraction of objects failed (1.0)",
    )
    p.add_argument("--max-triangles", type=int, help="pre-flight triangle budget (5000000)")
    p.add_argument(
        "--max-texture-pixels", type=int, help="pre-flight texture budget, pixels (268435456)"
    )
    p.add_argument("--blender", help="a Blender binary instead of the bpy module")
    p.add_argument(
        "--check-poses", action="store_true", default=None, help="COLMAP check per setting"
    )
    p.add_argument("--quiet", action="store_true", help="no progress bar")


def config_from_args(args: argparse.Namespace) -> BuildConfig:
    file_values = load_toml(args.config) if args.config else {}
    flags = {
        k: getattr(args, k)
        for k in (
            "objects out demo settings_per_object views latents latents_max max_ghost_px "
            "samples samples_total blur_method sharp_samples resolution latent_sampling "
            "light_paths device gpus gpus_per_task "
            "seed fov_deg latent_positions write_linear workers threads executor shard timeout "
            "object_timeout retries max_failure_rate max_triangles max_texture_pixels "
            "ray_address objaverse_dir objaverse_offline objaverse_count "
            "blender check_poses previews"
        ).split()
    }
    if args.levels is not None:
        flags["levels"] = parse_levels(args.levels)
    return make_config(file_values, flags)


def run(args: argparse.Namespace) -> int:
    cfg = config_from_args(args)
    summary = build(cfg, progress=not args.quiet)
    n, bad = summary["objects"], summary["objects_failed"]
    rate = bad / n if n else 0.0
    line = (
        f"blurset build: {summary['settings_complete']} settings complete "
        f"({summary['settings_new']} new), {bad} of {n} objects failed ({100 * rate:.0f}%)"
    )
    if summary["settings_failed"]:
        line += f", {summary['settings_failed']} settings failed QA"
    print(f"{line} -> {cfg.out}", file=sys.stderr)
    for f in summary["failures"][:5]:
        where = f.get("setting") or f["uid"]
        print(f"  {where}: {f['stage']}: {f['reason']}", file=sys.stderr)
    if len(summary["failures"]) > 5:
        print(f"  … see {Path(cfg.out) / 'failures.jsonl'}", file=sys.stderr)
    if n and summary["settings_complete"] == 0:
        return 1
    if rate > cfg.max_failure_rate:
        print(
            f"blurset build: error: {100 * rate:.0f}% of objects failed, more than "
            f"--max-failure-rate {cfg.max_failure_rate:g}",
            file=sys.stderr,
        )
        return 1
    return 0


# -- per setting -----------------------------------------------------------------------


@dataclass
class SettingJob:
    obj: ObjectSpec
    index: int
    theta0_deg: float

    @property
    def name(self) -> str:
        return setting_name(self.obj.uid, self.theta0_deg)


@dataclass
class ObjectResult:
    uid: str
    settings: list[str] = field(default_factory=list)
    # Failure records (failures.jsonl): the object's, or one per setting that failed QA.
    failures: list[dict[str, Any]] = field(default_factory=list)
    new_settings: int = 0


class SettingFailed(BlursetError):
    """One setting cannot be made (render QA); the object's other settings go on."""

    def __init__(self, stage: str, reason: str) -> None:
        super().__init__(reason)
        self.stage = stage


def frames_per_setting(cfg: BuildConfig) -> int:
    """Renders of a setting (an upper bound with --latents auto)."""
    return cfg.views * (1 + len(cfg.levels) * cfg.max_latents)


def level_renders(lp: dict, exr_prefix: Path, sequence: int | None = None) -> list[dict[str, Any]]:
    """The renders of one blurry image of a plan: its latent frames (average method)
    or its single motion blur render, each with its own Cycles samples. Under sample
    subsets (issue 15) frame k renders the samples [offset, offset + spf) of a sequence
    of `sequence` samples (default: the level's own); plans without subsets (independent
    seeds) render each frame's own first samples."""
    spf = lp["samples_per_frame"]
    subsets = lp.get("latent_sampling") == "subsets"
    seq = sequence if sequence is not None else lp.get("sample_sequence")

    def block(offset: int) -> dict[str, Any]:
        return {"sample_offset": offset, "sample_sequence": seq} if subsets else {}

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
                **block(0),
            }
        ]
    return [
        {
            "c2w": f["c2w"],
            "seed": f["seed"],
            "samples": spf,
            "out": f"{exr_prefix}_{k:04d}.exr",
            **block(f["sample_offset"]),
        }
        for k, f in enumerate(lp["latent_frames"])
    ]


def cycles_samples(plan: dict, cfg: BuildConfig) -> int | None:
    """The Cycles `samples` every render of a subsets build is pinned to (None: each
    render its own, as before): at least the longest sequence of the config and the
    sharp budget. Cycles sizes its sample pattern from `samples` and never shrinks it
    within a process, so one value for the whole build keeps every pixel independent of
    what the worker rendered before it (a resumed object equals an uninterrupted one)."""
    if cfg.latent_sampling != "subsets":
        return None
    return max(int(plan.get("sample_sequence_max") or 0), cfg.effective_sharp_samples)


def _render_frames(plan: dict, exr_dir: Path, pin: int | None = None) -> list[dict[str, Any]]:
    """The render list of a setting in stream order: per view, sharp then each level;
    `pin` (cycles_samples): the sharp image renders the first samples of a `pin`-sample
    sequence, the latent frames their blocks of it."""
    frames = []
    for v in plan["views"]:
        i = v["index"]
        sharp = {"c2w": v["c2w"], "seed": v["sharp_seed"], "out": str(exr_dir / f"{i:04d}_s.exr")}
        if pin is not None:
            sharp.update(sample_offset=0, sample_sequence=pin)
        frames.append(sharp)
        for lvl, lp in v["levels"].items():
            frames.extend(level_renders(lp, exr_dir / f"{i:04d}_{lvl}", pin))
    return frames


def _keys(plan: dict) -> list[tuple[int, str]]:
    """(view, level dir) of each rendered frame, aligned with `_render_frames`."""
    keys = []
    for v in plan["views"]:
        keys.append((v["index"], "sharp"))
        for lvl, lp in v["levels"].items():
            n = 1 if lp.get("motion_blur") else len(lp["latent_frames"])
            keys.extend([(v["index"], f"blur_{lvl}")] * n)
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
            # Per level: sample_sequence; per latent frame: seed and sample_offset.
            "latent_sampling": cfg.latent_sampling,
            "latent_sampling_is": (
                "latent frame k of a level renders the Cycles samples [sample_offset, "
                "sample_offset + samples_per_frame) of one sample_sequence-sample sequence "
                "on the view's sharp_seed; the sharp image renders its first sharp_samples; "
                "every render is a block of a cycles_samples-sample Cycles sequence"
                if cfg.latent_sampling == "subsets"
                else "every latent frame renders the first samples_per_frame samples of "
                "its own seed"
            ),
            # The Cycles `samples` of every render under subsets (see cycles_samples).
            "cycles_samples": cycles_samples(plan, cfg),
            # Cycles adaptive sampling stays off: with it the sharp image stops early while
            # sample blocks do not, and the pair loses its noise parity (issue 15).
            "adaptive_sampling": False,
            "light_paths": info.get("light_paths"),
            "device": info.get("device"),
            "blur_method": cfg.blur_method,
            "latents": "auto" if cfg.latents_auto else cfg.latents,
            "sharp_samples": cfg.effective_sharp_samples,
            "exr_codec": "NONE (intermediate frames, deleted after accumulation)",
            "background": cfg.background,
            "alpha": "premultiplied, averaged with colour, composited over background",
            "encoding": "sRGB (IEC 61966-2-1) of linear radiance, 8-bit PNG",
        },
        "object": {
            "source": str(obj.path),
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


def _write_json(path: Path, data: Any) -> None:
    tmp = path.with_name(f".{path.name}.tmp{os.getpid()}")
    tmp.write_text(json.dumps(data, indent=1, allow_nan=False) + "\n")
    os.replace(tmp, path)


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
    partial = out / f"{job.name}.partial"
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
    pin = cycles_samples(plan, cfg)
    frames = _render_frames(plan, exr_dir, pin)
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
            name = _core.image_name(view, n_views)
            a.write_png(partial / level / "images" / name, background=tuple(cfg.background))
            if cfg.write_linear:
                a.write_exr(partial / level / "linear" / name.replace(".png", ".exr"))
            if level == "sharp":
                qa[view] = json.loads(_core.frame_qa(a.mean()))
            del acc[key]
        progress.frame_done()

    t_plan = time.time() - t0
    # The sharp render gets its own (larger) sample count: render it separately.
    sharp_idx = [i for i, k in enumerate(keys) if k[1] == "sharp"]
    blur_idx = [i for i, k in enumerate(keys) if k[1] != "sharp"]
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
    _write_json(partial / "meta.json", meta)
    if cfg.check_poses:
        meta["pose_check"] = _pose_check(partial)
        _write_json(partial / "meta.json", meta)
    if cfg.previews:
        from blurset.preview import write_build_preview

        write_build_preview(partial, warn=progress.write)
    (partial / MARKER).write_text(f"{time.strftime('%Y-%m-%dT%H:%M:%S')}\n")
    if final.exists():
        shutil.rmtree(final)
    os.replace(partial, final)
    return final


def _pose_check(setting_dir: Path) -> dict:
    """The COLMAP verdict of the sharp level (DESIGN §6), compact for meta.json."""
    from blurset.check_poses import check_setting

    try:
        rep = check_setting(setting_dir, levels=["sharp"])["sharp"]
    except Exception as e:  # the check must never cost the setting itself
        return {"verdict": f"error: {e}", "pass": False}
    keep = ("verdict", "pass", "registered", "total", "median_rot_err_deg", "median_center_err_rel")
    return {k: rep.get(k) for k in keep}


# -- per object ------------------------------------------------------------------------


def build_object(
    obj: ObjectSpec, cfg: BuildConfig, progress: Progress, device: Device = ("AUTO", None)
) -> ObjectResult:
    """One work unit: every pending setting of one object, in one worker process
    rendering on `device` (a Cycles backend or AUTO, and GPU indices).

    Idempotent: complete settings are skipped, partial ones redone from scratch, so a
    retry (here, by Ray, or a rerun after a kill) is always safe."""
    out = Path(cfg.out)
    result = ObjectResult(uid=obj.uid)
    jobs = [SettingJob(obj, k, t) for k, t in enumerate(cfg.theta0s)]
    pending = [j for j in jobs if not (out / j.name / MARKER).exists()]
    result.settings = [j.name for j in jobs if j not in pending]
    progress.skip(len(jobs) - len(pending))
    if cfg.previews:
        from blurset.preview import write_build_preview

        # A rerun with --previews also draws the settings an earlier run finished without.
        for name in result.settings:
            if not (out / name / "preview.png").exists():
                write_build_preview(out / name, warn=progress.write)
    work = out / f".work-{obj.uid}"
    shutil.rmtree(work, ignore_errors=True)  # a killed run's scratch: worker log, frames
    if not pending:
        return result
    t0 = time.monotonic()
    stage = "fetch"
    try:
        if obj.source == "objaverse":
            _objaverse(cfg).ensure(obj.uid, obj.path)
        stage = "preflight"
        preflight.check(obj.path, preflight.Budget(cfg.max_triangles, cfg.max_texture_pixels))
    except (objaverse_cache.FetchError, preflight.PreflightError) as e:
        result.failures.append(_failure(obj, stage, str(e), t0, 1))
        progress.object_failed(len(pending))
        return result
    deadline = t0 + cfg.object_timeout if cfg.object_timeout > 0 else None
    attempt = 0
    while pending:
        attempt += 1
        stage = ["start"]
        try:
            _render_object(obj, cfg, pending, result, progress, work, deadline, stage, device)
        except Exception as e:
            from blurset.worker_client import WorkerError

            for j in pending:
                shutil.rmtree(out / f"{j.name}.partial", ignore_errors=True)
            if isinstance(e, WorkerError) and e.transient and attempt <= cfg.retries:
                progress.write(f"retrying {obj.uid} (attempt {attempt + 1}) after: {e}")
                continue
            if isinstance(e, BlursetError | ValueError | OSError):
                reason = str(e).splitlines()[0] if str(e) else repr(e)
            else:  # a bug must cost this object only, and be visible
                tb = traceback.format_exc(limit=3).strip().splitlines()[-1]
                reason = f"{type(e).__name__}: {e} [{tb}]"
            result.failures.append(_failure(obj, stage[0], reason, t0, attempt))
            progress.object_failed(len(pending))
            break
    shutil.rmtree(work, ignore_errors=True)
    return result


def _render_object(
    obj: ObjectSpec,
    cfg: BuildConfig,
    pending: list[SettingJob],
    result: ObjectResult,
    progress: Progress,
    work: Path,
    deadline: float | None,
    stage: list[str],
    device: Device = ("AUTO", None),
) -> None:
    """Load the object in a fresh worker and render the pending settings in order,
    taking each off `pending` once it is complete or has failed QA."""
    from blurset.worker_client import Worker

    out = Path(cfg.out)
    shutil.rmtree(work, ignore_errors=True)
    work.mkdir(parents=True)
    t0 = time.monotonic()
    with Worker(
        blender=cfg.blender,
        threads=cfg.threads,
        timeout=cfg.timeout,
        log_path=work / "worker.log",
        workdir=work / "scratch",
        deadline=deadline,
        device=device[0],
        gpus=device[1],
    ) as w:
        stage[0] = "load"
        info = w.load(obj.path, work / "vertices.npy", light_paths=cfg.light_paths)
        info["load_s"] = round(time.monotonic() - t0, 3)
        info["blender_version"] = w.info.get("blender_version")
        verts = np.ascontiguousarray(np.load(work / "vertices.npy"), dtype=np.float32)
        stage[0] = "render"
        while pending:
            j = pending[0]
            t1 = time.monotonic()
            try:
                render_setting(j, cfg, w, info, verts, progress)
            except SettingFailed as e:
                shutil.rmtree(out / f"{j.name}.partial", ignore_errors=True)
                rec = _failure(obj, e.stage, str(e), t1, 1)
                rec["setting"] = j.name
                result.failures.append(rec)
                progress.object_failed(1)
            else:
                result.settings.append(j.name)
                result.new_settings += 1
                progress.setting_done()
            pending.pop(0)


def _failure(obj: ObjectSpec, stage: str, reason: str, t0: float, attempts: int) -> dict:
    """A failures.jsonl record: uid, path, stage, reason, seconds (+ attempts, time)."""
    return {
        "uid": obj.uid,
        "path": str(obj.path),
        "stage": stage,
        "reason": reason,
        "seconds": round(time.monotonic() - t0, 3),
        "attempts": attempts,
        "time": time.strftime("%Y-%m-%dT%H:%M:%S"),
    }


# -- the whole build -------------------------------------------------------------------


def _objaverse(cfg: BuildConfig) -> objaverse_cache.Cache:
    return objaverse_cache.Cache(cfg.objaverse_dir, offline=cfg.objaverse_offline)


def _objects(cfg: BuildConfig) -> list[ObjectSpec]:
    """This job's objects: every entry resolved, sorted by id, then its shard. The
    partition depends on the set of objects only, so the shards of one config are
    disjoint and together are the whole build, however the entries were listed."""
    entries = list(cfg.objects)
    if cfg.demo:
        from blurset.demo import make_demo_objects

        demo_dir = Path(cfg.out) / ".demo_objects"
        entries += [str(p) for p in make_demo_objects(demo_dir, seed=cfg.seed)]
    objs = sorted(
        resolve_objects(
            entries, cache=_objaverse(cfg), objaverse_count=cfg.objaverse_count, seed=cfg.seed
        ),
        key=lambda o: o.uid,
    )
    if cfg.shard:
        i, n = (int(x) for x in cfg.shard.split("/"))
        objs = objs[i::n]
    return objs


def _report_missing(objs: list[ObjectSpec], cfg: BuildConfig, prog: Progress) -> None:
    """Say up front which objaverse objects are not cached and what will happen to them."""
    missing = [o for o in objs if o.source == "objaverse" and not o.path.is_file()]
    if not missing:
        return
    names = ", ".join(o.uid for o in missing[:8]) + (" …" if len(missing) > 8 else "")
    fate = (
        "offline: they fail (failures.jsonl)"
        if cfg.objaverse_offline
        else "downloading each when its turn comes"
    )
    prog.write(
        f"objaverse: {len(missing)} of {sum(o.source == 'objaverse' for o in objs)} objects "
        f"are not in the cache {_objaverse(cfg).versioned} ({fate}): {names}"
    )


def _run_local(objs, cfg, progress, on_result, slots: list[Device]) -> None:
    """`slots`: the device of each worker (blurset.devices.plan_local); an object takes
    a free slot, so with GPUs worker i stays pinned to its device."""
    if cfg.workers == 1:
        for o in objs:
            on_result(build_object(o, cfg, progress, slots[0]))
        return
    free: queue.Queue[Device] = queue.Queue()
    for s in slots:
        free.put(s)

    def unit(o: ObjectSpec) -> ObjectResult:
        slot = free.get()
        try:
            return build_object(o, cfg, progress, slot)
        finally:
            free.put(slot)

    with cf.ThreadPoolExecutor(cfg.workers) as pool:
        for fut in cf.as_completed([pool.submit(unit, o) for o in objs]):
            on_result(fut.result())


def _run_ray(objs, cfg, progress, on_result) -> None:
    """One Ray task per object. A task is idempotent (complete settings are skipped,
    partial ones redone), so Ray may retry it after a lost worker or node."""
    try:
        import ray
    except ImportError:
        raise BlursetError(
            "--executor ray: the ray package is not installed (pip install 'blurset[ray]')"
        ) from None
    started = not ray.is_initialized()
    if started:
        try:
            ray.init(
                address=cfg.ray_address or os.environ.get("RAY_ADDRESS"),
                log_to_driver=False,
                include_dashboard=False,
            )
        except (ConnectionError, RuntimeError, ValueError) as e:
            raise BlursetError(f"--ray-address {cfg.ray_address}: {_first_line(e)}") from None
    try:
        gpus = devices.ray_gpus_per_task(cfg, ray.cluster_resources().get("GPU", 0))
        remote = ray.remote(num_cpus=max(1, cfg.threads), num_gpus=gpus, max_retries=2)(_ray_unit)
        pending = [remote.remote(o, cfg) for o in objs]
        while pending:
            done, pending = ray.wait(pending, num_returns=1)
            res = ray.get(done[0])
            progress.skip(len(res.settings) - res.new_settings)
            progress.frame_done(res.new_settings * progress.fps)
            for _ in range(res.new_settings):
                progress.setting_done()
            on_result(res)
    finally:
        if started:
            ray.shutdown()


def _first_line(e: BaseException) -> str:
    return (str(e).strip().splitlines() or [type(e).__name__])[0]


def _ray_unit(obj: ObjectSpec, cfg: BuildConfig) -> ObjectResult:
    return build_object(obj, cfg, Progress(0, enabled=False), devices.for_ray(cfg))


@contextlib.contextmanager
def build_lock(out: Path):
    """Serialize the writes shared by every process building into OUT (failures.jsonl,
    splits.json, dataset.json): local workers, Ray tasks and Slurm shards alike."""
    with open(out / ".lock", "a") as f:
        fcntl.flock(f, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(f, fcntl.LOCK_UN)


def _sweep(out: Path, objs: list[ObjectSpec], cfg: BuildConfig) -> None:
    """What a killed run of these objects left behind: partial settings, scratch
    directories, temp files of the shared writes. Other shards' objects are left alone."""
    for o in objs:
        shutil.rmtree(out / f".work-{o.uid}", ignore_errors=True)
        for t in cfg.theta0s:
            shutil.rmtree(out / f"{setting_name(o.uid, t)}.partial", ignore_errors=True)
    for tmp in out.glob(".*.tmp*"):
        tmp.unlink(missing_ok=True)


def build(cfg: BuildConfig, *, progress: bool = True) -> dict:
    # Absolute, so Ray workers (another working directory, another machine with the
    # same shared path) write where the driver reads.
    cfg = dataclasses.replace(cfg, out=Path(cfg.out).resolve())
    out = Path(cfg.out)
    # Bad entries and a missing device fail before anything is written.
    resolve_objects(list(cfg.objects), cache=_objaverse(cfg))
    slots = devices.plan_local(cfg) if cfg.executor == "local" else []
    out.mkdir(parents=True, exist_ok=True)
    objs = _objects(cfg)
    with build_lock(out):
        _sweep(out, objs, cfg)
    n_settings = len(objs) * len(cfg.theta0s)
    prog = Progress(n_settings, frames_per_setting=frames_per_setting(cfg), enabled=progress)
    _report_missing(objs, cfg, prog)
    new_settings = 0
    lock = threading.Lock()
    t0 = time.time()

    def on_result(res: ObjectResult) -> None:
        nonlocal new_settings
        with lock:
            new_settings += res.new_settings
            if res.failures:
                with build_lock(out), open(out / "failures.jsonl", "a+b") as f:
                    # A record torn by a kill mid-append gets its line ended first, so
                    # the next record stays whole (readers skip the torn one).
                    f.seek(0, os.SEEK_END)
                    if f.tell() > 0:
                        f.seek(-1, os.SEEK_END)
                        if f.read(1) != b"\n":
                            f.write(b"\n")
                    f.write("".join(json.dumps(r) + "\n" for r in res.failures).encode())
                    f.flush()
                    os.fsync(f.fileno())
        for r in res.failures:
            prog.write(f"failed: {r.get('setting') or r['uid']}: {r['stage']}: {r['reason']}")

    with prog:
        if cfg.executor == "ray":
            _run_ray(objs, cfg, prog, on_result)
        else:
            _run_local(objs, cfg, prog, on_result, slots)
    with build_lock(out):
        summary = finalize(out, cfg, time.time() - t0)
    mine = {o.uid for o in objs}
    failed = [r for r in summary["failures"] if r["uid"] in mine]
    summary["objects"] = len(objs)
    summary["objects_failed"] = len({r["uid"] for r in failed})
    summary["settings_failed"] = sum(1 for r in failed if r.get("setting"))
    summary["settings_new"] = new_settings
    summary["failures"] = failed
    return summary


def _complete_settings(out: Path) -> list[tuple[str, dict]]:
    found = []
    for d in sorted(out.iterdir()):
        if d.is_dir() and not d.name.startswith(".") and (d / MARKER).exists():
            found.append((d.name, json.loads((d / "meta.json").read_text())))
    return found


def finalize(out: Path, cfg: BuildConfig, seconds: float) -> dict:
    """splits.json, dataset.json and failures.jsonl over what is on disk (call under
    build_lock). failures.jsonl keeps the latest record per object (or per setting, for
    QA failures) whose work is still not complete."""
    complete = _complete_settings(out)
    fpath = out / "failures.jsonl"
    text, _ = _core.current_failures(fpath, complete=[n for n, _ in complete], theta0s=cfg.theta0s)
    kept = json.loads(text)
    tmp = fpath.with_name(f".failures.jsonl.tmp{os.getpid()}")
    tmp.write_text("".join(json.dumps(r) + "\n" for r in kept))
    os.replace(tmp, fpath)
    entries = [{"setting": n, "object": m["uid"], "views": len(m["views"])} for n, m in complete]
    splits = json.loads(
        _core.make_splits(
            json.dumps(entries),
            view_stride=cfg.view_stride,
            test_fraction=cfg.test_fraction,
            test_objects=cfg.test_objects,
            seed=cfg.seed,
        )
    )
    _write_json(out / "splits.json", splits)
    checks = {n: m["pose_check"] for n, m in complete if "pose_check" in m}
    # What the workers rendered on (backend, device names, Cycles kernel), once each.
    used: list[dict] = []
    for _, m in complete:
        d = (m.get("render") or {}).get("device")
        if d and d not in used:
            used.append(d)
    dataset = {
        "name": "blurset Objaverse-Blur",
        "blurset_version": __version__,
        "created": time.strftime("%Y-%m-%dT%H:%M:%S"),
        "config": cfg.to_json(),
        "seed": cfg.seed,
        "levels": cfg.level_dirs,
        "versions": {
            "blurset": __version__,
            "python": platform.python_version(),
            "blender": next(
                (m["object"].get("blender_version") for _, m in complete if m.get("object")), None
            ),
        },
        "counts": {
            "objects": len({m["uid"] for _, m in complete}),
            "objects_failed": len({r["uid"] for r in kept}),
            "settings": len(complete),
            "settings_failed": sum(1 for r in kept if r.get("setting")),
            "images": sum(len(m["views"]) * len(m["levels"]) for _, m in complete),
        },
        "settings": [n for n, _ in complete],
        "render_devices": used,
        "seconds": round(seconds, 1),
    }
    if checks:
        dataset["pose_checks"] = checks
    _write_json(out / "dataset.json", dataset)
    return {"settings_complete": len(complete), "failures": kept}
