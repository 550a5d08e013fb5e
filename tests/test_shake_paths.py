"""The shake benches' logic (bench/shake_paths.py, bench_shake_recorded, bench_shake_cost)
and the build guide's generated shake blocks and figure (docs/gen/shake_guide.py): the
statistics on kernels whose answers are known, the MATLAB v5 reader on files written
here, the image centre's path against the core's own record, and the port of the
harmonics before issue 61. No timing is asserted."""

from __future__ import annotations

import json
import math
import struct
import zlib
from pathlib import Path

import numpy as np
import pytest

from tests.conftest import bench_module as _bench
from tests.conftest import gen_module as _gen

ROOT = Path(__file__).resolve().parents[1]
BENCH = ROOT / "bench"
GEN = ROOT / "docs" / "gen"


@pytest.fixture(scope="module")
def sp():
    return _bench("shake_paths")


# -- a MATLAB v5 writer for the tests ----------------------------------------------------


def _element(t: int, payload: bytes) -> bytes:
    return struct.pack("<II", t, len(payload)) + payload + b"\0" * ((-len(payload)) % 8)


def _small(t: int, payload: bytes) -> bytes:
    """A small data element, as MATLAB writes up to 4 bytes: type and size in one word."""
    return struct.pack("<I", (len(payload) << 16) | t) + payload.ljust(4, b"\0")


def _matrix(name: str, value) -> bytes:
    if isinstance(value, list):  # a cell array, one row
        flags, dims = 1, (1, len(value))
        body = b"".join(_element(14, _matrix("", v)) for v in value)
    else:
        a = np.asarray(value, dtype=np.float64)
        flags, dims = 6, a.shape
        body = _element(9, a.ravel(order="F").tobytes())
    return (
        _element(6, struct.pack("<II", flags, 0))
        + _element(5, struct.pack(f"<{len(dims)}i", *dims))
        + (_small(1, name.encode()) if len(name) <= 4 else _element(1, name.encode()))
        + body
    )


def _mat(path: Path, name: str, value, compressed: bool) -> Path:
    header = b"MATLAB 5.0 MAT-file, written by a test".ljust(116) + b"\0" * 8
    data = _element(14, _matrix(name, value))
    if compressed:
        z = zlib.compress(data)
        data = struct.pack("<II", 15, len(z)) + z
    path.write_bytes(header + struct.pack("<H", 0x0100) + b"IM" + data)
    return path


@pytest.mark.parametrize("compressed", [False, True])
def test_the_reader_reads_a_cell_of_kernels_column_major(sp, tmp_path, compressed):
    a = np.arange(6.0).reshape(2, 3)
    b = np.eye(3) / 3
    f = _mat(tmp_path / "k.mat", "kernels", [a, b], compressed)
    got = sp.recorded_kernels(f)
    assert len(got) == 2
    np.testing.assert_array_equal(got[0], a)
    np.testing.assert_array_equal(got[1], b)


def test_the_reader_refuses_hdf5_and_files_without_kernels(sp, tmp_path):
    h5 = tmp_path / "h.mat"
    h5.write_bytes(b"MATLAB 7.3 MAT-file, Platform: x".ljust(128))
    with pytest.raises(ValueError, match="7.3"):
        sp.read_mat(h5)
    other = _mat(tmp_path / "o.mat", "x", np.ones((2, 2)), False)
    with pytest.raises(ValueError, match="kernels"):
        sp.recorded_kernels(other)


# -- the statistics ----------------------------------------------------------------------


def test_a_straight_stroke_is_one_way_thin_and_even(sp):
    k = np.zeros((5, 15))
    k[2, 2:13] = 1.0
    s = sp.kernel_stats(k)
    assert s["extent_px"] == pytest.approx(10.0)
    assert s["length_over_extent"] == pytest.approx(1.0)
    assert s["ends_share"] == pytest.approx(1.0)
    assert s["width_px"] == pytest.approx(1.0)
    # 11 equal pixels: the brightest fifth (3 of them) holds 3/11 of the mass.
    assert s["dwell_share"] == pytest.approx(3 / 11)
    k[2, 7] = 20.0  # the hand stops in the middle
    assert sp.kernel_stats(k)["dwell_share"] > 0.6


