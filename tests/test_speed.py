"""Issue 6, speed against accuracy: --latents auto, --samples-total, --blur-method
motion_blur and `blurset tradeoff`, on real Blender renders at tiny sizes."""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from tests.conftest import run_cli

LEVEL_DIRS = ["sharp", "blur_1", "blur_4"]


@pytest.fixture(scope="module")
def demo_glbs(tmp_path_factory) -> list[Path]:
    from blurset.services.demo import make_demo_objects

    return make_demo_objects(tmp_path_factory.mktemp("objects"), seed=0)


def _settings(out: Path) -> list[Path]:
    return sorted(d for d in out.iterdir() if (d / ".complete").exists())


def _check_llff(setting: Path, views: int) -> None:
    """Every level a complete LLFF scene with the pose p of every view."""
    poses = [np.load(setting / lvl / "poses_bounds.npy") for lvl in LEVEL_DIRS]
    for lvl, pb in zip(LEVEL_DIRS, poses, strict=True):
        assert pb.shape == (views, 17)
        names = sorted(p.name for p in (setting / lvl / "images").iterdir())
        assert names == [f"{i:03d}.png" for i in range(views)]
        assert np.array_equal(pb, poses[0]), f"{lvl}: the pose of every level is p"


def _plan_dict(plan) -> dict:
    return plan.to_dict()


# -- the plan, no rendering --------------------------------------------------------------


def test_plan_auto_bound_budget_split_and_motion_keys():
    from blurset.plan import BuildConfig, plan_setting

    def plan(**kw) -> dict:
        cfg = BuildConfig(views=8, levels=[1, 4], resolution=128, **kw)
        return _plan_dict(
            plan_setting(
                cfg,
                uid="box",
                theta0_deg=90.0,
                seed=5,
                bbox_dims=[1.0, 0.7, 0.5],
                vertices=np.zeros((0, 3), np.float32),
            )
        )

    auto = plan(latents_auto=True, latent_positions="stratified", max_ghost_px=0.5,
                latents_max=200, samples_total=100, blur_budget="flat")  # fmt: skip
    fixed = plan(latents=7, samples_total=100, blur_budget="flat")
    # Under parity (the default) the same budget buys every level ⌈100 · m^0.4 / m⌉.
    for v in plan(latents=7, samples_total=100)["views"]:
        assert {lp["samples_per_frame"] for lp in v["levels"].values()} == {32}
    for va, vf in zip(auto["views"], fixed["views"], strict=True):
        for lvl in ("1", "4"):
            a, f = va["levels"][lvl], vf["levels"][lvl]
            assert a["max_gap_px"] <= 0.5 and a["latents"] == len(a["latent_frames"])
            assert a["samples_per_frame"] == math.ceil(100 / a["latents"])
            assert f["samples_per_frame"] == 15 and f["latents"] == 7
            assert (a["w_l"], a["motion_px"]) == (f["w_l"], f["motion_px"])  # same segment
        assert va["levels"]["1"]["latents"] < va["levels"]["4"]["latents"]
    mb = plan(blur_method="motion_blur", samples=4, latents=34)
    for v in mb["views"]:
        lp = v["levels"]["4"]
        keys = lp["motion_blur"]["keys"]
        assert lp["samples_per_frame"] == 4 * 34 and lp["latents"] == 1
        assert len(keys) == 2 ** lp["motion_blur"]["motion_steps"] + 1
        assert keys[0]["c2w"] == v["c2w"] and keys[-1]["t"] == 1.0


@pytest.mark.parametrize(
    ("args", "option"),
    [
        (["--latents-max", "10"], "--latents-max"),
        (["--max-ghost-px", "2"], "--max-ghost-px"),
        (["--latents", "auto", "--max-ghost-px", "0"], "--max-ghost-px"),
        (["--latents", "lots"], "--latents"),
        (["--samples-total", "0"], "--samples-total"),
        (["--blur-method", "motion_blur", "--latents", "auto"], "--latents auto"),
        (["--blur-method", "motion_blur", "--latent-positions", "stratified"],
         "--latent-positions"),
    ],
)  # fmt: skip
def test_bad_speed_options_one_line(tmp_path, args, option):
    p = run_cli("build", "--demo", "--out", str(tmp_path / "o"), *args, check=False)
    assert p.returncode == 2, p.stderr
    assert option in p.stderr and len(p.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "o").exists()


# -- builds -----------------------------------------------------------------------------


