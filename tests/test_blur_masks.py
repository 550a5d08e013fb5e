"""A blur level's masks are its own (issue 48): the pixels its exposure covered, the
sharp mask of the view included, not the sharp silhouette alone; verify, the rerun,
open_scene and export (nerfstudio's `mask_path`) take each level's own.

The stand-in worker's frames are a box with alpha 1 or 0, so there the union of the
frames' alpha ≥ 0.5 is exactly where the mean's alpha (kept with --keep-linear) is
above 0; the real renders (partial coverage, Cycles' motion blur, the target's rounds)
are checked in test_real_blurry_masks_cover_the_exposure."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from blurset import layout
from blurset.data import open_scene
from blurset.image import read_exr, read_image

from tests.conftest import copy_build, run_cli, standin_build

# The least alpha that is coverage (rust/core/src/image/mod.rs, COVERAGE_EPS): below it
# is Cycles' rounding on the background.
COVERAGE_EPS = 1e-6
# Three latent frames: a pixel one frame covers has a mean alpha of 1/3, under the half
# that the mean's own mask would need.
MASKS = ("--passes", "mask", "--keep-linear", "--latents", "3")
BLUR = ("blur_1", "blur_2")


@pytest.fixture(scope="module")
def masks_build(tmp_path_factory, standin_blender) -> Path:
    out = tmp_path_factory.mktemp("blur_masks") / "b"
    standin_build(out, standin_blender, *MASKS, "--settings-per-object", "1")
    return out


def _mask(level: Path, name: str, factor: int = 1) -> np.ndarray:
    m = read_image(level / layout.pass_dir("mask", factor) / name)[..., 0]
    assert set(np.unique(m)) <= {0, 255}
    return m > 0


def _blocks(x: np.ndarray, f: int) -> np.ndarray:
    h, w = x.shape
    return x.reshape(h // f, f, w // f, f).mean(axis=(1, 3))


def _check_level(setting: Path, level: str, covered) -> int:
    """Every view's masks of `level` at both sizes against the rule, `covered(alpha)`
    being a pixel's coverage from the mean's alpha; returns the views whose mask is
    larger than the sharp one. A held-out view (the sharp image) has the sharp masks."""
    larger = 0
    for exr in sorted((setting / level / layout.LINEAR).iterdir()):
        name = exr.with_suffix(".png").name
        sharp = setting / layout.SHARP
        if (setting / level / layout.IMAGES / name).read_bytes() == (
            sharp / layout.IMAGES / name
        ).read_bytes():
            for f in (1, 4):
                mask = setting / level / layout.pass_dir("mask", f) / name
                assert mask.read_bytes() == (sharp / layout.pass_dir("mask", f) / name).read_bytes()
            continue
        cover = covered(read_exr(exr)[..., 3]).astype(np.float64)
        for f in (1, 4):
            own, of_sharp = _mask(setting / level, name, f), _mask(sharp, name, f)
            assert np.array_equal(own, (_blocks(cover, f) >= 0.5) | of_sharp), (level, name, f)
        larger += int((_mask(setting / level, name) & ~_mask(sharp, name)).any())
    return larger


def test_a_blur_levels_mask_is_every_pixel_its_frames_covered(masks_build):
    for setting in layout.complete_settings(masks_build):
        for level in BLUR:
            # Binary frames: some frame covers a pixel exactly where the mean's alpha > 0.
            larger = _check_level(setting, level, lambda a: a > 0)
            # The box moved during the exposure: the smear lies outside its silhouette.
            assert larger > 0, (setting.name, level)
        render = json.loads((setting / layout.META).read_text())["render"]
        assert "blur_<l>/masks/" in render["passes_are"]["mask"]


@pytest.mark.parametrize(
    "extra", [("--blur-method", "motion_blur"), ("--target-psnr", "30")], ids=["motion", "target"]
)
def test_motion_blur_and_target_builds_give_blur_levels_their_own_masks(
    tmp_path, standin_blender, extra
):
    """Both other paths to a blurry image write a blur level's own masks by the same
    rule (the stand-in's motion-blur render is one sharp frame, whose alpha > 0 is the
    rule; the target's rounds render each frame again, which changes no union)."""
    out = tmp_path / "b"
    # The stand-in's arguments but --samples, which a render target refuses.
    run_cli("build", "--demo", "--views", "4", "--levels", "2", "--resolution", "32",
            "--settings-per-object", "1", "--quiet", *MASKS, *extra,
            "--blender", str(standin_blender), "--out", str(out))  # fmt: skip
    for setting in layout.complete_settings(out):
        _check_level(setting, "blur_2", lambda a: a > 0)
    assert run_cli("verify", str(out)).returncode == 0


@pytest.mark.parametrize("method", ["average", "motion_blur"])
def test_shake_levels_hold_their_own_masks_too(tmp_path, standin_blender, method):
    """Shake moves the camera during the exposure as motion blur does: its levels hold
    the pixels their exposure covered by the same rule (a lens, one instant at the
    written pose, takes the sharp masks), and verify and nerfstudio's export take them."""
    out = tmp_path / "b"
    standin_build(out, standin_blender, *MASKS, "--levels", "none", "--shake", "2,4",
                  "--latents", "4", "--blur-method", method, "--settings-per-object", "1")  # fmt: skip
    for setting in layout.complete_settings(out):
        assert _check_level(setting, "shake_4", lambda a: a > 0) > 0, setting.name
        _check_level(setting, "shake_2", lambda a: a > 0)
    assert run_cli("verify", str(out)).returncode == 0
    render = json.loads((layout.complete_settings(out)[0] / layout.META).read_text())["render"]
    assert "shake_<l>/masks/" in render["passes_are"]["mask"]
    ns = tmp_path / "ns"
    run_cli("export", str(out), "--for", "nerfstudio", "--levels", "shake_4", "--out", str(ns))
    doc = json.loads((ns / "export.json").read_text())
    for scene, rel in doc["scenes"].items():
        for p in sorted((out / rel / layout.pass_dir("mask", 1)).iterdir()):
            assert (ns / scene / "masks" / p.name).read_bytes() == p.read_bytes(), scene


def test_verify_and_the_rerun_hold_a_blur_levels_masks(masks_build, tmp_path, standin_blender):
    b = copy_build(masks_build, tmp_path / "b")
    setting = layout.complete_settings(b)[0]
    masks = setting / "blur_2" / layout.pass_dir("mask", 4)
    gone = sorted(masks.iterdir())[1]
    gone.unlink()
    proc = run_cli("verify", str(b), check=False)
    assert proc.returncode == 1
    assert f"{setting.name}/blur_2/masks_4/{gone.name}: missing" in proc.stdout, proc.stdout
    standin_build(b, standin_blender, *MASKS, "--settings-per-object", "1")
    assert gone.is_file() and run_cli("verify", str(b)).returncode == 0


def test_open_scene_and_exports_read_each_levels_own_masks(masks_build, tmp_path):
    setting = layout.complete_settings(masks_build)[0]
    for level in (layout.SHARP, "blur_2"):
        s = open_scene(masks_build, setting.name, level, downsample=4)
        names = sorted(p.name for p in (setting / level / layout.images_dir(4)).iterdir())
        want = np.stack([_mask(setting / level, n, 4) for n in names])
        assert np.array_equal(s.masks, want), level
    ns, ll = tmp_path / "ns", tmp_path / "ll"
    run_cli("export", str(masks_build), "--for", "nerfstudio", "--out", str(ns))
    run_cli("export", str(masks_build), "--out", str(ll))
    for root, top in ((ns, ns), (ll, ll / "nerf_llff_data")):
        doc = json.loads((root / "export.json").read_text())
        for scene, rel in doc["scenes"].items():
            level = masks_build / rel
            for f in (1, 4):
                sub = layout.pass_dir("mask", f)
                for p in sorted((level / layout.images_dir(f)).iterdir()):
                    own = (level if level.name in BLUR else level.parent / layout.SHARP) / sub
                    assert (top / scene / sub / p.name).read_bytes() == (
                        own / p.name
                    ).read_bytes(), (scene, sub, p.name)
            if root == ns:
                tf = json.loads((ns / scene / layout.TRANSFORMS).read_text())
                for fr in tf["frames"]:
                    name = Path(fr["file_path"]).name
                    assert fr["mask_path"] == f"masks/{name}", fr


def _views(build: Path, level: str):
    """(sharp mask, own mask, mean alpha) of every blurry view of `level` at full size."""
    out = []
    for setting in layout.complete_settings(build):
        sharp = setting / layout.SHARP
        for exr in sorted((setting / level / layout.LINEAR).iterdir()):
            name = exr.with_suffix(".png").name
            if (setting / level / layout.IMAGES / name).read_bytes() == (
                sharp / layout.IMAGES / name
            ).read_bytes():
                continue  # a held-out view: the sharp image (the stand-in test checks it)
            alpha = read_exr(exr)[..., 3]
            out.append((_mask(sharp, name), _mask(setting / level, name), alpha))
    assert out
    return out


@pytest.mark.blender
def test_real_blurry_masks_cover_the_exposure(tmp_path):
    """Real Cycles renders of a demo box at 32 px, blur level 4. Averaged frames: the mask
    holds the sharp mask and every pixel the mean covers half (a frame must have), and
    no pixel whose mean alpha is under 1/(2 m) (no frame can have covered it half); with
    one latent frame the union is that frame's alpha ≥ 0.5, exactly. Motion blur: the
    render's alpha over Cycles' rounding plus the sharp mask, exactly, which is more than
    its alpha ≥ 0.5; under a target too, where the rounding covers the background.
    Under a render target (rounds, two halves): the sharp mask and the mean's half cover.
    In each, some view's mask is larger than the sharp one: the object moved."""
    from blurset.services.demo import make_demo_objects

    box = make_demo_objects(tmp_path / "objects", seed=0)[0]

    def build(name: str, *extra: str) -> Path:
        out = tmp_path / name
        run_cli("build", "--objects", str(box), "--out", str(out), "--views", "3",
                "--levels", "4", "--resolution", "32", "--settings-per-object", "1",
                "--seed", "3", "--quiet", "--passes", "mask", "--keep-linear", *extra)  # fmt: skip
        return out

    m = 3
    for sharp, own, alpha in (
        views := _views(build("avg", "--samples", "4", "--latents", str(m)), "blur_4")
    ):
        assert not (sharp & ~own).any()
        assert not ((alpha >= 0.5) & ~own).any()
        assert not (own & ~sharp & (alpha < 0.5 / m - 1e-6)).any()
    assert any((own & ~sharp).any() for sharp, own, _ in views)
    for sharp, own, alpha in _views(build("one", "--samples", "4", "--latents", "1"), "blur_4"):
        assert np.array_equal(own, sharp | (alpha >= 0.5))
    views = _views(build("mb", "--samples", "4", "--blur-method", "motion_blur"), "blur_4")
    for sharp, own, alpha in views:
        assert np.array_equal(own, sharp | (alpha > COVERAGE_EPS))
    assert any((own & ~(sharp | (alpha >= 0.5))).any() for sharp, own, alpha in views)
    # Cycles writes a background's alpha as 1 - its transparency summed and scaled by 1/N
    # in f32: where N is not a power of two (a target's rounds) that leaves ~1e-8 over
    # the whole background. It is not coverage: the mask and the target's object pixels
    # leave it out (counted, this image's mask was the whole frame).
    mbt = build("mbt", "--blur-method", "motion_blur", "--target-psnr", "35")
    views = _views(mbt, "blur_4")
    for sharp, own, alpha in views:
        assert np.array_equal(own, sharp | (alpha > COVERAGE_EPS))
    assert any(((alpha > 0) & ~own).sum() > alpha.size // 4 for _, own, alpha in views)
    (setting,) = layout.complete_settings(mbt)
    meta = json.loads((setting / "meta.json").read_text())
    rendered = [v for v in meta["views"] if "blur_4" in v["images"]]
    assert rendered
    for v in rendered:
        name = layout.linear_name(layout.image_name(v["index"], len(meta["views"])))
        alpha = read_exr(setting / "blur_4" / layout.LINEAR / name)[..., 3]
        coverage = v["images"]["blur_4"]["coverage"]
        assert abs(coverage - (alpha > COVERAGE_EPS).mean()) < 0.02, (v["index"], coverage)
    views = _views(build("target", "--target-psnr", "30", "--latents", str(m)), "blur_4")
    for sharp, own, alpha in views:
        assert not (sharp & ~own).any() and not ((alpha >= 0.5) & ~own).any()
    assert any((own & ~sharp).any() for sharp, own, _ in views)


def test_a_build_made_before_blur_masks_is_still_whole_and_read_as_made(
    masks_build, tmp_path, standin_blender
):
    """A setting whose meta.json does not record `level_masks` (every --passes mask build
    before issue 48) holds masks in sharp/ only: verify finds it whole, open_scene and the
    nerfstudio export give every level the sharp masks, and a rerun keeps it."""
    from blurset.services import publish

    old = copy_build(masks_build, tmp_path / "old")
    for setting in layout.complete_settings(old):
        meta = json.loads((setting / layout.META).read_text())
        assert meta["render"].pop("level_masks") is True
        (setting / layout.META).write_text(json.dumps(meta, indent=2))
        for level in BLUR:
            for f in (1, 4):
                d = setting / level / layout.pass_dir("mask", f)
                for p in d.iterdir():
                    p.unlink()
                d.rmdir()
    publish.write_manifest(old)  # its manifest, as that build wrote it
    run_cli("verify", str(old))
    rerun = standin_build(old, standin_blender, *MASKS, "--settings-per-object", "1")
    assert "redoing" not in rerun.stderr, rerun.stderr
    assert not (layout.complete_settings(old)[0] / "blur_1" / "masks").exists()
    run_cli("verify", str(old))
    setting = layout.complete_settings(old)[0]
    sharp = open_scene(old, setting.name, layout.SHARP)
    assert np.array_equal(open_scene(old, setting.name, "blur_2").masks, sharp.masks)
    run_cli("export", str(old), "--for", "nerfstudio", "--out", str(tmp_path / "ns"))
    scene = tmp_path / "ns" / f"{setting.name}__blur_2" / layout.TRANSFORMS
    tf = json.loads(scene.read_text())
    first = scene.parent / tf["frames"][0]["mask_path"]
    name = Path(tf["frames"][0]["file_path"]).name
    assert first.read_bytes() == (setting / layout.SHARP / "masks" / name).read_bytes()
