"""`blurset stats` on real builds: every number traces back to meta.json, figures are
drawn, incomplete and failed work is counted, bad input fails with one line, and
10,000 settings aggregate."""

from __future__ import annotations

import csv
import functools
import json
import math
import operator
import shutil
import statistics
import subprocess
import sys
import time
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest
from blurset import layout
from blurset.commands.stats import BAR, load_stats
from PIL import Image

from tests.conftest import DEMO_ARGS, run_cli, write_synthetic_build

FIGURES = ["scene_range", "scene_dimension", "blur_weight", "factors", "latent_frames", "motion_px"]


def complete_settings(build: Path) -> list[Path]:
    return sorted(
        d
        for d in build.iterdir()
        if d.is_dir() and not d.name.endswith(".partial") and (d / ".complete").is_file()
    )


def cbrt_correctly_rounded(p: float) -> float:
    """The double nearest to p^(1/3), decided exactly with rationals (math.cbrt is
    glibc's, which can be an ulp off; blurset uses a correctly rounded cube root)."""
    if p == 0:
        return 0.0
    x = Fraction(p)
    c = math.cbrt(p)  # a start, a few ulp off at most; walk to the rounding interval

    def mid(a: float, b: float) -> Fraction:
        return (Fraction(a) + Fraction(b)) / 2

    while mid(c, math.nextafter(c, math.inf)) ** 3 < x:
        c = math.nextafter(c, math.inf)
    while mid(math.nextafter(c, 0), c) ** 3 > x:
        c = math.nextafter(c, 0)
    return c


def recompute(build: Path) -> dict:
    """The stats of a build, computed here from the meta.json files with plain Python."""
    dirs = complete_settings(build)
    metas = [json.loads((d / "meta.json").read_text()) for d in dirs]
    views = [v for m in metas for v in m["views"]]
    levels = sorted({lvl for v in views for lvl in v["levels"]}, key=int)
    # Held-out views whose blur levels hold the sharp image have no blur to count.
    copies = [
        m.get("test_view_images") == "sharp" and v["index"] in m.get("test_views", [])
        for m in metas
        for v in m["views"]
    ]

    def per_level(key):
        return {
            lvl: [
                v["levels"][lvl][key] if lvl in v["levels"] and not copy else None
                for v, copy in zip(views, copies, strict=True)
            ]
            for lvl in levels
        }

    exp = {
        "scene_range": [v["far"] / v["near"] for v in views],
        "scene_dimension": [
            cbrt_correctly_rounded(d[0] * d[1] * d[2]) for d in (m["bbox_dims"] for m in metas)
        ],
        **{q: [v[q] for v in views] for q in ("flatness", "depth_range", "orientation", "w_u")},
        "blur_weight": per_level("w_l"),
        "latent_frames": per_level("latents"),
        "motion_px": per_level("motion_px"),
        "view_index": [v["index"] for v in views],
        "settings": [d.name for d in dirs],
    }
    splits_path = build / "splits.json"
    splits = json.loads(splits_path.read_text()) if splits_path.exists() else None
    test = [(d, m) for d, m in zip(dirs, metas, strict=True) if splits and d.name in splits["test"]]
    # failures.jsonl as the build leaves it: the failing work now (latest record per
    # object or setting); a setting record whose setting is complete no longer counts.
    records = []
    if (build / "failures.jsonl").exists():
        records = [json.loads(line) for line in (build / "failures.jsonl").read_text().splitlines()]
    done = {d.name for d in dirs}
    current = [r for r in records if not (r.get("setting") and r["setting"] in done)]
    # An object --licenses left out is a skip, counted apart from the failures.
    failing = [r for r in current if r.get("stage") != "license"]
    uids = {m["uid"] for m in metas}
    exp["counts"] = {
        "objects": len(uids),
        "settings": len(metas),
        "views": len(views),
        "images": sum(len(m["views"]) * len(m["levels"]) for m in metas),
        "sharp_copy_views": sum(copies),
        "test_settings": len(test) if splits else None,
        "test_views": sum(len(splits["test_views"][d.name]) for d, _ in test) if splits else None,
        "test_images": (
            sum(len(splits["test_views"][d.name]) * len(m["levels"]) for d, m in test)
            if splits
            else None
        ),
        "unsplit_settings": (
            sum(d.name not in splits["train"] + splits["test"] for d in dirs) if splits else None
        ),
        "failures": len({r["uid"] for r in failing}),
        "settings_failed": sum(1 for r in failing if r.get("setting")),
        "failure_lines_skipped": 0,
        "licence_skipped": sum(r.get("stage") == "license" for r in current),
        # What a rerun would redo (a synthetic build's settings hold no images at all).
        "damaged_settings": sum(layout.setting_problem(d) is not None for d in dirs),
        "incomplete_settings": sum(
            d.is_dir()
            and not d.name.startswith(".")
            and d not in dirs
            and (d.name.endswith(".partial") or (d / "meta.json").exists())
            for d in build.iterdir()
        ),
    }
    return exp


