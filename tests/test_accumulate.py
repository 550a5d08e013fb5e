"""Accumulation of linear EXR latent frames into sRGB PNGs, through the bindings.

Frames are written by the OpenEXR package (the same library family Blender writes with),
read back by blurset, averaged in linear light and checked against a float64 NumPy
reference of the DESIGN §3 pipeline: mean, composite over background, sRGB, 8-bit.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import OpenEXR
import pytest
from blurset.exceptions import ImageError
from blurset.image import Accumulator, read_exr, srgb_encode
from PIL import Image

W, H = 37, 23  # odd sizes catch row/column mix-ups


def write_exr(path: Path, pixels: np.ndarray, compression=OpenEXR.ZIP_COMPRESSION) -> Path:
    """Write (H, W, 4) as RGBA or (H, W, 3) as RGB float32 channels."""
    name = "RGBA" if pixels.shape[2] == 4 else "RGB"
    header = {"compression": compression, "type": OpenEXR.scanlineimage}
    with OpenEXR.File(header, {name: np.ascontiguousarray(pixels, dtype=np.float32)}) as f:
        f.write(str(path))
    return path


def premultiplied_frame(rng, h=H, w=W) -> np.ndarray:
    """A transparent-film render: colour premultiplied by coverage, some HDR values > 1."""
    alpha = rng.random((h, w, 1), dtype=np.float32)
    alpha[: h // 3] = 0.0  # empty background rows
    alpha[-2:] = 1.0
    colour = rng.random((h, w, 3), dtype=np.float32) * 1.5
    return np.concatenate([colour * alpha, alpha], axis=2).astype(np.float32)


def reference_png(frames: list[np.ndarray], background=(1.0, 1.0, 1.0)) -> np.ndarray:
    mean = np.mean(np.stack(frames).astype(np.float64), axis=0)
    rgb = mean[..., :3] + (1.0 - np.clip(mean[..., 3:], 0.0, 1.0)) * np.asarray(background)
    x = np.clip(rgb, 0.0, 1.0)
    enc = np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)
    return np.round(enc * 255.0).astype(np.uint8)


def read_png(path: Path) -> np.ndarray:
    with Image.open(path) as im:
        assert im.mode == "RGB"
        return np.asarray(im)


@pytest.mark.parametrize("background", [(1.0, 1.0, 1.0), (0.0, 0.0, 0.0), (0.2, 0.5, 0.9)])
def test_exr_frames_average_to_reference_png(tmp_path, rng, background):
    frames = [premultiplied_frame(rng) for _ in range(5)]
    paths = [write_exr(tmp_path / f"{i:03d}.exr", f) for i, f in enumerate(frames)]
    acc = Accumulator(W, H)
    for p in paths:
        acc.add_exr(p)
    assert acc.count == 5
    mean = acc.mean()
    assert mean.shape == (H, W, 4) and mean.dtype == np.float32
    np.testing.assert_allclose(mean, np.mean(np.stack(frames), axis=0), rtol=1e-6, atol=1e-7)

    out = tmp_path / "out" / "blur.png"
    acc.write_png(out, background=background)
    got, want = read_png(out), reference_png(frames, background)
    assert got.shape == (H, W, 3)
    # Exact except where float64 rounding of the two implementations straddles a half code.
    diff = np.abs(got.astype(int) - want.astype(int))
    assert diff.max() <= 1 and np.count_nonzero(diff) <= 2
    assert not list(out.parent.glob(".*tmp*")), "atomic write left a temp file"


def test_transparent_pixels_take_the_background_and_opaque_keep_colour(tmp_path):
    frame = np.zeros((2, 2, 4), np.float32)
    frame[1, 1] = (0.5, 0.25, 0.0, 1.0)  # opaque
    frame[0, 1] = (0.25, 0.0, 0.0, 0.5)  # half coverage, premultiplied
    acc = Accumulator(2, 2)
    acc.add(frame)
    acc.write_png(tmp_path / "a.png", background=(1.0, 1.0, 1.0))
    png = read_png(tmp_path / "a.png")
    assert tuple(png[0, 0]) == (255, 255, 255)
    assert tuple(png[1, 1]) == (188, 137, 0)  # sRGB of linear 0.5 and 0.25
    assert tuple(png[0, 1]) == (225, 188, 188)  # 0.25 + 0.5 * 1 = 0.75; 0 + 0.5 = 0.5


def test_sharp_and_blurry_share_one_encoding(tmp_path, rng):
    """One frame through the accumulator gives the same bytes as N copies of it."""
    frame = premultiplied_frame(rng)
    one, many = Accumulator(W, H), Accumulator(W, H)
    one.add(frame)
    for _ in range(34):
        many.add(frame)
    np.testing.assert_array_equal(many.mean(), frame)
    one.write_png(tmp_path / "sharp.png")
    many.write_png(tmp_path / "blur.png")
    np.testing.assert_array_equal(read_png(tmp_path / "sharp.png"), read_png(tmp_path / "blur.png"))


def test_linear_mean_exr_roundtrips(tmp_path, rng):
    frames = [premultiplied_frame(rng) for _ in range(3)]
    acc = Accumulator(W, H)
    for f in frames:
        acc.add(f)
    acc.write_exr(tmp_path / "mean.exr")
    np.testing.assert_array_equal(read_exr(tmp_path / "mean.exr"), acc.mean())
    with OpenEXR.File(str(tmp_path / "mean.exr")) as f:
        np.testing.assert_array_equal(f.channels()["RGBA"].pixels, acc.mean())


@pytest.mark.parametrize(
    "compression",
    [
        OpenEXR.NO_COMPRESSION,
        OpenEXR.ZIP_COMPRESSION,
        OpenEXR.ZIPS_COMPRESSION,
        OpenEXR.PIZ_COMPRESSION,
    ],
)
def test_read_exr_is_lossless_for_blender_codecs(tmp_path, rng, compression):
    frame = premultiplied_frame(rng)
    path = write_exr(tmp_path / "f.exr", frame, compression)
    np.testing.assert_array_equal(read_exr(path), frame)


def test_read_exr_tiled_and_half_float(tmp_path, rng):
    """Tiled files take the sequential placement path; half floats widen exactly."""
    frame = premultiplied_frame(rng)
    tiles = OpenEXR.TileDescription()
    tiles.xSize, tiles.ySize, tiles.mode = 16, 16, OpenEXR.ONE_LEVEL
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.tiledimage, "tiles": tiles}
    with OpenEXR.File(header, {"RGBA": frame}) as f:
        f.write(str(tmp_path / "tiled.exr"))
    np.testing.assert_array_equal(read_exr(tmp_path / "tiled.exr"), frame)

    half = frame.astype(np.float16)
    header = {"compression": OpenEXR.PIZ_COMPRESSION, "type": OpenEXR.scanlineimage}
    with OpenEXR.File(header, {"RGBA": half}) as f:
        f.write(str(tmp_path / "half.exr"))
    np.testing.assert_array_equal(read_exr(tmp_path / "half.exr"), half.astype(np.float32))


def test_exr_without_alpha_is_opaque(tmp_path, rng):
    rgb = rng.random((H, W, 3), dtype=np.float32)
    path = write_exr(tmp_path / "rgb.exr", rgb)
    back = read_exr(path)
    np.testing.assert_array_equal(back[..., :3], rgb)
    assert np.all(back[..., 3] == 1.0)


def test_size_mismatch_names_the_file_and_both_sizes(tmp_path, rng):
    path = write_exr(tmp_path / "small_frame.exr", premultiplied_frame(rng, h=H - 1))
    acc = Accumulator(W, H)
    with pytest.raises(ValueError, match=r"small_frame\.exr") as e:
        acc.add_exr(path)
    assert f"{W}x{H - 1}" in str(e.value) and f"{W}x{H}" in str(e.value)
    assert acc.count == 0


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_exr_is_refused_with_the_file_named(tmp_path, rng, bad):
    good = premultiplied_frame(rng)
    frame = good.copy()
    frame[5, 7, 2] = bad
    path = write_exr(tmp_path / "poisoned.exr", frame)
    acc = Accumulator(W, H)
    acc.add(good)
    with pytest.raises(ImageError, match=r"poisoned\.exr") as e:
        acc.add_exr(path)
    assert "(7, 5)" in str(e.value) and "channel B" in str(e.value)
    # The refused frame left no trace in the sum.
    assert acc.count == 1
    np.testing.assert_array_equal(acc.mean(), good)


def test_missing_and_corrupt_files_name_the_file(tmp_path):
    acc = Accumulator(W, H)
    with pytest.raises(FileNotFoundError, match=r"nowhere\.exr"):
        acc.add_exr(tmp_path / "nowhere.exr")
    junk = tmp_path / "junk.exr"
    junk.write_bytes(b"\x76\x2f\x31\x01 truncated")
    with pytest.raises(ImageError, match=r"junk\.exr"):
        acc.add_exr(junk)
    with pytest.raises(FileNotFoundError, match=r"nowhere\.exr"):
        read_exr(tmp_path / "nowhere.exr")


def test_empty_accumulator_refuses_to_write(tmp_path):
    acc = Accumulator(4, 4)
    with pytest.raises(ValueError, match="no frames"):
        acc.mean()
    with pytest.raises(ValueError, match="no frames"):
        acc.write_png(tmp_path / "x.png")
    assert not (tmp_path / "x.png").exists()
    with pytest.raises(ValueError, match="positive"):
        Accumulator(0, 4)


@pytest.mark.parametrize(
    ("array", "exc", "msg"),
    [
        (np.zeros((H, W, 4), np.float64), TypeError, "float32"),
        (np.zeros((H, W, 3), np.float32), ValueError, r"\(H, W, 4\)"),
        (np.zeros((H, W), np.float32), ValueError, r"\(H, W, 4\)"),
        (np.zeros((W, H, 4), np.float32), ValueError, f"{H}x{W}"),
        (np.zeros((H, 2 * W, 4), np.float32)[:, ::2], ValueError, "C-contiguous"),
        ([[0.0, 0.0, 0.0, 0.0]], TypeError, "numpy.ndarray"),
    ],
)
def test_add_validates_numpy_input(array, exc, msg):
    acc = Accumulator(W, H)
    with pytest.raises(exc, match=msg):
        acc.add(array)
    assert acc.count == 0


def test_add_refuses_nan_frames():
    frame = np.zeros((H, W, 4), np.float32)
    frame[1, 2, 3] = np.nan
    acc = Accumulator(W, H)
    with pytest.raises(ValueError, match=r"\(2, 1\) channel A"):
        acc.add(frame)
    assert acc.count == 0


def test_srgb_encode_matches_the_standard(rng):
    x = np.concatenate(
        [
            rng.random(1000, dtype=np.float32),
            np.float32([0.0, 0.0031308, 0.0031309, 1.0, -1.0, 2.0, np.nan, np.inf]),
        ]
    ).reshape(4, -1)
    got = srgb_encode(x)
    assert got.shape == x.shape and got.dtype == np.float32
    xd = np.clip(np.nan_to_num(x.astype(np.float64), nan=0.0), 0.0, 1.0)
    want = np.where(xd <= 0.0031308, 12.92 * xd, 1.055 * xd ** (1 / 2.4) - 0.055)
    np.testing.assert_allclose(got, want, rtol=2e-7, atol=1e-9)
    # The two pieces meet at the breakpoint (linear 0.0031308 <-> encoded 0.04045).
    assert abs(float(srgb_encode(np.float32([0.0031308]))[0]) - 0.04045) < 1e-6
    # Strided views are read in logical order.
    np.testing.assert_array_equal(srgb_encode(x[:, ::3]), got[:, ::3])
    with pytest.raises(TypeError, match="float32"):
        srgb_encode(x.astype(np.float64))
