"""The scene read: images, intrinsics and poses, and a blur level's mean latent poses and exposure ends (meta.json)."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from blurset import _core, layout
from blurset._core import read_poses_bounds
from blurset.exceptions import InputError
from blurset.services.options import check_range

IMAGE_SUFFIXES = {".png", ".jpg", ".jpeg"}


def _image_dir(scene_dir: Path, factor: int | None) -> tuple[Path, int]:
    """The image directory and its downsampling factor, chosen as the LLFF loaders do:
    `images_<F>` for factor F, else `images`; a scene shipping a single `images_<F>`
    (fern) uses it without being told."""
    if factor is not None:
        check_range("--factor", factor, 1)
        d = scene_dir / layout.images_dir(factor)
        if not d.is_dir():
            raise InputError(f"no image directory for --factor {factor}: {d}")
        return d, factor
    if (scene_dir / layout.IMAGES).is_dir():
        return scene_dir / layout.IMAGES, 1
    if layout.is_level_dir(scene_dir.name) and (scene_dir.parent / layout.META).is_file():
        # A build writes images/ in every level: without it the setting is damaged, and
        # its small images_<f>/ copies would only measure "too little texture".
        raise InputError(
            f"no {layout.IMAGES}/ in this level of a build setting (damaged: rerun the "
            f"build to redo it, or give --factor to check images_<f>/): {scene_dir}"
        )
    found = sorted(
        (int(m.group(1)), p)
        for p in scene_dir.glob("images_*")
        if p.is_dir() and (m := re.fullmatch(r"images_(\d+)", p.name))
    )
    if len(found) == 1:
        return found[0][1], found[0][0]
    if not found:
        raise InputError(f"no images/ directory in {scene_dir}")
    raise InputError(
        f"several image directories ({', '.join(p.name for _, p in found)}); "
        f"pick one with --factor: {scene_dir}"
    )


def _load_scene(scene_dir: Path, factor: int | None):
    pb_path = scene_dir / layout.POSES_BOUNDS
    if not pb_path.is_file():
        raise InputError(f"no poses_bounds.npy in {scene_dir}")
    rows = np.asarray(read_poses_bounds(pb_path), dtype=np.float64)
    image_dir, factor = _image_dir(scene_dir, factor)
    names = sorted(p.name for p in image_dir.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES)
    if len(names) != len(rows):
        raise InputError(f"{len(names)} images in {image_dir} but {len(rows)} poses in {pb_path}")
    if not names:
        raise InputError(f"no images in {image_dir}")

    from PIL import Image

    with Image.open(image_dir / names[0]) as im:
        w, h = im.size
    hwf = rows[0, [4, 9, 14]]
    # The LLFF loaders take h, w from the image and divide only the focal by the factor.
    if abs(hwf[0] / factor - h) > 1.0 or abs(hwf[1] / factor - w) > 1.0:
        raise InputError(
            f"image size {w}x{h} does not match hwf {hwf[1]:g}x{hwf[0]:g} / factor {factor} "
            f"(wrong --factor?): {image_dir / names[0]}"
        )
    focal = float(hwf[2]) / factor
    mats = rows[:, :15].reshape(-1, 3, 5)
    # OpenCV camera-to-world: x = right = col 1, y = down = col 0, z = forward = -col 2.
    rot_c2w = np.stack([mats[:, :, 1], mats[:, :, 0], -mats[:, :, 2]], axis=2)
    centers = mats[:, :, 3]
    return image_dir, names, (w, h, focal), rot_c2w, centers


def mean_latent_poses(scene_dir: Path, n: int):
    """OpenCV camera-to-world rotations and centres of the mean latent poses of a blur
    level of a build setting (`SETTING/blur_<l>`, from `SETTING/meta.json`, read by the
    core), or None for a sharp level, a plain LLFF scene, or a build from before meta.json
    recorded them."""
    level = scene_dir.name
    # Sharp and defocus images are rendered at the written pose: no mean to report.
    if layout.written_pose(level) or not layout.is_level_dir(level):
        return None
    if not (scene_dir.parent / layout.META).is_file():
        return None
    poses = layout.mean_poses(scene_dir.parent, level)
    if poses is None:
        return None
    if len(poses) != n:
        raise InputError(
            f"{len(poses)} views in meta.json but {n} images in {level}: "
            f"{scene_dir.parent / layout.META}"
        )
    c2w = np.asarray(poses, dtype=np.float64)
    # OpenGL (right, up, backwards) → OpenCV (right, down, forward).
    return c2w[:, :3, :3] * np.array([1.0, -1.0, -1.0]), c2w[:, :3, 3]


def exposure_ends(scene_dir: Path, mean):
    """OpenCV ((rotations, centres) at the first latent frame, (…) at the last) of each
    view's exposure in a blur level of a build setting (meta.json, read by the core), where
    the streaks a blurry image shows begin and end (the first and last motion key under
    the motion blur method); the mean latent pose for a view whose image is a sharp copy
    or that has neither (no streak). None when meta.json does not say."""
    level = _core.parse_level_dir(scene_dir.name)
    if level is None:
        return None
    ends = _core.read_exposure_ends(scene_dir.parent / layout.META, level)
    if ends is None:
        return None
    rot_mean, c_mean = mean
    out = [(rot_mean.copy(), c_mean.copy()), (rot_mean.copy(), c_mean.copy())]
    for i, pair in enumerate(ends):
        if pair is None:
            continue
        for (rot, c), rows in zip(out, pair, strict=True):
            c2w = np.asarray(rows, dtype=np.float64)
            # OpenGL (right, up, backwards) → OpenCV (right, down, forward).
            rot[i] = c2w[:3, :3] * np.array([1.0, -1.0, -1.0])
            c[i] = c2w[:3, 3]
    return out
