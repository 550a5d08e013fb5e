"""`blurset build`: GLB objects → Objaverse-Blur style dataset (DESIGN §1–4, §10, §11).

Per object (`unit`): one Blender worker process loads and normalizes the GLB once; per
setting (`setting`), blurset-core plans every view, trajectory, level and latent frame
(seeded); the worker renders the frames to linear EXR while this process streams each
one into a Rust accumulator and writes the sRGB PNG when a view/level is complete.
Objects run locally or on Ray (`executors`); the files shared by all objects are written
under a lock at the end (`dataset`). The flags are in `cli`.
"""

from __future__ import annotations

import threading
import time
from pathlib import Path

from blurset import devices, layout, publish
from blurset.build.dataset import (
    append_failures,
    build_lock,
    check_same_options,
    finalize,
    sweep,
)
from blurset.build.executors import run_local, run_ray
from blurset.build.setting import frames_per_setting
from blurset.build.unit import ObjectResult, objaverse
from blurset.config import BuildConfig
from blurset.exceptions import ConfigError
from blurset.objects import ObjectSpec, resolve_objects
from blurset.progress import Progress

__all__ = ["build", "BuildConfig"]


def check_out(out: Path, cfg: BuildConfig) -> None:
    """OUT is new, empty, or a blurset build; it never is, holds or lies in an input."""
    if out.exists():
        if not out.is_dir():
            raise ConfigError(f"--out exists and is not a directory: {out}")
        if not layout.is_build_dir(out) and any(out.iterdir()):
            raise ConfigError(
                f"--out is a folder with other files, not a blurset build: {out} "
                "(give a new or empty folder)"
            )
    inputs = [Path(e[1:] if e.startswith("@") else e) for e in cfg.objects]
    layout.refuse_overlap(out, [p for p in inputs if p.exists()])


def job_objects(cfg: BuildConfig) -> list[ObjectSpec]:
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
            entries, cache=objaverse(cfg), objaverse_count=cfg.objaverse_count, seed=cfg.seed
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
        f"are not in the cache {objaverse(cfg).versioned} ({fate}): {names}"
    )


def build(cfg: BuildConfig, *, progress: bool = True) -> dict:
    # Absolute, so Ray workers (another working directory, another machine with the
    # same shared path) write where the driver reads.
    cfg = cfg.replace(out=str(Path(cfg.out).resolve()))
    out = Path(cfg.out)
    if cfg.denoise == "oidn":  # a missing OIDN fails before anything is written
        from blurset.denoise import denoiser, device_for

        denoiser(device_for(cfg.device))
    # Bad entries and a missing device fail before anything is written.
    resolve_objects(list(cfg.objects), cache=objaverse(cfg))
    check_out(out, cfg)
    slots = devices.plan_local(cfg) if cfg.executor == "local" else []
    out.mkdir(parents=True, exist_ok=True)
    objs = job_objects(cfg)
    with build_lock(out):
        check_same_options(out, cfg)
        sweep(out, objs, cfg)
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
            if res.failures or res.local:
                with build_lock(out):
                    if res.failures:
                        append_failures(out, res.failures)
                    # The absolute path stays here, unpublished (issue 19).
                    publish.log_local(out, [res.local] if res.local else [])
        for r in res.failures:
            prog.write(f"failed: {r.get('setting') or r['uid']}: {r['stage']}: {r['reason']}")

    with prog:
        if cfg.executor == "ray":
            run_ray(objs, cfg, prog, on_result)
        else:
            run_local(objs, cfg, prog, on_result, slots)
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
