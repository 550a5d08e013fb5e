"""`blurset build` end to end on real Blender renders, checked from the files alone."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from tests.conftest import run_cli, shared

pytestmark = pytest.mark.blender

LEVELS = ["sharp", "blur_1", "blur_2", "blur_3", "blur_4"]


def settings(out: Path) -> list[Path]:
    return sorted(d for d in out.iterdir() if (d / ".complete").exists())


def c2w_from_llff(row: np.ndarray) -> np.ndarray:
    """OpenGL camera-to-world from an LLFF row, as IBRNet/NAN loaders do it."""
    m = row[:15].reshape(3, 5)
    down, right, back, t = m[:, 0], m[:, 1], m[:, 2], m[:, 3]
    c2w = np.eye(4)
    c2w[:3, 0], c2w[:3, 1], c2w[:3, 2], c2w[:3, 3] = right, -down, back, t
    return c2w


def test_layout_and_names(demo_build):
    assert (demo_build / "dataset.json").exists()
    ds = json.loads((demo_build / "dataset.json").read_text())
    assert ds["counts"]["settings"] == 3 and ds["counts"]["objects_failed"] == 0
    assert ds["versions"]["blender"].startswith("5.0")  # the pinned bpy that rendered it
    for s in settings(demo_build):
        meta = json.loads((s / "meta.json").read_text())
        for key in ("uid", "theta0_deg", "seed", "resolution", "fov_deg", "bbox_dims", "views"):
            assert key in meta
        v = meta["views"][0]
        for key in ("index", "r", "phi_deg", "theta_deg", "near", "far", "flatness",
                    "depth_range", "orientation", "w_u", "trajectory", "levels"):  # fmt: skip
            assert key in v
        assert set(v["levels"]) == {"1", "2", "3", "4"}
        for lvl in LEVELS:
            names = sorted(p.name for p in (s / lvl / "images").iterdir())
            assert names == [f"{i:03d}.png" for i in range(17)]
            assert np.load(s / lvl / "poses_bounds.npy").shape == (17, 17)


def test_cameras_point_at_object_and_bounds_bracket_it(demo_build):
    for s in settings(demo_build):
        pb = np.load(s / "sharp" / "poses_bounds.npy")
        for row in pb:
            c2w = c2w_from_llff(row)
            eye, fwd = c2w[:3, 3], -c2w[:3, 2]
            cos = fwd @ (-eye / np.linalg.norm(eye))
            assert cos > 1 - 1e-9
            near, far = row[15], row[16]
            assert near < np.linalg.norm(eye) < far
            assert np.allclose(c2w[:3, :3].T @ c2w[:3, :3], np.eye(3), atol=1e-9)


def test_hwf_matches_images_and_fov(demo_build):
    for s in settings(demo_build):
        meta = json.loads((s / "meta.json").read_text())
        pb = np.load(s / "blur_2" / "poses_bounds.npy")
        h, w, f = pb[0, 4], pb[0, 9], pb[0, 14]
        img = np.asarray(Image.open(s / "blur_2" / "images" / "000.png"))
        assert (h, w) == img.shape[:2]
        assert math.isclose(2 * math.degrees(math.atan(w / 2 / f)), meta["fov_deg"], rel_tol=1e-9)


def gradient_energy(path: Path) -> float:
    a = np.asarray(Image.open(path).convert("L"), np.float64) / 255
    return float((np.diff(a, axis=0) ** 2).mean() + (np.diff(a, axis=1) ** 2).mean())


def test_blur_grows_with_level(demo_build):
    # Every latent frame and the sharp frame use the same samples here, so the
    # blur levels share one noise level and the fall between them is blur alone.
    energy = []
    for lvl in LEVELS:
        energy.append(
            sum(
                gradient_energy(p)
                for s in settings(demo_build)
                for p in sorted((s / lvl / "images").iterdir())
            )
        )
    assert all(a > b for a, b in zip(energy, energy[1:], strict=False)), energy


def test_test_views_every_16th(demo_build):
    sp = json.loads((demo_build / "splits.json").read_text())
    assert sp["view_stride"] == 16
    assert all(v == [0, 16] for v in sp["test_views"].values())
    assert sp["train"] and sp["test"] and not set(sp["train"]) & set(sp["test"])


def test_sharp_image_equals_a_render_at_p(demo_build, tmp_path):
    from blurset.image import Accumulator
    from blurset.services.worker_client import Worker

    s = settings(demo_build)[0]
    meta = json.loads((s / "meta.json").read_text())
    view = 5
    c2w = c2w_from_llff(np.load(s / "sharp" / "poses_bounds.npy")[view])
    glb = demo_build / ".demo_objects" / f"{meta['uid']}.glb"
    with Worker(timeout=120) as w:
        w.load(glb, tmp_path / "v.npy")
        w.render(
            [
                {
                    "c2w": c2w.tolist(),
                    "seed": meta["views"][view]["sharp_seed"],
                    "out": str(tmp_path / "f.exr"),
                }
            ],  # fmt: skip
            resolution=meta["resolution"][0],
            fov_deg=meta["fov_deg"],
            samples=meta["render"]["sharp_samples"],
        )
    acc = Accumulator(*meta["resolution"])
    acc.add_exr(tmp_path / "f.exr")
    acc.write_png(tmp_path / "f.png")
    ours = np.asarray(Image.open(s / "sharp" / "images" / f"{view:03d}.png"), np.int16)
    again = np.asarray(Image.open(tmp_path / "f.png"), np.int16)
    assert np.abs(ours - again).max() <= 1


def test_rerun_skips_complete_settings(demo_build):
    before = {p: p.stat().st_mtime_ns for p in demo_build.glob("*/meta.json")}
    from tests.conftest import DEMO_ARGS

    run_cli("build", *DEMO_ARGS, "--out", str(demo_build))
    after = {p: p.stat().st_mtime_ns for p in demo_build.glob("*/meta.json")}
    assert before == after


def test_bad_input_one_line(tmp_path):
    p = run_cli("build", "--objects", str(tmp_path / "nope.glb"), "--out", str(tmp_path / "o"),
                check=False)  # fmt: skip
    assert p.returncode == 2
    assert "nope.glb" in p.stderr and len(p.stderr.strip().splitlines()) == 1
    p = run_cli("build", "--demo", "--levels", "1,x", "--out", str(tmp_path / "o"), check=False)
    assert p.returncode == 2 and "--levels" in p.stderr
    cfg = tmp_path / "c.toml"
    cfg.write_text("latentz = 3\n")
    p = run_cli("build", "--demo", "--config", str(cfg), "--out", str(tmp_path / "o"), check=False)
    assert p.returncode == 2 and "latentz" in p.stderr


@pytest.mark.slow
def test_shared_glbs_build_or_fail_cleanly(tmp_path):
    glbs = shared("glb")
    out = tmp_path / "out"
    run_cli("build", "--objects", str(glbs), "--out", str(out), "--views", "2", "--latents", "2",
            "--levels", "1", "--resolution", "48", "--samples", "2", "--settings-per-object", "1",
            "--quiet")  # fmt: skip
    built = {json.loads((s / "meta.json").read_text())["uid"] for s in settings(out)}
    failed = {
        json.loads(line)["uid"]
        for line in (out / "failures.jsonl").read_text().splitlines()
        if line.strip()
    }
    stems = {p.stem for p in glbs.glob("*.glb")}
    assert built | failed == stems and not built & failed
    for line in (out / "failures.jsonl").read_text().splitlines():
        assert json.loads(line)["reason"]
    # no silently black object: the sharp images of each built object have colour
    for s in settings(out):
        a = np.asarray(Image.open(s / "sharp" / "images" / "000.png").convert("RGB"), float)
        obj = (a < 250).any(axis=2)
        assert obj.mean() > 0.01 and a[obj].mean() > 20, s.name


def test_centered_trajectory_puts_p_mid_exposure_with_the_same_draws(tmp_path):
    """`--trajectory centered` (issue 18): every latent position of every view and level
    lies on p + t·w_l·δ with t ∈ [−½, ½] (meta.json), drawn with the same seeds as the
    default `start` (t − ½), so the sharp images and all pose files are the same bytes,
    and the mean latent pose recorded per view and level is the camera at the mean t."""
    from blurset.services.demo import make_demo_objects

    glb = make_demo_objects(tmp_path / "objects")[0]
    args = ("--objects", str(glb), "--views", "3", "--levels", "1,4", "--latents", "3",
            "--resolution", "32", "--samples", "2", "--sharp-samples", "2",
            "--settings-per-object", "1", "--quiet")  # fmt: skip
    out = {a: tmp_path / a for a in ("start", "centered")}
    run_cli("build", *args, "--out", str(out["start"]))
    run_cli("build", *args, "--trajectory", "centered", "--out", str(out["centered"]))
    (s_start,), (s_cent,) = settings(out["start"]), settings(out["centered"])
    meta = {
        "start": json.loads((s_start / "meta.json").read_text()),
        "centered": json.loads((s_cent / "meta.json").read_text()),
    }
    assert meta["start"]["sampling"]["trajectory"] == "start"
    assert meta["centered"]["sampling"]["trajectory"] == "centered"
    r_min = 1.05 * 0.5 * float(np.linalg.norm(meta["centered"]["bbox_dims"]))
    for vs, vc in zip(meta["start"]["views"], meta["centered"]["views"], strict=True):
        assert (vs["trajectory"], vs["c2w"]) == (vc["trajectory"], vc["c2w"])
        d = vc["trajectory"]
        for lvl, lc in vc["levels"].items():
            ls = vs["levels"][lvl]
            assert lc["w_l"] == ls["w_l"] and len(lc["latent_frames"]) == 3
            for fs, fc in zip(ls["latent_frames"], lc["latent_frames"], strict=True):
                assert (fc["t"], fc["seed"]) == (fs["t"] - 0.5, fs["seed"])
                assert -0.5 <= fc["t"] <= 0.5 and 0.0 <= fs["t"] <= 1.0
                s = fc["t"] * lc["w_l"]
                want = (
                    max(vc["r"] * (1 + s * d["dr"] / 100), r_min),
                    vc["phi_deg"] + s * d["dphi_deg"],
                    vc["theta_deg"] + s * d["dtheta_deg"],
                )
                got = (fc["r"], fc["phi_deg"], fc["theta_deg"])
                assert got == pytest.approx(want, rel=1e-12, abs=1e-12)
            for lp in (ls, lc):
                mp = lp["mean_pose"]
                assert mp["t"] == pytest.approx(np.mean([f["t"] for f in lp["latent_frames"]]))
                # The camera at the mean t: its centre at (r, φ, θ) of that t.
                phi, theta = math.radians(mp["phi_deg"]), math.radians(mp["theta_deg"])
                eye = mp["r"] * np.array(
                    [
                        math.sin(phi) * math.cos(theta),
                        math.sin(phi) * math.sin(theta),
                        math.cos(phi),
                    ]
                )
                assert np.asarray(mp["c2w"])[:3, 3] == pytest.approx(eye, abs=1e-9)
            # Centred, the segment's ends t = ∓½ are symmetric about p.
            assert abs(lc["mean_pose"]["t"]) < 0.5 and 0.0 < ls["mean_pose"]["t"] < 1.0
    # Same sharp images, same poses in every level; the blurry exposures moved.
    for rel in ["transforms.json", *(f"{lv}/poses_bounds.npy" for lv in ("sharp", "blur_1"))]:
        assert (s_start / rel).read_bytes() == (s_cent / rel).read_bytes(), rel
    for name in ("000.png", "001.png", "002.png"):
        assert (s_start / "sharp/images" / name).read_bytes() == (
            s_cent / "sharp/images" / name
        ).read_bytes()
    assert any(
        (s_start / "blur_4/images" / n).read_bytes() != (s_cent / "blur_4/images" / n).read_bytes()
        for n in ("000.png", "001.png", "002.png")
    )
