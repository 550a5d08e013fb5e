"""The layout of what blurset writes, in one place (DESIGN §4, §10).

Every reader and writer of a build or a noise output goes through here for: the names
of settings, level directories and gain directories; the `.complete` marker and what a
complete setting is; the `.partial` staging directories; atomic JSON writes. A setting
(or a noise unit) is complete only when its final directory (never a `*.partial` one)
holds the marker, which is written last, just before the rename that publishes it.
"""

from __future__ import annotations

import json
import os
import time
from pathlib import Path
from typing import Any

from blurset import _core
from blurset.exceptions import InputError

MARKER: str = _core.MARKER
PARTIAL_SUFFIX: str = _core.PARTIAL_SUFFIX
SHARP: str = _core.SHARP
# The files and folders of the layout (blurset-core's ground::names::files): Python
# spells them with these names only (tests/test_layout_names.py holds it to that).
META: str = _core.META
DATASET: str = _core.DATASET
SPLITS: str = _core.SPLITS
FAILURES: str = _core.FAILURES
POSES_BOUNDS: str = _core.POSES_BOUNDS
TRANSFORMS: str = _core.TRANSFORMS
NOISE: str = _core.NOISE
NOISE_DATASET: str = _core.NOISE_DATASET
NOISE_SCENE: str = _core.NOISE_SCENE
EXPORT: str = _core.EXPORT
STATS: str = _core.STATS
IMAGES: str = _core.IMAGES
LINEAR: str = _core.LINEAR
MANIFEST: str = _core.MANIFEST
# A setting's `--previews` figure (drawn from its images: a rerun draws a missing one).
PREVIEW = "preview.png"
# A build's private names: its demo objects, its lock, and per object a lock and a
# scratch folder (the core's; no other module spells them).
DEMO_OBJECTS: str = _core.DEMO_OBJECTS
BUILD_LOCK: str = _core.OutputKind.BUILD.lock_name
work_dir = _core.work_dir
object_lock = _core.object_lock
linear_name = _core.linear_name


def images_dir(factor: int) -> str:
    """The image folder at downsampling factor `factor`: `images` at 1, else `images_<f>`."""
    return _core.images_dir(factor)


def linear_dir(factor: int) -> str:
    """The linear EXR folder at downsampling factor `factor`: `linear` or `linear_<f>`."""
    return _core.linear_dir(factor)


# The per-view outputs besides colour (`--passes`): depth, normal, mask.
PASSES: tuple[str, ...] = tuple(_core.PASSES)


def pass_dir(p: str, factor: int) -> str:
    """The sharp level's folder of pass `p` at downsampling factor `factor` (`depth`,
    `normals_4`, `masks`)."""
    return _core.pass_dir(p, factor)


def nerfstudio_depth_dir(factor: int) -> str:
    """nerfstudio's depth folder in an exported scene (`depths`, `depths_4`: its parser
    reads `depths_<f>/` when it downscales)."""
    return _core.nerfstudio_depth_dir(factor)


def pass_level(p: str, level: str, level_masks: bool) -> str:
    """The level folder holding `level`'s files of pass `p`: the own masks of a level
    whose camera moves during the exposure (motion blur's, and every kind the core's
    `ImageKind.own_masks` names: the coverage of its exposure) in a setting that records them (`level_masks`, meta.json
    `render.level_masks`), everything else the sharp level's."""
    return _core.pass_level(p, level, level_masks)


def level_masks(meta: dict) -> bool:
    """Whether a setting's moving-exposure levels (blur …) hold masks of their own
    (its meta.json): false in a setting built before they had them, whose levels all take
    the sharp masks."""
    return bool((meta.get("render") or {}).get("level_masks", False))


def own_mask_levels(levels: list[str]) -> list[str]:
    """The levels of `levels` that hold masks of their own in a build made now (the blur
    levels, and every level whose camera moves during the exposure)."""
    return [lv for lv in levels if lv != SHARP and pass_level("mask", lv, True) == lv]


def pass_file(p: str, image: str) -> str:
    """The file of an image's view in pass `p`'s folder (`007.exr`; masks `007.png`)."""
    return _core.pass_file(p, image)


def setting_name(uid: str, theta0_deg: float) -> str:
    """`<uid>_<theta0>`, e.g. `chair_090`."""
    return _core.setting_name(uid, theta0_deg)


def theta0s(settings_per_object: int) -> list[float]:
    """The θ0 of each of an object's settings, evenly spaced from 0°."""
    return _core.theta0s(settings_per_object)


