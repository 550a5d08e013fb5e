"""`blurset preview` and `blurset build --previews` (issue 9) on a real tiny build: the
figures open, have the labelled grid size, hold the right images at the right places,
are not blank, and the contact sheet flags an empty or black object."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from blurset.commands import preview
from PIL import Image

from tests.conftest import DEMO_ARGS, run_cli

pytestmark = pytest.mark.blender

LEVELS = ["sharp", "blur_1", "blur_2", "blur_3", "blur_4"]


def settings(build: Path) -> list[Path]:
    return sorted(d for d in build.iterdir() if (d / ".complete").is_file())


def rgb(path: Path) -> np.ndarray:
    return np.asarray(Image.open(path).convert("RGB"))


def tile_at(fig: np.ndarray, x: int, y: int, tile: tuple[int, int], source: Path) -> np.ndarray:
    """The tile at (x, y), brought back to the source's size (tiles are integer
    NEAREST enlargements of 64 px images here)."""
    src = rgb(source)
    f = tile[0] // src.shape[1]
    assert tile[0] == f * src.shape[1], "64 px images are enlarged by an integer factor"
    return fig[y : y + tile[1] : f, x : x + tile[0] : f]


def has_text(region: np.ndarray) -> bool:
    """Dark label pixels on the white figure background."""
    return int((region.min(axis=2) < 100).sum()) >= 20


def check_setting_figure(path: Path, setting: Path, columns: list[tuple[str, Path]]) -> None:
    meta = json.loads((setting / "meta.json").read_text())
    views = preview.choose_views(len(meta["views"]), meta["test_views"], 4)
    assert views[: len(meta["test_views"])] == meta["test_views"], "test views come first"
    fig = rgb(path)
    tile = preview.tile_size(64, 64)
    assert tile == (128, 128)
    assert fig.shape[1::-1] == preview.grid_size(len(views), len(columns), tile)
    assert fig.std() > 20, "figure is blank"
    for c, (_, level_images) in enumerate(columns):
        x, y = preview.cell_origin(0, c, tile)
        assert has_text(fig[preview.TITLE_H : y, x : x + tile[0]]), f"no label over column {c}"
        for r, v in enumerate(views):
            x, y = preview.cell_origin(r, c, tile)
            src = level_images / f"{v:03d}.png"
            np.testing.assert_array_equal(tile_at(fig, x, y, tile, src), rgb(src))
    for r in range(len(views)):
        x, y = preview.cell_origin(r, 0, tile)
        assert has_text(fig[y : y + 32, : preview.LABEL_W]), f"no label on row {r}"


def test_build_previews_are_the_labelled_level_grid(linear_build):
    for s in settings(linear_build):
        check_setting_figure(s / "preview.png", s, [(lvl, s / lvl / "images") for lvl in LEVELS])


def test_rerun_with_previews_draws_the_missing_ones_only(linear_build, tmp_path):
    out = tmp_path / "out"
    shutil.copytree(linear_build, out)
    names = [s.name for s in settings(out)]
    (out / names[0] / "preview.png").unlink()
    kept = (out / names[1] / "preview.png").stat().st_mtime_ns
    image = out / names[0] / "blur_4" / "images" / "000.png"
    rendered = image.stat().st_mtime_ns
    p = run_cli("build", *DEMO_ARGS, "--keep-linear", "--previews", "--out", str(out))
    assert "(0 new)" in p.stderr + p.stdout, p.stdout + p.stderr
    assert image.stat().st_mtime_ns == rendered  # nothing re-rendered
    check_setting_figure(out / names[0] / "preview.png", out / names[0],
                         [(lvl, out / names[0] / lvl / "images") for lvl in LEVELS])  # fmt: skip
    assert (out / names[1] / "preview.png").stat().st_mtime_ns == kept
    # The preview drawn again is what the manifest now certifies.
    run_cli("verify", "--no-decode", str(out))


def test_preview_with_a_noise_gain(linear_build, tmp_path):
    noise = tmp_path / "noise"
    run_cli("noise", str(linear_build), "--out", str(noise), "--gains", "4", "--levels",
            "sharp,blur_4", "--quiet")  # fmt: skip
    s = settings(linear_build)[0]
    out = tmp_path / "fig.png"
    p = run_cli("preview", str(s), "--out", str(out), "--noise", str(noise), "--gain", "4")
    assert "7 columns" in p.stdout, p.stdout
    columns = [(lvl, s / lvl / "images") for lvl in LEVELS] + [
        (f"{lvl} · gain 4", noise / s.name / lvl / "gain_4" / "images")
        for lvl in ("sharp", "blur_4")
    ]
    check_setting_figure(out, s, columns)


def test_contact_sheet_grid_and_flags(linear_build, tmp_path):
    out = tmp_path / "sheet.png"
    p = run_cli("preview", str(linear_build), "--out", str(out))
    assert "3 settings (0 flagged)" in p.stdout and not p.stderr.strip(), p.stdout + p.stderr
    sheet = rgb(out)
    tile = preview.tile_size(64, 64)
    cols = 2  # ceil(sqrt(3))
    assert sheet.shape[1::-1] == preview.sheet_size(3, cols, tile)
    for k, s in enumerate(settings(linear_build)):
        x, y = preview.sheet_origin(k, cols, tile)
        src = s / "sharp" / "images" / "000.png"  # the first test view
        np.testing.assert_array_equal(tile_at(sheet, x, y, tile, src), rgb(src))
        assert has_text(sheet[y + tile[1] : y + tile[1] + preview.CAPTION_H, x : x + tile[0]])
    # An empty render and a black one are flagged, in red, and named on stderr.
    broken = tmp_path / "broken"
    shutil.copytree(linear_build, broken, ignore=shutil.ignore_patterns("linear"))
    names = [s.name for s in settings(broken)]
    Image.new("RGB", (64, 64), (255, 255, 255)).save(broken / names[1] / "sharp/images/000.png")
    a = rgb(broken / names[2] / "sharp/images/000.png")
    dark = np.where((a < 247).any(axis=2, keepdims=True), a // 12, a)  # same object, nearly black
    Image.fromarray(dark).save(broken / names[2] / "sharp/images/000.png")
    p = run_cli("preview", str(broken), "--out", str(out))
    assert "(2 flagged)" in p.stdout, p.stdout
    assert f"flagged: {names[1]}: EMPTY" in p.stderr and f"flagged: {names[2]}: BLACK" in p.stderr
    sheet = rgb(out)
    for k in range(3):
        x, y = preview.sheet_origin(k, cols, tile)
        caption = sheet[y + tile[1] : y + tile[1] + preview.CAPTION_H, x : x + tile[0]].astype(int)
        red = ((caption[..., 0] > 150) & (caption[..., 1] < 80)).sum()
        assert (red > 20) == (k > 0), (k, red)


def test_contact_sheet_of_one_setting_keeps_its_counts_whole(linear_build, tmp_path):
    one = tmp_path / "one"
    shutil.copytree(linear_build, one, ignore=shutil.ignore_patterns("linear"))
    for s in settings(one)[1:]:
        shutil.rmtree(s)
    out = tmp_path / "sheet.png"
    p = run_cli("preview", str(one), "--out", str(out))
    assert "contact sheet of 1 setting (0 flagged)" in p.stdout, p.stdout
    sheet = rgb(out)
    assert sheet.shape[1] == preview.SHEET_MIN_W
    # The counts line ends well inside the sheet: cut with an ellipsis, it would run to the
    # right margin (it did, above a single thumbnail, before the sheet had a minimum width).
    counts = sheet[24 : preview.SHEET_TITLE_H, :]
    inked = np.flatnonzero((counts.min(axis=2) < 100).any(axis=0))
    assert inked.size and inked[-1] < sheet.shape[1] - preview.PAD - 20, inked[-1]


def test_preview_bad_input_one_line(linear_build, tmp_path):
    s = settings(linear_build)[0]
    cases = [
        ([str(tmp_path / "nope")], "nope"),
        ([str(s), "--gain", "4"], "--noise"),
        ([str(s), "--noise", str(tmp_path), "--gain", "3"], "not a blurset noise output"),
        ([str(s / "sharp")], "meta.json"),
        ([str(linear_build), "--gain", "4"], "--noise"),
    ]
    for args, fragment in cases:
        p = run_cli("preview", *args, "--out", str(tmp_path / "x.png"), check=False)
        lines = p.stderr.strip().splitlines()
        assert p.returncode == 2 and len(lines) == 1, p.stderr
        assert lines[0].startswith("blurset preview: error:") and fragment in lines[0], lines[0]
        assert not (tmp_path / "x.png").exists()
