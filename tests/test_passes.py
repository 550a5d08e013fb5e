"""`build --passes depth,normal,mask` (issue 35): per-view depth, normals and masks in
the sharp level, written through the layout, checked by verify and the rerun, read by
open_scene and carried by export (nerfstudio gets its own depth PNGs and keys).

The stand-in worker's geometry is analytic (a box), so the orchestration is checked
exactly here; the real renders (Cycles' passes against the meshes) are checked in
test_real_passes_land_on_the_mesh."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from blurset import layout
from blurset.data import open_scene
from blurset.image import read_depth, read_exr, read_image

from tests.conftest import ROOT, copy_build, run_cli, shared_if_present, standin_build

PASSES = ("--passes", "depth,normal,mask", "--keep-linear")


@pytest.fixture(scope="module")
def passes_build(tmp_path_factory, standin_blender) -> Path:
    out = tmp_path_factory.mktemp("passes") / "b"
    standin_build(out, standin_blender, *PASSES)
    return out


def _setting(build: Path) -> Path:
    return layout.complete_settings(build)[0]


def _rays(setting: Path, factor: int) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """Each view's c2w (OpenGL) and the pixel-centre rays' camera directions (z = -1) at
    the size of `images_<factor>/`."""
    tf = json.loads((setting / layout.SHARP / layout.TRANSFORMS).read_text())
    f, w = tf["fl_x"] / factor, tf["w"] // factor
    px = (np.arange(w) + 0.5 - w / 2) / f
    x, y = np.meshgrid(px, -px)
    dirs = np.stack([x, y, -np.ones_like(x)], -1)
    c2w = np.array([fr["transform_matrix"] for fr in tf["frames"]])
    return c2w, dirs, [Path(fr["file_path"]).name for fr in tf["frames"]]


@pytest.mark.parametrize("factor", [1, 4])
def test_depth_puts_every_pixel_on_the_box_and_normals_are_its_faces(passes_build, factor):
    setting = _setting(passes_build)
    half = np.array(json.loads((setting / layout.META).read_text())["object"]["bbox_dims"]) / 2
    c2w, dirs, names = _rays(setting, factor)
    for m, name in zip(c2w, names, strict=True):
        depth = read_depth(
            setting
            / layout.SHARP
            / layout.pass_dir("depth", factor)
            / layout.pass_file("depth", name)
        )
        normal = read_exr(
            setting
            / layout.SHARP
            / layout.pass_dir("normal", factor)
            / layout.pass_file("normal", name)
        )[..., :3]
        hit = depth > 0
        assert 0 < hit.mean() < 1
        p = (dirs * depth[..., None]) @ m[:3, :3].T + m[:3, 3]
        # On the box: the largest |coordinate| / half-side is 1 there.
        on = np.max(np.abs(p[hit]) / half, axis=-1)
        assert np.abs(on - 1).max() < 1e-5
        axis = np.argmax(np.abs(p[hit]) / half, axis=-1)
        want = np.zeros_like(p[hit])
        want[np.arange(len(axis)), axis] = np.sign(p[hit][np.arange(len(axis)), axis])
        assert np.abs(normal[hit] - want).max() < 1e-6
        assert not normal[~hit].any()


def test_masks_are_the_sharp_images_coverage_at_every_size(passes_build):
    for setting in layout.complete_settings(passes_build):
        for exr in sorted((setting / layout.SHARP / layout.LINEAR).iterdir()):
            alpha = read_exr(exr)[..., 3]
            name = exr.with_suffix(".png").name
            for f in (1, 4):
                mask = read_image(setting / layout.SHARP / layout.pass_dir("mask", f) / name)
                assert mask.shape[2] == 1 and set(np.unique(mask)) <= {0, 255}
                h, w = alpha.shape
                cover = alpha.reshape(h // f, f, w // f, f).mean(axis=(1, 3))
                assert np.array_equal(mask[..., 0] > 0, cover >= 0.5)


def test_meta_says_what_each_pass_holds_and_a_default_build_has_none(
    passes_build, standin_build_dir
):
    render = json.loads((_setting(passes_build) / layout.META).read_text())["render"]
    assert render["passes"] == ["depth", "normal", "mask"]
    assert "viewing axis" in render["passes_are"]["depth"]
    assert "world frame" in render["passes_are"]["normal"]
    plain = _setting(standin_build_dir)
    assert "passes" not in json.loads((plain / layout.META).read_text())["render"]
    assert not any((plain / layout.SHARP / layout.pass_dir(k, 1)).exists() for k in layout.PASSES)


def test_the_option_reads_names_in_any_order_and_refuses_others(tmp_path, standin_blender):
    out = tmp_path / "b"
    proc = standin_build(out, standin_blender, "--passes", "mask,depth,albedo", check=False)
    assert proc.returncode != 0 and not out.exists()
    line = proc.stderr.strip().splitlines()[-1]
    assert "passes" in line and "depth, normal, mask" in line, proc.stderr
    standin_build(out, standin_blender, "--passes", "Mask, depth", "--settings-per-object", "1")
    setting = _setting(out)
    render = json.loads((setting / layout.META).read_text())["render"]
    assert render["passes"] == ["depth", "mask"]
    assert not (setting / layout.SHARP / "normals").exists()


def test_verify_and_a_rerun_catch_a_missing_or_cut_depth_file(
    passes_build, tmp_path, standin_blender
):
    b = copy_build(passes_build, tmp_path / "b")
    setting = _setting(b)
    depth = setting / layout.SHARP / layout.pass_dir("depth", 1)
    gone, cut = sorted(depth.iterdir())[:2]
    gone.unlink()
    cut.write_bytes(cut.read_bytes()[: cut.stat().st_size // 2])
    proc = run_cli("verify", str(b), check=False)
    assert proc.returncode == 1
    assert f"{setting.name}/sharp/depth/{gone.name}: missing" in proc.stdout, proc.stdout
    assert f"{setting.name}/sharp/depth/{cut.name}: does not decode" in proc.stdout, proc.stdout
    # The rerun's cheap check redoes the setting, and the build is whole again.
    standin_build(b, standin_blender, *PASSES)
    assert run_cli("verify", str(b)).returncode == 0


def test_open_scene_gives_depth_normals_and_masks_at_the_size_read(passes_build, standin_build_dir):
    setting = _setting(passes_build).name
    s = open_scene(passes_build, setting, "blur_1", downsample=4)
    n, h, w = s.images.shape[:3]
    assert s.depth.shape == (n, h, w) and s.normals.shape == (n, h, w, 3)
    assert s.masks.dtype == bool and s.masks.shape == (n, h, w)
    full = open_scene(passes_build, setting)
    assert np.array_equal(full.masks, full.depth > 0)  # the box: no partial cover edge case
    plain = open_scene(standin_build_dir, _setting(standin_build_dir).name)
    assert plain.depth is None and plain.normals is None and plain.masks is None


def test_exports_carry_the_passes_and_nerfstudio_gets_millimetres(passes_build, tmp_path):
    ns, ll = tmp_path / "ns", tmp_path / "ll"
    run_cli("export", str(passes_build), "--for", "nerfstudio", "--out", str(ns))
    run_cli("export", str(passes_build), "--out", str(ll))
    doc = json.loads((ns / "export.json").read_text())
    assert doc["passes"] == ["depth", "normal", "mask"]
    for scene in doc["scenes"]:
        d = ns / scene
        tf = json.loads((d / layout.TRANSFORMS).read_text())
        setting = passes_build / doc["scenes"][scene].split("/")[0] / layout.SHARP
        for fr in tf["frames"]:
            name = Path(fr["file_path"]).name
            assert fr["mask_path"] == f"masks/{name}" and (d / fr["mask_path"]).is_file()
            mm = read_image(d / fr["depth_file_path"])
            assert mm.dtype == np.uint16
            for sub, f in (("depths", 1), ("depths_4", 4)):
                mm = read_image(d / sub / name)[..., 0].astype(np.float64)
                depth = read_depth(
                    setting / layout.pass_dir("depth", f) / layout.pass_file("depth", name)
                )
                assert np.abs(mm / 1000 - depth).max() <= 0.0005 + 1e-6
                assert np.array_equal(mm > 0, depth > 0)
    for scene in json.loads((ll / "export.json").read_text())["scenes"]:
        d = ll / "nerf_llff_data" / scene
        for k in layout.PASSES:
            for f in (1, 4):
                assert (d / layout.pass_dir(k, f)).is_dir()
        assert "depth_file_path" not in (d / layout.TRANSFORMS).read_text()


@pytest.mark.blender
def test_real_passes_land_on_the_mesh(tmp_path):
    """Real Cycles renders of the demo objects and the textured models of ../shared/data
    (BoxTextured, MapPin, WaterBottle with its normal map, the thin panel):
    every depth pixel put back through the written pose lies on the mesh (the worker's
    own import and normalization, a BVH of its triangles) within a fraction of a pixel;
    normals are the mesh's (flat faces exactly; smooth shading and normal maps within a
    few degrees at the median) and face the camera; masks are the coverage; the same
    command writes the same depth and normal bytes."""
    names = ("khronos_BoxTextured.glb", "sketchfab_MapPin.glb", "WaterBottle_blender_reexport.glb",
             "textured_panel_blender_reexport.glb")  # fmt: skip
    glbs = [shared_if_present("glb", n) for n in names]
    args = ["--views", "3", "--levels", "1", "--resolution", "48", "--samples", "8",
            "--settings-per-object", "1", "--quiet", *PASSES]  # fmt: skip
    out, models = tmp_path / "b", tmp_path / "models"
    run_cli("build", "--demo", *args, "--out", str(out))
    settings = layout.complete_settings(out)
    if any(glbs):
        run_cli("build", "--objects", *(str(g) for g in glbs if g), *args, "--out", str(models))
        settings += layout.complete_settings(models)
    for setting in settings:
        src = json.loads((setting / layout.META).read_text())["object"]["path"]
        glb = next((g for g in glbs if g and g.name == src), out / layout.DEMO_OBJECTS / src)
        res = tmp_path / f"{setting.name}.json"
        subprocess.run([sys.executable, str(ROOT / "tests" / "geometry_probe.py"), str(glb),
                        str(setting), str(res)], check=True, capture_output=True)  # fmt: skip
        views = json.loads(res.read_text())
        dist = np.concatenate([v["dist_px"] for v in views])
        angle = np.concatenate([v["angle_deg"] for v in views])
        assert len(dist) > 300, setting.name
        assert dist.max() < 0.05, (setting.name, dist.max())
        flat = "box" in setting.name.lower()
        assert (angle.max() if flat else np.median(angle)) < (0.5 if flat else 5.0), setting.name
        assert min(v["facing"] for v in views) >= 0.99, setting.name
        for exr in sorted((setting / layout.SHARP / layout.LINEAR).iterdir()):
            mask = read_image(
                setting / layout.SHARP / layout.pass_dir("mask", 1) / exr.with_suffix(".png").name
            )
            assert np.array_equal(mask[..., 0] > 0, read_exr(exr)[..., 3] >= 0.5)
    again = tmp_path / "again"
    run_cli("build", "--demo", *args, "--out", str(again))
    for setting in layout.complete_settings(again):
        for k in ("depth", "normal"):
            d = layout.pass_dir(k, 4)
            for p in sorted((setting / layout.SHARP / d).iterdir()):
                assert (
                    p.read_bytes() == (out / setting.name / layout.SHARP / d / p.name).read_bytes()
                )