def image_name(view: int, n_views: int) -> str:
    """The image file of a view (`000.png` …): sorted file order is view order."""
    return _core.image_name(view, n_views)


def level_dir(level: int) -> str:
    """Directory of a blur level (`blur_<l>`); level 0 is the sharp image."""
    return _core.level_dir(level)


def level_dirs(levels: list[int]) -> list[str]:
    """`sharp` then `blur_<l>` of every blur level, in order."""
    return _core.level_dirs(levels)


def is_level_dir(name: str) -> bool:
    """`sharp`, or a level of any kind (`blur_<l>`, `defocus_<l>` …) with l in 1..64:
    what `blurset build` can write."""
    return _core.is_level_dir(name)


def level_kind(name: str) -> str | None:
    """The kind of a level directory (`sharp`, `blur`, `defocus` …: the core's
    ImageKind), or None for a name that is no level directory."""
    return _core.level_kind(name)


def level_means(name: str) -> tuple[str, str] | None:
    """What a level's kind is, as a dataset card says it: (`blur_l`, "the same views
    blurred at level l"); None for `sharp` and a name that is no level directory."""
    m = _core.level_means(name)
    return None if m is None else (m[0].replace("<l>", "l"), m[1])


def level_record(name: str) -> tuple[str, str] | None:
    """Where meta.json records a level's image in each view: (its kind's key, its level's
    key), `("levels", "2")` for `blur_2`, `("defocus", "1")` for `defocus_1`; None for
    `sharp` and for a name that is no level directory."""
    return _core.level_record(name)


def written_pose(name: str) -> bool:
    """Whether a level's images are seen from the written poses (sharp, defocus) rather
    than being means over a moving camera whose mean latent poses meta.json records."""
    return _core.written_pose(name)


def sort_level_dirs(names: list[str]) -> list[str]:
    """Level directory names in level order (sharp first, then by number)."""
    return _core.sort_level_dirs(names)


def setting_levels(setting: Path) -> list[str]:
    """The level directories a setting holds (`sharp`, `blur_1` …), in level order."""
    return _core.setting_levels(setting)


def mean_poses(setting: Path, level: str) -> list[list[list[float]]] | None:
    """The mean latent pose (OpenGL c2w rows) of every view of blur level `level`
    (`blur_<l>`) from the setting's meta.json; None for a meta.json from before mean
    poses. InputError naming the file when it lacks the level or a pose is not finite."""
    number = _core.parse_level_dir(level)
    if number is None:
        raise ValueError(f"{level!r} is not a level directory (sharp or blur_<l>)")
    return _core.read_mean_poses(Path(setting) / "meta.json", number)


def gain_name(g: float) -> str:
    """Directory name of a noise gain: gain_4, gain_2.5."""
    return _core.gain_name(g)


def partial_dir(final: Path) -> Path:
    """Where a setting or noise unit is written before it is published."""
    return Path(_core.partial_dir(final))


def is_complete(d: Path) -> bool:
    """A finished setting or noise unit: a final (not `*.partial`) directory with its marker."""
    return _core.is_complete(d)


def complete_settings(build: Path) -> list[Path]:
    """The complete setting directories of a build, sorted by name."""
    return [Path(build) / n for n in _core.complete_settings(build)]


def publish(partial: Path, final: Path) -> None:
    """Write the marker into `partial` and rename it to `final` (replacing an old one).
    What the old one holds that a build does not write (a user's note) is kept: moved
    into the new one at the same place, and named on stderr."""
    import sys

    partial, final = Path(partial), Path(final)
    for rel in not_written_by_build(final):
        dst = partial / rel
        if dst.exists() or dst.is_symlink():
            continue  # (the new setting wrote that name: cannot happen for a foreign one)
        dst.parent.mkdir(parents=True, exist_ok=True)
        os.replace(final / rel, dst)
        print(
            f"blurset: kept {final.name}/{rel} (not written by blurset) in the redone "
            f"setting: {final / rel}",
            file=sys.stderr,
        )
    _core.publish(partial, final, time.strftime("%Y-%m-%dT%H:%M:%S"))


def replace_dir(new: Path, dst: Path) -> None:
    """Put the folder `new` at `dst`, replacing what is there (the core's one rule: the
    old entry renamed aside, the new one renamed in, then the old one removed)."""
    _core.replace_dir(new, dst)