def summary_of(values: list) -> tuple:
    v = [x for x in values if x is not None]
    mean = functools.reduce(operator.add, v) / len(v)  # left to right, as documented
    return (len(v), min(v), statistics.median(v), max(v), mean)


def check_against_meta(build: Path, stats: dict) -> None:
    exp = recompute(build)
    assert stats["counts"] == exp["counts"]
    assert [s["name"] for s in stats["settings"]] == exp["settings"]
    assert stats["view_index"] == exp["view_index"]
    for q in ("scene_range", "scene_dimension", "flatness", "depth_range", "orientation", "w_u"):
        assert stats[q] == exp[q], q  # exact: same floats, not approximately
    for q in ("blur_weight", "latent_frames", "motion_px"):
        assert stats[q] == exp[q], q
    by_name = {s["quantity"]: s for s in stats["summary"]}
    flat = {q: exp[q] for q in ("scene_range", "scene_dimension", "flatness", "depth_range",
                                "orientation", "w_u")}  # fmt: skip
    for q in ("blur_weight", "latent_frames", "motion_px"):
        flat.update({f"{q}_{lvl}": v for lvl, v in exp[q].items()})
    assert set(by_name) == set(flat)
    for q, values in flat.items():
        s = by_name[q]
        assert (s["n"], s["min"], s["median"], s["max"], s["mean"]) == summary_of(values), q


@pytest.fixture(scope="module")
def demo_stats(demo_build, tmp_path_factory):
    out = tmp_path_factory.mktemp("stats") / "st"
    proc = run_cli("stats", str(demo_build), "--out", str(out))
    return out, proc


@pytest.mark.blender
def test_every_number_traces_back_to_meta_json(demo_build, demo_stats):
    out, proc = demo_stats
    stats = json.loads((out / "stats.json").read_text())
    assert stats["schema"] == "blurset-stats/1"
    assert stats["counts"]["settings"] == 3 and stats["counts"]["views"] == 3 * 17
    assert set(stats["blur_weight"]) == {"1", "2", "3", "4"}
    check_against_meta(demo_build, stats)
    # scene range is the depth-range factor R by construction (near floored before both)
    assert stats["scene_range"] == stats["depth_range"]
    # w_l lies in its sampling interval around w_u · l, for the blurry views; the two
    # held-out views of each setting hold the sharp image at every level: no w_l.
    assert stats["counts"]["sharp_copy_views"] == 3 * 2
    for lvl, w in stats["blur_weight"].items():
        held = [k for k, i in enumerate(stats["view_index"]) if i in (0, 16)]
        assert [w[k] for k in held] == [None] * 6
        for w_l, w_u in zip(w, stats["w_u"], strict=True):
            if w_l is not None:
                assert 0.9 * w_u * int(lvl) - 1e-12 <= w_l <= 1.1 * w_u * int(lvl) + 1e-12
    # the terminal summary names the counts and where the report is
    assert "3 settings" in proc.stdout and str(out / "report.md") in proc.stdout


