"""What every `blurset export` target shares: the interface a target declares itself
with (`Target`: one module of blurset.commands.export.targets each), the output kind and its record, the
temp names, the options read against the build (--levels, --gains), and the rules of
what an export may write over (DESIGN §10): never an input, never an entry an earlier
export here did not write, never an export of another build or --noise by itself.
"""

from __future__ import annotations

import argparse
import os
import shutil
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from blurset import layout
from blurset.exceptions import ConfigError
from blurset.services import outputs

if TYPE_CHECKING:
    from blurset import _records

EXPORT = outputs.OutputKind.EXPORT
EXPORT_FILE = EXPORT.record
# Temp names (`.<name>.tmp<pid>`) of the staged scenes and of what makes way.
STAGE, TRASH = "export", "export.old"
# The files an export writes at the top of --out besides its scenes.
LISTS = ("train.txt", "test.txt", EXPORT_FILE)


@dataclass(frozen=True)
class SceneSource:
    """One (setting, level[, gain]) folder to export, as a target's `split` sees it."""

    scene: str  # `<setting>__<level>[__gain_<g>]`
    src: Path  # the level (or gain) folder
    held_out: list[int]  # the setting's held-out views
    clean_held: bool  # whether those views hold clean copies (sharp, or noise-free)
    is_test: bool  # whether the setting is a test setting


def one_scene(s: SceneSource) -> list[tuple[str, list[int] | None]]:
    """The test-scene rule of a loader that holds views out itself (llffhold, the split
    in transforms.json): the folder is one scene, with every view."""
    return [(s.scene, None)]


@dataclass(frozen=True)
class StagedScene:
    """A scene being written: staged at `path`, moved to `final` once every scene is,
    made from the folder `src` of the build `build` (or of its noise output); `name` is
    its key in the record's `scenes`."""

    path: Path
    final: Path
    src: Path
    name: str
    build: Path
    doc: _records.ExportDoc

    def put(self, source: Path, rel: str) -> None:
        """`rel` of the scene links to (or, with --copy, is a copy of) `source`."""
        link(source, self.path / rel, self.final / rel, self.doc["copy"])


@dataclass(frozen=True)
class SceneFolders:
    """A target that is a folder of scene folders, which blurset.commands.export.cli plans, stages and
    puts in place: what sets its scenes apart."""

    folder: str  # where its scenes lie under --out (`.`: at the top)
    write: Callable[[StagedScene], None]  # one staged scene's files
    hint: Callable[[_records.ExportDoc, Path], str]  # how its loader is pointed at the root
    split: Callable[[SceneSource], list[tuple[str, list[int] | None]]] = one_scene
    passes: bool = True  # whether its scenes carry the build's --passes
    one_frame: bool = False  # whether its loader reads one image per view (no --frames)
    factor: int | None = None  # the images_<f>/ its loader reads, which the build must have
    reader: str = ""  # its loader, as a refusal names it

    def __post_init__(self) -> None:
        if (self.one_frame or self.factor is not None) and not self.reader:
            raise TypeError("a target that refuses builds names its loader (reader)")


@dataclass(frozen=True)
class OwnOutput:
    """A target that writes an output of its own kind (hub: Parquet shards) by its own
    `run`, with options only it reads."""

    run: Callable[[argparse.Namespace], int]
    add_arguments: Callable[[argparse.ArgumentParser], None]
    options: tuple[str, ...]  # the options' dests: refused with another target
    does: str  # what they are for, as that refusal says (`writes shards`)
    # What an export of another target that replaces this one in OUT removes beside the
    # entries export.json lists (hub: its dataset card), given OUT.
    replaced: Callable[[Path], None] | None = None


@dataclass(frozen=True)
class Target:
    """An export target, `blurset export --for NAME`: the `TARGET` of its module in
    blurset.commands.export.targets, the only place that names it."""

    name: _records.ExportTarget  # `--for NAME`, the record's `for` (dataset/records.rs)
    help: str  # its part of `--for`'s help
    docs: str  # its page, relative to docs/
    output: SceneFolders | OwnOutput


def link(s: Path, dst: Path, final: Path, copy: bool) -> None:
    """`dst` (staged) links to or copies `s`; `final` is where `dst` will end up."""
    if copy:
        try:
            (shutil.copytree if s.is_dir() else shutil.copyfile)(s, dst)
        except shutil.Error as e:
            # copytree gathers every file's error into one list of (src, dst, why)
            # tuples: say the first reason, how many, and where, in one line.
            errors = e.args[0] if e.args and isinstance(e.args[0], list) else []
            why = str(errors[0][2]) if errors else str(e)
            why = why.split("] ", 1)[-1].split(":", 1)[0] if why.startswith("[Errno") else why
            raise OSError(
                f"--copy: {why} ({len(errors) or 'some'} files not copied; nothing of the "
                f"new export was put in place): {final}"
            ) from None
    else:
        # Relative to where the link will live: the export and the build may move
        # together.
        os.symlink(os.path.relpath(s, final.parent), dst)