def not_written_by_build(setting: Path) -> list[str]:
    """The entries (relative paths) of a setting folder that no build writes: anything
    but meta.json, transforms.json, the marker, preview.png, the level folders with
    their images/, linear/ and pass folders (depth/, normals/, masks/), each also at a
    factor (images_<f>/), of image files, poses_bounds.npy and transforms.json, and a
    killed writer's temp names (the core's rule of what a manifest lists in a setting)."""
    setting = Path(setting)
    if setting.is_symlink() or not setting.is_dir():
        return []
    found: list[str] = []
    for p in sorted(setting.iterdir()):
        if p.name in (META, TRANSFORMS, MARKER, PREVIEW) and not p.is_dir():
            continue
        if _core.parse_temp_name(p.name) is not None:
            continue
        if not (is_level_dir(p.name) and p.is_dir() and not p.is_symlink()):
            found.append(p.name)
            continue
        for q in sorted(p.iterdir()):
            rel = f"{p.name}/{q.name}"
            if q.name in (POSES_BOUNDS, TRANSFORMS) and not q.is_dir():
                continue
            if _core.parse_temp_name(q.name) is not None:
                continue
            if not (_core.is_image_folder(q.name) and q.is_dir() and not q.is_symlink()):
                found.append(rel)
                continue
            for r in sorted(q.iterdir()):
                ok = r.suffix.lower() in (".png", ".exr") and r.is_file()
                if not ok and _core.parse_temp_name(r.name) is None:
                    found.append(f"{rel}/{r.name}")
    return found


def temp_path(path: Path) -> Path:
    """The temp name of an atomic write of `path` (dot-prefixed, per process)."""
    return Path(_core.temp_path(path))


def setting_problem(setting: Path) -> str | None:
    """What is missing or damaged in a complete setting, checked cheaply (names, sizes,
    headers; `blurset verify` decodes everything): None when it looks whole. A rerun
    redoes a setting with a problem instead of counting it."""
    return _core.setting_problem(setting)


def setting_problems(setting: Path) -> list[tuple[str, _core.SettingFault, str]]:
    """Every problem the check of setting_problem finds (it reports the first): (path
    relative to the setting, its kind, what is wrong in words); `blurset verify` lists
    them all."""
    return _core.setting_problems(setting)


def png_problem(path: Path) -> str | None:
    """What is wrong with a PNG read without decoding (its signature, its end chunk), or
    None: the image rule of setting_problems."""
    return _core.png_problem(path)


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def remove_stale_temps(folder: Path, names: list[str]) -> list[Path]:
    """Remove the temp files or folders (`.<name>.tmp<pid>`) of these names whose process
    is gone (a killed run's); a live process's and anything else are left alone."""
    import shutil

    removed: list[Path] = []
    if not folder.is_dir():
        return removed
    for p in folder.iterdir():
        parsed = _core.parse_temp_name(p.name)
        if parsed is None or parsed[0] not in names or _pid_alive(parsed[1]):
            continue
        if p.is_dir() and not p.is_symlink():
            shutil.rmtree(p, ignore_errors=True)
        else:
            p.unlink(missing_ok=True)
        removed.append(p)
    return removed


def write_bytes_atomic(path: Path, data: bytes) -> None:
    """Write `data` to `path` through a synced temp file and a rename, so readers see the
    old file or the new one, never a torn one, even after a crash."""
    _core.write_atomic(path, data)


def write_text_atomic(path: Path, text: str) -> None:
    """`write_bytes_atomic` of UTF-8 text."""
    write_bytes_atomic(path, text.encode("utf-8"))


def write_figure(path: Path, save) -> None:
    """An image made by `save(file_object)` (PIL, matplotlib), written atomically."""
    import io

    buf = io.BytesIO()
    save(buf)
    write_bytes_atomic(path, buf.getvalue())


def write_json(path: Path, data: Any, *, indent: int = 1) -> None:
    """JSON (no NaN/inf) written atomically."""
    write_text_atomic(path, json.dumps(data, indent=indent, allow_nan=False) + "\n")


def read_json(path: Path, what: str | None = None) -> Any:
    """JSON of a file blurset wrote; InputError names the file when it is missing or bad."""
    what = what or path.name
    try:
        return json.loads(path.read_text())
    except FileNotFoundError:
        raise InputError(f"{what} not found: {path}") from None
    except (OSError, ValueError) as e:
        raise InputError(f"{what} is not readable JSON ({e}): {path}") from None
