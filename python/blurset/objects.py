"""Resolve `--objects` into GLB files with safe, unique ids.

An entry is a GLB file, a folder (its `*.glb`, sorted), or a text file listing one
path per line (`#` comments; relative paths are relative to the list). Output
directories are named from sanitized ids, never from file contents (DESIGN §10).
"""

from __future__ import annotations

import hashlib
import re
from dataclasses import dataclass
from pathlib import Path

from blurset.exceptions import InputError

_UNSAFE = re.compile(r"[^A-Za-z0-9_-]+")


@dataclass(frozen=True)
class ObjectSpec:
    uid: str
    path: Path


def sanitize(stem: str) -> str:
    uid = _UNSAFE.sub("_", stem).strip("_")[:64]
    return uid or "object"


def _expand(entry: str) -> list[Path]:
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
    # A list file: one path per line.
    try:
        lines = p.read_text().splitlines()
    except UnicodeDecodeError:
        raise InputError(f"--objects: {str(p)!r} is neither a .glb nor a text list") from None
    out = []
    for n, line in enumerate(lines, 1):
        line = line.split("#", 1)[0].strip()
        if not line:
            continue
        q = Path(line).expanduser()
        q = q if q.is_absolute() else p.parent / q
        if not q.is_file():
            raise InputError(f"--objects: {str(p)!r} line {n}: no such file {str(q)!r}")
        out.append(q)
    if not out:
        raise InputError(f"--objects: list {str(p)!r} names no files")
    return out


def resolve_objects(entries: list[str]) -> list[ObjectSpec]:
    paths: list[Path] = []
    seen: set[Path] = set()
    for e in entries:
        for p in _expand(e):
            r = p.resolve()
            if r not in seen:
                seen.add(r)
                paths.append(p)
    specs, used = [], set()
    for p in paths:
        uid = sanitize(p.stem)
        if uid in used:
            uid = f"{uid[:55]}_{hashlib.sha1(str(p.resolve()).encode()).hexdigest()[:8]}"
        used.add(uid)
        specs.append(ObjectSpec(uid=uid, path=p))
    return specs


def setting_name(uid: str, theta0_deg: float) -> str:
    """`<uid>_<theta0>`, e.g. `chair_090`."""
    return f"{uid}_{round(theta0_deg):03d}"
