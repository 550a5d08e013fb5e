"""`build --defocus` (issue 35): defocus levels beside the blur levels, depth of field
rendered by Cycles through a thin lens per view and level.

The stand-in worker renders a pinhole image for every frame, so the layout, the held-out
copies, the records and the other commands are checked here with it; the optics (the
circle of confusion Cycles draws against meta.json's) on real renders in
test_real_circles_of_confusion_are_meta_jsons."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from blurset import layout
from blurset.image import circle_of_confusion, read_depth, read_exr

from tests.conftest import run_cli, standin_build

DEFOCUS = ("--defocus", "1,2")


@pytest.fixture(scope="module")
def defocus_build(tmp_path_factory, standin_blender) -> Path:
    out = tmp_path_factory.mktemp("defocus") / "b"
    standin_build(out, standin_blender, *DEFOCUS, "--keep-linear")
    return out


def test_defocus_levels_sit_beside_the_blur_levels_and_hold_the_sharp_image_held_out(
    defocus_build,
):
    for setting in layout.complete_settings(defocus_build):
        meta = json.loads((setting / layout.META).read_text())
        assert meta["levels"] == ["sharp", "blur_1", "blur_2", "defocus_1", "defocus_2"]
        assert layout.setting_levels(setting) == meta["levels"]
        sharp = setting / layout.SHARP
        held = meta["test_views"]
        for level in ("defocus_1", "defocus_2"):
            d = setting / level
            assert (d / layout.POSES_BOUNDS).read_bytes() == (
                sharp / layout.POSES_BOUNDS
            ).read_bytes()
            for sub in (layout.IMAGES, layout.images_dir(4), layout.LINEAR):
                names = sorted(p.name for p in (sharp / sub).iterdir())
                assert names == sorted(p.name for p in (d / sub).iterdir())
                for v in held:
                    name = names[v]
                    assert (d / sub / name).read_bytes() == (sharp / sub / name).read_bytes()
            tf = json.loads((d / layout.TRANSFORMS).read_text())
            assert tf["level"] == level and tf["test_view_images"] == "sharp"
        for v in meta["views"]:
            assert set(v["defocus"]) == {"1", "2"}
            one, two = v["defocus"]["1"], v["defocus"]["2"]
            # One focus per view, inside the object's depth range; the aperture doubles.
            assert one["focus_distance"] == two["focus_distance"]
            assert v["near"] <= one["focus_distance"] <= v["far"]
            assert two["aperture_radius"] == pytest.approx(2 * one["aperture_radius"])
            assert one["coc_px"] == [0.0, pytest.approx(2 * 32 / 512)]
            assert one["f_number"] == pytest.approx(2 * two["f_number"])


def test_a_default_build_has_no_defocus(standin_build_dir):
    setting = layout.complete_settings(standin_build_dir)[0]
    meta = json.loads((setting / layout.META).read_text())
    assert not any("defocus" in lvl for lvl in meta["levels"])
    assert all("defocus" not in v for v in meta["views"])
    assert "defocus" not in meta["sampling"]


def test_noise_export_stats_and_check_poses_take_defocus_levels(defocus_build, tmp_path):
    noisy = tmp_path / "noisy"
    run_cli(
        "noise", str(defocus_build), "--gains", "4", "--levels", "defocus_2", "--out", str(noisy)
    )
    setting = layout.complete_settings(defocus_build)[0].name
    assert layout.is_complete(noisy / setting / "defocus_2" / layout.gain_name(4))
    data = tmp_path / "data"
    run_cli("export", str(defocus_build), "--levels", "sharp,defocus_1", "--out", str(data))
    scenes = json.loads((data / "export.json").read_text())["scenes"]
    assert f"{setting}__defocus_1" in scenes
    st = tmp_path / "stats"
    run_cli("stats", str(defocus_build), "--out", str(st))
    doc = json.loads((st / "stats.json").read_text())
    assert set(doc["defocus_coc_px"]) == {"1", "2"} and (st / "defocus_coc_px.png").is_file()
    card = tmp_path / "card.md"
    run_cli("card", str(defocus_build), "--out", str(card))
    text = card.read_text()
    assert "| defocus_2 | 0.25 |" in text and "`defocus_l` the same views" in text
    proc = run_cli("check-poses", str(defocus_build / setting), "--level", "defocus_1", check=False)
    assert "--level must be" not in proc.stderr, proc.stderr


# -- real renders --------------------------------------------------------------------------


def _card(path: Path) -> Path:
    """A flat square card (two triangles): no side faces, so a thin lens sees nothing of
    it that the pinhole does not, and the defocused alpha is the sharp alpha spread by
    each pixel's circle of confusion, which the test can compute."""
    import trimesh

    v = np.array([[-0.5, 0, -0.5], [0.5, 0, -0.5], [0.5, 0, 0.5], [-0.5, 0, 0.5]], float)
    m = trimesh.Trimesh(v, np.array([[0, 1, 2], [0, 2, 3]]), process=False)
    m.visual = trimesh.visual.ColorVisuals(m, vertex_colors=np.tile([200, 120, 60, 255], (4, 1)))
    m.export(path)
    return path


