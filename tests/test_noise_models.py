"""`blurset noise --model` (issue 61): the camera models `unprocess` (Brooks et al. 2019)
and `eld:<camera>` (Wei et al. ELD) on a small LLFF scene: same seed same bytes at any
thread count, noise.json naming the model and its parameters, outputs read back, the
clean views the scene's own files, and an unknown camera refused. Their statistics are
the core's property tests (rust/core/src/noise/raw.rs)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from blurset.image import read_image
from blurset.noise.model import noise_image_model, noise_key, noise_white_balance

from tests.conftest import copy_build, run_cli
from tests.test_noise import blurset_noise, make_scene, ok, read_exr, tree_bytes

MODELS = ("eld:SonyA7S2", "unprocess")


@pytest.fixture
def smooth_scene(tmp_path):
    """Four 40 x 56 views of smooth colour ramps (as a render looks, unlike random codes)."""
    y, x = np.mgrid[0:40, 0:56]
    imgs = []
    for i in range(4):
        rgb = np.stack([x * 4 + i * 5, y * 5 + 20, 200 - x * 2 - i * 3], axis=-1)
        imgs.append(np.clip(rgb, 0, 255).astype(np.uint8))
    return make_scene(tmp_path / "scene", imgs)


def run(scene, out, model, *extra, threads=None):
    return ok(
        blurset_noise(
            scene,
            "--factor",
            2,
            "--model",
            model,
            "--gains",
            1,
            20,
            "--out",
            out,
            *extra,
            threads=threads,
        )
    )


@pytest.mark.parametrize("model", MODELS)
def test_same_seed_same_bytes_and_another_seed_other_noise(model, smooth_scene, tmp_path):
    a, b, c = tmp_path / "a", tmp_path / "b", tmp_path / "c"
    every = "--noisy-test-views"
    run(smooth_scene, a, model, "--seed", 4, every, threads=1)
    run(smooth_scene, b, model, "--seed", 4, every, threads=2)
    run(smooth_scene, c, model, "--seed", 5, every, threads=2)
    ta, tc = tree_bytes(a), tree_bytes(c)
    assert ta == tree_bytes(b)
    images = [k for k in ta if k.endswith((".png", ".exr"))]
    assert len(images) == 2 * 4 * 2
    assert all(ta[k] != tc[k] for k in images)


@pytest.mark.parametrize("model", MODELS)
def test_noise_json_names_the_model_and_outputs_read_back(model, smooth_scene, tmp_path):
    out = tmp_path / "out"
    run(smooth_scene, out, model, "--seed", 2, "--noisy-test-views")
    clean = [
        read_image(p).astype(np.float64) for p in sorted((smooth_scene / "images_2").iterdir())
    ]
    for gain in (1, 20):
        meta = json.loads((out / f"gain_{gain}" / "noise.json").read_text())
        raw = meta["raw_model"]
        assert raw["name"] == model and "demosaic" in raw and raw["cfa"] == "RGGB"
        assert meta["model"].startswith("raw pipeline") and meta["gain"] == gain
        assert meta["sigma_read"] > 0 and meta["sigma_shot"] > 0
        if model.startswith("eld:"):
            assert raw["camera"] == "SonyA7S2" and "Vandermode/ELD" in raw["source"]
            assert raw["system_gain_k"] == pytest.approx(gain * raw["k_min"])
            assert raw["read_noise"]["distribution"] == "tukey-lambda"
            assert raw["bits"] == 14 and raw["black_level_dn"] < raw["white_level_dn"]
            assert raw["iso_stops_above_k_min"] == pytest.approx(np.log2(gain))
        else:
            assert "Brooks" in raw["source"] and len(raw["ccm_weights"]) == 4
            assert raw["shot_noise"] == pytest.approx(gain * raw["shot_noise_gain_1"])
        for i, src in enumerate(clean):
            png = read_image(out / f"gain_{gain}" / "images_2" / f"img{i:03d}.png")
            exr = read_exr(out / f"gain_{gain}" / "linear_2" / f"img{i:03d}.exr")
            assert png.shape == src.shape and png.dtype == np.uint8
            assert exr.shape[:2] == src.shape[:2] and np.isfinite(exr).all()
            diff = png.astype(np.float64) - src
            # Noisy, and the noise is zero-mean in raw: the image keeps its level up to
            # what the curves and clipping make of it, small beside the noise.
            assert np.abs(diff).mean() > 0.2
            assert abs(diff.mean()) < 0.35 * np.abs(diff).mean() + 0.5, (model, gain)
    # More gain, more noise (through the whole pipeline, in codes).
    err = {
        g: np.mean(
            [
                np.abs(read_image(out / f"gain_{g}" / "images_2" / f"img{i:03d}.png") - src).mean()
                for i, src in enumerate(clean)
            ]
        )
        for g in (1, 20)
    }
    assert err[20] > 2 * err[1], err
    record = json.loads((out / "noise_scene.json").read_text())
    assert record["model"] == model


@pytest.mark.parametrize("model", MODELS)
def test_the_binding_makes_what_the_command_writes(model, smooth_scene, tmp_path):
    out = tmp_path / "out"
    run(smooth_scene, out, model, "--seed", 9)
    src = read_image(smooth_scene / "images_2" / "img001.png")
    lin = ((src.astype(np.float64) / 255) ** 2.2).astype(np.float32)
    linear, png, record = noise_image_model(
        lin, model=model, gain=20, seed=9, key=noise_key(9, 20), view=1, gamma="2.2",
        white_balance=noise_white_balance(9),
    )  # fmt: skip
    assert (
        json.loads(record) == json.loads((out / "gain_20" / "noise.json").read_text())["raw_model"]
    )
    np.testing.assert_array_equal(png, read_image(out / "gain_20" / "images_2" / "img001.png"))
    np.testing.assert_allclose(
        linear, read_exr(out / "gain_20" / "linear_2" / "img001.exr"), atol=1e-6
    )


def test_clean_views_are_the_scenes_own_files(smooth_scene, tmp_path):
    out = tmp_path / "out"
    run(smooth_scene, out, "eld:CanonEOS70D", "--clean-views", 2)
    src = smooth_scene / "images_2"
    for i in range(4):
        same = (out / "gain_20" / "images_2" / f"img{i:03d}.png").read_bytes() == (
            src / f"img{i:03d}.png"
        ).read_bytes()
        assert same == (i % 2 == 0), i


def test_an_unknown_camera_names_the_flag_and_the_cameras(smooth_scene, tmp_path):
    proc = blurset_noise(smooth_scene, "--model", "eld:Pixel4", "--out", tmp_path / "o")
    assert proc.returncode != 0
    assert "--model" in proc.stderr and "SonyA7S2" in proc.stderr
    assert not (tmp_path / "o").exists()


def test_build_mode_verify_and_export_read_a_camera_model(standin_build_dir, tmp_path):
    """`blurset noise BUILD --model eld:NikonD850`: its downsampled copies, `verify`, and
    an export with the noise read it as they read the paper model's."""
    b = copy_build(standin_build_dir, tmp_path / "b")
    n = tmp_path / "n"
    args = ("noise", str(b), "--out", str(n), "--gains", "1", "4", "--levels", "blur_1")
    run_cli(*args, "--model", "eld:NikonD850", "--quiet")
    doc = json.loads((n / "noise_dataset.json").read_text())
    assert doc["params"]["model"] == "eld:NikonD850"
    records = sorted(n.rglob("noise.json"))
    assert records
    for p in records:
        meta = json.loads(p.read_text())
        assert meta["raw_model"]["camera"] == "NikonD850"
        assert "raw pipeline" in meta["clean"] and "/ wb" not in meta["clean"]
        for f in meta["files"]:
            for factor in [1, *meta["downsample"]]:
                sub = "" if factor == 1 else f"_{factor}"
                png = p.parent / f["image"].replace("images/", f"images{sub}/")
                assert read_image(png).shape[2] == 3
    assert run_cli("verify", str(n)).returncode == 0
    # A rerun with another model is refused (its options differ), nothing rewritten.
    again = run_cli(*args, "--model", "unprocess", "--quiet", check=False)
    assert again.returncode != 0 and "model" in again.stderr
    run_cli("export", str(b), "--out", str(tmp_path / "en"), "--noise", str(n))
    scenes = sorted((tmp_path / "en" / "nerf_llff_data").glob("*__blur_1__gain_4"))
    assert scenes and all(any((s / "images").glob("*.png")) for s in scenes)
    run_cli("card", str(b), "--noise", str(n), "--out", str(tmp_path / "card.md"))
    card = (tmp_path / "card.md").read_text()
    assert "`--model eld:NikonD850`" in card and "LLFF-N style" not in card
    # The Hub export carries each image's noise.json (its raw_model included), verified.
    hub = tmp_path / "hub"
    run_cli("export", str(b), "--out", str(hub), "--for", "hub", "--noise", str(n))
    assert run_cli("verify", str(hub)).returncode == 0
    import pyarrow.parquet as pq

    shard = next(p for p in sorted(hub.rglob("*.parquet")) if "gain_4" in str(p))
    cells = pq.read_table(shard, columns=["noise"]).column("noise").to_pylist()
    assert cells and all(json.loads(c)["raw_model"]["system_gain_k"] > 0 for c in cells)
