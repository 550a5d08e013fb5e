"""Issue 47: the accuracy presets render each blurry image by the method its device makes
for less (`--blur-method auto`, rust/core/src/plan/cost.rs): averaged latent frames on a
CPU, one Cycles motion-blur render on a GPU. CI has no GPU: BLURSET_PRICE_BACKEND (test
only) prices a CPU render as a GPU's, so the motion-blur choice runs through real Blender."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from blurset import plan
from blurset.commands.builder.setting import PRICE_BACKEND_ENV
from blurset.exceptions import ConfigError
from blurset.services.config import make_config

from tests.conftest import run_cli


def _cfg(**flags):
    return make_config({}, {"objects": ["x.glb"], "out": "/tmp/o", **flags})


def _levels(cfg, backend: str | None) -> list[dict]:
    p = plan.plan_setting(cfg, uid="box", theta0_deg=90.0, seed=5, bbox_dims=[1.0, 0.7, 0.5],
                          vertices=np.zeros((0, 3), np.float32), backend=backend)  # fmt: skip
    return [lv for v in p.to_dict()["views"] for lv in v["levels"].values()]


def test_the_presets_price_the_method_and_paper_and_a_given_method_stay():
    cam = {"views": 4, "levels": [1, 4], "resolution": 64}
    for name in ("balanced", "floor", "fast"):
        cfg = _cfg(preset=name, **cam)
        assert cfg.blur_method == "auto"
        # On a CPU: the plan the preset made before the choice existed, frame for frame.
        cpu = _levels(cfg, "CPU")
        assert cpu == _levels(cfg.replace(blur_method="average"), None)
        assert all(lv["method"] == "average" for lv in cpu)
        # On a GPU: one motion-blur render wherever the ghost bound plans several frames.
        for gpu, avg in zip(_levels(cfg, "OPTIX"), cpu, strict=True):
            assert gpu["method"] == ("motion_blur" if avg["latents"] > 1 else "average")
            assert gpu["w_l"] == avg["w_l"] and gpu["motion_px"] == avg["motion_px"]
        with pytest.raises(ValueError, match="blur_method"):
            _levels(cfg, None)  # auto is the device's choice: no backend, no plan
    assert _cfg(preset="paper").blur_method == "average"
    given = _cfg(preset="fast", blur_method="average", **cam)
    assert all(lv["method"] == "average" for lv in _levels(given, "CUDA"))
    # motion_blur beside a preset: kept, the preset's frames by motion dropped, its target kept.
    mb = _cfg(preset="fast", blur_method="motion_blur", **cam)
    assert not mb.latents_auto and mb.target_psnr == 40.0
    assert all(lv["method"] == "motion_blur" for lv in _levels(mb, "CPU"))
    with pytest.raises(ConfigError, match="target_psnr"):
        _cfg(blur_method="auto")


# -- real renders ------------------------------------------------------------------------


@pytest.fixture(scope="module")
def box(tmp_path_factory) -> Path:
    from blurset.services.demo import make_demo_objects

    return make_demo_objects(tmp_path_factory.mktemp("objects"), seed=0)[0]


def _build(out: Path, glb: Path, *extra: str) -> dict:
    run_cli("build", "--objects", str(glb), "--out", str(out), "--views", "3",
            "--levels", "1,4", "--resolution", "16", "--settings-per-object", "1",
            "--seed", "3", "--quiet", "--preset", "fast", *extra)  # fmt: skip
    (s,) = [d for d in out.iterdir() if (d / ".complete").exists()]
    return json.loads((s / "meta.json").read_text()) | {"_dir": s}


def _blurry(meta: dict) -> list[tuple[dict, dict]]:
    """(level plan, image record) of every blurry image rendered (not a sharp copy)."""
    return [
        (v["levels"][level.removeprefix("blur_")], rec)
        for v in meta["views"]
        for level, rec in v["images"].items()
        if level != "sharp"
    ]


@pytest.mark.blender
def test_priced_as_a_gpu_motion_blur_renders_each_image_in_two_calls_a_round(
    tmp_path, box, monkeypatch
):
    monkeypatch.setenv(PRICE_BACKEND_ENV, "cuda")
    a = _build(tmp_path / "a", box, "--passes", "mask")
    b = _build(tmp_path / "b", box, "--passes", "mask")
    choice = a["render"]["blur_choice"]
    assert choice["device"] == "cuda" and choice["model"]["kind"] == "gpu"
    assert "cuda" in choice["reason"] and choice["rule"] == "auto"
    assert choice["images"].get("motion_blur", 0) >= 1
    assert choice["cost_s"]["chosen"] < choice["cost_s"]["average"]
    assert a["sampling"]["blur_method"] == "auto"
    blurry = _blurry(a)
    assert sum(choice["images"].values()) == sum(len(v["levels"]) for v in a["views"])
    assert any(lv["method"] == "motion_blur" for lv, _ in blurry)
    for lv, rec in blurry:
        if lv["method"] == "motion_blur":
            assert lv["latents"] == 1 and lv["motion_blur"]["keys"]
        assert rec["rounds"] >= 1 and rec["samples"] >= 2
    # Every image (sharp, motion blur, or averaged from the one frame its bound plans)
    # renders one call per half a round: the build's calls are 2 x its rounds.
    rounds = sum(rec["rounds"] for v in a["views"] for rec in v["images"].values())
    assert a["timings"]["frames"] == 2 * rounds
    # Same command, same bytes (images, poses, masks) and the same records.
    assert [v["images"] for v in a["views"]] == [v["images"] for v in b["views"]]
    assert a["render"]["blur_choice"] == b["render"]["blur_choice"]

    def data(out: Path) -> list[str]:
        lines = (out / "MANIFEST.sha256").read_text().splitlines()
        return [x for x in lines if x.endswith((".png", ".npy"))]

    assert any("/blur_4/masks/" in x for x in data(tmp_path / "a"))
    run_cli("card", str(tmp_path / "a"), "--out", str(tmp_path / "card.md"))
    chose = ", ".join(f"{n} {k}" for k, n in sorted(choice["images"].items()))
    assert f"auto, priced on cuda: {chose} blurry images" in (tmp_path / "card.md").read_text()
    assert data(tmp_path / "a") == data(tmp_path / "b")
    # An image that needs more samples gets more: the same images to a 6 dB higher target.
    hi = _build(tmp_path / "hi", box, "--target-psnr", "46")
    total = {"lo": 0, "hi": 0}
    for (lv, lo_rec), (hv, hi_rec) in zip(blurry, _blurry(hi), strict=True):
        assert hv["method"] == lv["method"]
        assert hi_rec["samples"] >= lo_rec["samples"]
        total["lo"] += lo_rec["samples"]
        total["hi"] += hi_rec["samples"]
    assert total["hi"] > 1.5 * total["lo"], total


@pytest.mark.blender
def test_on_the_cpu_the_preset_averages_frames(tmp_path, box, monkeypatch):
    monkeypatch.delenv(PRICE_BACKEND_ENV, raising=False)
    meta = _build(tmp_path / "c", box)
    choice = meta["render"]["blur_choice"]
    assert choice["device"] == "cpu" and set(choice["images"]) == {"average"}
    assert all(lv["method"] == "average" for lv, _ in _blurry(meta))
    # The bytes of the preset before the choice existed (its frames averaged, as given).
    given = _build(tmp_path / "g", box, "--blur-method", "average")
    assert "blur_choice" not in given["render"]
    assert [v["levels"] for v in meta["views"]] == [v["levels"] for v in given["views"]]

    def data(out: Path) -> list[str]:
        lines = (out / "MANIFEST.sha256").read_text().splitlines()
        return [x for x in lines if x.endswith((".png", ".npy"))]

    assert len(data(tmp_path / "c")) > 10 and data(tmp_path / "c") == data(tmp_path / "g")
