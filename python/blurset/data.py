"""A build's scenes as NumPy arrays, for training code (issue 13; no framework needed).

    from blurset.data import open_scene
    s = open_scene("OUT", "chair_090", "blur_4", downsample=4)
    s.images[s.train_views]   # blurry sources, (n, H, W, 3) float32 in [0, 1] (sRGB)
    s.clean[s.train_views]    # their sharp versions: the restoration head's supervision
    s.images[s.test_views]    # the targets: sharp (Deblur-NeRF's convention)
    s.c2w_opencv, s.intrinsics, s.near, s.far
    s.depth, s.normals, s.masks  # with `build --passes`, else None

The same scene comes from a `blurset export --for hub` folder (`open_scene("HUB", …)`),
or from the rows of a `datasets` split, streaming or not (`open_scene(rows, setting,
level, sharp_rows=sharp)`): the same arrays as from the build's folders.

With `gain=` and `noise=` (a `blurset noise BUILD` output) the degraded images are that
gain's noisy copies of the level (drawn at the size read). `clean` is always the sharp
level at the same size: the undegraded truth of every degradation.

Which pose a blurry image gets (`pose=`):

- `"written"` (default): the pose p of the level's `poses_bounds.npy` (LLFF columns down,
  right, backwards), exactly as the LLFF loaders read it. It is the sharp image's pose;
  under `--trajectory start` (the paper's default) a blurry image's exposure starts there,
  so what the image shows is centred half its blur away from it.
- `"mean"`: the mean latent pose of each blurry image, from meta.json
  (`views[i].levels[l].mean_pose`): the mean of the poses its latent frames were rendered
  from, which is what its content is centred on and what structure from motion recovers.
  Views whose blur-level image is the sharp copy (held-out views, Deblur-NeRF's
  convention) keep p, where that image was rendered; so does every view of `sharp`.

`near` and `far` are those of `poses_bounds.npy` under either choice.
"""

from __future__ import annotations

import io
import json
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from blurset import _core, layout
from blurset.exceptions import ImageError, InputError, reason_of

__all__ = ["Scene", "open_scene", "list_scenes", "POSES"]

#: What `open_scene(pose=…)` accepts: the written pose p, or the mean latent pose.
POSES = ("written", "mean")


@dataclass(frozen=True)
class Scene:
    """One (setting, level[, gain]) of a build at one size (see `open_scene`)."""

    setting: str
    level: str
    gain: float | None
    downsample: int
    #: Degraded images (N, H, W, 3) float32 in [0, 1], sRGB as stored, view order.
    images: np.ndarray
    #: The sharp images of the same views and size.
    clean: np.ndarray
    image_files: list[Path]
    clean_files: list[Path]
    #: Camera to world, OpenCV axes (x right, y down, z forward), (N, 4, 4) float64:
    #: the written or the mean latent pose, as `pose` says.
    c2w_opencv: np.ndarray
    #: The same in OpenGL axes (x right, y up, z backwards); for `pose="written"` the
    #: matrices of transforms.json.
    c2w_opengl: np.ndarray
    #: Pinhole intrinsics at this size (focal / downsample, principal point centred).
    intrinsics: np.ndarray
    near: np.ndarray
    far: np.ndarray
    train_views: np.ndarray
    test_views: np.ndarray
    #: The gain's noise.json (sigmas, white balance, seed), or None.
    noise: dict | None = None
    #: Which pose the cameras are: "written" (poses_bounds.npy) or "mean" (meta.json).
    pose: str = "written"
    #: With `--passes` (else None), per view at this size, of the sharp image at the
    #: written pose p: depth (N, H, W) float32 along the viewing axis in world units (0:
    #: no surface), normals (N, H, W, 3) float32 in the world frame, masks (N, H, W) bool
    #: (a blur level's: the pixels its exposure covered, the sharp mask's included).
    depth: np.ndarray | None = None
    normals: np.ndarray | None = None
    masks: np.ndarray | None = None

    @property
    def size(self) -> tuple[int, int]:
        """(height, width) of the images."""
        return int(self.images.shape[1]), int(self.images.shape[2])


def _subdir(downsample: int) -> str:
    return layout.images_dir(downsample)


def _decoded(p: Path, size: tuple[int, int]) -> np.ndarray:
    """The image file `p`, refused from its header, before it is decoded, unless it is
    `size` (width, height): the scene's size, not the size a file claims, bounds memory."""
    w, h = _core.image_info(p)[:2]
    if (w, h) != size:
        raise InputError(f"image is {w}x{h} px, the scene's are {size[0]}x{size[1]}: {p}")
    return _core.read_image(p)


