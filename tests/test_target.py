"""Issue 37: every image rendered to a render-noise target (--target-psnr) and the named
presets (--preset). Options and rules without renders; the properties of the images on
real Blender renders at tiny sizes."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from blurset import image, plan
from blurset.services.config import make_config

from tests.conftest import run_cli

# -- options, presets, the rule (no renders) ---------------------------------------------


def _cfg(**flags):
    return make_config({}, {"objects": ["x.glb"], "out": "/tmp/o", **flags})


def test_a_preset_sets_targets_and_flags_beside_it_override_it():
    floor = _cfg(preset="floor")
    assert floor.preset == "floor" and floor.latents_auto
    assert floor.target_psnr == pytest.approx(58.92)
    assert floor.latent_positions == "stratified" and floor.max_ghost_px == 1.0
    mine = _cfg(preset="floor", target_psnr=52.0, max_ghost_px=0.5)
    assert (mine.target_psnr, mine.max_ghost_px, mine.preset) == (52.0, 0.5, "floor")
    # The paper preset is the paper's construction: the defaults.
    assert _cfg(preset="paper") == _cfg(preset=None).replace(preset="paper")
    assert _cfg(preset="paper").target_psnr is None
    # Every accuracy preset is a target, never a sample count.
    for name in ("balanced", "floor", "fast"):
        sets = plan.preset_values(name)
        assert "target_psnr" in sets and not any("samples" in k for k in sets)


def test_an_accuracy_preset_keeps_its_ghost_bound_at_512_px():
    """latents auto alone stops at 34 frames, which leave gaps of several pixels at level 4
    of a 512 px view; a preset promises its bound, so it takes as many frames as that needs."""
    cam = {"views": 4, "levels": [1, 4], "resolution": 512}
    by_motion = plan.BuildConfig(**cam, latents_auto=True, latent_positions="stratified")
    for name, bound in (("balanced", 1.0), ("fast", 2.0)):
        cfg = _cfg(preset=name, **cam)
        assert cfg.max_ghost_px == bound
        gaps, frames = [], []
        for c in (cfg, by_motion):
            levels = [
                lv
                for v in plan.plan_setting(c, uid="box", theta0_deg=90.0, seed=5,
                                           bbox_dims=[1.0, 0.7, 0.5],
                                           vertices=np.zeros((0, 3), np.float32),
                                           backend="CPU").to_dict()["views"]
                for lv in v["levels"].values()
            ]  # fmt: skip
            gaps.append(max(lv["max_gap_px"] for lv in levels))
            frames.append(max(lv["latents"] for lv in levels))
        assert gaps[0] <= bound < gaps[1], name
        assert frames[0] > 34 == frames[1], name
    # A cap given beside the preset is the user's and is kept.
    assert _cfg(preset="floor", latents_max=34).latents_max == 34


def test_a_build_says_when_latents_max_breaks_the_ghost_bound(tmp_path, standin_blender):
    """--latents auto with a cap below what the motion needs: every setting says so on the
    command line (the gaps were only in meta.json); under a preset, no cap and no word."""
    from tests.conftest import standin_build

    capped = standin_build(tmp_path / "a", standin_blender, "--latents", "auto",
                           "--latents-max", "2", "--levels", "4", "--resolution", "96")  # fmt: skip
    said = [ln for ln in capped.stderr.splitlines() if "--latents-max 2 caps them" in ln]
    assert len(said) == 6, capped.stderr  # the demo's 3 objects x 2 settings
    meta = json.loads(next((tmp_path / "a").glob("demo_box_000/meta.json")).read_text())
    assert max(lv["max_gap_px"] for v in meta["views"] for lv in v["levels"].values()) > 1.0
    free = run_cli("build", "--demo", "--views", "4", "--levels", "4", "--resolution", "96",
                   "--preset", "fast", "--quiet", "--blender", str(standin_blender),
                   "--out", str(tmp_path / "b"))  # fmt: skip
    assert "caps them" not in free.stderr


def test_a_preset_in_toml_and_any_case(tmp_path):
    from blurset.services.config import load_toml

    f = tmp_path / "b.toml"
    f.write_text('preset = "FAST"\nobjects = ["x.glb"]\nout = "o"\n')
    cfg = make_config(load_toml(f), {})
    assert cfg.preset == "fast" and cfg.target_psnr == 40.0 and cfg.max_ghost_px == 2.0


def test_an_empty_out_in_toml_is_refused_by_name(tmp_path):
    from blurset.exceptions import ConfigError
    from blurset.services.config import load_toml

    f = tmp_path / "b.toml"
    f.write_text('out = ""\nobjects = ["x.glb"]\n')
    with pytest.raises(ConfigError, match=r"b.toml: out is empty"):
        make_config(load_toml(f), {}, config_path=f)
    p = run_cli("build", "--config", str(f), check=False)
    assert p.returncode == 2 and "out is empty" in p.stderr
    assert len(p.stderr.strip().splitlines()) == 1


def test_the_demo_under_a_preset_keeps_the_preset_and_its_small_size():
    cfg = make_config({}, {"demo": True, "out": "/tmp/o", "preset": "fast"})
    assert cfg.latents_auto and cfg.target_psnr == 40.0 and cfg.views == 17


@pytest.mark.parametrize(
    ("args", "option"),
    [
        (["--preset", "floor", "--samples-total", "100"], "--samples-total"),
        (["--target-psnr", "50", "--sharp-samples", "100"], "--sharp-samples"),
        (["--target-psnr", "50", "--denoise", "oidn"], "--denoise"),
        (["--target-pilot-samples", "8"], "--target-pilot-samples"),
        (["--target-psnr", "5"], "--target-psnr"),
        (
            ["--target-psnr", "50", "--target-pilot-samples", "64", "--target-max-samples", "32"],
            "--target-pilot-samples",
        ),
    ],
)
def test_bad_target_options_one_line(tmp_path, args, option):
    p = run_cli("build", "--demo", "--out", str(tmp_path / "o"), *args, check=False)
    assert p.returncode == 2, p.stderr
    assert option in p.stderr and len(p.stderr.strip().splitlines()) == 1, p.stderr
    assert not (tmp_path / "o").exists()


def test_next_round_extrapolates_from_the_estimate():
    cfg = _cfg(target_psnr=40.0, target_pilot_samples=32)
    # The pilot: 16 samples a half, split over the frames (at least one each).
    assert plan.target_next_round(cfg, frames=1, spent_per_frame=0, rounds=0) == 16
    assert plan.target_next_round(cfg, frames=5, spent_per_frame=0, rounds=0) == 4
    # 5x the target's MSE after 16: from the pilot alone the noise is taken to fall as
    # samples^-2 (the fewest samples), so sqrt(5)x (aimed 0.2 dB above the target).
    add = plan.target_next_round(cfg, frames=1, spent_per_frame=16, rounds=1, mse=5e-4)
    assert 16 + add == math.ceil(16 * (5 * 10**0.02) ** 0.5)
    # Far from it: at most 8x before the fall of the noise is seen, then the fitted fall.
    more = plan.target_next_round(cfg, frames=1, spent_per_frame=16, rounds=1, mse=1.0)
    assert 16 + more == 128
    fit = plan.target_next_round(
        cfg, frames=1, spent_per_frame=128, rounds=2, mse=1e-2 / 8**1.5, previous=(16, 1e-2)
    )
    assert 128 + fit == math.ceil(128 * (1e-2 / 8**1.5 / 10**-4.02) ** (1 / 1.5))
    assert plan.target_next_round(cfg, frames=1, spent_per_frame=16, rounds=1, mse=9e-5) is None


def test_half_noise_on_object_pixels_only():
    rng = np.random.default_rng(0)
    a = np.zeros((32, 32, 4), np.float32)
    a[8:24, 8:24] = 0.5
    a[8:24, 8:24, 3] = 1.0
    b = a.copy()
    b[8:24, 8:24, :3] += rng.normal(0, 0.01, (16, 16, 3)).astype(np.float32)
    e = image.half_noise(a, b)
    assert e.object_px == 256 and e.coverage == pytest.approx(0.25)
    whole = image.image_error(a, b)
    # The whole frame reads 10·log10(1/coverage) high; the half estimate 6 dB above MSE
    # (to sRGB's bend over a 1 % spread, which it takes about the merged image).
    assert whole.psnr - image.object_error(a, b).psnr == pytest.approx(10 * math.log10(4))
    assert e.psnr - image.object_error(a, b).psnr == pytest.approx(10 * math.log10(4), abs=1e-3)


def test_the_bound_opens_where_a_few_pixels_carry_the_noise():
    # Fireflies (a specular highlight's rare bright samples) in 0.2 % of the pixels: the
    # plain estimate rests on a handful of them, and its bound says so; on smooth noise
    # the bound is the estimate within a fraction of a dB.
    rng = np.random.default_rng(4)
    n = 64 * 64
    base = np.full((64, 64, 4), 0.4, np.float32)
    base[..., 3] = 1.0

    def half(fireflies: bool) -> np.ndarray:
        h = base.copy()
        h[..., :3] += rng.normal(0, 0.002, (64, 64, 1)).astype(np.float32)
        if fireflies:
            hit = rng.random((64, 64)) < 0.002
            h[hit, :3] += 0.4
        return h

    smooth = image.half_noise_bound(half(False), half(False))
    # 2.809 · √(4/3 / n_eff) of the estimate: under half a dB over 4096 pixels.
    assert smooth["estimate"]["psnr"] - smooth["psnr_bound"] < 0.45
    assert smooth["n_eff"] > n / 4
    spiky = image.half_noise_bound(half(True), half(True))
    assert spiky["n_eff"] < 40
    assert spiky["estimate"]["psnr"] - spiky["psnr_bound"] > 1.0


# -- real renders ------------------------------------------------------------------------


@pytest.fixture(scope="module")
def box(tmp_path_factory) -> Path:
    from blurset.services.demo import make_demo_objects

    return make_demo_objects(tmp_path_factory.mktemp("objects"), seed=0)[0]


def _build(out: Path, glb: Path, *extra: str, config: Path | None = None) -> dict:
    args = ["build", "--objects", str(glb), "--out", str(out), "--views", "3",
            "--levels", "1,4", "--resolution", "32", "--settings-per-object", "1",
            "--seed", "3", "--quiet", *extra]  # fmt: skip
    if config is not None:
        args += ["--config", str(config)]
    run_cli(*args)
    (s,) = [d for d in out.iterdir() if (d / ".complete").exists()]
    return json.loads((s / "meta.json").read_text()) | {"_dir": s}


@pytest.mark.blender
def test_target_build_records_every_image_and_gives_the_same_bytes_twice(tmp_path, box):
    a = _build(tmp_path / "a", box, "--preset", "fast")
    b = _build(tmp_path / "b", box, "--preset", "fast")
    assert a["render"]["target_psnr_db"] == 40.0 and a["render"]["preset"] == "fast"
    for v in a["views"]:
        levels = ["sharp"] if v["index"] in a["test_views"] else ["sharp", "blur_1", "blur_4"]
        assert sorted(v["images"]) == sorted(levels)
        for rec in v["images"].values():
            assert rec["samples"] >= 2 and rec["rounds"] >= 1 and 0 < rec["coverage"] < 1
            # The rounds stop on the estimate's bound, which is never above it.
            assert rec["render_psnr_bound_db"] <= rec["render_psnr_db"]
            assert rec["reached"] == (rec["render_psnr_bound_db"] >= 40.0 - 0.25)
    # Same command, same bytes: the rounds follow from rendered pixels only.
    assert [v["images"] for v in a["views"]] == [v["images"] for v in b["views"]]

    def images(out: Path) -> list[str]:
        lines = (out / "MANIFEST.sha256").read_text().splitlines()
        return [x for x in lines if x.endswith((".png", ".npy"))]

    assert len(images(tmp_path / "a")) > 20
    assert images(tmp_path / "a") == images(tmp_path / "b")
    # stats and the card show the distributions of what each image cost and reached.
    run_cli("stats", str(tmp_path / "a"), "--out", str(tmp_path / "st"))
    st = json.loads((tmp_path / "st" / "stats.json").read_text())
    n_images = sum(len(v["images"]) for v in a["views"])
    assert sum(x is not None for xs in st["render_psnr"].values() for x in xs) == n_images
    assert sorted(st["image_samples"]) == ["blur_1", "blur_4", "sharp"]
    assert (tmp_path / "st" / "render_psnr.png").stat().st_size > 1000
    run_cli("card", str(tmp_path / "a"), "--out", str(tmp_path / "card.md"))
    card = (tmp_path / "card.md").read_text()
    assert "| preset | - | fast |" in card and "render PSNR dB (worst, 5th pct, median)" in card


@pytest.mark.blender
def test_every_kind_is_certified_under_a_preset(tmp_path, box):
    """Defocus and shake images render to the target as blur images do: each image of
    each kind has its estimate and bound on object pixels, the rounds stop on the bound,
    and a shake level under latents auto takes the frames its ghost bound needs."""
    kinds = ("--defocus", "1,2", "--shake", "1,4", "--passes", "mask")
    a = _build(tmp_path / "a", box, "--preset", "fast", *kinds)
    b = _build(tmp_path / "b", box, "--preset", "fast", *kinds)
    want = ["sharp", "blur_1", "blur_4", "defocus_1", "defocus_2", "shake_1", "shake_4"]
    for v in a["views"]:
        if v["index"] in a["test_views"]:
            assert sorted(v["images"]) == ["sharp"]
            continue
        assert sorted(v["images"]) == sorted(want)
        for level, rec in v["images"].items():
            assert rec["rounds"] >= 1 and 0 < rec["coverage"] < 1, level
            assert rec["render_psnr_bound_db"] <= rec["render_psnr_db"], level
            assert rec["reached"] and rec["render_psnr_bound_db"] >= 40.0 - 0.25, (level, rec)
        for lvl, shake in v["shake"].items():
            # --preset fast bounds the ghost gap at 2 px: the frames follow the path.
            assert shake["max_gap_px"] <= 2.0, (lvl, shake["max_gap_px"])
            assert len(shake["poses"]) < 4096
        # At least two frames (one is the sharp image); level 4 moves 8 times farther
        # than level 1 and takes more.
        frames = [len(v["shake"][lvl]["poses"]) for lvl in ("1", "4")]
        assert 2 <= frames[0] < frames[1], frames
        # Every frame of a shake image is one of the image's: its samples are even
        # (two halves) and at least one per frame and half.
        assert v["images"]["shake_4"]["samples"] >= 2 * frames[1]
    assert [v["images"] for v in a["views"]] == [v["images"] for v in b["views"]]

    def images(out: Path) -> list[str]:
        lines = (out / "MANIFEST.sha256").read_text().splitlines()
        return [x for x in lines if x.endswith(".png")]

    lines = images(tmp_path / "a")
    assert lines == images(tmp_path / "b")
    assert any("/defocus_2/" in x for x in lines) and any("/shake_4/" in x for x in lines)
    assert run_cli("verify", str(tmp_path / "a")).returncode == 0
    run_cli("stats", str(tmp_path / "a"), "--out", str(tmp_path / "st"))
    st = json.loads((tmp_path / "st" / "stats.json").read_text())
    n_images = sum(len(v["images"]) for v in a["views"])
    assert sum(x is not None for xs in st["render_psnr"].values() for x in xs) == n_images
    assert set(st["render_psnr"]) == set(want)
    assert (tmp_path / "st" / "render_psnr.png").stat().st_size > 1000


@pytest.mark.blender
def test_an_image_that_needs_more_gets_more(tmp_path, box):
    lo = _build(tmp_path / "lo", box, "--target-psnr", "38", "--latents", "auto",
                "--latent-positions", "stratified")  # fmt: skip
    hi = _build(tmp_path / "hi", box, "--target-psnr", "44", "--latents", "auto",
                "--latent-positions", "stratified")  # fmt: skip
    total = {"lo": 0, "hi": 0}
    for vl, vh in zip(lo["views"], hi["views"], strict=True):
        for level, rec in vl["images"].items():
            # 6 dB more accuracy: never fewer samples, and more in all (the pilot is
            # shared, and the noise falls as samples^-α with α between 1 and 2, so 2x to
            # 4x each).
            assert vh["images"][level]["samples"] >= rec["samples"], (level, rec)
            assert vh["images"][level]["render_psnr_db"] >= 44 - 0.25
            total["lo"] += rec["samples"]
            total["hi"] += vh["images"][level]["samples"]
    assert total["hi"] > 1.5 * total["lo"], total
    # Within one build: the samples of an image after its second round follow from its
    # own pilot estimate's bound (variance as samples^-2, aimed 0.2 dB above the target,
    # at most 8x the pilot in one step), so a noisier image at the pilot gets more: done
    # after that round, exactly those; after more rounds, which only add, at least those.
    checked = 0
    for meta, target in ((lo, 38), (hi, 44)):
        for v in meta["views"]:
            for level, rec in v["images"].items():
                if rec["rounds"] < 2:
                    continue
                m = 1 if level == "sharp" else v["levels"][level.removeprefix("blur_")]["latents"]
                pilot = max(1, math.ceil(16 / m))
                aim = target + 0.2
                need = min(pilot * 10 ** ((aim - rec["pilot_psnr_db"]) / 20), 8 * pilot)
                if rec["rounds"] == 2:
                    assert rec["samples"] == pytest.approx(
                        2 * m * need, abs=2 * m + 0.01 * need * m
                    )
                else:
                    assert rec["samples"] >= 2 * m * need - 2 * m, (level, rec)
                checked += 1
    assert checked > 0


@pytest.mark.blender
def test_a_pair_at_zero_motion_reaches_the_target_at_equal_samples(tmp_path, box):
    toml = tmp_path / "still.toml"
    toml.write_text("delta0 = 0.0\n")
    meta = _build(tmp_path / "z", box, "--target-psnr", "42", "--latents", "auto",
                  "--latent-positions", "stratified", config=toml)  # fmt: skip
    s = meta["_dir"]
    for v in meta["views"]:
        if v["index"] in meta["test_views"]:
            continue
        sharp = v["images"]["sharp"]
        for level in ("blur_1", "blur_4"):
            assert v["levels"][level.removeprefix("blur_")]["latents"] == 1
            assert v["images"][level]["samples"] == sharp["samples"]
            assert v["images"][level]["render_psnr_db"] == sharp["render_psnr_db"]
            name = f"{v['index']:03d}.png"
            assert (s / level / "images" / name).read_bytes() == (
                s / "sharp" / "images" / name
            ).read_bytes()
