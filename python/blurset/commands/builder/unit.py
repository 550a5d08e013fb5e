"""One object: the retried, idempotent unit of work of a build (DESIGN §10, §11).

Every pending setting of one object renders in one Blender worker process; a crash or
hang is retried, a refused file is not, and any failure costs this object only
(recorded for failures.jsonl). Complete settings are skipped and partial ones redone,
so a retry (here, by Ray, or a rerun after a kill) is always safe.
"""

from __future__ import annotations

import contextlib
import errno
import json
import shutil
import time
import traceback
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from blurset import _core, layout
from blurset.commands.builder.setting import (
    LoadedObject,
    SettingFailed,
    SettingJob,
    render_setting,
)
from blurset.exceptions import BlursetError
from blurset.services import attribution, objaverse_cache, outputs, preflight, publish
from blurset.services.config import BuildConfig, out_dir
from blurset.services.devices import Device
from blurset.services.objects import ObjectSpec
from blurset.services.progress import Progress
from blurset.services.stop import STOP


@dataclass
class ObjectResult:
    uid: str
    settings: list[str] = field(default_factory=list)
    # Failure records (failures.jsonl): the object's, or one per setting that failed QA.
    failures: list[dict[str, Any]] = field(default_factory=list)
    new_settings: int = 0
    # What this run wrote: the settings it published, the previews it drew (the manifest
    # hashes only what a run wrote or checked).
    written: list[str] = field(default_factory=list)
    # The files of the complete settings it reused after checking them (`_reusable`):
    # the manifest lists them too, even where no manifest was written yet (a killed
    # shard's rerun).
    checked: list[str] = field(default_factory=list)
    # For the local paths file (publish.local_paths_file, never under OUT): where this
    # object came from.
    local: dict[str, Any] = field(default_factory=dict)


