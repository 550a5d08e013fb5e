"""`blurset.data.open_scene` without rendering: a setting written as a build writes it
(meta.json with mean latent poses, LLFF poses, PNGs, the marker), read with either pose."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from blurset.data import POSES, open_scene
from blurset.exceptions import InputError
from PIL import Image

N = 5  # views; view 0 is held out (its blur-level image is the sharp copy)


def _look_at(eye: np.ndarray) -> np.ndarray:
    """OpenGL camera-to-world looking at the origin, up +Z."""
    back = eye / np.linalg.norm(eye)
    right = np.cross([0.0, 0.0, 1.0], back)
    right /= np.linalg.norm(right)
    up = np.cross(back, right)
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = right, up, back, eye
    return m


def _llff_rows(c2w_gl: np.ndarray, hwf=(8.0, 8.0, 10.0)) -> np.ndarray:
    """poses_bounds.npy rows: [down, right, back | t | h w f], near, far."""
    rows = np.zeros((len(c2w_gl), 17))
    for i, m in enumerate(c2w_gl):
        llff = np.stack([-m[:3, 1], m[:3, 0], m[:3, 2], m[:3, 3], hwf], axis=1)
        rows[i, :15] = llff.ravel()
        rows[i, 15:] = [1.0, 5.0]
    return rows


@pytest.fixture
def setting(tmp_path):
    """One complete setting with levels sharp and blur_2: written poses on an orbit, mean
    latent poses 3° further round it (as under `--trajectory start`)."""
    build = tmp_path / "build"
    s = build / "obj_000"
    ang = np.radians(np.arange(N) * 4.0)
    written = [_look_at(np.array([3 * np.cos(a), 3 * np.sin(a), 1.5])) for a in ang]
    mean = [_look_at(np.array([3 * np.cos(a), 3 * np.sin(a), 1.5])) for a in ang + np.radians(3)]
    views = [
        {
            "index": i,
            "c2w": written[i].tolist(),
            "levels": {"2": {"w_l": 1.0, "latents": 4, "mean_pose": {"c2w": mean[i].tolist()}}},
        }
        for i in range(N)
    ]
    meta = {"views": views, "test_views": [0], "test_view_images": "sharp"}
    rows = _llff_rows(np.asarray(written))
    g = np.random.default_rng(0)
    for level in ("sharp", "blur_2"):
        (s / level / "images").mkdir(parents=True)
        np.save(s / level / "poses_bounds.npy", rows)
        for i in range(N):
            px = g.integers(0, 256, (8, 8, 3), dtype=np.uint8)
            Image.fromarray(px).save(s / level / "images" / f"{i:03d}.png")
    (s / "meta.json").write_text(json.dumps(meta))
    (s / ".complete").write_text("x\n")
    return build, np.asarray(written), np.asarray(mean)


def test_written_pose_is_poses_bounds_and_the_default(setting):
    build, written, _ = setting
    sc = open_scene(build, "obj_000", "blur_2")
    assert sc.pose == "written" and POSES == ("written", "mean")
    np.testing.assert_allclose(sc.c2w_opengl, written, atol=1e-12)
    np.testing.assert_allclose(sc.c2w_opencv, written @ np.diag([1, -1, -1, 1.0]), atol=1e-12)
    same = open_scene(build, "obj_000", "blur_2", pose="written")
    np.testing.assert_array_equal(same.c2w_opencv, sc.c2w_opencv)


def test_mean_pose_is_meta_json_except_the_sharp_copies(setting):
    build, written, mean = setting
    sc = open_scene(build, "obj_000", "blur_2", pose="mean")
    assert sc.pose == "mean"
    assert list(sc.test_views) == [0]
    # The held-out view holds the sharp image, rendered at p: it keeps the written pose.
    np.testing.assert_allclose(sc.c2w_opengl[0], written[0], atol=1e-12)
    np.testing.assert_allclose(sc.c2w_opengl[1:], mean[1:], atol=1e-12)
    np.testing.assert_allclose(sc.c2w_opencv, sc.c2w_opengl @ np.diag([1, -1, -1, 1.0]))
    # The two differ by the 3° of azimuth, and the images are the same files either way.
    w = open_scene(build, "obj_000", "blur_2")
    azimuth = lambda c: np.degrees(np.arctan2(c[1:, 1, 3], c[1:, 0, 3]))  # noqa: E731
    np.testing.assert_allclose(azimuth(sc.c2w_opencv) - azimuth(w.c2w_opencv), 3.0, atol=1e-9)
    np.testing.assert_array_equal(sc.images, w.images)
    np.testing.assert_array_equal(sc.near, w.near)
    # sharp has one pose: p.
    sharp = open_scene(build, "obj_000", "sharp", pose="mean")
    np.testing.assert_allclose(sharp.c2w_opengl, written, atol=1e-12)


def test_mean_pose_of_a_build_without_them_and_a_bad_name(setting):
    build, _, _ = setting
    meta_path = build / "obj_000" / "meta.json"
    meta = json.loads(meta_path.read_text())
    for v in meta["views"]:
        del v["levels"]["2"]["mean_pose"]
    meta_path.write_text(json.dumps(meta))
    with pytest.raises(InputError, match="no mean latent poses.*pose='written'"):
        open_scene(build, "obj_000", "blur_2", pose="mean")
    assert open_scene(build, "obj_000", "blur_2").pose == "written"
    with pytest.raises(ValueError, match="pose must be one of 'written', 'mean'"):
        open_scene(build, "obj_000", "blur_2", pose="middle")


def test_mean_pose_path_names_the_setting(setting, tmp_path: Path):
    build, _, _ = setting
    (build / "obj_000" / "meta.json").write_text("{")
    with pytest.raises(InputError, match="meta.json"):
        open_scene(build, "obj_000", "blur_2", pose="mean")


def test_downsample_none_is_the_full_size_and_a_bad_one_is_named(setting):
    """`downsample=None` reads the full size, as 1 does (issue 60: it raised a bare
    TypeError); a factor that is no whole number of 1 or more is refused by name."""
    build, _, _ = setting
    full = open_scene(build, "obj_000", "blur_2")
    none = open_scene(build, "obj_000", "blur_2", downsample=None)
    assert none.downsample == 1 and np.array_equal(none.images, full.images)
    assert np.array_equal(none.intrinsics, full.intrinsics)
    for bad in (0, -2, 2.5, "4", True):
        with pytest.raises(ValueError, match=r"downsample must be .*got"):
            open_scene(build, "obj_000", "blur_2", downsample=bad)
