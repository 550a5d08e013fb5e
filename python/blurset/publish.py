"""What a build or a noise output may publish (issue 19): no builder paths inside, and a
checksum manifest of every file.

- Absolute paths (the input files, OUT, a cache or a Blender binary) stay on the build
  machine, in `OUT/.local/paths.jsonl`: dot-prefixed, so never in the manifest, the card
  or an upload that skips dot files. Outputs name inputs by their path relative to the
  folder or list they came from (blurset.objects) and a build by its folder's name;
  dataset.json's config record drops the paths in the core (BuildConfig.record()).
- `MANIFEST.sha256` (sha256sum format) is hashed in blurset-core, which also owns the
  rule of which files it lists (the manifest itself, the lock, dot files and dot
  folders, `*.partial` staging directories are not).
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

from blurset import _core

MANIFEST = "MANIFEST.sha256"
LOCAL_DIR = ".local"
LOCAL_PATHS = "paths.jsonl"


def log_local(out: Path, records: list[dict[str, Any]]) -> None:
    """Append records naming absolute paths to OUT/.local/paths.jsonl (call under the
    build lock): the one place a build keeps them."""
    if not records:
        return
    d = Path(out) / LOCAL_DIR
    d.mkdir(exist_ok=True)
    with open(d / LOCAL_PATHS, "a") as f:
        f.write("".join(json.dumps(r) + "\n" for r in records))
        f.flush()
        os.fsync(f.fileno())


def manifest_files(root: Path) -> list[str]:
    """The files MANIFEST.sha256 of `root` lists (relative, sorted bytewise)."""
    return _core.manifest_files(Path(root))


def write_manifest(root: Path) -> int:
    """Hash every listed file of `root` into root/MANIFEST.sha256 (atomic); the count."""
    return _core.write_manifest(Path(root))


def _manifest_root(path: Path) -> Path | None:
    """The build or noise output holding `path` that has a manifest, or None."""
    for d in Path(path).resolve().parents:
        if (d / MANIFEST).is_file() and (
            (d / "dataset.json").is_file() or (d / "noise_dataset.json").is_file()
        ):
            return d
    return None


def refresh_manifest(written: list[Path]) -> None:
    """After files were written into a build or noise output that has a manifest (a
    card, statistics, a preview), rehash just those into it, so `sha256sum -c` and
    `blurset verify` stay whole. Files outside such a tree are left alone."""
    by_root: dict[Path, list[str]] = {}
    for p in written:
        root = _manifest_root(p)
        if root is not None:
            by_root.setdefault(root, []).append(Path(p).resolve().relative_to(root).as_posix())
    for root, rels in by_root.items():
        _core.update_manifest(root, rels)


def check_manifest(root: Path) -> list[tuple[str, str]]:
    """(relative path, problem) of every file that does not match the manifest:
    `missing`, `checksum mismatch`, or `not in MANIFEST.sha256`."""
    return _core.check_manifest(Path(root))
