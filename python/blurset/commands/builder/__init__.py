"""`blurset build`: GLB objects → Objaverse-Blur style dataset (DESIGN §1–4, §10, §11).

Per object (`unit`): one Blender worker process loads and normalizes the GLB once; per
setting (`setting`), blurset-core plans every view, trajectory, level and latent frame
(seeded); the worker renders the frames to linear EXR while this process streams each
one into a Rust accumulator and writes the sRGB PNG when a view/level is complete.
Objects run locally or on Ray (`executors`); the files shared by all objects are written
under a lock at the end (`dataset`). The flags are in `cli`.
"""

from __future__ import annotations

import os
import shutil
import tempfile
import threading
import time
from pathlib import Path

from blurset import _core, layout
from blurset.commands.builder.dataset import (
    append_failures,
    build_lock,
    check_same_options,
    finalize,
    sweep,
)
from blurset.commands.builder.executors import ray_cluster, run_local, run_ray
from blurset.commands.builder.setting import frames_per_setting
from blurset.commands.builder.unit import ObjectResult, objaverse
from blurset.exceptions import ConfigError
from blurset.services import devices, outputs, publish
from blurset.services.config import BuildConfig, flag, out_dir
from blurset.services.objects import ObjectSpec, resolve_objects
from blurset.services.progress import Progress, duration

__all__ = ["build", "BuildConfig"]


def check_out(out: Path, cfg: BuildConfig) -> None:
    """OUT is new, empty, or a blurset build (the output owner's rule: never another
    kind of output or a folder of other files); it never is, holds or lies in an input."""
    outputs.claim(out, outputs.OutputKind.BUILD, "--out")
    inputs = [Path(e[1:] if e.startswith("@") else e) for e in cfg.objects]
    outputs.refuse_overlap(out, [p for p in inputs if p.exists()])


def all_objects(cfg: BuildConfig) -> list[ObjectSpec]:
    """Every object of the build (all shards): every entry resolved, sorted by id; with
    demo, the demo objects are written into OUT first. Refuses test objects that are
    not among them (ConfigError naming the option), so that fails before any render."""
    entries = list(cfg.objects)
    if cfg.demo:
        from blurset.services.demo import make_demo_objects

        demo_dir = out_dir(cfg) / layout.DEMO_OBJECTS
        entries += [str(p) for p in make_demo_objects(demo_dir, seed=cfg.seed)]
    objs = sorted(
        resolve_objects(
            entries, cache=objaverse(cfg), objaverse_count=cfg.objaverse_count, seed=cfg.seed
        ),
        key=lambda o: o.uid,
    )
    try:
        cfg.check_test_objects([o.uid for o in objs])
    except _core.ConfigValueError as e:
        raise ConfigError(f"{flag(e.option)} {e.detail}") from None
    return objs


def check_blender(cfg: BuildConfig) -> None:
    """`--blender` names an executable file (else every object would fail to start)."""
    if cfg.blender is None:
        return
    exe = shutil.which(cfg.blender)
    if exe is None:
        what = "is not executable" if Path(cfg.blender).is_file() else "does not exist"
        raise ConfigError(f"--blender {cfg.blender!r}: {what} (a Blender binary, or none: bpy)")


def job_objects(cfg: BuildConfig, objs: list[ObjectSpec] | None = None) -> list[ObjectSpec]:
    """This job's objects: its shard of `objs` (default: all_objects). The partition
    depends on the set of objects only, so the shards of one config are disjoint and
    together are the whole build, however the entries were listed."""
    objs = all_objects(cfg) if objs is None else objs
    if cfg.shard_index is not None:
        i, n = cfg.shard_index
        objs = objs[i::n]
    return objs


def resumed_settings(out: Path, objs: list[ObjectSpec], cfg: BuildConfig) -> int:
    """How many of this job's settings an earlier run left complete in OUT."""
    mine = {layout.setting_name(o.uid, t) for o in objs for t in cfg.theta0s}
    return sum(1 for s in layout.complete_settings(out) if s.name in mine)


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
        f"are not in the cache {objaverse(cfg).versioned} ({fate}): {names}"
    )


# What a build leaves on disk a pixel of an image: its PNG and images_<f>/ copies and
# records (the demo build: 4.9 MB for 255 images of 96 px, 2.1 bytes), and with
# --keep-linear its half-float RGBA EXR (8 bytes before compression).
_DISK_BYTES_PX = 2.1
_EXR_BYTES_PX = 8.0
# The objects whose settings the plan prices (planned from their GLBs); the rest are
# counted at their mean, so a plan of thousands of objects takes seconds.
_PLAN_OBJECTS = 8
_LONG_S = 3600.0


