"""What a build or a noise output may publish (issue 19): no builder paths inside, and a
checksum manifest of every file.

- Absolute paths (the input files, OUT, a cache or a Blender binary) stay on the build
  machine, in the user's state directory (`local_paths_file`), never under OUT: an
  upload takes dot folders too. Outputs name inputs by their path relative to the
  folder or list they came from (blurset.services.objects) and a build by its folder's name;
  dataset.json's config record drops the paths in the core (BuildConfig.record()).
- `MANIFEST.sha256` (sha256sum format) is hashed in blurset-core, which also owns the
  rule of which files it lists (the manifest itself, the lock, dot files and dot
  folders, `*.partial` staging directories are not).
"""

from __future__ import annotations

import contextlib
import json
import os
from collections.abc import Collection
from pathlib import Path
from typing import Any

from blurset import _core

MANIFEST = _core.MANIFEST
# Where builds of older blurset versions kept their absolute paths, under OUT.
LEGACY_LOCAL_DIR = ".local"
LOCAL_PATHS = "paths.jsonl"


def state_dir() -> Path:
    """blurset's state on this machine (never under an output): $BLURSET_STATE_DIR, or
    $XDG_STATE_HOME/blurset, or ~/.local/state/blurset."""
    if os.environ.get("BLURSET_STATE_DIR"):
        return Path(os.environ["BLURSET_STATE_DIR"])
    base = os.environ.get("XDG_STATE_HOME") or str(Path.home() / ".local" / "state")
    return Path(base) / "blurset"


def local_paths_file(out: Path) -> Path:
    """Where the absolute paths of the build at `out` are kept: the user's state
    directory, keyed by the build folder's name and its absolute path's hash."""
    import hashlib

    real = Path(out).resolve()
    key = hashlib.sha256(str(real).encode()).hexdigest()[:16]
    return state_dir() / "builds" / f"{real.name}-{key}" / LOCAL_PATHS


def log_local(out: Path, records: list[dict[str, Any]]) -> None:
    """Append records naming absolute paths to the build's local paths file (call under
    the build lock): the one place a build keeps them, outside OUT, so no upload of the
    build can take them."""
    if not records:
        return
    path = local_paths_file(out)
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "a") as f:
        f.write("".join(json.dumps(r) + "\n" for r in records))
        f.flush()
        os.fsync(f.fileno())


def move_local_paths(out: Path) -> None:
    """A build made by an older blurset kept them in OUT/.local/paths.jsonl: move them to
    the state directory (call under the build lock)."""
    old = Path(out) / LEGACY_LOCAL_DIR / LOCAL_PATHS
    if not old.is_file():
        return
    text = old.read_text()
    path = local_paths_file(out)
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "a") as f:
        f.write(text if text.endswith("\n") or not text else text + "\n")
        f.flush()
        os.fsync(f.fileno())
    old.unlink()
    with contextlib.suppress(OSError):
        old.parent.rmdir()


def manifest_files(root: Path) -> list[str]:
    """The files MANIFEST.sha256 of `root` lists (relative, sorted bytewise)."""
    return _core.manifest_files(Path(root))


def write_manifest(root: Path) -> int:
    """Hash every listed file of `root` into root/MANIFEST.sha256 (atomic); the count."""
    return _core.write_manifest(Path(root))


def rewrite_manifest(root: Path, vouched: list[str], *, keep_old: bool = True) -> int:
    """root/MANIFEST.sha256 at the end of a run: the files and folders (relative to
    `root`) it vouches for, because it wrote them or checked them before reusing them,
    are hashed; with `keep_old`, every other file the existing manifest lists keeps its
    line (damage since stays a mismatch for `verify`). Nothing else is listed: a file
    nobody wrote or checked (a user's note in OUT) is never certified. The count listed."""
    return _core.rewrite_manifest(Path(root), list(vouched), keep_old)


def manifest_problem(root: Path, folder: str, skip: Collection[str] = ()) -> str | None:
    """Why the folder `folder` of `root` (a setting, a noise unit's gain) is not what
    root/MANIFEST.sha256 certifies: its first file that is gone or holds other bytes, in
    words; None when it matches (or there is no manifest). A rerun redoes such a folder
    rather than certify what it did not write. `skip`: files of the folder (relative to
    it) the rerun remakes from the rest, whose state is no reason to redo it."""
    left = {f"{folder}/{s}" for s in skip}
    found = [f for f in _core.manifest_mismatches(Path(root), folder) if f[0] not in left]
    if not found:
        return None
    rel, _, what = found[0]
    more = f" (and {len(found) - 1} more)" if len(found) > 1 else ""
    inside = rel[len(folder) + 1 :] if rel.startswith(folder + "/") else rel
    return f"{inside}: {what} against {MANIFEST}{more}"


def _manifest_root(path: Path) -> Path | None:
    """The build or noise output holding `path` that has a manifest, or None."""
    from blurset.services import outputs

    for d in Path(path).resolve().parents:
        if (d / MANIFEST).is_file() and outputs.kind_of(d) in (
            outputs.OutputKind.BUILD,
            outputs.OutputKind.NOISE,
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


def check_manifest(root: Path) -> list[tuple[str, _core.ManifestFault, str]]:
    """(relative path, kind, what is wrong) of every file that does not match the
    manifest: kinds `missing`, `mismatch` (checksum mismatch), `unlisted` (not in
    MANIFEST.sha256)."""
    return _core.check_manifest(Path(root))
