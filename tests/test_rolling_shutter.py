"""`build --rolling-shutter` (issue 59): a phone camera's rolling shutter, each row read
at its own time while the camera turns, added as a kind of the registry
(rust/core/src/plan/kinds/rolling_shutter.rs and one line of `kinds!`).

The stand-in worker checks the layout, the records, the render target and the other
commands; real renders at 32 px, by both methods, check the images: they differ from
the sharp image and more at a higher level, repeat byte for byte from one seed, and the
two methods (bands of rows; Cycles' own rolling shutter) agree with each other better
than either agrees with the sharp image, so both read the rows in the same order."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from blurset import layout
from blurset.image import read_exr

from tests.conftest import run_cli, standin_build

RS = ("--rolling-shutter", "2,3", "--latents", "4")


@pytest.fixture(scope="module")
def rs_build(tmp_path_factory, standin_blender) -> Path:
    out = tmp_path_factory.mktemp("rolling") / "b"
    standin_build(out, standin_blender, *RS, "--keep-linear")
    return out


def test_levels_sit_beside_the_blur_levels_with_the_written_poses(rs_build):
    settings = layout.complete_settings(rs_build)
    assert settings
    for setting in settings:
        meta = json.loads((setting / layout.META).read_text())
        levels = ["rolling_shutter_2", "rolling_shutter_3"]
        assert meta["levels"][-2:] == levels and layout.setting_levels(setting) == meta["levels"]
        sharp = setting / layout.SHARP
        for level in levels:
            d = setting / level
            assert (d / layout.POSES_BOUNDS).read_bytes() == (
                sharp / layout.POSES_BOUNDS
            ).read_bytes()
            for v in meta["test_views"]:
                name = layout.image_name(v, len(meta["views"]))
                assert (d / layout.IMAGES / name).read_bytes() == (
                    sharp / layout.IMAGES / name
                ).read_bytes()
        res = meta["sampling"]["resolution"]
        for v in meta["views"]:
            two, three = v["rolling_shutter"]["2"], v["rolling_shutter"]["3"]
            # 2^l px at 512 px over the readout; one direction per view.
            assert (two["amplitude_px"], three["amplitude_px"]) == (4 * res / 512, 8 * res / 512)
            assert two["direction_deg"] == three["direction_deg"]
            # Four bands tiling the rows, top first, each at its middle row's time.
            bands = three["bands"]
            assert len(bands) == 4 and bands[0][0] == 0 and bands[-1][1] == res
            assert all(a[1] == b[0] for a, b in zip(bands, bands[1:], strict=False))
            mid = [(b[0] + b[1]) / 2 / res for b in bands]
            assert three["times"] == pytest.approx(mid)
            assert three["method"] == "average" and len(three["seeds"]) == 4


def test_one_band_is_refused_and_torn_bands_are_said_in_one_line(tmp_path, standin_blender):
    # One band, read at the middle row's time, is the sharp image under the level's name.
    out = tmp_path / "one"
    proc = standin_build(out, standin_blender, "--rolling-shutter", "7", "--latents", "1",
                         check=False)  # fmt: skip
    assert proc.returncode != 0 and not out.exists()
    line = proc.stderr.strip().splitlines()[-1]
    assert "--latents 1" in line and "written pose" in line, proc.stderr
    # Two bands over 8 px (level 7 at 32 px) tear the image 4 px at their edge: built,
    # and every setting says so with the fix.
    two = standin_build(tmp_path / "two", standin_blender, "--rolling-shutter", "7")
    said = [ln for ln in two.stderr.splitlines() if "--latents 2 sets them" in ln]
    assert len(said) == 6 and all("rolling_shutter_7" in ln for ln in said), two.stderr
    assert "motion_blur" in said[0]


def test_a_render_target_certifies_rolling_shutter_images(tmp_path, standin_blender):
    out = tmp_path / "t"
    run_cli("build", "--demo", "--views", "4", "--levels", "1", "--resolution", "32",
            "--settings-per-object", "1", "--rolling-shutter", "3", "--latents", "4",
            "--target-psnr", "30", "--quiet", "--blender", str(standin_blender),
            "--out", str(out))  # fmt: skip
    st = tmp_path / "stats"
    run_cli("stats", str(out), "--out", str(st))
    doc = json.loads((st / "stats.json").read_text())
    # Each rendered image's estimate is recorded per level directory, this kind's too
    # (none at the held-out views, which hold the sharp image).
    got = [x for x in doc["render_psnr"]["rolling_shutter_3"] if x is not None]
    assert len(got) == len([x for x in doc["render_psnr"]["blur_1"] if x is not None]) > 0
    assert all(x >= 30 - 0.5 for x in got)


def test_noise_export_stats_card_and_data_take_rolling_shutter_levels(rs_build, tmp_path):
    noisy = tmp_path / "noisy"
    run_cli("noise", str(rs_build), "--gains", "4", "--levels", "rolling_shutter_2",
            "--out", str(noisy))  # fmt: skip
    setting = layout.complete_settings(rs_build)[0].name
    assert layout.is_complete(noisy / setting / "rolling_shutter_2" / layout.gain_name(4))
    data = tmp_path / "data"
    run_cli("export", str(rs_build), "--levels", "sharp,rolling_shutter_3", "--out", str(data))
    assert (
        f"{setting}__rolling_shutter_3" in json.loads((data / "export.json").read_text())["scenes"]
    )
    st = tmp_path / "stats"
    run_cli("stats", str(rs_build), "--out", str(st))
    doc = json.loads((st / "stats.json").read_text())
    assert set(doc["rolling_shutter_px"]) == {"2", "3"}
    assert (st / "rolling_shutter_px.png").is_file()
    card = tmp_path / "card.md"
    run_cli("card", str(rs_build), "--out", str(card))
    assert "`rolling_shutter_l` the same views read out row by row" in card.read_text()
    from blurset.data import open_scene

    scene = open_scene(rs_build, setting, "rolling_shutter_3", pose="mean")
    sharp = open_scene(rs_build, setting)
    np.testing.assert_array_equal(scene.c2w_opengl, sharp.c2w_opengl)


@pytest.mark.parametrize("method", ["average", "motion_blur"])
def test_its_levels_hold_their_own_masks_and_verify_and_nerfstudio_take_them(
    tmp_path, standin_blender, method
):
    out = tmp_path / "b"
    run_cli("build", "--demo", "--views", "4", "--levels", "none", "--resolution", "32",
            "--settings-per-object", "1", "--rolling-shutter", "3", "--latents", "4",
            "--samples", "2", "--passes", "mask", "--blur-method", method, "--quiet",
            "--blender", str(standin_blender), "--out", str(out))  # fmt: skip
    for setting in layout.complete_settings(out):
        masks = setting / "rolling_shutter_3" / layout.pass_dir("mask", 1)
        meta = json.loads((setting / layout.META).read_text())
        assert len(list(masks.iterdir())) == len(meta["views"])
    assert run_cli("verify", str(out)).returncode == 0
    ns = tmp_path / "ns"
    run_cli("export", str(out), "--for", "nerfstudio", "--levels", "rolling_shutter_3",
            "--out", str(ns))  # fmt: skip
    doc = json.loads((ns / "export.json").read_text())
    assert doc["scenes"]
    for scene, rel in doc["scenes"].items():
        tf = json.loads((ns / scene / "transforms.json").read_text())
        assert all("mask_path" in f for f in tf["frames"])
        for p in sorted((out / rel / layout.pass_dir("mask", 1)).iterdir()):
            assert (ns / scene / "masks" / p.name).read_bytes() == p.read_bytes(), scene


# -- real renders --------------------------------------------------------------------------


def _build(out: Path, *args: str) -> Path:
    # At 32 px, levels 5 and 7 move the image centre 2 and 8 px over the readout.
    run_cli("build", "--demo", "--out", str(out), "--resolution", "32", "--views", "3",
            "--levels", "none", "--rolling-shutter", "5,7", "--latents", "8", "--samples", "4",
            "--sharp-samples", "16", "--settings-per-object", "1", "--keep-linear",
            "--test-view-stride", "8", "--passes", "mask", *args, "--quiet")  # fmt: skip
    return out


def _linear(setting: Path, level: str, name: str) -> np.ndarray:
    return read_exr(setting / level / layout.LINEAR / layout.linear_name(name)).astype(np.float64)


@pytest.mark.blender
def test_real_rolling_shutter_by_both_methods(tmp_path):
    avg = _build(tmp_path / "avg")
    again = _build(tmp_path / "again")
    mb = _build(tmp_path / "mb", "--blur-method", "motion_blur")
    closer = 0
    compared = 0
    for setting in layout.complete_settings(avg):
        meta = json.loads((setting / layout.META).read_text())
        assert meta["levels"] == ["sharp", "rolling_shutter_5", "rolling_shutter_7"]
        other = mb / setting.name
        for v in meta["views"]:
            if v["index"] in meta["test_views"]:
                continue
            name = layout.image_name(v["index"], len(meta["views"]))
            sharp = _linear(setting, layout.SHARP, name)
            five, seven = (_linear(setting, f"rolling_shutter_{lv}", name) for lv in (5, 7))
            # Skewed more at the higher level.
            assert 0 < np.abs(five - sharp).mean() < np.abs(seven - sharp).mean()
            # The two methods read the rows in one order: closer to each other than to
            # the unskewed image.
            seven_mb = _linear(other, "rolling_shutter_7", name)
            compared += 1
            closer += int(np.abs(seven - seven_mb).mean() < np.abs(seven - sharp).mean())
        for level in ("rolling_shutter_5", "rolling_shutter_7"):
            for f in sorted((setting / level / layout.IMAGES).iterdir()):
                twin = again / setting.name / level / layout.IMAGES / f.name
                assert f.read_bytes() == twin.read_bytes(), f
    assert compared and closer == compared, (closer, compared)
