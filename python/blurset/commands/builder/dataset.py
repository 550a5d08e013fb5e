"""The files a build shares across all its objects: failures.jsonl, splits.json and
dataset.json (DESIGN §4), and the lock every process building into OUT takes to write
them (local workers, Ray tasks and Slurm shards alike)."""

from __future__ import annotations

import contextlib
import fcntl
import json
import os
import platform
import shutil
import sys
import time
from collections.abc import Iterator
from pathlib import Path

from blurset import __version__, _core, layout
from blurset.exceptions import ConfigError
from blurset.services import outputs, publish
from blurset.services.config import BUILD, BuildConfig, flag
from blurset.services.objects import ObjectSpec
from blurset.services.progress import Progress

DATASET_NAME = "blurset Objaverse-Blur"
# The files every process building into OUT shares (written under build_lock).
SHARED_FILES = (layout.FAILURES, layout.SPLITS, layout.DATASET, layout.MANIFEST)


@contextlib.contextmanager
def build_lock(out: Path) -> Iterator[None]:
    """Serialize the writes shared by every process building into OUT."""
    with outputs.open_lock(out / layout.BUILD_LOCK) as f:
        fcntl.flock(f, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(f, fcntl.LOCK_UN)


def sweep(
    out: Path, objs: list[ObjectSpec], cfg: BuildConfig, prog: Progress | None = None
) -> list[str]:
    """What a killed run left behind that no object owns: temp files of the shared
    writes (a partial setting and an object's scratch folder are its object's, cleaned
    under that object's lock: another process may be writing them now). And settings
    whose source file now has another id (`objs` is every object of the build, all
    shards): one source file, one set of settings. Call under build_lock. Returns the
    settings removed (the manifest drops their lines)."""
    current = [(o.uid, o.rel or o.path.name) for o in objs]
    superseded = _core.superseded_settings(out, current)
    # A superseded setting holds only what a build writes: a user's file there (a note)
    # is named before anything is removed, never deleted with it.
    for setting, source, now in superseded:
        foreign = layout.not_written_by_build(out / setting)
        if foreign:
            raise ConfigError(
                f"--out/{setting} holds {foreign[0]}, which the build did not write and "
                f"would delete with the setting (its source file {source} now has the id "
                f"{now}): move it out of the setting folder, then rerun (nothing was "
                f"changed): {out / setting / foreign[0]}"
            )
    # Only blurset's own temp names: a user's `.notes.tmp1` in OUT is not ours to delete.
    # A setting's is the old setting a killed publish had moved aside (replace_dir).
    settings = [p.name for p in layout.complete_settings(out)]
    layout.remove_stale_temps(out, [*SHARED_FILES, *settings])
    for setting, source, now in superseded:
        shutil.rmtree(out / setting)
        say = prog.write if prog is not None else print
        say(f"removed {setting}: its source file {source} now has the id {now} (a name it shares)")
    publish.move_local_paths(out)
    return [setting for setting, _, _ in superseded]


# Options that decide where and how a build runs, not what it writes: a rerun may change
# them freely. Every other option shapes the files, so a rerun must keep it. Both from
# the core's declarations (`shapes`/`run` in build_options!).
RUN_OPTIONS = frozenset(BUILD.names) - BUILD.shaping
# What a recorded config without the key was built with (blurset before the option),
# where that is not today's default: declared with the option (`before`).
BEFORE_OPTION = {d.name: d.before for d in BUILD.decls if d.before != d.default}


def check_same_options(out: Path, cfg: BuildConfig) -> None:
    """Refuse (naming the options) a rerun into OUT whose output-shaping options differ
    from those OUT was made with, unless --allow-mixed; the first run records them in a
    provisional dataset.json (call under build_lock)."""
    path = out / layout.DATASET
    record = cfg.record()
    # Compared option by option, whatever the option: a plain mapping of its values.
    now: dict[str, object] = dict(record)
    if not path.is_file():
        outputs.write_record(path, {"name": DATASET_NAME, "config": record, "provisional": True})
        return
    try:
        was = json.loads(path.read_text())["config"]
        if not isinstance(was, dict):
            raise TypeError
    except (OSError, ValueError, KeyError, TypeError):
        raise ConfigError(
            f"dataset.json of OUT is unreadable; move it away to rebuild: {path}"
        ) from None
    defaults: dict[str, object] = dict(BuildConfig(out=cfg.out, objects=cfg.objects).record())
    before = {k: was.get(k, BEFORE_OPTION.get(k, defaults.get(k))) for k in now}
    differ = [k for k in sorted(now) if k not in RUN_OPTIONS and before[k] != now[k]]
    if differ and not cfg.allow_mixed:
        said = ", ".join(f"{flag(k)} {before[k]!r} → {now[k]!r}" for k in differ[:4])
        raise ConfigError(
            f"--out was built with other options ({said}{' …' if len(differ) > 4 else ''}): "
            f"use a new --out, or --allow-mixed to mix settings: {out}"
        )


def append_failures(out: Path, records: list[dict[str, object]]) -> None:
    """Append failure records to failures.jsonl (call under build_lock)."""
    with open(out / layout.FAILURES, "a+b") as f:
        # A record torn by a kill mid-append gets its line ended first, so the next
        # record stays whole (readers skip the torn one).
        f.seek(0, os.SEEK_END)
        if f.tell() > 0:
            f.seek(-1, os.SEEK_END)
            if f.read(1) != b"\n":
                f.write(b"\n")
        f.write("".join(json.dumps(r) + "\n" for r in records).encode())
        f.flush()
        os.fsync(f.fileno())


def finalize(out: Path, cfg: BuildConfig, seconds: float, vouched: list[str]) -> dict[str, object]:
    """splits.json, dataset.json and failures.jsonl over what is on disk, written by the
    core from the settings' meta.json (`dataset/build_tail.rs`), and the manifest (call
    under build_lock). failures.jsonl keeps the latest record per object (or per
    setting, for QA failures) whose work is still not complete. A complete setting whose
    meta.json does not read is left out, named on stderr (its object's next run redoes
    it). `vouched`: the settings this run published, removed or checked and reused; the
    manifest hashes only those and the files written here, keeps its lines of the rest,
    and lists nothing else (another shard's settings are listed by that shard's run)."""
    complete, failures, test_settings, skipped = _core.write_build_tail(
        out,
        cfg,
        name=DATASET_NAME,
        blurset_version=__version__,
        python_version=platform.python_version(),
        created=time.strftime("%Y-%m-%dT%H:%M:%S"),
        seconds=seconds,
    )
    for name, why in skipped:
        print(f"skipped {name}: unreadable meta.json ({why}): {out / name / layout.META}",
              file=sys.stderr)  # fmt: skip
    # Last: the checksums of what this run wrote or checked (another shard's finalize
    # rewrites it with its own); a file it did not write keeps the line it had.
    shared = [f for f in SHARED_FILES if f != layout.MANIFEST]
    publish.rewrite_manifest(out, [*vouched, *shared])
    return {"settings_complete": complete, "failures": failures, "test_settings": test_settings}