def test_a_stroke_that_bends_back_has_near_ends_and_a_ring_is_long(sp):
    t = np.linspace(0, 1, 600)
    # A U: out along y = 0, round, back along y = 8.
    u = np.concatenate([
        np.stack([30 * t, 0 * t], 1),
        np.stack([30 + 4 * np.sin(math.pi * t), 4 - 4 * np.cos(math.pi * t)], 1),
        np.stack([30 - 30 * t, 8 + 0 * t], 1),
    ])  # fmt: skip
    s = sp.kernel_stats(sp.rasterize(u, 34.0))
    assert s["ends_share"] < 0.35 and s["length_over_extent"] > 1.8
    # A closed ring: its longest shortest path is half of it, ends opposite.
    a = np.linspace(0, 2 * math.pi, 800, endpoint=False)
    ring = sp.kernel_stats(sp.rasterize(np.stack([np.cos(a), np.sin(a)], 1), 30.0))
    assert ring["length_over_extent"] == pytest.approx(math.pi / 2, rel=0.1)
    line = sp.rasterize(np.stack([np.linspace(0, 1, 200), np.zeros(200)], 1), 12.0)
    one = sp.kernel_stats(line)
    line[0, -1] = line.max()  # a far pixel, not connected to the stroke
    assert sp.kernel_stats(line)["extent_px"] == pytest.approx(one["extent_px"])


def test_a_drawn_path_sums_to_one_at_its_extent_and_keeps_its_time_order(sp):
    t = np.linspace(0, 1, 300)
    path = np.stack([30 * t, 5 * np.sin(2 * math.pi * t)], 1)
    k = sp.rasterize(path, 15.0)
    assert k.sum() == pytest.approx(1.0)
    assert sp.kernel_stats(k)["extent_px"] == pytest.approx(15.0, abs=1.5)
    s = sp.path_stats(path, 15.0)
    assert s["drift_share"] == pytest.approx(30 / sp.extent(path))
    assert s["path_over_extent"] > 1.0
    back = np.concatenate([path, path[::-1]])
    assert sp.path_stats(back, 15.0)["drift_share"] == pytest.approx(0.0)


def test_keys_on_a_straight_path_do_not_stray_and_on_a_circle_they_do(sp):
    t = np.linspace(0, 1, 2001)
    line = np.stack([3 * t, 2 * t], 1)
    assert sp.key_midpoint_error(line, t, 2) == pytest.approx(0.0, abs=1e-12)
    r = 100.0
    circle = np.stack([r * np.cos(2 * math.pi * t), r * np.sin(2 * math.pi * t)], 1)
    # The sagitta of a chord of 2π/4: r (1 - cos(π/4)).
    want = r * (1 - math.cos(math.pi / 4))
    assert sp.key_midpoint_error(circle, t, 2) == pytest.approx(want, rel=1e-3)


# -- the core's paths --------------------------------------------------------------------


def test_the_centre_path_is_the_one_the_core_records(sp):
    paths = sp.model_paths(3, [1, 3], ghost_px=1.0)
    for lv, views in paths.items():
        for v in views:
            rec = v["record"]
            assert sp.polyline_length(v["path"]) == pytest.approx(rec["path_px"], rel=1e-9)
            amp = float(np.hypot(*v["path"].T).max())
            assert amp == pytest.approx(rec["amplitude_px"], rel=1e-9)
            # The frames lie on a path spanning the level's extent, no more than 1 px apart.
            assert 2.0 ** (lv + 2) - 2.0 <= sp.extent(v["path"]) <= 2.0 ** (lv + 2) * 1.01


# -- the harmonics before issue 61 -------------------------------------------------------


def test_the_old_paths_are_closed_loops_of_their_level_amplitude(sp):
    rng = np.random.default_rng(1)
    for _ in range(5):
        h = sp.old_draw(rng)
        d = sp.old_level(h, 3, 512)
        grid = d(np.linspace(0, 1, sp.OLD_GRID + 1))
        assert float(np.hypot(*grid.T).max()) == pytest.approx(16.0)
        np.testing.assert_allclose(d(0.0), d(1.0), atol=1e-9)
        # Evenly spread frames average to the written pose from 4 frames on.
        m = 7
        assert np.abs(d((np.arange(m) + 0.5) / m).mean(axis=0)).max() < 1e-9