@pytest.mark.blender
def test_build_latents_auto_with_sample_budget(tmp_path, demo_glbs):
    out = tmp_path / "out"
    run_cli("build", "--objects", str(demo_glbs[0]), "--out", str(out), "--views", "3",
            "--levels", "1,4", "--resolution", "48", "--settings-per-object", "1",
            "--latents", "auto", "--latent-positions", "stratified", "--max-ghost-px", "1",
            "--latents-max", "40", "--samples-total", "12", "--seed", "2", "--quiet")  # fmt: skip
    (s,) = _settings(out)
    _check_llff(s, 3)
    meta = json.loads((s / "meta.json").read_text())
    assert meta["sampling"]["latents_auto"] and meta["sampling"]["max_ghost_px"] == 1.0
    assert meta["render"]["samples_total"] == 12 and meta["render"]["latents"] == "auto"
    assert meta["render"]["sharp_samples"] == 12 and meta["render"]["blur_budget"] == "parity"
    frames = 0
    for v in meta["views"]:
        for lp in v["levels"].values():
            assert lp["max_gap_px"] <= 1.0 or lp["latents"] == 40
            assert lp["latents"] == len(lp["latent_frames"])
            # The default parity budget: each level's own m gets m^0.4 times the budget.
            m = lp["latents"]
            assert lp["samples_per_frame"] == math.ceil(12 * m**0.4 / m)
            # A test view's blur levels are copies of its sharp image: nothing rendered.
            frames += 0 if v["index"] in meta["test_views"] else lp["latents"]
        assert v["levels"]["1"]["latents"] < v["levels"]["4"]["latents"]
    assert meta["timings"]["frames"] == 3 + frames
    cfg = json.loads((out / "dataset.json").read_text())["config"]
    assert cfg["latents"] == "auto" and cfg["samples_total"] == 12


@pytest.mark.blender
def test_build_motion_blur_one_render_per_blurry_image(tmp_path, demo_glbs):
    out = tmp_path / "out"
    run_cli("build", "--objects", str(demo_glbs[1]), "--out", str(out), "--views", "2",
            "--levels", "1,4", "--resolution", "48", "--settings-per-object", "1",
            "--blur-method", "motion_blur", "--samples-total", "16", "--quiet")  # fmt: skip
    (s,) = _settings(out)
    _check_llff(s, 2)
    meta = json.loads((s / "meta.json").read_text())
    # Sharp + one render per level per view, but test view 0 renders only its sharp image.
    assert meta["test_views"] == [0]
    assert meta["timings"]["frames"] == 2 * 3 - 2
    assert meta["render"]["blur_method"] == "motion_blur"
    for v in meta["views"]:
        for lp in v["levels"].values():
            assert lp["method"] == "motion_blur" and lp["samples_per_frame"] == 16
            mb = lp["motion_blur"]
            assert len(mb["keys"]) == 2 ** mb["motion_steps"] + 1
            assert "c2w" not in mb["keys"][0] and mb["interpolation_error_px"] <= 0.02
    # View 1: view 0 is a test view, whose blur levels hold the sharp image.
    sharp = np.asarray(Image.open(s / "sharp" / "images" / "001.png"), float)
    blur4 = np.asarray(Image.open(s / "blur_4" / "images" / "001.png"), float)
    assert np.abs(sharp - blur4).mean() > 1.0  # the camera moved during the shutter


# -- motion blur = latent average in expectation ----------------------------------------


def _psnr(a: np.ndarray, b: np.ndarray) -> float:
    from blurset.image import image_error

    return image_error(a, b).psnr


@pytest.mark.blender
def test_motion_blur_equals_a_high_m_average_of_the_same_segment(tmp_path, demo_glbs):
    from blurset.image import Accumulator
    from blurset.plan import BuildConfig, plan_setting
    from blurset.services.worker_client import Worker

    res, view, level = 64, 2, "4"
    with Worker(timeout=300) as w:
        info = w.load(demo_glbs[0], tmp_path / "v.npy")
        verts = np.ascontiguousarray(np.load(tmp_path / "v.npy"), dtype=np.float32)

        def image(**kw):
            cfg = BuildConfig(views=view + 1, levels=[4], resolution=res, **kw)
            setting = plan_setting(
                cfg,
                uid="t",
                theta0_deg=30.0,
                seed=9,
                bbox_dims=info["bbox_dims"],
                vertices=verts,
            )
            plan = setting.to_dict()["views"][view]
            lp = plan["levels"][level]
            frames = setting.level_renders(view, int(level), str(tmp_path / "f"))
            if kw.get("latents") == 96:  # the reference: noise independent of the others'
                for f in frames:
                    f["seed"] = (f["seed"] ^ 0x5BD1E995) & 0x7FFFFFFF
            if kw.get("latents") == 1:  # the sharp image at p, same budget
                frames = [dict(frames[0], c2w=plan["c2w"])]
            acc = Accumulator(res, res)
            n = []

            def on_frame(_i, p, origin):
                acc.add_exr(p, origin)
                Path(p).unlink()
                n.append(p)

            w.render(frames, resolution=res, fov_deg=cfg.fov_deg, samples=1, on_frame=on_frame)
            return acc.mean(), len(n), lp

        ref, n_ref, lp = image(latents=96, latent_positions="stratified", samples=8)
        mb, n_mb, lp_mb = image(blur_method="motion_blur", samples_total=384)
        sharp, _, _ = image(latents=1, samples_total=384)
        few, _, _ = image(latents=3, latent_positions="stratified", samples_total=384)
    assert n_mb == 1 and n_ref == 96
    assert lp["motion_px"] > 8  # a real blur: several pixels of motion at 64 px
    q_mb, q_sharp, q_few = _psnr(mb, ref), _psnr(sharp, ref), _psnr(few, ref)
    # Same trajectory, same expectation: only render noise separates them (measured:
    # 45 dB; a 3-frame average 33 dB, the sharp image at p 18 dB).
    assert q_mb > 38.0, (q_mb, q_sharp, q_few)
    # The test has teeth: no blur, or a 3-frame average (ghosts), is far worse.
    assert q_mb > q_sharp + 8 and q_mb > q_few + 3, (q_mb, q_sharp, q_few)