def levels(value: str | None, available: list[str]) -> list[str]:
    """The levels `--levels` names (all without it), in the build's order."""
    if value is None:
        return available
    names = [s.strip() for s in value.split(",") if s.strip()]
    for n in names:
        if n not in available:
            raise ConfigError(f"--levels: the build has no level {n!r} ({', '.join(available)})")
    return [lvl for lvl in available if lvl in names]


def gains(noise: Path, doc: dict, value: list[str] | None) -> list[str]:
    """The gain folders `--gains` names of the noise output `noise` (all without it)."""
    have = [layout.gain_name(g["gain"]) for g in doc["gains"]]
    if value is None:
        return have
    names = []
    for v in value:
        try:
            name = layout.gain_name(float(v))
        except ValueError:
            raise ConfigError(f"--gains {v!r}: not a number") from None
        if name not in have:
            raise ConfigError(f"--gains {v}: {noise} has no {name} ({', '.join(have)})")
        names.append(name)
    return names


def refuse_overlap(out: Path, doc: _records.ExportDoc, inputs: list[Path]) -> None:
    """--out may hold the build (IBRNet's `data/` may keep it beside the export), but it
    may not be or lie in an input, and no entry the export writes may touch one."""
    o = out.resolve()
    for i in inputs:
        r = Path(i).resolve()
        if o == r or o.is_relative_to(r):
            outputs.refuse_overlap(out, [i])
        if r.is_relative_to(o):
            top = doc["scenes_dir"] if doc["scenes_dir"] != "." else None
            mine = [top] if top else list(doc["scenes"])
            for e in [*mine, *LISTS]:
                if r == o / e or r.is_relative_to(o / e):
                    raise ConfigError(f"--out/{e} would hold the input {str(i)!r}: {out}")


def _other_noise(was: str | None, now: str | None, out: Path) -> str:
    """Why an export of the build with another --noise (or none) does not replace the one
    in OUT by itself: a loader reads one root, so clean and noisy scenes need two."""

    def of(noise: str | None) -> str:
        return f"the noise output {noise!r}" if noise else "the build without --noise"

    return (
        f"--out holds the export of {of(was)}; this export of {of(now)} would replace it. "
        "To keep both, give this one its own root (IBRNet and GNT read only "
        "<rootdir>/data/nerf_llff_data/: --out ROOTN/data, then --rootdir ROOTN), or "
        f"--overwrite to replace it: {out}"
    )


def refuse_other_export(old: dict, doc: _records.ExportDoc, out: Path, overwrite: bool) -> None:
    """An export of another build, or with another --noise, is not replaced by itself."""
    # (an export.json of an older blurset names the build by its absolute path)
    was_of = Path(str(old.get("build"))).name if old.get("build") else doc["build"]
    if was_of != doc["build"] and not overwrite:
        raise ConfigError(
            f"--out holds an export of the build {was_of!r}: give another --out, "
            f"or --overwrite to replace that export: {out}"
        )
    if old.get("state") != "replacing" and old.get("noise") != doc["noise"] and not overwrite:
        raise ConfigError(_other_noise(old.get("noise"), doc["noise"], out))


def refuse_foreign(out: Path, doc: _records.ExportDoc, owned: set[str], new: list[str]) -> None:
    """Nothing an earlier export did not write is replaced, and a scene folder that makes
    way holds only what an export writes: a user's file there (a note) is named, never
    deleted with it."""
    for rel in new:
        p = out / rel
        if (p.exists() or p.is_symlink()) and rel not in owned:
            raise ConfigError(
                f"--out already holds {rel}, which no earlier export here wrote: move it, or "
                f"give another --out: {out}"
            )
    outputs.refuse_links(out, sorted(owned), "export")
    if doc["scenes_dir"] != "." and (out / doc["scenes_dir"]).is_file():
        raise ConfigError(f"--out holds a file {doc['scenes_dir']}: {out}")
    # (The core's rule of what an exported scene holds: images/, images_<f>/, the passes'
    # folders and links, nerfstudio's depths/, poses_bounds.npy, transforms.json.)
    scenes = [rel for rel in sorted(owned) if rel not in LISTS]
    outputs.refuse_not_written(out, EXPORT, scenes, "export")


def record_replacing(
    out: Path, doc: _records.ExportDoc, owns: set[str], shards: dict | None = None
) -> None:
    """What a run may put in place, recorded before it writes: an export stopped half-way
    still owns every entry it wrote, and its rerun replaces (or keeps) them. `shards`
    (`--for hub`): the records of the shards the run wrote or checked so far, which its
    rerun checks a kept shard against."""
    rec: dict = {
        "kind": "blurset export",
        "state": "replacing",
        "build": doc["build"],
        "scenes_dir": doc["scenes_dir"],
        "scenes": {},
        "owns": sorted(owns),
    }
    if shards is not None:
        rec["shards"] = shards
    outputs.write_record(out / EXPORT_FILE, rec)


def prune_empty_parents(out: Path, rel: str) -> None:
    """The folders above an entry that made way (`data/blur_4`, `nerf_llff_data`), once
    empty, go too; never `out` itself."""
    d = (out / rel).parent
    while d != out and d.is_relative_to(out):
        try:
            d.rmdir()
        except OSError:
            return  # not empty (or not ours to remove)
        d = d.parent