def _read(files: list[Path], shape: tuple[int, int]) -> np.ndarray:
    """The images, as floats in [0, 1], decoded one at a time into the one array returned
    (no full-size copy); InputError naming the first that is not `shape` (h × w)."""
    h, w = shape
    out = np.empty((len(files), h, w, 3), np.float32)
    for i, p in enumerate(files):
        out[i] = _decoded(p, (w, h))[..., :3]
    return np.divide(out, 255.0, out=out)


def _cameras(rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """OpenCV and OpenGL camera-to-world matrices of LLFF pose rows."""
    m = rows[:, :15].reshape(-1, 3, 5)
    down, right, back, t = m[:, :, 0], m[:, :, 1], m[:, :, 2], m[:, :, 3]
    gl = np.tile(np.eye(4), (len(rows), 1, 1))
    cv = gl.copy()
    gl[:, :3, 0], gl[:, :3, 1], gl[:, :3, 2], gl[:, :3, 3] = right, -down, back, t
    cv[:, :3, 0], cv[:, :3, 1], cv[:, :3, 2], cv[:, :3, 3] = right, down, -back, t
    return cv, gl


def _mean_cameras(sdir: Path, level: str, n: int) -> tuple[np.ndarray, np.ndarray]:
    """OpenCV and OpenGL camera-to-world matrices of the mean latent poses of a level."""
    poses = layout.mean_poses(sdir, level)
    if poses is None:
        raise InputError(
            "meta.json records no mean latent poses (a build from before them): "
            f"use pose='written': {sdir / layout.META}"
        )
    gl = np.asarray(poses, dtype=np.float64)
    if len(gl) != n:
        raise InputError(f"{len(gl)} views in meta.json but {n} poses: {sdir / layout.META}")
    # OpenGL (right, up, backwards) → OpenCV (right, down, forward).
    return gl * np.array([1.0, -1.0, -1.0, 1.0]), gl


def _downsample(d: Any) -> int:
    """`open_scene`'s downsample as a factor: None is the full size, as 1."""
    if d is None:
        return 1
    if isinstance(d, bool) or not isinstance(d, int | np.integer) or d < 1:
        raise ValueError(
            f"downsample must be a whole factor of 1 or more (images_<f>/; None or 1 for "
            f"the full size), got {d!r}"
        )
    return int(d)


def open_scene(
    build: str | Path,
    setting: str,
    level: str = layout.SHARP,
    gain: float | None = None,
    *,
    noise: str | Path | None = None,
    downsample: int | None = 1,
    pose: str = "written",
    sharp_rows: Iterable[Mapping[str, Any]] | None = None,
) -> Scene:
    """Read one scene of a build: `level` (`sharp`, `blur_<l>`) of `setting`, or with
    `gain` the noisy copy of it in `noise` (a `blurset noise BUILD` output), at full
    size (`downsample` 1 or None) or from `images_<downsample>/`.

    `build` may also be a `blurset export --for hub` folder (the same scene from its
    Parquet shards: `noise` is not needed, the gain's config is in it), or the rows of
    the level's config (a `datasets` split, streaming or not: `load_dataset(...,
    "blur_4", split="train", streaming=True)`), read until the setting's rows end; the
    clean images then come from `sharp_rows` (the `sharp` config's rows), needed unless
    `level` is `sharp`. Either gives the arrays the build's folders give.

    `pose` picks the cameras of a blur level: `"written"` (default) the pose p in
    `poses_bounds.npy`, as the LLFF loaders read it; `"mean"` each blurry image's mean
    latent pose from meta.json (`views[i].levels[l].mean_pose`), what its content is
    centred on (held-out views holding the sharp copy keep p). For `sharp` both are p.
    Raises InputError naming a missing file, or a meta.json from before mean poses."""
    if pose not in POSES:
        raise ValueError(f"pose must be one of {', '.join(map(repr, POSES))}, got {pose!r}")
    downsample = _downsample(downsample)
    if not isinstance(build, str | Path):
        # Rows: a `datasets` split (streaming or not) of the level's config.
        return _scene_from_rows(build, setting, level, gain, sharp_rows, downsample, pose)
    build = Path(build)
    from blurset.services import hub_format

    if hub_format.hub_doc(build) is not None:
        # A `blurset export --for hub` folder: only the setting's row group of its shard.
        config = hub_format.config_name(level, None if gain is None else layout.gain_name(gain))
        found = hub_format.iter_rows(build, config, setting)
        sharp = hub_format.iter_rows(build, layout.SHARP, setting)
        return _scene_from_rows(found, setting, level, gain, sharp, downsample, pose)
    return _scene_from_folders(build, setting, level, gain, noise, downsample, pose)


def _scene_from_folders(
    build: Path,
    setting: str,
    level: str,
    gain: float | None,
    noise: str | Path | None,
    downsample: int,
    pose: str,
) -> Scene:
    """open_scene of a build's folders (or, with `gain`, of `noise`'s)."""
    sdir = build / setting
    if not layout.is_complete(sdir):
        raise InputError(f"no complete setting {setting!r} in the build: {sdir}")
    if not (sdir / level).is_dir():
        raise InputError(f"setting {setting!r} has no level {level!r}: {sdir / level}")
    sub = _subdir(downsample)
    n = len(np.asarray(_core.read_poses_bounds(sdir / level / layout.POSES_BOUNDS)))
    scene_dir, names, meta = _scene_dir(sdir, setting, level, n, gain, noise)
    image_files = [scene_dir / sub / name for name in names]
    clean_files = [sdir / layout.SHARP / sub / layout.image_name(i, n) for i in range(n)]
    for p in (*image_files, *clean_files):
        if not p.is_file():
            raise InputError(f"image not found (downsample {downsample}?): {p}")
    rows = np.asarray(_core.read_poses_bounds(scene_dir / layout.POSES_BOUNDS), np.float64)
    rows = rows[:: len(rows) // n] if len(rows) != n else rows
    cv, gl = _cameras(rows)
    if pose == "mean" and not layout.written_pose(level):
        cv, gl = _mean_cameras(sdir, level, n)
    # The size its poses record (hwf: the full size), not what a file's header claims.
    h, w = int(rows[0, 4]) // downsample, int(rows[0, 9]) // downsample
    images = _read(image_files, (h, w))
    clean = _read(clean_files, (h, w))
    # hwf holds the full size (LLFF); the focal length scales with the size read.
    focal = rows[0, 14] * w / rows[0, 9]
    k = np.array([[focal, 0, w / 2], [0, focal, h / 2], [0, 0, 1]], dtype=np.float64)
    held = _held_out(build, setting)
    test = np.array(sorted(held), dtype=np.int64)
    train = np.array([i for i in range(n) if i not in set(held)], dtype=np.int64)
    return Scene(
        setting=setting,
        level=level,
        gain=gain,
        downsample=downsample,
        images=images,
        clean=clean,
        image_files=image_files,
        clean_files=clean_files,
        c2w_opencv=cv,
        c2w_opengl=gl,
        intrinsics=k,
        near=rows[:, 15].copy(),
        far=rows[:, 16].copy(),
        train_views=train,
        test_views=test,
        noise=meta,
        pose=pose,
        **_passes(sdir, level, n, downsample, (w, h)),
    )


def _passes(
    sdir: Path, level: str, n: int, downsample: int, size: tuple[int, int]
) -> dict[str, np.ndarray]:
    """The `--passes` files of `level` at one size, as Scene's fields (none without): the
    sharp level's, but a blur level's own masks (`layout.pass_level`). An EXR that is
    not the images' `size` (width, height) is refused from its header, never decoded."""
    meta = layout.read_json(sdir / layout.META, layout.META)
    kinds = (meta.get("render") or {}).get("passes") or []
    names = [layout.image_name(i, n) for i in range(n)]

    def files(kind: str) -> list[Path]:
        holder = layout.pass_level(kind, level, layout.level_masks(meta))
        d = sdir / holder / layout.pass_dir(kind, downsample)
        out = [d / layout.pass_file(kind, name) for name in names]
        for p in out:
            if not p.is_file():
                raise InputError(f"{kind} file not found (downsample {downsample}?): {p}")
        return out

    out: dict[str, np.ndarray] = {}
    if "depth" in kinds:
        out["depth"] = np.stack([_core.read_depth(p, size=size) for p in files("depth")])
    if "normal" in kinds:
        out["normals"] = np.stack([_core.read_exr(p, size=size)[..., :3] for p in files("normal")])
    if "mask" in kinds:
        out["masks"] = np.stack([_decoded(p, size)[..., 0] > 0 for p in files("mask")])
    return out


def _scene_dir(
    sdir: Path, setting: str, level: str, n: int, gain: float | None, noise: str | Path | None
) -> tuple[Path, list[str], dict | None]:
    """The folder a scene's images are read from (the level, or its noisy copy of
    `gain`), their file names, one per view, and the copy's noise.json (None for the
    level itself)."""
    if gain is None:
        return sdir / level, [layout.image_name(i, n) for i in range(n)], None
    if noise is None:
        raise InputError("gain needs noise= (a `blurset noise BUILD` output folder)")
    scene_dir = Path(noise) / setting / level / layout.gain_name(gain)
    if not layout.is_complete(scene_dir):
        raise InputError(f"no complete noisy scene of gain {gain:g}: {scene_dir}")
    meta = layout.read_json(scene_dir / layout.NOISE, layout.NOISE)
    # One file per view: frame 0 of a burst.
    by_view = {f["view"]: Path(f["image"]).name for f in meta["files"] if f["frame"] == 0}
    return scene_dir, [by_view[i] for i in range(n)], meta


def _held_out(build: Path, setting: str) -> list[int]:
    """A setting's held-out views: the build's splits.json, else its own meta.json."""
    splits = build / layout.SPLITS
    held = None
    if splits.is_file():
        held = layout.read_json(splits, layout.SPLITS).get("test_views", {}).get(setting)
    if held is None:
        held = layout.read_json(build / setting / layout.META, layout.META).get("test_views", [])
    return held


def list_scenes(build: str | Path) -> list[tuple[str, str]]:
    """(setting, level) of every complete setting of a build, in order; of a `blurset
    export --for hub` folder, every setting and level its shards hold."""
    from blurset.services import hub_format

    doc = hub_format.hub_doc(Path(build))
    if doc is not None:
        held = {(s, r["config"]) for r in (doc.get("shards") or {}).values() for s in r["settings"]}
        return [(s, lvl) for s in sorted({s for s, _ in held}) for lvl in doc["levels"]
                if (s, lvl) in held]  # fmt: skip
    return [
        (s.name, lvl)
        for s in layout.complete_settings(Path(build))
        for lvl in layout.setting_levels(s)
    ]


# -- a scene from Parquet shards (`blurset export --for hub`) ------------------------------


def _setting_rows(rows: Iterable[Mapping[str, Any]], setting: str) -> list[Mapping[str, Any]]:
    """The rows of one setting, in view order: a shard holds a setting's rows together, so
    reading stops where they end (a stream is not read to its end)."""
    out: list[Mapping[str, Any]] = []
    for r in rows:
        if r["setting"] == setting:
            out.append(r)
        elif out:
            break
    return sorted(out, key=lambda r: int(r["view"]))


def _decode_png(value: Any, what: str) -> np.ndarray:
    """An image cell: {bytes, path} (pyarrow, or `datasets` with decode=False) or a PIL
    image (`datasets` decoding), as the uint8 array the build's file decodes to."""
    if isinstance(value, Mapping):
        data = value.get("bytes")
        if not data:
            raise InputError(f"a row's {what} has no bytes")
        from PIL import Image

        with Image.open(io.BytesIO(data)) as im:
            a = np.asarray(im)
    else:
        a = np.asarray(value)
    return a[..., None] if a.ndim == 2 else a


def _cell(read: Any, row: Mapping[str, Any], name: str) -> np.ndarray:
    """One pass cell of a row decoded; a cell that does not is named by its setting, view
    and column (its bytes went through a temp file, whose name would say nothing)."""
    try:
        return read(row[name])
    except ImageError as e:
        raise InputError(
            f"the {name} cell of {row.get('setting')} view {row.get('view')} does not "
            f"decode: {reason_of(e)}"
        ) from None


def _decode_with(reader: Any, data: bytes, suffix: str, size: tuple[int, int]) -> np.ndarray:
    """A pass file's bytes decoded by the core's reader of that file (through a temp
    file: the readers take paths), refused from its header unless it is `size`."""
    import tempfile

    with tempfile.NamedTemporaryFile(suffix=suffix) as f:
        f.write(data)
        f.flush()
        return np.asarray(reader(f.name, size=size))


def _column(rows: list[Mapping[str, Any]], name: str, setting: str) -> list[Any]:
    if name not in rows[0]:
        raise InputError(f"the shards of {setting} have no column {name!r}")
    return [r[name] for r in rows]


def _checked_rows(
    rows: Iterable[Mapping[str, Any]],
    setting: str,
    level: str,
    gain: float | None,
    sharp_rows: Iterable[Mapping[str, Any]] | None,
) -> tuple[list[Mapping[str, Any]], list[Mapping[str, Any]]]:
    """The setting's rows of `level` (and `gain`) and the rows of its clean images (the
    `sharp` config's; the same rows for `sharp`), one per view in view order."""
    mine = _setting_rows(rows, setting)
    if not mine:
        raise InputError(f"no rows of the setting {setting!r} (level {level})")
    for r in mine:
        if r["level"] != level or (gain is not None and r.get("gain") != float(gain)):
            raise InputError(
                f"the rows of {setting} are of level {r['level']} gain {r.get('gain')}, "
                f"not {level} gain {gain}"
            )
    if sharp_rows is None:
        if level != layout.SHARP:
            raise InputError("sharp_rows is needed for a degraded level (the `sharp` config)")
        clean_rows = mine
    else:
        clean_rows = _setting_rows(sharp_rows, setting)
    n = len(mine)
    if [int(r["view"]) for r in mine] != list(range(n)) or len(clean_rows) != n:
        raise InputError(f"the rows of {setting} are not one per view ({n} rows)")
    return mine, clean_rows


def _scene_from_rows(
    rows: Iterable[Mapping[str, Any]],
    setting: str,
    level: str,
    gain: float | None,
    sharp_rows: Iterable[Mapping[str, Any]] | None,
    downsample: int,
    pose: str,
) -> Scene:
    mine, clean_rows = _checked_rows(rows, setting, level, gain, sharp_rows)
    n = len(mine)
    col = "image" if downsample == 1 else f"image_{downsample}"
    images = np.stack([_decode_png(v, col)[..., :3] for v in _column(mine, col, setting)])
    clean = np.stack([_decode_png(v, col)[..., :3] for v in _column(clean_rows, col, setting)])
    if images.shape != clean.shape:
        raise InputError(f"the images of {setting} are {images.shape}, its sharp {clean.shape}")
    images = images.astype(np.float32) / 255.0
    clean = clean.astype(np.float32) / 255.0
    pb = np.asarray([r["poses_bounds"] for r in mine], dtype=np.float64)
    cv, gl = _cameras(pb)
    if pose == "mean" and not layout.written_pose(level):
        cv, gl = _row_mean_cameras(mine, setting)
    h, w = images.shape[1:3]
    focal = pb[0, 14] * w / pb[0, 9]
    k = np.array([[focal, 0, w / 2], [0, focal, h / 2], [0, 0, 1]], dtype=np.float64)
    held = [int(r["view"]) for r in mine if r["held_out"]]
    noise = json.loads(mine[0]["noise"]) if mine[0].get("noise") else None
    passes = _row_passes(mine, downsample, (w, h))

    def files(rs: list[Mapping[str, Any]]) -> list[Path]:
        return [Path(v["path"]) if isinstance(v, Mapping) else Path() for v in (r[col] for r in rs)]

    return Scene(
        setting=setting,
        level=level,
        gain=gain,
        downsample=downsample,
        images=images,
        clean=clean,
        image_files=files(mine),
        clean_files=files(clean_rows),
        c2w_opencv=cv,
        c2w_opengl=gl,
        intrinsics=k,
        near=pb[:, 15].copy(),
        far=pb[:, 16].copy(),
        train_views=np.array([i for i in range(n) if i not in set(held)], dtype=np.int64),
        test_views=np.array(sorted(held), dtype=np.int64),
        noise=noise,
        pose=pose,
        **passes,
    )


def _row_mean_cameras(mine: list[Mapping[str, Any]], setting: str) -> tuple[np.ndarray, np.ndarray]:
    """(OpenCV, OpenGL) camera-to-world of each row's mean latent pose (`mean_c2w`), as
    _mean_cameras reads them from meta.json."""
    means = [r.get("mean_c2w") for r in mine]
    if any(m is None for m in means):
        raise InputError(
            f"the rows of {setting} record no mean latent poses (a build from before "
            "them): use pose='written'"
        )
    gl = np.asarray(means, dtype=np.float64)
    return gl * np.array([1.0, -1.0, -1.0, 1.0]), gl


def _row_passes(
    mine: list[Mapping[str, Any]], downsample: int, size: tuple[int, int]
) -> dict[str, np.ndarray]:
    """The pass columns of the rows at one size, as Scene's fields (none without), as
    _passes reads the files (an EXR of another `size` than the images' refused)."""
    from blurset.services import hub_format

    passes: dict[str, np.ndarray] = {}
    readers = {
        "depth": ("depth", lambda b: _decode_with(_core.read_depth, b, ".exr", size)),
        "normal": ("normals", lambda b: _decode_with(_core.read_exr, b, ".exr", size)[..., :3]),
        "mask": ("masks", lambda b: _decode_png(b, "mask")[..., 0] > 0),
    }
    for kind, (field_name, read) in readers.items():
        name = hub_format.pass_column(kind, downsample)
        if name in mine[0] and mine[0][name] is not None:
            passes[field_name] = np.stack([_cell(read, r, name) for r in mine])
    return passes