# -- blurset tradeoff --------------------------------------------------------------------


@pytest.mark.blender
def test_tradeoff_quick_writes_csv_plot_and_a_recommendation(tmp_path, demo_glbs):
    out = tmp_path / "tradeoff"
    p = run_cli("tradeoff", "--object", str(demo_glbs[0]), "--out", str(out), "--quick",
                "--resolution", "64", "--quiet")  # fmt: skip
    assert "recommendation: --" in p.stdout
    rows = list(csv.DictReader((out / "tradeoff.csv").open()))
    for col in ("method", "sampling", "latents", "samples_per_frame", "seconds", "psnr"):
        assert col in rows[0]
    (ref,) = [r for r in rows if r["role"] == "reference"]
    assert int(ref["latents"]) == 64 and int(ref["samples_per_frame"]) == 32
    cands = [r for r in rows if r["role"] == "candidate"]
    assert {r["method"] for r in cands} == {"average", "motion_blur"}
    assert {r["sampling"] for r in cands} >= {"random", "stratified", "auto-stratified"}
    for r in cands:
        assert float(r["seconds"]) > 0 and 10.0 < float(r["psnr"]) < 100.0
        assert int(r["latents"]) >= 1 and int(r["samples_per_frame"]) >= 1
    assert any(r["pareto"] == "True" for r in cands)

    def psnr(sampling: str, m: int, budget: int) -> float:
        (r,) = [r for r in cands if r["sampling"] == sampling and int(r["latents"]) == m
                and int(r["budget"]) == budget]  # fmt: skip
        return float(r["psnr"])

    for sampling in ("random", "stratified"):
        for m in (2, 8, 32):  # more samples for the same frames: less noise
            assert psnr(sampling, m, 16) < psnr(sampling, m, 64)
        # More frames at the same samples per frame (8, then 2): fewer ghosts, less noise.
        assert psnr(sampling, 2, 16) < psnr(sampling, 8, 64)
        assert psnr(sampling, 8, 16) < psnr(sampling, 32, 64)
        # Two frames leave ~8 px gaps (ghosts): any budget spread over 8 frames beats them.
        assert psnr(sampling, 2, 64) < psnr(sampling, 8, 16)
    for r in cands:
        if r["sampling"] == "auto-stratified":
            assert float(r["max_gap_px"]) <= 1.0  # the 1 px ghost bound, from the plan
    # Render error (issue 15): against a converged render of the same positions, two
    # frames' ghosts do not count; their 2 large sample blocks carry about the sharp
    # image's noise at the same budget.
    for r in cands:
        assert 10.0 < float(r["render_psnr"]) < 100.0
        assert 10.0 < float(r["sharp_render_psnr"]) < 100.0
        if r["method"] == "average" and int(r["latents"]) == 2:
            assert float(r["render_psnr"]) > float(r["psnr"]) + 5.0
            assert float(r["render_psnr"]) > float(r["sharp_render_psnr"]) - 1.0
    sharp_by_budget = {int(r["budget"]): float(r["sharp_render_psnr"]) for r in cands}
    assert sharp_by_budget[16] < sharp_by_budget[64]  # one sharp image per budget
    assert len({(int(r["budget"]), r["sharp_render_psnr"]) for r in cands}) == 2
    png = Image.open(out / "tradeoff.png")
    assert png.size[0] >= 800 and png.size[1] >= 500
    assert json.loads((out / "tradeoff.json").read_text())["recommendation"]["best"]