@pytest.mark.blender
def test_csv_holds_the_same_numbers(demo_stats):
    out, _ = demo_stats
    stats = json.loads((out / "stats.json").read_text())
    rows = list(csv.DictReader((out / "views.csv").open()))
    assert len(rows) == stats["counts"]["views"]
    for k, r in enumerate(rows):
        assert r["setting"] == stats["settings"][stats["view_setting"][k]]["name"]
        assert float(r["scene_range"]) == stats["scene_range"][k]
        assert float(r["w_u"]) == stats["w_u"][k]
        for lvl in stats["blur_weight"]:
            w, m = stats["blur_weight"][lvl][k], stats["latent_frames"][lvl][k]
            assert r[f"blur_weight_{lvl}"] == ("" if w is None else repr(w))
            assert r[f"latent_frames_{lvl}"] == ("" if m is None else str(m))
    srows = list(csv.DictReader((out / "settings.csv").open()))
    assert [float(r["scene_dimension"]) for r in srows] == stats["scene_dimension"]
    summary = {r["quantity"]: r for r in csv.DictReader((out / "summary.csv").open())}
    for s in stats["summary"]:
        assert float(summary[s["quantity"]]["median"]) == s["median"]
    counts = {r["count"]: r["value"] for r in csv.DictReader((out / "counts.csv").open())}
    assert int(counts["images"]) == stats["counts"]["images"]


@pytest.mark.blender
def test_figures_open_and_are_not_blank(demo_stats):
    out, _ = demo_stats
    report = (out / "report.md").read_text()
    bar = np.array(Image.new("RGB", (1, 1), BAR)).reshape(3)
    for name in FIGURES:
        path = out / f"{name}.png"
        with Image.open(path) as im:
            im.verify()
        a = np.asarray(Image.open(path).convert("RGB"))
        assert a.shape[0] >= 300 and a.shape[1] >= 500, (name, a.shape)
        bars = np.all(a == bar, axis=-1).mean()
        ink = np.any(a < 200, axis=-1).mean()
        if name == "latent_frames":
            # A fixed --latents 4: one number for every level, not four one-bar panels.
            assert a.shape[1] <= 704, "one panel"
            assert 0.0005 < bars < 0.02, f"{name}: the number is not drawn ({bars:.4f})"
        else:
            assert bars > 0.01, f"{name}: no histogram bars drawn ({bars:.4f})"
        assert ink > 0.005, f"{name}: no axes or labels ({ink:.4f})"
        assert f"]({name}.png)" in report
    for section in (
        "## Counts",
        "## Summary",
        "| scene_range |",
        "| blur_weight_4 |",
        "test_images",
    ):
        assert section in report
    assert not list(out.glob(".*tmp*")), "temporary files left behind"


