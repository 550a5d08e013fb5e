"""Resolve `--objects` into GLB files with safe, unique ids.

An entry is a model (`.glb`, or `.gltf` with its external files), a folder (every
model under it, sorted), an Objaverse reference (`objaverse:<uid>`,
`objaverse:lvis=<category>[+<category>…]`, `objaverse:all`; see
`blurset.objaverse_cache`), or a list file (`.txt`/`.lst`, or any file as `@FILE`)
naming one such entry per line (`#` comments; relative paths are relative to the list). Output directories are named from
sanitized ids, never from file contents (DESIGN §10).
"""

from __future__ import annotations

import hashlib
import re
import sys
from dataclasses import dataclass
from pathlib import Path

from blurset import _core, objaverse_cache
from blurset.exceptions import InputError

_UNSAFE = re.compile(r"[^A-Za-z0-9_-]+")


@dataclass(frozen=True)
class ObjectSpec:
    uid: str
    path: Path
    # "file", or "objaverse" for an object fetched into the objaverse cache on demand.
    source: str = "file"


def sanitize(stem: str) -> str:
    uid = _UNSAFE.sub("_", stem).strip("_")[:64]
    return uid or "object"


MODEL_SUFFIXES = (".glb", ".gltf")
LIST_SUFFIXES = (".txt", ".lst")


def _models_in(folder: Path, warn) -> list[Path]:
    """The .glb/.gltf files under a folder (its subfolders too: a .gltf usually sits in
    its own folder with its textures), sorted; hidden folders are not entered. Dangling
    symlinks are named, not silently dropped."""
    found: list[Path] = []
    dangling: list[Path] = []
    for p in sorted(folder.rglob("*")):
        rel = p.relative_to(folder)
        if any(part.startswith(".") for part in rel.parts):
            continue
        if p.suffix.lower() not in MODEL_SUFFIXES:
            continue
        if p.is_file():
            found.append(p)
        elif p.is_symlink():
            dangling.append(p)
    if dangling:
        names = ", ".join(str(p) for p in dangling[:5]) + (" …" if len(dangling) > 5 else "")
        warn(f"--objects: skipped {len(dangling)} dangling symlink(s) in {str(folder)!r}: {names}")
    return found


def _model_or_list(p: Path, where: str) -> str:
    """ "model" or "list" for an existing file, by its suffix; anything else is refused."""
    suffix = p.suffix.lower()
    if suffix in MODEL_SUFFIXES:
        return "model"
    if suffix in LIST_SUFFIXES:
        return "list"
    raise InputError(
        f"{where}: {str(p)!r} is not a .glb/.gltf model (a list of models is a .txt/.lst "
        "file, or any file given as @FILE)"
    )


def _expand(entry: str, refs: list[str], warn) -> list[Path]:
    """Model paths of one entry; objaverse references go to `refs` instead."""
    if objaverse_cache.is_entry(entry):
        refs.append(entry)
        return []
    forced_list = entry.startswith("@")
    p = Path(entry[1:] if forced_list else entry).expanduser()
    if p.is_dir() and not forced_list:
        found = _models_in(p, warn)
        if not found:
            raise InputError(f"--objects: no .glb/.gltf files in folder {str(p)!r}")
        return found
    if not p.exists():
        what = "dangling symlink" if p.is_symlink() else "no such file or folder"
        raise InputError(f"--objects: {what} {str(p)!r}")
    if not forced_list and _model_or_list(p, "--objects") == "model":
        return [p]
    return _read_list(p, refs, warn)


def _read_list(p: Path, refs: list[str], warn) -> list[Path]:
    """A list file: one entry per line (a model, a folder of models, an objaverse
    reference), `#` comments; relative paths are relative to the list's folder."""
    try:
        # utf-8-sig: a byte-order mark (Windows editors write one) is not part of line 1.
        lines = p.read_text(encoding="utf-8-sig").splitlines()
    except UnicodeDecodeError:
        raise InputError(f"--objects: list {str(p)!r} is not UTF-8 text") from None
    except IsADirectoryError:
        raise InputError(f"--objects: @{str(p)!r} is a folder, not a list file") from None
    out: list[Path] = []
    named = 0
    for n, line in enumerate(lines, 1):
        line = line.split("#", 1)[0].strip()
        if not line:
            continue
        named += 1
        if objaverse_cache.is_entry(line):
            refs.append(line)
            continue
        q = Path(line).expanduser()
        q = q if q.is_absolute() else p.parent / q
        where = f"--objects: {str(p)!r} line {n}"
        if q.is_dir():
            found = _models_in(q, warn)
            if not found:
                raise InputError(f"{where}: no .glb/.gltf files in folder {str(q)!r}")
            out.extend(found)
            continue
        if not q.is_file():
            what = "dangling symlink" if q.is_symlink() else "no such file"
            raise InputError(f"{where}: {what} {str(q)!r}")
        if q.suffix.lower() not in MODEL_SUFFIXES:
            raise InputError(f"{where}: {str(q)!r} is not a .glb/.gltf model")
        out.append(q)
    if not named:
        raise InputError(f"--objects: list {str(p)!r} names no files")
    return out


def _stderr(msg: str) -> None:
    print(msg, file=sys.stderr)


def local_ids(paths: list[Path]) -> dict[Path, str]:
    """The id of every resolved model path: its sanitized stem, or, when several paths
    share one, stem + a hash of the path for every one of them. A function of the set of
    paths alone, so listing order, shards and earlier runs cannot change it."""
    by_stem: dict[str, list[Path]] = {}
    for p in sorted(set(paths)):
        by_stem.setdefault(sanitize(p.stem), []).append(p)
    ids: dict[Path, str] = {}
    for stem, group in by_stem.items():
        for p in group:
            if len(group) == 1:
                ids[p] = stem
            else:
                ids[p] = f"{stem[:55]}_{hashlib.sha1(str(p).encode()).hexdigest()[:8]}"
    return ids


def resolve_objects(
    entries: list[str],
    *,
    cache: objaverse_cache.Cache | None = None,
    objaverse_count: int | None = None,
    seed: int = 0,
    warn=_stderr,
) -> list[ObjectSpec]:
    """ObjectSpecs of every entry, local files first, then Objaverse objects (a seeded
    subset of `objaverse_count` of them when given). Objaverse files need not be local
    yet: the build fetches each one when it gets to it."""
    paths: list[Path] = []
    refs: list[str] = []
    seen: set[Path] = set()
    for e in entries:
        for p in _expand(e, refs, warn):
            r = p.resolve()
            if r not in seen:
                seen.add(r)
                paths.append(r)
    ids = local_ids(paths)
    specs = [ObjectSpec(uid=ids[p], path=p) for p in paths]
    used = set(ids.values())
    if refs:
        cache = cache or objaverse_cache.Cache()
        uids = sorted({u for ref in refs for u in cache.uids(ref)})
        if objaverse_count is not None:
            uids = _core.seeded_subset(uids, objaverse_count, seed)
        for u in uids:
            uid = sanitize(u)
            if uid in used:
                raise InputError(f"--objects: objaverse:{u} clashes with a local file's id {uid!r}")
            used.add(uid)
            specs.append(ObjectSpec(uid=uid, path=cache.path(u), source="objaverse"))
    return specs


def setting_name(uid: str, theta0_deg: float) -> str:
    """`<uid>_<theta0>`, e.g. `chair_090` (blurset-core names it, for build and stats)."""
    return _core.setting_name(uid, theta0_deg)
