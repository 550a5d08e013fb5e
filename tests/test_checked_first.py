"""Issue 48: facts a build publishes are the ones it rendered, and options that could
only fail at render are refused first, in one line naming the option. Real commands;
the builds are stand-in builds (no Blender render)."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest
from blurset import layout
from blurset.commands.card import make_card

from tests.conftest import one_error_line, run_cli

# A small target-driven build of the demo objects by the stand-in worker.
TARGET_ARGS = (
    "--demo", "--views", "4", "--levels", "1", "--resolution", "32",
    "--settings-per-object", "1", "--quiet",
)  # fmt: skip


def target_build(out: Path, blender: Path, *args: str, check: bool = True):
    return run_cli("build", *TARGET_ARGS, *args, "--blender", str(blender), "--out", str(out),
                   check=check)  # fmt: skip


def sharp_samples_rendered(build: Path) -> list[int]:
    """What every sharp image of the build rendered, by its own record in meta.json."""
    return [
        v["images"]["sharp"]["samples"]
        for s in layout.complete_settings(build)
        for v in json.loads((s / layout.META).read_text())["views"]
    ]


def card_row(card: str, label: str) -> str:
    """The value cell of the card's construction row `label`."""
    row = next(ln for ln in card.splitlines() if ln.startswith(f"| {label} |"))
    return row.split("|")[3].strip()


# -- a target build states the samples it rendered, never a count it did not ------------


@pytest.mark.parametrize("args", [("--preset", "fast"), ("--target-psnr", "30")])
def test_a_target_build_publishes_the_samples_its_images_rendered(tmp_path, standin_blender,
                                                                 args):  # fmt: skip
    out = tmp_path / "b"
    target_build(out, standin_blender, *args)
    rendered = sharp_samples_rendered(out)
    assert rendered
    doc = json.loads((out / "dataset.json").read_text())
    # No fixed count: the config's derived one is null, as is meta.json's.
    assert doc["config"]["effective_sharp_samples"] is None
    for s in layout.complete_settings(out):
        render = json.loads((s / layout.META).read_text())["render"]
        assert render["sharp_samples"] is None and render["samples_per_latent"] is None
    card = make_card(out)
    cell = card_row(card, "Cycles samples of a sharp image")
    lo, hi = min(rendered), max(rendered)
    spread = str(lo) if lo == hi else f"{lo}–{hi}"
    assert cell.startswith(f"{spread} (median "), cell
    # Every number the card states for it is one the images rendered.
    numbers = {int(n) for n in re.findall(r"\d+", cell.split("(median")[0])}
    assert numbers <= set(rendered), cell
    assert card_row(card, "Cycles samples per latent frame") == "-"
    assert card_row(card, "blurry sample budget") == "-"


def test_a_fixed_count_build_still_states_its_count(standin_build_dir):
    doc = json.loads((standin_build_dir / "dataset.json").read_text())
    sharp = doc["config"]["effective_sharp_samples"]
    assert isinstance(sharp, int) and sharp > 0
    assert card_row(make_card(standin_build_dir), "Cycles samples of a sharp image") == str(sharp)


# -- a cap an image cannot stop at is refused before anything renders -------------------


def test_a_target_cap_under_one_sample_per_frame_and_half_is_refused_naming_the_least(
    tmp_path, standin_blender
):
    # The demo's 6 latent frames need 12 (one per frame and half); 11 failed every
    # object at its first render.
    out = tmp_path / "b"
    proc = target_build(out, standin_blender, "--latents", "6", "--target-psnr", "30",
                        "--target-max-samples", "11", "--target-pilot-samples", "2",
                        check=False)  # fmt: skip
    one_error_line(proc, "--target-max-samples", "11", "at least 12", "fewer latents")
    assert not out.exists()
    # Under latents auto an image may take up to --latents-max frames.
    proc = target_build(out, standin_blender, "--preset", "fast", "--latents-max", "50",
                        "--target-max-samples", "99", check=False)  # fmt: skip
    one_error_line(proc, "--target-max-samples", "99", "at least 100", "lower latents_max")
    assert not out.exists()
    # At the least value every image renders and stops there, as the help promises.
    target_build(out, standin_blender, "--latents", "6", "--target-psnr", "60",
                 "--target-max-samples", "12", "--target-pilot-samples", "2")  # fmt: skip
    metas = [json.loads((s / layout.META).read_text()) for s in layout.complete_settings(out)]
    images = [im for m in metas for v in m["views"] for im in v["images"].values()]
    assert images and all(im["samples"] <= 12 for im in images)
    assert run_cli("verify", str(out)).returncode == 0


# -- depth and normals at a size Blender cannot render are refused --------------------


@pytest.mark.parametrize("resolution", ["8", "12"])
def test_rendered_passes_under_4_px_are_refused_in_one_line(tmp_path, resolution):
    out = tmp_path / "b"
    proc = run_cli("build", "--demo", "--resolution", resolution, "--passes", "depth,mask",
                   "--out", str(out), check=False)  # fmt: skip
    one_error_line(proc, "--passes", "depth_4", "4 px", "downsample", "at least 16")
    assert not out.exists()


def test_masks_at_8_px_and_passes_without_small_copies_still_build(tmp_path, standin_blender):
    for args in (["--passes", "mask"], ["--passes", "depth,normal", "--downsample", "none"]):
        out = tmp_path / args[1].replace(",", "_")
        run_cli("build", "--demo", "--views", "4", "--levels", "1", "--latents", "2",
                "--samples", "2", "--settings-per-object", "1", "--resolution", "8", "--quiet",
                *args, "--blender", str(standin_blender), "--out", str(out))  # fmt: skip
        assert run_cli("verify", str(out)).returncode == 0


# -- defocus levels whose circle would be wider than the image are refused -------------


@pytest.mark.parametrize("levels", ["10", "1,31", "64"])
def test_defocus_levels_past_the_image_width_are_refused_in_one_line(tmp_path, levels):
    out = tmp_path / "b"
    proc = run_cli("build", "--demo", "--defocus", levels, "--out", str(out), check=False)
    one_error_line(proc, "--defocus", "1..=9")
    assert not out.exists()