def plan_lines(cfg: BuildConfig, objs: list[ObjectSpec]) -> list[str]:
    """What the build will do, said before it renders (and all `--dry-run` says):
    settings, images, renders, samples, disk and the time on this machine, with cheaper
    choices beside a long estimate."""
    from blurset.commands.builder.setting import SettingJob, frame_samples, object_geometry

    n_settings = len(objs) * len(cfg.theta0s)
    images = n_settings * cfg.views * len(cfg.level_dirs)
    disk = images * cfg.resolution**2 * (_DISK_BYTES_PX + _EXR_BYTES_PX * cfg.write_linear)
    lines = [
        f"plan: {len(objs)} objects x {len(cfg.theta0s)} settings = {n_settings} settings of "
        f"{cfg.views} views at {cfg.resolution} px; levels {', '.join(cfg.level_dirs)}: "
        f"{images} images, about {disk / 1e6:,.0f} MB on disk"
    ]
    backend = cfg.device if cfg.device not in ("auto", "gpu") else "cpu"
    est = estimate(cfg, objs, backend)
    if est is None:
        why = "each image renders to --target-psnr" if cfg.target_psnr else "no object read"
        return [*lines, f"estimate: none before rendering ({why}); the log gives an ETA"]
    renders, samples, seconds, priced = est
    lines[0] += f", {renders:,} renders, {samples:,} samples"
    first = SettingJob(priced[0], 0, cfg.theta0s[0])
    per_frame = frame_samples(cfg, first, object_geometry(priced[0].path))
    if per_frame and per_frame != [cfg.samples]:
        shown = "-".join(str(n) for n in sorted({per_frame[0], per_frame[-1]}))
        lines.append(f"  each latent frame renders {shown} samples (--samples {cfg.samples} is "
                     f"a frame's share of its image's budget, raised by --blur-budget "
                     f"{cfg.blur_budget})")  # fmt: skip
    unread = [o.uid for o in objs[:_PLAN_OBJECTS] if o not in priced]
    lines.append(
        f"estimate: {duration(seconds)} on this machine ({backend}, {os.cpu_count()} cores; "
        "the benchmarks' costs in rust/core/src/plan/cost.rs)"
        + (f"; not priced (unreadable): {', '.join(unread)}" if unread else "")
    )
    if seconds > _LONG_S:
        half = cfg.replace(resolution=max(32, cfg.resolution // 2))
        cheaper = [
            f"--resolution {half.resolution}: {duration(estimate(half, objs, backend)[2])}",  # type: ignore[index]
            f"a GPU (--device optix): {duration(estimate(cfg, objs, 'optix')[2])}",  # type: ignore[index]
            "--preset fast: each image rendered only to a 40 dB target",
        ]
        lines.append(f"  cheaper: {'; '.join(cheaper)}")
    return lines


def estimate(
    cfg: BuildConfig, objs: list[ObjectSpec], backend: str
) -> tuple[int, int, float, list[ObjectSpec]] | None:
    """(renders, samples, seconds, the objects priced) of the build on `backend`: each of
    the first objects' settings priced by the core from its own plan (its GLB read as the
    worker normalizes it), a worker's start and load per object, the rest of the objects
    at their mean; None under a render target (each image's samples are its own) or when
    no object reads."""
    from blurset.commands.builder.setting import SettingJob, estimate_setting, object_geometry

    priced, per = [], []
    for o in objs[:_PLAN_OBJECTS] if cfg.target_psnr is None else []:
        try:
            g = object_geometry(o.path)
            per += [estimate_setting(SettingJob(o, k, t), cfg, g, backend)
                    for k, t in enumerate(cfg.theta0s)]  # fmt: skip
        except Exception:  # noqa: BLE001 - a file the plan cannot read is not priced: its
            continue  # failure is the build's to record, never the estimate's
        priced.append(o)
    if not priced:
        return None
    r, n, t = (sum(col) * len(objs) / len(priced) for col in zip(*per, strict=True))
    return int(r), int(n), t + len(objs) * _core.OBJECT_LOAD_S, priced


def build(cfg: BuildConfig, *, progress: bool = True) -> dict:
    # Absolute, so Ray workers (another working directory, another machine with the
    # same shared path) write where the driver reads.
    cfg = cfg.replace(out=str(out_dir(cfg).resolve()))
    out = out_dir(cfg)
    everything, slots = _check(cfg, out)
    # Ray's cluster is joined for the whole build, its devices checked before a byte is
    # written (the local executor's were, in _check).
    with ray_cluster(cfg):
        return _build(cfg, out, everything, slots, progress)


def _build(
    cfg: BuildConfig,
    out: Path,
    everything: list[ObjectSpec] | None,
    slots: list,
    progress: bool,
) -> dict:
    out.mkdir(parents=True, exist_ok=True)
    # Every object of the build (all shards), for the sweep's one-file-one-set rule; the
    # demo's are written into OUT now.
    every = everything if everything is not None else all_objects(cfg)
    objs = job_objects(cfg, every)
    n_settings = len(objs) * len(cfg.theta0s)
    prog = Progress(n_settings, frames_per_setting=frames_per_setting(cfg), enabled=progress)
    with build_lock(out):
        check_same_options(out, cfg)
        # A link where a setting goes: the sweep and the publish would remove or replace
        # what the build never made.
        names = [layout.setting_name(o.uid, t) for o in every for t in cfg.theta0s]
        outputs.refuse_links(out, [*names, *(layout.partial_dir(Path(n)).name for n in names)],
                             "build")  # fmt: skip
        removed = sweep(out, every, cfg, prog)
    if found := resumed_settings(out, objs, cfg):
        prog.write(
            f"resuming: {found} of {n_settings} settings are complete from an earlier run "
            "and are skipped (each is checked first; one that is not whole is redone)"
        )
    _report_missing(objs, cfg, prog)
    for line in plan_lines(cfg, objs):
        prog.write(line)
    t0 = time.time()
    written, new = _run_objects(objs, cfg, prog, slots, out)
    with build_lock(out):
        summary = finalize(out, cfg, time.time() - t0, [*removed, *written])
    return _summary(summary, objs, new)


def dry_run(cfg: BuildConfig) -> list[str]:
    """`--dry-run`: the plan and its estimate after every check that needs no render;
    nothing is written (the demo's objects are made in a temporary folder)."""
    cfg = cfg.replace(out=str(out_dir(cfg).resolve()))
    check_blender(cfg)
    if cfg.demo:
        with tempfile.TemporaryDirectory() as d:
            return plan_lines(cfg, job_objects(cfg.replace(out=d)))
    check_out(out_dir(cfg), cfg)
    return plan_lines(cfg, job_objects(cfg))


def _check(cfg: BuildConfig, out: Path) -> tuple[list[ObjectSpec] | None, list]:
    """Everything that can fail before a byte is written: bad entries, unknown test
    objects, a missing Blender, device or OIDN, an OUT of another kind. Returns every
    object of the build (None for the demo, whose objects are not written yet) and the
    local executor's device slots."""
    if cfg.denoise == "oidn":
        from blurset.services.denoise import denoiser, device_for

        denoiser(device_for(cfg.device))
    if cfg.demo:
        # The demo's objects are written into OUT, and checked once they are.
        resolve_objects(list(cfg.objects), cache=objaverse(cfg))
        everything = None
    else:
        everything = all_objects(cfg)
    check_blender(cfg)
    check_out(out, cfg)
    slots = devices.plan_local(cfg) if cfg.executor == "local" else []
    return everything, slots


def _run_objects(
    objs: list[ObjectSpec], cfg: BuildConfig, prog: Progress, slots: list, out: Path
) -> tuple[list[str], int]:
    """Every object rendered by the configured executor; each result's failures and
    local record appended under the build lock as it arrives. Returns what this run
    vouches for (the settings it published or checked and reused, the previews it drew)
    and how many settings it published."""
    written: list[str] = []
    new = 0
    lock = threading.Lock()

    def on_result(res: ObjectResult) -> None:
        nonlocal new
        with lock:
            written.extend(res.written)
            written.extend(res.checked)
            new += res.new_settings
            if res.failures or res.local:
                with build_lock(out):
                    if res.failures:
                        append_failures(out, res.failures)
                    # The absolute path stays on this machine, outside OUT.
                    publish.log_local(out, [res.local] if res.local else [])
        for r in res.failures:
            if r.get("stage") == "license":  # left out by --licenses: by request
                prog.write(f"skipped {r['uid']} ({r['reason']})")
            else:
                prog.write(f"failed: {r.get('setting') or r['uid']}: {r['stage']}: {r['reason']}")

    with prog:
        if cfg.executor == "ray":
            run_ray(objs, cfg, prog, on_result)
        else:
            run_local(objs, cfg, prog, on_result, slots)
    return written, new


def _summary(summary: dict, objs: list[ObjectSpec], new_settings: int) -> dict:
    """The build's summary, its failures those of this run's objects (a shard's own)."""
    mine = {o.uid for o in objs}
    failed = [r for r in summary["failures"] if r["uid"] in mine]
    summary["objects"] = len(objs)
    # An object --licenses leaves out is skipped by request, not a failure of the build.
    skipped = {r["uid"] for r in failed if r.get("stage") == "license"}
    summary["objects_skipped"] = len(skipped)
    summary["objects_failed"] = len({r["uid"] for r in failed} - skipped)
    summary["settings_failed"] = sum(1 for r in failed if r.get("setting"))
    summary["settings_new"] = new_settings
    summary["failures"] = failed
    return summary