class ObjectUnit:
    """Every pending setting of one object, rendered in one worker process per attempt.

    `stage` is where the current attempt is (fetch, preflight, start, load, render): a
    failure is recorded under the stage it happened in."""

    def __init__(
        self,
        obj: ObjectSpec,
        cfg: BuildConfig,
        progress: Progress,
        device: Device = ("AUTO", None),
    ) -> None:
        self.obj, self.cfg, self.progress = obj, cfg, progress
        # The Cycles backend (or AUTO) and GPU indices the worker renders on.
        self.device = device
        self.out = out_dir(cfg)
        self.work = self.out / layout.work_dir(obj.uid)
        self.result = ObjectResult(
            uid=obj.uid, local={"uid": obj.uid, "path": str(obj.path), "rel": obj.rel}
        )
        self.stage = "fetch"
        self._sha256: str | None = None
        # meta.json `object` fields that say where the object came from (issue 19).
        self.provenance: dict[str, Any] = {}

    def run(self) -> ObjectResult:
        # One process at a time per object in OUT: two builds of the same object (a
        # repeated command, overlapping shard lists) take turns; the second finds the
        # first's settings complete.
        with object_lock(self.out, self.obj.uid, self.progress.write):
            result = self._run()
        for r in result.failures:
            r["reason"] = self._scrub(r["reason"])
        return result

    def _scrub(self, text: str) -> str:
        """A failure reason without the builder's absolute paths (worker and importer
        messages name files): the input becomes its relative path, OUT becomes `OUT`."""
        swaps = [
            (str(self.obj.path), self.obj.rel or self.obj.path.name),
            (str(self.out), "OUT"),
            (str(self.obj.path.parent), "."),
            (str(Path.home()), "~"),
        ]
        if self.obj.source == "objaverse":
            root = objaverse(self.cfg).root
            swaps.append((str(root), root.name))
        for old, new in sorted(swaps, key=lambda s: -len(s[0])):
            if len(old) > 1:
                text = text.replace(old, new)
        return text

    def _run(self) -> ObjectResult:
        pending = self._pending()
        if not pending:
            return self.result
        t0 = time.monotonic()
        if self._admit(t0, len(pending)):
            self._render(pending, t0)
        shutil.rmtree(self.work, ignore_errors=True)
        return self.result

    def _pending(self) -> list[SettingJob]:
        """The object's settings still to render; the finished ones are recorded (and
        drawn, under --previews, if an earlier run did not), and a killed run's scratch
        and partial settings of this object are swept: its lock is held, so no other
        process is writing them."""
        obj, cfg, progress, result = self.obj, self.cfg, self.progress, self.result
        jobs = [SettingJob(obj, k, t) for k, t in enumerate(cfg.theta0s)]
        pending = [j for j in jobs if not self._reusable(self.out / j.name)]
        result.settings = [j.name for j in jobs if j not in pending]
        # Vouched for file by file: the check skips the preview (drawn from the images),
        # so a kept preview keeps its manifest line (or stays unlisted), never rehashed.
        result.checked = [
            p.relative_to(self.out).as_posix()
            for name in result.settings
            for p in sorted((self.out / name).rglob("*"))
            if p.is_file() and p.name != layout.PREVIEW
        ]
        progress.skip(len(jobs) - len(pending))
        if cfg.previews:
            from blurset.commands.preview import write_build_preview

            for name in result.settings:
                if not (self.out / name / layout.PREVIEW).exists():
                    write_build_preview(self.out / name, warn=progress.write)
                    result.written.append(f"{name}/{layout.PREVIEW}")  # the manifest hashes it
        shutil.rmtree(self.work, ignore_errors=True)
        for j in jobs:
            shutil.rmtree(layout.partial_dir(self.out / j.name), ignore_errors=True)
        return pending

    def _admit(self, t0: float, n_pending: int) -> bool:
        """Fetch, pre-flight and licence: False (and a failure recorded) when the object
        cannot be rendered. Whatever a file does here costs that file only."""
        obj, cfg = self.obj, self.cfg
        self.stage = "fetch"
        try:
            if obj.source == "objaverse":
                objaverse(cfg).ensure(obj.uid, obj.path)
            self.stage = "preflight"
            report = preflight.check(
                obj.path, preflight.Budget(cfg.max_triangles, cfg.max_texture_pixels)
            )
            self.provenance = self._provenance(report)
            self.stage = "license"
            lic = self.provenance["license"]
            if not attribution.allowed(lic, cfg.licenses):
                raise LicenseRefused(
                    f"licence {lic} ({self.provenance['license_text']}) is not in --licenses "
                    f"{','.join(cfg.licenses or [])}"
                )
        except Exception as e:
            if isinstance(
                e, objaverse_cache.FetchError | preflight.PreflightError | LicenseRefused
            ):
                reason = str(e)
            else:
                reason = f"{type(e).__name__}: {' '.join(str(e).split())[:300]}"
            self.result.failures.append(failure_record(obj, self.stage, reason, t0, 1))
            if isinstance(e, LicenseRefused):
                self.progress.object_skipped(n_pending)  # by request: not a failure
            else:
                self.progress.object_failed(n_pending)
            return False
        return True

    def _render(self, pending: list[SettingJob], t0: float) -> None:
        """Render the pending settings, retrying a transient worker failure up to
        --retries times; any other failure is recorded against this object only."""
        from blurset.services.worker_client import WorkerError

        obj, cfg, progress, result = self.obj, self.cfg, self.progress, self.result
        deadline = t0 + cfg.object_timeout if cfg.object_timeout > 0 else None
        attempt = 0
        while pending:
            attempt += 1
            self.stage = "start"
            try:
                self._attempt(pending, deadline)
            except Exception as e:
                for j in pending:
                    shutil.rmtree(layout.partial_dir(self.out / j.name), ignore_errors=True)
                if STOP.is_set():  # stopping: not this object's failure; a rerun redoes it
                    return
                if disk_full(self.out, e):
                    # Not this object's fault, and every next one would fail the same way.
                    shutil.rmtree(self.work, ignore_errors=True)
                    raise DiskFull(f"No space left on device: {self.out}") from e
                if isinstance(e, WorkerError) and e.transient and attempt <= cfg.retries:
                    progress.write(f"retrying {obj.uid} (attempt {attempt + 1}) after: {e}")
                    continue
                if isinstance(e, BlursetError | ValueError | OSError):
                    reason = str(e).splitlines()[0] if str(e) else repr(e)
                else:  # a bug must cost this object only, and be visible
                    tb = traceback.format_exc(limit=3).strip().splitlines()[-1]
                    reason = f"{type(e).__name__}: {e} [{tb}]"
                result.failures.append(failure_record(obj, self.stage, reason, t0, attempt))
                progress.object_failed(len(pending))
                return

    def sha256(self) -> str:
        """sha256 of the object's file (hashed once per unit)."""
        if self._sha256 is None:
            self._sha256 = _core.sha256_file(self.obj.path)
            self.result.local["sha256"] = self._sha256
        return self._sha256

    def _provenance(self, report: preflight.Report) -> dict[str, Any]:
        """Where the object came from and who made it, for meta.json: its relative path,
        the sha256 of its bytes and its attribution (blurset.services.attribution)."""
        obj = self.obj
        sources = [attribution.from_asset(report.asset)]
        if obj.source == "objaverse":
            cache = objaverse(self.cfg)
            ann = attribution.objaverse_annotation(cache.versioned, obj.path, obj.uid)
            sources.append(attribution.from_objaverse_annotation(ann))
        return {"path": obj.rel, "sha256": self.sha256(), **attribution.attribution(*sources)}

    def _reusable(self, setting: Path) -> bool:
        """A complete setting made from this very file (the same bytes), whole, and the
        bytes OUT's manifest certifies (another file may have had this id in an earlier
        run, a file may have been damaged, deleted or copied over since): anything else
        is redone, never passed off as this object's nor certified anew."""
        if not layout.is_complete(setting):
            return False
        problem = layout.setting_problem(setting)
        if problem is None:
            made_from = json.loads((setting / layout.META).read_text()).get("object") or {}
            problem = self._other_file(made_from)
        if problem is None:
            # A preview is drawn from the images, not data: a missing one is drawn again
            # (--previews), not a reason to render the setting again.
            problem = publish.manifest_problem(self.out, setting.name, skip=(layout.PREVIEW,))
            if problem is None:
                return True
        self.progress.write(f"redoing {setting.name}: {problem}")
        return False

    def _other_file(self, made_from: Mapping[str, object]) -> str | None:
        """Why a setting's meta.json `object` is not this object's file, or None. The
        file's content decides (a build moved elsewhere, or a demo object made again, is
        still the same object); without a recorded hash (a build before issue 19), its
        absolute path."""
        if "sha256" not in made_from:
            source = made_from.get("source")
            return None if source == str(self.obj.path) else f"made from another file ({source})"
        if self.obj.source == "objaverse" and not self.obj.path.is_file():
            # An objaverse uid names one file: a cleaned cache needs no refetch.
            return None if made_from.get("path") == self.obj.rel else "made from another file"
        try:
            if made_from["sha256"] == self.sha256():
                return None
        except OSError as e:
            return f"cannot read {self.obj.rel} ({e.strerror})"
        if made_from.get("path") != self.obj.rel:
            return f"made from another file ({made_from.get('path')})"
        return f"made from other bytes of {self.obj.rel} (sha256 differs)"

    def _attempt(self, pending: list[SettingJob], deadline: float | None) -> None:
        """Load the object in a fresh worker and render the pending settings in order,
        taking each off `pending` once it is complete or has failed QA."""
        from blurset.services.worker_client import Worker

        obj, cfg, progress, result, work = (
            self.obj,
            self.cfg,
            self.progress,
            self.result,
            self.work,
        )
        shutil.rmtree(work, ignore_errors=True)
        work.mkdir(parents=True)
        t0 = time.monotonic()
        with Worker.in_folder(
            work,
            blender=cfg.blender,
            threads=cfg.threads,
            timeout=cfg.timeout,
            deadline=deadline,
            device=self.device[0],
            gpus=self.device[1],
        ) as w:
            self.stage = "load"
            loaded = LoadedObject(
                w.load(obj.path, work / "vertices.npy", light_paths=cfg.light_paths),
                load_s=round(time.monotonic() - t0, 3),
                provenance=self.provenance,
                blender_version=w.info["blender_version"],
            )
            verts = np.ascontiguousarray(np.load(work / "vertices.npy"), dtype=np.float32)
            self.stage = "render"
            while pending:
                j = pending[0]
                t1 = time.monotonic()
                try:
                    render_setting(j, cfg, w, loaded, verts, progress)
                except SettingFailed as e:
                    shutil.rmtree(layout.partial_dir(self.out / j.name), ignore_errors=True)
                    rec = failure_record(obj, e.stage, str(e), t1, 1)
                    rec["setting"] = j.name
                    result.failures.append(rec)
                    progress.object_failed(1)
                else:
                    result.settings.append(j.name)
                    result.written.append(j.name)
                    result.new_settings += 1
                    progress.setting_done()
                pending.pop(0)