def test_the_old_frame_search_takes_the_fewest_frames_within_the_bound(sp):
    rng = np.random.default_rng(2)
    for lv in (1, 4):
        d = sp.old_level(sp.old_draw(rng), lv, 512)
        m = sp.old_frames(d, 1.0)
        assert sp.old_gap(d, (np.arange(m) + 0.5) / m) <= 1.0
        assert m == sp.OLD_MIN_FRAMES or sp.old_gap(d, (np.arange(m - 1) + 0.5) / (m - 1)) > 1.0
    assert sp.old_frames(sp.old_level(sp.old_draw(rng), 4, 512), 1.0, latents_max=10) == 10


def test_seconds_grow_with_frames_beyond_the_sample_budget():
    cost = _bench("bench_shake_cost")
    unit = {"samples_total": 100, "sharp_s": 10.0, "per_render_overhead_s": 0.01}
    assert cost.image_seconds(1, unit) == pytest.approx(10.0)
    assert cost.image_seconds(100, unit) == pytest.approx(10.0 + 99 * 0.01)
    assert cost.image_seconds(200, unit) == pytest.approx(20.0 + 199 * 0.01)


# -- the recorded bench and the guide ----------------------------------------------------


def test_the_recorded_bench_skips_without_its_file_and_keeps_no_pixel(tmp_path, monkeypatch):
    rec = _bench("bench_shake_recorded")
    monkeypatch.delenv(rec.ENV, raising=False)
    assert rec.run() == []
    monkeypatch.setenv(rec.ENV, str(tmp_path / "absent.mat"))
    assert rec.run() == []
    k1 = np.zeros((9, 9))
    k1[4, 1:8] = 1 / 7
    k2 = np.eye(7) / 7
    monkeypatch.setenv(rec.ENV, str(_mat(tmp_path / "k.mat", "kernels", [k1, k2], True)))
    monkeypatch.setattr(rec, "VIEWS", 3)
    rows = rec.run()
    assert [r["name"] for r in rows] == [
        "shake_recorded_levin09",
        *(f"shake_paths_level{lv}" for lv in rec.LEVELS),
    ]
    recorded = rows[0]
    assert recorded["count"] == 2 and recorded["kernels"][0]["extent_px"] == pytest.approx(6.0)
    # Summary numbers only: no list longer than one number per kernel's statistic.
    text = json.dumps(rows)
    assert all(not isinstance(v, list) for k in recorded["kernels"] for v in k.values())
    assert len(text) < 20000
    assert rows[1]["ratio"] == pytest.approx(
        rows[1]["extent_share_of_image"] / recorded["extent_share_of_image_median"]
    )


def _results() -> dict[str, dict]:
    return {r["name"]: r for r in json.loads((BENCH / "results.json").read_text())}


def test_the_guide_blocks_are_markers_the_results_fill():
    guide = _gen("shake_guide")
    figures = _gen("figures")
    results = _results()
    text = guide.PAGE.read_text()
    assert guide.rewrite(text, results) == text, "run `make docs`"
    for name in ("recorded", "cost"):
        body = "\n".join(guide.BLOCKS[name](results))
        assert "Not measured yet" not in body
        assert figures.strays(body) == []
        assert figures.stale(body, results) == []
    # Without the rows a block says how to measure them.
    assert "Not measured yet" in "\n".join(guide.recorded_block({}))


def test_the_figure_is_drawn_from_the_rows_and_names_a_stale_one(tmp_path):
    guide = _gen("shake_guide")
    results = _results()
    rows = {k: dict(v) for k, v in results.items() if k.startswith("shake_")}
    for k in rows:
        if k.startswith("shake_paths_level"):
            rows[k] |= {"views": 3}
    out = tmp_path / "f.png"
    assert guide.draw_figure(rows, out) == []
    assert out.read_bytes()[:4] == b"\x89PNG"
    bad = json.loads(json.dumps(rows))
    bad["shake_paths_level2"]["examples"][0]["path_px"] += 1.0
    stale = guide.draw_figure(bad, out)
    assert len(stale) == 1 and "level 2 view 0" in stale[0]
