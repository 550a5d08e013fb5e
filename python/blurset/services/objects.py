"""Resolve `--objects` into GLB files with safe, unique ids.

An entry is a model (`.glb`, or `.gltf` with its external files), a folder (every
model under it, sorted), an Objaverse reference (`objaverse:<uid>`,
`objaverse:lvis=<category>[+<category>…]`, `objaverse:all`; see
`blurset.services.objaverse_cache`), or a list file (`.txt`/`.lst`, or any file as `@FILE`)
naming one such entry per line (`#` comments; relative paths are relative to the list). Output directories are named from
sanitized ids, never from file contents (DESIGN §10).
"""

from __future__ import annotations

import hashlib
import os
import re
import sys
from dataclasses import dataclass
from pathlib import Path

from blurset import _core
from blurset.exceptions import InputError
from blurset.services import objaverse_cache

_UNSAFE = re.compile(r"[^A-Za-z0-9_-]+")


@dataclass(frozen=True)
class ObjectSpec:
    uid: str
    path: Path
    # "file", or "objaverse" for an object fetched into the objaverse cache on demand.
    source: str = "file"
    # The path relative to the root it was found in (the folder or list naming it; a
    # file given itself: its name), or `objaverse:<uid>`: what a build publishes instead
    # of the builder's absolute path (issue 19).
    rel: str = ""


def sanitize(stem: str) -> str:
    # No leading '-' or '.': an id names folders that users pass to commands (a `-x_000`
    # reads as an option) and that must not be hidden.
    uid = _UNSAFE.sub("_", stem).strip("_").lstrip("-.")[:64]
    return uid or "object"


MODEL_SUFFIXES = (".glb", ".gltf")
LIST_SUFFIXES = (".txt", ".lst")


def _models_in(folder: Path, warn) -> list[tuple[Path, str]]:
    """The .glb/.gltf files under a folder (its subfolders too: a .gltf usually sits in
    its own folder with its textures), sorted; hidden folders are not entered. Dangling
    symlinks are named, not silently dropped."""
    found: list[tuple[Path, str]] = []
    dangling: list[Path] = []
    for p in sorted(folder.rglob("*")):
        rel = p.relative_to(folder)
        if any(part.startswith(".") for part in rel.parts):
            continue
        if p.suffix.lower() not in MODEL_SUFFIXES:
            continue
        if p.is_file():
            found.append((p, rel.as_posix()))
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


def _expand(entry: str, refs: list[str], warn) -> list[tuple[Path, str]]:
    """(path, path relative to its root) of the models of one entry; objaverse
    references go to `refs` instead."""
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
        return [(p, p.name)]
    return _read_list(p, refs, warn)


def _relative_to_list(q: Path, root: Path, fallback: str | None = None) -> str:
    """A list line's model relative to the list's folder; when it lies elsewhere, the
    fallback (its path in a listed folder) or its name (never `..` or an absolute path)."""
    norm = Path(os.path.normpath(q))
    try:
        return norm.relative_to(os.path.normpath(root)).as_posix()
    except ValueError:
        return fallback or norm.name


def _read_list(p: Path, refs: list[str], warn) -> list[tuple[Path, str]]:
    """A list file: one entry per line (a model, a folder of models, an objaverse
    reference), `#` comments; relative paths are relative to the list's folder."""
    try:
        # utf-8-sig: a byte-order mark (Windows editors write one) is not part of line 1.
        lines = p.read_text(encoding="utf-8-sig").splitlines()
    except UnicodeDecodeError:
        raise InputError(f"--objects: list {str(p)!r} is not UTF-8 text") from None
    except IsADirectoryError:
        raise InputError(f"--objects: @{str(p)!r} is a folder, not a list file") from None
    out: list[tuple[Path, str]] = []
    named = 0
    for n, line in enumerate(lines, 1):
        line = line.strip()
        if not line or line.startswith("#"):
            continue
        # A comment after an entry starts with whitespace and '#': `a#b.glb` is a name.
        if not (p.parent / line).exists():
            line = re.split(r"\s#", line, maxsplit=1)[0].strip()
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
            out.extend((m, _relative_to_list(m, p.parent, rel)) for m, rel in found)
            continue
        if not q.is_file():
            what = "dangling symlink" if q.is_symlink() else "no such file"
            raise InputError(f"{where}: {what} {str(q)!r}")
        if q.suffix.lower() not in MODEL_SUFFIXES:
            raise InputError(f"{where}: {str(q)!r} is not a .glb/.gltf model")
        out.append((q, _relative_to_list(q, p.parent)))
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
    rels: dict[Path, str] = {}
    refs: list[str] = []
    for e in entries:
        for p, rel in _expand(e, refs, warn):
            r = p.resolve()
            if r not in rels:
                rels[r] = rel
                paths.append(r)
    ids = local_ids(paths)
    specs = [ObjectSpec(uid=ids[p], path=p, rel=rels[p]) for p in paths]
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
            specs.append(
                ObjectSpec(uid=uid, path=cache.path(u), source="objaverse", rel=f"objaverse:{u}")
            )
    return specs


def setting_name(uid: str, theta0_deg: float) -> str:
    """`<uid>_<theta0>`, e.g. `chair_090` (blurset-core names it, for build and stats)."""
    return _core.setting_name(uid, theta0_deg)