@contextlib.contextmanager
def object_lock(out: Path, uid: str, say):
    """Hold OUT/.lock-<uid> while an object is built; a process that finds it held says
    who holds it (once) and waits."""
    said: list[bool] = []

    def wait(holder: str) -> None:
        if not said:
            say(f"waiting: {out / uid}_* is being built by {holder}")
            said.append(True)

    with outputs.flock_file(out / layout.object_lock(uid), wait):
        yield


# Below this much free space an object's failure is taken for a full disk: Blender then
# writes truncated EXRs, whose read errors do not say ENOSPC themselves.
DISK_FULL_BYTES = 64 * 2**20


class LicenseRefused(BlursetError):
    """The object's licence is not one `--licenses` allows: skipped before rendering."""


class DiskFull(BlursetError):
    """OUT's file system is full: the build stops (nothing half-written is kept)."""


def disk_full(out: Path, e: BaseException) -> bool:
    if isinstance(e, OSError) and e.errno == errno.ENOSPC:
        return True
    if "No space left on device" in str(e) or "os error 28" in str(e):
        return True
    try:
        return shutil.disk_usage(out).free < DISK_FULL_BYTES
    except OSError:
        return False


def build_object(
    obj: ObjectSpec, cfg: BuildConfig, progress: Progress, device: Device = ("AUTO", None)
) -> ObjectResult:
    """One work unit: every pending setting of one object (see ObjectUnit), rendered on
    `device` (blurset.services.devices)."""
    return ObjectUnit(obj, cfg, progress, device).run()


def failure_record(obj: ObjectSpec, stage: str, reason: str, t0: float, attempts: int) -> dict:
    """A failures.jsonl record: uid, path (relative to its root: the absolute one goes to
    local paths file only), stage, reason, seconds (+ attempts, time)."""
    return {
        "uid": obj.uid,
        "path": obj.rel or obj.path.name,
        "stage": stage,
        "reason": reason,
        "seconds": round(time.monotonic() - t0, 3),
        "attempts": attempts,
        "time": time.strftime("%Y-%m-%dT%H:%M:%S"),
    }


def objaverse(cfg: BuildConfig) -> objaverse_cache.Cache:
    return objaverse_cache.Cache(cfg.objaverse_dir, offline=cfg.objaverse_offline)