@pytest.mark.blender
def test_failed_object_and_half_written_settings_are_counted(demo_build, tmp_path):
    build = tmp_path / "build"
    shutil.copytree(demo_build, build)
    bad = tmp_path / "objs" / "broken.glb"
    bad.parent.mkdir()
    bad.write_bytes(b"glTF but not really")
    # the real build resumes (complete settings skipped) and logs the failed object
    run_cli("build", *DEMO_ARGS, "--objects", str(bad), "--out", str(build))
    assert "broken" in (build / "failures.jsonl").read_text()
    names = [d.name for d in complete_settings(build)]
    shutil.copytree(build / names[0], build / f"{names[0]}.partial")  # marker and all
    shutil.copytree(build / names[1], build / "demo_half_000")
    (build / "demo_half_000" / ".complete").unlink()

    out = tmp_path / "st"
    proc = run_cli("stats", str(build), "--out", str(out))
    stats = json.loads((out / "stats.json").read_text())
    c = stats["counts"]
    assert (c["settings"], c["views"], c["failures"], c["incomplete_settings"]) == (3, 51, 1, 2)
    assert stats["incomplete"] == sorted([f"{names[0]}.partial", "demo_half_000"])
    assert stats["failures"][0]["uid"] == "broken" and stats["failures"][0]["stage"] == "preflight"
    check_against_meta(build, stats)
    assert "2 incomplete settings; 1 failed objects" in proc.stdout
    report = (out / "report.md").read_text()
    assert "failed object `broken` (preflight)" in report and "demo_half_000" in report

    # a setting completed after splits.json was written, then a build with no splits yet
    shutil.copytree(build / names[2], build / "demo_late_000")
    stats = load_stats(build)
    assert stats["counts"]["unsplit_settings"] == 1 and stats["counts"]["settings"] == 4
    check_against_meta(build, stats)
    (build / "splits.json").unlink()
    (build / "dataset.json").unlink()
    run_cli("stats", str(build), "--out", str(out))
    stats = json.loads((out / "stats.json").read_text())
    assert stats["counts"]["test_images"] is None and stats["counts"]["settings"] == 4
    check_against_meta(build, stats)
    assert "No splits.json yet" in (out / "report.md").read_text()


@pytest.mark.blender
def test_rust_parses_meta_floats_exactly(demo_build):
    """poses_bounds.npy is written by Rust from the plan JSON; with serde_json's default
    parser near/far and translations came out 1 ulp off meta.json (float_roundtrip)."""
    for d in complete_settings(demo_build):
        meta = json.loads((d / "meta.json").read_text())
        pb = np.load(d / "blur_1" / "poses_bounds.npy")
        assert pb[:, 15].tolist() == [v["near"] for v in meta["views"]]
        assert pb[:, 16].tolist() == [v["far"] for v in meta["views"]]
        t = pb[:, :15].reshape(-1, 3, 5)[:, :, 3]
        assert t.tolist() == [[row[3] for row in v["c2w"][:3]] for v in meta["views"]]


def test_bad_input_one_line_nonzero_exit_nothing_half_written(tmp_path):
    proc = run_cli("stats", str(tmp_path / "nope"), "--out", str(tmp_path / "st"), check=False)
    assert proc.returncode == 2
    assert proc.stderr.strip().count("\n") == 0
    assert "no such build directory" in proc.stderr and str(tmp_path / "nope") in proc.stderr
    assert not (tmp_path / "st").exists()

    (tmp_path / "plain").mkdir()
    (tmp_path / "plain" / "notes.txt").write_text("hello")
    proc = run_cli("stats", str(tmp_path / "plain"), check=False)
    assert proc.returncode == 2 and "not a blurset build" in proc.stderr

    build = tmp_path / "build"
    write_synthetic_build(build, 8, views=5)
    out = tmp_path / "st"
    run_cli("stats", str(build), "--out", str(out))
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    assert set(before) >= {"stats.json", "report.md", "views.csv", "blur_weight.png"}
    meta = build / "obj00001_090" / "meta.json"
    meta.write_text(meta.read_text()[:500])  # truncated, in a complete setting
    proc = run_cli("stats", str(build), "--out", str(out), check=False)
    assert proc.returncode == 2
    assert proc.stderr.strip().count("\n") == 0
    assert "corrupt meta.json" in proc.stderr and str(meta) in proc.stderr
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before  # old stats intact

    meta.write_text(json.dumps({**json.loads((build / "obj00000_000" / "meta.json").read_text()),
                                "views": [{"index": 0, "near": 0.0, "far": 1.0, "flatness": 1,
                                           "depth_range": 1, "orientation": 1, "w_u": 1}]}))  # fmt: skip
    proc = run_cli("stats", str(build), "--out", str(out), check=False)
    assert proc.returncode == 2 and "view 0: near 0 must be > 0" in proc.stderr


