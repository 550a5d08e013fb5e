"""Resolve `--objects` into GLB files with safe, unique ids.

An entry is a GLB file, a folder (its `*.glb`, sorted), an Objaverse reference
(`objaverse:<uid>`, `objaverse:lvis=<category>[+<category>…]`, `objaverse:all`; see
`blurset.objaverse_cache`), or a text file listing one such entry per line (`#`
comments; relative paths are relative to the list). Output directories are named from
sanitized ids, never from file contents (DESIGN §10).
"""

from __future__ import annotations

import hashlib
import re
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


def _expand(entry: str, refs: list[str]) -> list[Path]:
    """GLB paths of one entry; objaverse references go to `refs` instead."""
    if objaverse_cache.is_entry(entry):
        refs.append(entry)
        return []
    p = Path(entry).expanduser()
    if p.is_dir():
        found = sorted(q for q in p.iterdir() if q.suffix.lower() == ".glb" and q.is_file())
        if not found:
            raise InputError(f"--objects: no .glb files in folder {str(p)!r}")
        return found
    if not p.exists():
        raise InputError(f"--objects: no such file or folder {str(p)!r}")
    if p.suffix.lower() in (".glb", ".gltf"):
        return [p]
    # A list file: one entry per line.
    try:
        lines = p.read_text().splitlines()
    except UnicodeDecodeError:
        raise InputError(f"--objects: {str(p)!r} is neither a .glb nor a text list") from None
    out = []
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
        if not q.is_file():
            raise InputError(f"--objects: {str(p)!r} line {n}: no such file {str(q)!r}")
        out.append(q)
    if not named:
        raise InputError(f"--objects: list {str(p)!r} names no files")
    return out


def resolve_objects(
    entries: list[str],
    *,
    cache: objaverse_cache.Cache | None = None,
    objaverse_count: int | None = None,
    seed: int = 0,
) -> list[ObjectSpec]:
    """ObjectSpecs of every entry, local files first, then Objaverse objects (a seeded
    subset of `objaverse_count` of them when given). Objaverse files need not be local
    yet: the build fetches each one when it gets to it."""
    paths: list[Path] = []
    refs: list[str] = []
    seen: set[Path] = set()
    for e in entries:
        for p in _expand(e, refs):
            r = p.resolve()
            if r not in seen:
                seen.add(r)
                paths.append(r)
    specs, used = [], set()
    for p in paths:
        uid = sanitize(p.stem)
        if uid in used:
            uid = f"{uid[:55]}_{hashlib.sha1(str(p).encode()).hexdigest()[:8]}"
        used.add(uid)
        specs.append(ObjectSpec(uid=uid, path=p))
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
