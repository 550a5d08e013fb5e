"""`build --shake` (issue 49): camera shake levels beside the blur levels, a hand-held
camera turning about its centre during the exposure, added through the degradation
interface (rust/core/src/plan/kinds/shake.rs).

The stand-in worker renders a pinhole image per frame, so the layout, the records and the
other commands are checked with it; the images (they differ from the sharp image, grow
with the level, repeat byte for byte from one seed) on real renders at a tiny size, by
both blur methods."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest
from blurset import layout
from blurset.image import read_exr, read_image

from tests.conftest import run_cli, standin_build

ROOT = Path(__file__).resolve().parents[1]
# Four averaged frames (any count from two has the written pose as its mean).
SHAKE = ("--shake", "1,2", "--latents", "4")


@pytest.fixture(scope="module")
def shake_build(tmp_path_factory, standin_blender) -> Path:
    out = tmp_path_factory.mktemp("shake") / "b"
    standin_build(out, standin_blender, *SHAKE, "--keep-linear")
    return out


def test_shake_levels_sit_beside_the_blur_levels_with_the_written_poses(shake_build):
    for setting in layout.complete_settings(shake_build):
        meta = json.loads((setting / layout.META).read_text())
        assert meta["levels"] == ["sharp", "blur_1", "blur_2", "shake_1", "shake_2"]
        assert layout.setting_levels(setting) == meta["levels"]
        sharp = setting / layout.SHARP
        for level in ("shake_1", "shake_2"):
            d = setting / level
            # LLFF poses as the other levels: the written pose of every view.
            assert (d / layout.POSES_BOUNDS).read_bytes() == (
                sharp / layout.POSES_BOUNDS
            ).read_bytes()
            tf = json.loads((d / layout.TRANSFORMS).read_text())
            assert tf["level"] == level and tf["test_view_images"] == "sharp"
            for v in meta["test_views"]:
                name = layout.image_name(v, len(meta["views"]))
                assert (d / layout.IMAGES / name).read_bytes() == (
                    sharp / layout.IMAGES / name
                ).read_bytes()
        for v in meta["views"]:
            one, two = v["shake"]["1"], v["shake"]["2"]
            # Extent 2^(l+2) px at 512 px, at 32 px; one trajectory per view, about
            # twice as far at level 2.
            assert (one["extent_px"], two["extent_px"]) == (8 * 32 / 512, 16 * 32 / 512)
            assert two["path_px"] == pytest.approx(2 * one["path_px"], rel=0.02)
            assert two["extent_deg"] == pytest.approx(2 * one["extent_deg"], rel=0.02)
            assert one["method"] == "average" and len(one["poses"]) == 4
            # What was rendered: the frames' gap at the centre and corners, and their
            # turns, roll included, about the written pose (their mean).
            assert 0 < one["max_gap_px"] and one["path_px"] <= 3 * one["max_gap_px"] + 1e-9
            poses = one["poses"]
            assert any(abs(q["roll_deg"]) > 0 for q in poses)
            for key in ("yaw_deg", "pitch_deg", "roll_deg"):
                assert (
                    abs(sum(q[key] for q in poses) / 4)
                    < 1e-2 * max(abs(q[key]) for q in poses) + 1e-12
                )


def test_a_default_build_has_no_shake(standin_build_dir):
    setting = layout.complete_settings(standin_build_dir)[0]
    meta = json.loads((setting / layout.META).read_text())
    assert not any("shake" in lvl for lvl in meta["levels"])
    assert all("shake" not in v for v in meta["views"])
    assert "shake" not in meta["sampling"]


def test_one_frame_at_the_written_pose_is_refused_in_one_line(tmp_path, standin_blender):
    # The frames' mean is the written pose at any count, so one frame is the sharp image.
    out = tmp_path / "b"
    proc = standin_build(out, standin_blender, "--shake", "1", "--latents", "1", check=False)
    assert proc.returncode != 0 and not out.exists()
    line = proc.stderr.strip().splitlines()[-1]
    assert "--latents 1" in line and "written pose" in line, proc.stderr


def test_noise_export_stats_and_data_take_shake_levels(shake_build, tmp_path):
    noisy = tmp_path / "noisy"
    run_cli("noise", str(shake_build), "--gains", "4", "--levels", "shake_2", "--out", str(noisy))
    setting = layout.complete_settings(shake_build)[0].name
    assert layout.is_complete(noisy / setting / "shake_2" / layout.gain_name(4))
    data = tmp_path / "data"
    run_cli("export", str(shake_build), "--levels", "sharp,shake_1", "--out", str(data))
    scenes = json.loads((data / "export.json").read_text())["scenes"]
    assert f"{setting}__shake_1" in scenes
    st = tmp_path / "stats"
    run_cli("stats", str(shake_build), "--out", str(st))
    doc = json.loads((st / "stats.json").read_text())
    assert set(doc["shake_path_px"]) == {"1", "2"} and (st / "shake_path_px.png").is_file()
    assert "shake_path_px" in {q["name"] for q in doc["quantities"]}
    from blurset.data import open_scene

    scene = open_scene(shake_build, setting, "shake_1", pose="mean")
    sharp = open_scene(shake_build, setting)
    # Shaken about the written pose: its cameras are the written ones.
    np.testing.assert_array_equal(scene.c2w_opengl, sharp.c2w_opengl)
    proc = run_cli("check-poses", str(shake_build / setting), "--level", "shake_1", check=False)
    assert "--level must be" not in proc.stderr, proc.stderr


# -- a kind is its file and one line of the registry: tests/test_kinds.py ----------------


def test_the_builder_schedules_render_phases_without_naming_a_kind():
    """The builder renders the plan's phases in order (`Render.phase`): no degraded kind
    is named in it, so a new kind schedules itself (defocus's images once had a phase
    of their own there, picked by their folder names)."""
    builder = ROOT / "python" / "blurset" / "commands" / "builder"
    named = re.compile(r"defocus|shake|\.startswith\(|is_level_dir|parse_level_dir")
    for f in ("setting.py", "unit.py"):
        hits = [ln for ln in (builder / f).read_text().splitlines() if named.search(ln)]
        assert hits == [], (f, hits)


# -- real renders --------------------------------------------------------------------------


def _build(out: Path, *args: str) -> Path:
    run_cli("build", "--demo", "--out", str(out), "--resolution", "32", "--views", "3",
            "--levels", "none", "--shake", "1,4", "--latents", "4", "--samples", "4",
            "--sharp-samples", "8", "--settings-per-object", "1", "--keep-linear",
            "--test-view-stride", "8", "--passes", "mask", *args, "--quiet")  # fmt: skip
    return out


def _masks(setting: Path, level: str, name: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(sharp mask, the level's own mask, the level's mean alpha) of one view."""
    sub = layout.pass_dir("mask", 1)
    sharp, own = (read_image(setting / lv / sub / name)[..., 0] > 0 for lv in (layout.SHARP, level))
    return sharp, own, read_exr(setting / level / layout.LINEAR / layout.linear_name(name))[..., 3]