def test_sharp_only_and_mixed_level_builds(tmp_path):
    """A build without blur levels draws and reports; a setting lacking a level leaves
    empty cells (null in stats.json), not shifted columns."""
    sharp = tmp_path / "sharp"
    write_synthetic_build(sharp, 4, views=5, levels=())
    run_cli("stats", str(sharp), "--out", str(tmp_path / "st1"))
    stats = json.loads((tmp_path / "st1" / "stats.json").read_text())
    assert stats["blur_weight"] == {} and stats["counts"]["images"] == 4 * 5
    check_against_meta(sharp, stats)
    assert (tmp_path / "st1" / "blur_weight.png").stat().st_size > 0

    mixed = tmp_path / "mixed"
    write_synthetic_build(mixed, 3, views=4)
    meta_path = mixed / "obj00000_090" / "meta.json"
    meta = json.loads(meta_path.read_text())
    for v in meta["views"]:
        del v["levels"]["4"]
    meta["levels"] = meta["levels"][:-1]
    meta_path.write_text(json.dumps(meta))
    run_cli("stats", str(mixed), "--out", str(tmp_path / "st2"))
    stats = json.loads((tmp_path / "st2" / "stats.json").read_text())
    check_against_meta(mixed, stats)
    assert stats["blur_weight"]["4"][4:8] == [None] * 4
    assert stats["counts"]["images"] == 3 * 4 * 5 - 4
    rows = list(csv.DictReader((tmp_path / "st2" / "views.csv").open()))
    assert [r["blur_weight_4"] == "" for r in rows] == [False] * 4 + [True] * 4 + [False] * 4
    assert float(rows[4]["blur_weight_3"]) == meta["views"][0]["levels"]["3"]["w_l"]