def _disk(c: float) -> np.ndarray:
    """A uniform disk of diameter c px, area-sampled on the pixel grid, sum 1."""
    r, n, ss = c / 2, int(np.ceil(c / 2)) + 1, 8
    y, x = (np.mgrid[-n * ss : (n + 1) * ss, -n * ss : (n + 1) * ss] + 0.5) / ss - 0.5
    k = ((x**2 + y**2) <= r**2).reshape(2 * n + 1, ss, 2 * n + 1, ss).mean(axis=(1, 3))
    if k.sum() == 0:  # a circle smaller than the sampling: a point
        k[n, n] = 1.0
    return k / k.sum()


def _spread(alpha: np.ndarray, coc: np.ndarray) -> np.ndarray:
    """Each pixel's alpha spread over a disk of its own circle of confusion (binned to
    0.25 px): the thin lens's image of a flat object's coverage."""
    h, w = alpha.shape
    out = np.zeros((h, w))
    bins = np.round(coc * 4) / 4
    for b in np.unique(bins[alpha > 0]):
        k = _disk(max(float(b), 0.01))
        kernel = np.zeros((h, w))
        kernel[: k.shape[0], : k.shape[1]] = k
        kernel = np.roll(kernel, (-(k.shape[0] // 2), -(k.shape[1] // 2)), axis=(0, 1))
        part = np.where(bins == b, alpha, 0.0)
        out += np.real(np.fft.ifft2(np.fft.fft2(part) * np.fft.fft2(kernel)))
    return out


def _filled(depth: np.ndarray) -> np.ndarray:
    """Depth carried a few pixels past the object's edge (the nearest surface's), so a
    pixel the pinhole image covers in part gets its edge's depth."""
    d = depth.copy()
    for _ in range(4):
        pad = np.pad(d, 1)
        h, w = d.shape
        nb = np.stack(
            [
                pad[1 + dy : h + 1 + dy, 1 + dx : w + 1 + dx]
                for dy in (-1, 0, 1)
                for dx in (-1, 0, 1)
            ]
        )
        d = np.where(d > 0, d, nb.max(axis=0))
    return d


@pytest.mark.blender
def test_real_circles_of_confusion_are_meta_jsons(tmp_path):
    """A card at 512 px, defocus levels 2–4 (largest circles 4, 8, 16 px): the alpha a
    defocused render spills outside the sharp silhouette equals, within 10 %, the spill of
    the sharp alpha spread by the circle of confusion meta.json's focus and aperture give
    each pixel's depth, at every level; so the spill grows level to level as meta.json
    says. Held-out views are the sharp image, byte for byte."""
    out = tmp_path / "b"
    run_cli("build", "--objects", str(_card(tmp_path / "card.glb")), "--out", str(out),
            "--resolution", "512", "--views", "3", "--levels", "none", "--defocus", "2,3,4",
            "--passes", "depth", "--keep-linear", "--samples", "16", "--sharp-samples", "32",
            "--settings-per-object", "1", "--quiet")  # fmt: skip
    setting = layout.complete_settings(out)[0]
    meta = json.loads((setting / layout.META).read_text())
    checked = 0
    for v in meta["views"]:
        name = layout.image_name(v["index"], len(meta["views"]))
        exr = layout.linear_name(name)
        if v["index"] in meta["test_views"]:
            for lvl in v["defocus"]:
                d = setting / f"defocus_{lvl}"
                assert (d / layout.IMAGES / name).read_bytes() == (
                    setting / layout.SHARP / layout.IMAGES / name
                ).read_bytes()
            continue
        a0 = read_exr(setting / layout.SHARP / layout.LINEAR / exr)[..., 3].astype(np.float64)
        depth = _filled(read_depth(setting / layout.SHARP / layout.pass_dir("depth", 1) / exr))
        outside = a0 < 0.5
        spills, wants = [], []
        for lvl, d in sorted(v["defocus"].items(), key=lambda kv: int(kv[0])):
            a = read_exr(setting / f"defocus_{lvl}" / layout.LINEAR / exr)[..., 3]
            coc = circle_of_confusion(
                depth, d["focus_distance"], d["aperture_radius"], meta["focal_px"]
            )
            assert coc.max() == pytest.approx(d["coc_px"][1], rel=0.05)
            spill = float((a[outside] - a0[outside]).sum())
            want = float((_spread(a0, coc)[outside] - a0[outside]).sum())
            assert 0.9 <= spill / want <= 1.1, (v["index"], lvl, spill, want)
            spills.append(spill)
            wants.append(want)
        growth = np.array(spills[1:]) / np.array(spills[:-1])
        assert np.all(np.abs(growth / (np.array(wants[1:]) / np.array(wants[:-1])) - 1) <= 0.1)
        checked += 1
    assert checked >= 2