def _moved(setting: Path, level: str, name: str) -> float:
    """How far a shake image is from the sharp one: mean absolute difference of the
    linear RGBA."""
    exr = layout.linear_name(name)
    a = read_exr(setting / layout.SHARP / layout.LINEAR / exr).astype(np.float64)
    b = read_exr(setting / level / layout.LINEAR / exr).astype(np.float64)
    return float(np.abs(a - b).mean())


@pytest.mark.blender
@pytest.mark.parametrize("method", ["average", "motion_blur"])
def test_real_shake_differs_from_sharp_grows_with_level_and_repeats(tmp_path, method):
    a = _build(tmp_path / "a", "--blur-method", method)
    b = _build(tmp_path / "b", "--blur-method", method)
    larger = 0
    for setting in layout.complete_settings(a):
        meta = json.loads((setting / layout.META).read_text())
        assert meta["levels"] == ["sharp", "shake_1", "shake_4"]
        for v in meta["views"]:
            assert v["shake"]["4"]["method"] == method
            if v["index"] in meta["test_views"]:
                continue
            name = layout.image_name(v["index"], len(meta["views"]))
            one, four = _moved(setting, "shake_1", name), _moved(setting, "shake_4", name)
            assert 0 < one < four, (setting.name, v["index"], one, four)
            # Its own masks: the sharp mask and every pixel the exposure covered half
            # (motion blur: any coverage at all), as a blur level's.
            sharp, own, alpha = _masks(setting, "shake_4", name)
            assert not (sharp & ~own).any() and not ((alpha >= 0.5) & ~own).any()
            if method == "motion_blur":
                assert np.array_equal(own, sharp | (alpha > 0))
            larger += int((own & ~sharp).any())
        for level in ("shake_1", "shake_4"):
            # One seed, the same bytes; the same poses as the sharp level.
            for f in sorted((setting / level / layout.IMAGES).iterdir()):
                other = b / setting.name / level / layout.IMAGES / f.name
                assert f.read_bytes() == other.read_bytes(), f
            assert (setting / level / layout.POSES_BOUNDS).read_bytes() == (
                setting / layout.SHARP / layout.POSES_BOUNDS
            ).read_bytes()
    # The shaken camera smears the object outside its sharp silhouette somewhere.
    assert larger > 0


def test_the_card_says_what_a_shake_level_is(shake_build, tmp_path):
    """The card names every kind its levels hold (the kind's own sentence, from the
    core's table of kinds), not only blur and defocus."""
    card = tmp_path / "card.md"
    run_cli("card", str(shake_build), "--out", str(card))
    text = card.read_text()
    assert "`shake_l` the same views shaken by a hand-held camera at level l" in text
    assert "`blur_l` the same views blurred at level l" in text and "`defocus_l`" not in text