@pytest.mark.slow  # 20 s of a scale test: `make test`, not the fast layer
def test_ten_thousand_settings_aggregate(tmp_path):
    build = tmp_path / "big"
    t0 = time.perf_counter()
    write_synthetic_build(build, 10_000)
    t_gen = time.perf_counter() - t0
    # the whole command in a fresh process, which reports its own peak memory
    code = (
        "import json, resource, sys, time\n"
        "from blurset.cli import main\n"
        "t = time.perf_counter()\n"
        f"rc = main(['stats', {str(build)!r}, '--out', {str(tmp_path / 'st')!r}, '--quiet'])\n"
        "print(json.dumps({'rc': rc, 's': time.perf_counter() - t,\n"
        "    'maxrss_mb': resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}))\n"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr[-2000:]
    res = json.loads(proc.stdout.strip().splitlines()[-1])
    t0 = time.perf_counter()
    stats = load_stats(build)
    t_agg = time.perf_counter() - t0
    print(
        f"\n10,000 settings: synthetic build {t_gen:.1f} s; aggregation {t_agg:.2f} s; "
        f"blurset stats {res['s']:.1f} s, peak RSS {res['maxrss_mb']:.0f} MB"
    )
    assert res["rc"] == 0 and res["maxrss_mb"] < 2048
    c = stats["counts"]
    assert (c["settings"], c["objects"], c["views"]) == (10_000, 2_500, 340_000)
    assert (c["images"], c["test_settings"], c["test_views"]) == (1_700_000, 2_000, 6_000)
    assert c["failures"] == 1
    assert len(stats["scene_range"]) == len(stats["blur_weight"]["4"]) == 340_000
    on_disk = json.loads((tmp_path / "st" / "stats.json").read_text())
    assert on_disk["counts"] == c and on_disk["summary"] == stats["summary"]
    # spot checks against the files themselves
    first = {}
    for k, s in enumerate(stats["view_setting"]):
        first.setdefault(s, k)
    for si in np.random.default_rng(1).choice(10_000, 25, replace=False).tolist():
        s = stats["settings"][si]
        meta = json.loads((build / s["name"] / "meta.json").read_text())
        k = first[si]
        assert stats["scene_range"][k : k + 34] == [v["far"] / v["near"] for v in meta["views"]]
        assert stats["blur_weight"]["3"][k : k + 34] == [
            v["levels"]["3"]["w_l"] for v in meta["views"]
        ]
        d = meta["bbox_dims"]
        assert stats["scene_dimension"][si] == cbrt_correctly_rounded(d[0] * d[1] * d[2])


def test_blur_levels_count_the_blurry_views_only_and_a_constant_is_one_number(tmp_path):
    """Held-out views holding the sharp image (`test_view_images` sharp) are left out of
    every per-level quantity; a quantity with one value everywhere (a fixed --latents)
    is drawn as that number in one panel, a varying one as a panel per level."""
    build = tmp_path / "b"
    write_synthetic_build(build, 4, views=20, latents=6)  # test views 0 and 16
    for d in complete_settings(build)[:3]:
        meta = json.loads((d / "meta.json").read_text())
        meta["test_view_images"] = "sharp"
        (d / "meta.json").write_text(json.dumps(meta))
    out = tmp_path / "st"
    run_cli("stats", str(build), "--out", str(out))
    stats = json.loads((out / "stats.json").read_text())
    check_against_meta(build, stats)
    assert stats["counts"]["sharp_copy_views"] == 3 * 2
    for lvl in ("1", "4"):
        w = stats["blur_weight"][lvl]
        assert [w[k] is None for k in (0, 16, 20, 36, 40, 56)] == [True] * 6
        # The fourth setting's meta.json predates the field: its test views were blurry.
        assert w[60] is not None and w[76] is not None
    n = {s["quantity"]: s["n"] for s in stats["summary"]}
    assert n["blur_weight_1"] == n["latent_frames_4"] == 4 * 20 - 6
    assert n["w_u"] == 4 * 20
    bar = np.array(Image.new("RGB", (1, 1), BAR)).reshape(3)
    a = np.asarray(Image.open(out / "latent_frames.png").convert("RGB"))
    b = np.asarray(Image.open(out / "blur_weight.png").convert("RGB"))
    one = np.asarray(Image.open(out / "scene_range.png")).shape
    assert a.shape[:2] == one[:2] != b.shape[:2], "one panel, not one per level"
    assert 0.0005 < np.all(a == bar, axis=-1).mean() < 0.02  # the number, no bars
    assert np.all(b == bar, axis=-1).mean() > 0.01
    assert "| sharp_copy_views | 6 |" in (out / "report.md").read_text()


def test_report_names_what_the_numbers_leave_out() -> None:
    """report.md's Skipped section: incomplete settings, failed objects and licence skips,
    the first 50 of each named and the rest counted; no section when nothing was left out."""
    from blurset.commands.stats import _skipped_lines

    none = {"incomplete": [], "failures": [], "licence_skipped": []}
    assert _skipped_lines(none) == []
    stats = {
        "incomplete": [f"s_{i:03d}" for i in range(53)],
        "failures": [{"uid": "bad", "stage": "import", "reason": "draco"}]
        + [{"setting": f"x_{i}", "reason": "timeout"} for i in range(51)],
        "licence_skipped": [{"uid": "nc", "reason": "CC-BY-NC"}],
    }
    lines = _skipped_lines(stats)
    assert lines[:2] == ["## Skipped", ""] and lines[-1] == ""
    assert lines[2].startswith("- incomplete settings: `s_000`, ") and lines[2].endswith(
        "`s_049` and 3 more"
    )
    assert "- failed object `bad` (import): draco" in lines
    assert "- failed setting `x_0` (?): timeout" in lines
    assert "- and 2 more failed objects (failures.jsonl)" in lines
    assert "- skipped object `nc` (CC-BY-NC)" in lines
