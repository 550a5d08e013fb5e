"""Training and evaluating on a build (issue 13): Deblur-NeRF's test views, `images_4/`
in linear light with hwf at full size, per-level transforms.json, `blurset export`, the
splits options and `blurset.data.open_scene`, on the shared real demo build."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from blurset.data import list_scenes, open_scene
from PIL import Image

from tests.conftest import run_cli

BLUR = ["blur_1", "blur_2", "blur_3", "blur_4"]


def settings(out: Path) -> list[Path]:
    return sorted(d for d in out.iterdir() if (d / ".complete").exists())


def srgb_decode(x: np.ndarray) -> np.ndarray:
    return np.where(x <= 0.04045, x / 12.92, ((x + 0.055) / 1.055) ** 2.4)


def srgb_encode(y: np.ndarray) -> np.ndarray:
    y = np.clip(y, 0, 1)
    return np.where(y <= 0.0031308, 12.92 * y, 1.055 * y ** (1 / 2.4) - 0.055)


def block_mean(a: np.ndarray, f: int) -> np.ndarray:
    h, w = a.shape[:2]
    return a.reshape(h // f, f, w // f, f, -1).mean(axis=(1, 3))


@pytest.mark.blender
def test_test_views_are_sharp_in_every_blur_level_and_train_views_blurry(demo_build):
    splits = json.loads((demo_build / "splits.json").read_text())
    assert splits["test_view_images"] == "sharp"
    for s in settings(demo_build):
        meta = json.loads((s / "meta.json").read_text())
        assert meta["test_view_images"] == "sharp" and meta["downsample"] == [4]
        test = splits["test_views"][s.name]
        assert test == meta["test_views"] == [0, 16]
        for sub in ("images", "images_4"):
            sharp = sorted((s / "sharp" / sub).iterdir())
            for lvl in BLUR:
                for i, p in enumerate(sharp):
                    same = (s / lvl / sub / p.name).read_bytes() == p.read_bytes()
                    assert same == (i in test), (s.name, lvl, sub, p.name)
    # Only the train views were rendered blurry: the frame count says so.
    ds = json.loads((demo_build / "dataset.json").read_text())
    meta = json.loads((settings(demo_build)[0] / "meta.json").read_text())
    cfg = ds["config"]
    assert meta["timings"]["frames"] == 17 + 15 * len(BLUR) * cfg["latents"]


@pytest.mark.blender
def test_images_4_are_the_linear_area_mean_and_hwf_stays_full(demo_build):
    worst_linear = worst_srgb = 0.0
    for s in settings(demo_build):
        for lvl in ["sharp", *BLUR]:
            pb = np.load(s / lvl / "poses_bounds.npy")
            assert (pb[:, 4] == 64).all() and (pb[:, 9] == 64).all()
            names = sorted(p.name for p in (s / lvl / "images").iterdir())
            assert sorted(p.name for p in (s / lvl / "images_4").iterdir()) == names
            for name in names[:6]:
                full = np.asarray(Image.open(s / lvl / "images" / name), np.float64) / 255
                small = np.asarray(Image.open(s / lvl / "images_4" / name), np.float64)
                assert small.shape == (16, 16, 3)
                # images/ downsampled in linear light from the float image: within one
                # code of the same from the 8-bit PNG; averaging sRGB codes is further off.
                linear = srgb_encode(block_mean(srgb_decode(full), 4)) * 255
                worst_linear = max(worst_linear, np.abs(linear - small).max())
                worst_srgb = max(worst_srgb, np.abs(block_mean(full, 4) * 255 - small).max())
    assert worst_linear <= 1.0, worst_linear
    assert worst_srgb > 2.0, worst_srgb


@pytest.mark.blender
def test_level_transforms_name_existing_files_and_split_as_splits_json(demo_build):
    splits = json.loads((demo_build / "splits.json").read_text())
    for s in settings(demo_build):
        setting_doc = json.loads((s / "transforms.json").read_text())
        test = set(splits["test_views"][s.name])
        for lvl in ["sharp", *BLUR]:
            doc = json.loads((s / lvl / "transforms.json").read_text())
            paths = [f["file_path"] for f in doc["frames"]]
            assert all((s / lvl / p).is_file() for p in paths)
            assert len(paths) == 17 and doc["fl_x"] == setting_doc["fl_x"]
            train, val, tst = (set(doc[f"{k}_filenames"]) for k in ("train", "val", "test"))
            assert train | tst == set(paths) and not train & tst and val == tst
            assert tst == {f["file_path"] for f in doc["frames"] if f["index"] in test}
            for f, g in zip(doc["frames"], setting_doc["frames"], strict=True):
                assert f["transform_matrix"] == g["transform_matrix"]
            assert doc.get("test_view_images") == (None if lvl == "sharp" else "sharp")


def export(build: Path, out: Path, *args: str, check: bool = True):
    return run_cli("export", str(build), "--out", str(out), *args, check=check)


@pytest.mark.blender
def test_export_is_one_root_of_llff_scenes_and_a_rerun_is_a_no_op(demo_build, tmp_path):
    out = tmp_path / "data"
    p = export(demo_build, out)
    assert "use llffhold 16" in p.stdout, p.stdout
    root = out / "nerf_llff_data"
    names = {f"{s.name}__{lvl}" for s in settings(demo_build) for lvl in ["sharp", *BLUR]}
    # IBRNet and NAN take every entry of nerf_llff_data as a scene: nothing else there.
    assert {d.name for d in root.iterdir()} == names
    splits = json.loads((demo_build / "splits.json").read_text())
    train = (out / "train.txt").read_text().split()
    test = (out / "test.txt").read_text().split()
    # The paper's protocol: degraded scenes only, the clean __sharp ones in neither list.
    assert sorted(train + test) == sorted(n for n in names if not n.endswith("__sharp"))
    assert {n.split("__")[0] for n in test} == set(splits["test"])
    doc = json.loads((out / "export.json").read_text())
    assert doc["llffhold"] == 16 and doc["factors"] == [4] and doc["test_view_images"] == "sharp"
    scene = root / f"{settings(demo_build)[0].name}__blur_2"
    for part in ("images", "images_4", "poses_bounds.npy", "transforms.json"):
        assert (scene / part).is_symlink()
        assert (scene / part).resolve() == (settings(demo_build)[0] / "blur_2" / part).resolve()
    # What an LLFF loader with factor 4 reads: 16 px images, hwf 64 (focal / 4 is its job).
    assert np.asarray(Image.open(scene / "images_4" / "000.png")).shape == (16, 16, 3)
    assert np.load(scene / "poses_bounds.npy")[0, 4] == 64
    before = {p: p.lstat().st_mtime_ns for p in out.rglob("*")}
    p = export(demo_build, out)
    assert "up to date" in p.stdout
    assert {p: p.lstat().st_mtime_ns for p in out.rglob("*")} == before
    # Another selection replaces the export whole.
    export(demo_build, out, "--levels", "blur_4", "--copy")
    assert {d.name for d in root.iterdir()} == {n for n in names if n.endswith("blur_4")}
    assert not (root / f"{settings(demo_build)[0].name}__blur_4" / "images").is_symlink()


@pytest.mark.blender
def test_export_refuses_the_build_and_bad_options(demo_build, tmp_path):
    before = sorted(p.name for p in demo_build.iterdir())
    for out in (demo_build / "exp", settings(demo_build)[0] / "exp", demo_build):
        p = export(demo_build, out, check=False)
        assert p.returncode == 2 and "--out" in p.stderr, p.stderr
        assert len(p.stderr.strip().splitlines()) == 1
        assert not (demo_build / "exp").exists()
    assert sorted(p.name for p in demo_build.iterdir()) == before
    p = export(demo_build, tmp_path / "x", "--levels", "blur_9", check=False)
    assert p.returncode == 2 and "blur_9" in p.stderr
    p = export(demo_build, tmp_path / "x", "--gains", "4", check=False)
    assert p.returncode == 2 and "--noise" in p.stderr
    # An export lives beside what else its folder holds (IBRNet's data/), touching none of it.
    (tmp_path / "notes").mkdir()
    (tmp_path / "notes" / "mine.txt").write_text("keep")
    export(demo_build, tmp_path / "notes")
    assert (tmp_path / "notes" / "mine.txt").read_text() == "keep"


@pytest.mark.blender
def test_export_for_nerfstudio_has_transforms_per_scene(demo_build, tmp_path):
    out = tmp_path / "ns"
    p = export(demo_build, out, "--for", "nerfstudio", "--levels", "blur_1")
    assert "splits in each transforms.json" in p.stdout and "llffhold" not in p.stdout
    scenes = sorted(d for d in out.iterdir() if d.is_dir())
    assert len(scenes) == 3
    doc = json.loads((scenes[0] / "transforms.json").read_text())
    assert all((scenes[0] / f["file_path"]).is_file() for f in doc["frames"])
    assert all((scenes[0] / "images_4" / Path(f).name).is_file() for f in doc["test_filenames"])


@pytest.mark.blender
def test_open_scene_pairs_match_the_files(demo_build):
    s = settings(demo_build)[1]
    meta = json.loads((s / "meta.json").read_text())
    assert (s.name, "blur_3") in list_scenes(demo_build)
    sc = open_scene(demo_build, s.name, "blur_3", downsample=4)
    assert sc.images.shape == sc.clean.shape == (17, 16, 16, 3)
    for v in (0, 5):
        want = np.asarray(Image.open(s / "blur_3" / "images_4" / f"{v:03d}.png")) / 255
        clean = np.asarray(Image.open(s / "sharp" / "images_4" / f"{v:03d}.png")) / 255
        np.testing.assert_allclose(sc.images[v], want, atol=1e-6)
        np.testing.assert_allclose(sc.clean[v], clean, atol=1e-6)
    assert list(sc.test_views) == [0, 16] and len(sc.train_views) == 15
    np.testing.assert_array_equal(sc.images[sc.test_views], sc.clean[sc.test_views])
    assert not np.array_equal(sc.images[sc.train_views], sc.clean[sc.train_views])
    frames = json.loads((s / "transforms.json").read_text())["frames"]
    np.testing.assert_allclose(sc.c2w_opengl, [f["transform_matrix"] for f in frames], atol=1e-12)
    flip = np.diag([1.0, -1.0, -1.0, 1.0])
    np.testing.assert_allclose(sc.c2w_opencv, sc.c2w_opengl @ flip, atol=1e-12)
    assert sc.intrinsics[0, 0] == pytest.approx(meta["focal_px"] / 4)
    assert sc.intrinsics[0, 2] == 8.0
    # Every camera looks at the object centre (the origin) in OpenCV's +z.
    for c in sc.c2w_opencv:
        fwd, eye = c[:3, 2], c[:3, 3]
        assert fwd @ (-eye / np.linalg.norm(eye)) > 1 - 1e-9
    assert (sc.near < np.linalg.norm(sc.c2w_opencv[:, :3, 3], axis=1)).all()
    # pose="mean": each blurry image's mean latent pose from meta.json; the held-out
    # views (sharp copies) keep the written pose.
    mean = open_scene(demo_build, s.name, "blur_3", downsample=4, pose="mean")
    want = [
        v["c2w"] if v["index"] in meta["test_views"] else v["levels"]["3"]["mean_pose"]["c2w"]
        for v in meta["views"]
    ]
    np.testing.assert_allclose(mean.c2w_opengl, want, atol=1e-12)
    np.testing.assert_allclose(mean.c2w_opencv, mean.c2w_opengl @ flip, atol=1e-12)
    assert not np.allclose(mean.c2w_opengl[sc.train_views], sc.c2w_opengl[sc.train_views])
    np.testing.assert_array_equal(mean.images, sc.images)
    with pytest.raises(Exception, match="gain needs noise"):
        open_scene(demo_build, s.name, "blur_3", gain=4)


@pytest.mark.blender
def test_blurry_test_views_and_no_downsample_keep_the_old_layout(tmp_path):
    out = tmp_path / "b"
    run_cli("build", "--demo", "--views", "3", "--levels", "1", "--latents", "2",
            "--samples", "2", "--sharp-samples", "2", "--resolution", "32", "--quiet",
            "--blurry-test-views", "--downsample", "none", "--test-view-stride", "2",
            "--test-settings", "1", "--out", str(out))  # fmt: skip
    sp = json.loads((out / "splits.json").read_text())
    assert sp["test_view_images"] == "blurry" and sp["holdout"] == "settings"
    assert len(sp["test"]) == 1 and sp["test_settings"] == 1
    for s in settings(out):
        assert not (s / "blur_1" / "images_4").exists()
        assert sp["test_views"][s.name] == [0, 2]
        for v in ("000", "002"):
            a = (s / "sharp" / "images" / f"{v}.png").read_bytes()
            assert (s / "blur_1" / "images" / f"{v}.png").read_bytes() != a


# --- options, without rendering -------------------------------------------------------


def test_split_options_flags_and_toml_keys(tmp_path):
    import argparse

    from blurset.commands.builder.cli import add_arguments, config_from_args
    from blurset.exceptions import ConfigError
    from blurset.services.config import load_toml

    parser = argparse.ArgumentParser()
    add_arguments(parser)

    def cfg(*args: str):
        return config_from_args(parser.parse_args(["--demo", "--out", "x", *args]))

    c = cfg()
    assert (c.test_fraction, c.test_settings, c.view_stride, c.downsample) == (0.2, None, 16, [4])
    assert cfg("--test-settings", "52").test_settings == 52
    assert cfg("--test-objects", "0.5").test_fraction == 0.5
    assert cfg("--test-objects", "a,b").test_objects == ["a", "b"]
    assert cfg("--test-view-stride", "8", "--downsample", "8", "4").downsample == [4, 8]
    assert cfg("--downsample", "none").downsample == []
    with pytest.raises(SystemExit):  # argparse: one of the two
        parser.parse_args(["--test-objects", "0.1", "--test-settings", "3"])
    for args, words in [
        (["--downsample", "5"], ["--downsample", "5: does not divide", "96"]),
        (["--downsample", "1"], ["--downsample", "2..=64"]),
        (["--test-objects", "1.5"], ["--test-objects"]),
        (["--test-settings", "0"], ["--test-settings"]),
        (["--test-view-stride", "0"], ["--test-view-stride"]),
    ]:
        with pytest.raises(ConfigError) as e:
            cfg(*args)
        assert all(w in str(e.value) for w in words), str(e.value)
    toml = tmp_path / "c.toml"
    toml.write_text("test-settings = 52\ntest-view-stride = 8\ndownsample = [4, 8]\n")
    assert load_toml(toml) == {"test_settings": 52, "view_stride": 8, "downsample": [4, 8]}
    toml.write_text("test-objects = 0.3\n")
    assert load_toml(toml) == {"test_fraction": 0.3}
    toml.write_text('test-objects = ["chair"]\n')
    assert load_toml(toml) == {"test_objects": ["chair"]}
    toml.write_text("test-objects = 0.3\ntest-settings = 4\n")
    with pytest.raises(ConfigError, match="not both"):
        config_from_args(parser.parse_args(["--demo", "--out", "x", "--config", str(toml)]))


@pytest.mark.blender
def test_the_example_loader_gives_pairs_without_torch(demo_build):
    import importlib.util

    path = Path(__file__).resolve().parents[1] / "examples" / "gnerf_loader.py"
    spec = importlib.util.spec_from_file_location("gnerf_loader", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)  # imports no torch: that is inside make_dataset only
    s = settings(demo_build)[0].name
    sc = open_scene(demo_build, s, "blur_4", downsample=4)
    b = mod.sample(sc, 16, n_sources=4)
    assert b["src_rgbs"].shape == b["src_rgbs_clean"].shape == (4, 16, 16, 3)
    np.testing.assert_array_equal(b["rgb"], b["rgb_clean"])  # a sharp test target
    assert not np.array_equal(b["src_rgbs"], b["src_rgbs_clean"])  # blurry sources
    src = mod.nearest_sources(sc, 16, 4)
    assert set(src) <= set(sc.train_views) and 16 not in src
    assert b["camera"].shape == (34,) and b["camera"][2] == pytest.approx(sc.intrinsics[0, 0])
    lo, hi = b["depth_range"]
    assert lo < np.linalg.norm(sc.c2w_opencv[16, :3, 3]) < hi


def test_the_lists_follow_the_papers_protocol_and_print_the_clients_command(
    standin_build_dir, tmp_path
):
    """train.txt / test.txt hold the degraded scenes of the train and test settings (the
    paper's protocol: train on blurry levels, evaluate on them with sharp targets), the
    clean __sharp scenes in neither; the summary prints the client's command for them."""
    out = tmp_path / "data"
    p = export(standin_build_dir, out)
    splits = json.loads((standin_build_dir / "splits.json").read_text())
    train = (out / "train.txt").read_text().split()
    test = (out / "test.txt").read_text().split()
    levels = ["blur_1", "blur_2"]
    assert sorted(train) == sorted(f"{s}__{lvl}" for s in splits["train"] for lvl in levels)
    assert sorted(test) == sorted(f"{s}__{lvl}" for s in splits["test"] for lvl in levels)
    assert test and not [n for n in train + test if n.endswith("__sharp")]
    # The clean scenes stay in the root, the pairs' truth.
    assert (out / "nerf_llff_data" / f"{splits['test'][0]}__sharp").is_dir()
    assert f"--llffhold 16 --train_dataset llff_test --train_scenes $(cat {out}/train.txt)" in (
        p.stdout
    ), p.stdout
    assert "`cp -a` dangles; copy it with `cp -rL`, or export with --copy" in p.stdout
    # An export of the sharp level alone lists its scenes: they are all it holds.
    only = export(standin_build_dir, tmp_path / "sharp", "--levels", "sharp")
    assert (tmp_path / "sharp" / "test.txt").read_text().split(), only.stdout
    ns = export(standin_build_dir, tmp_path / "ns", "--for", "nerfstudio")
    assert "nerfstudio-data --center-method focus" in ns.stdout, ns.stdout


def test_an_empty_test_split_is_said_with_the_option_that_fixes_it(standin_blender, tmp_path):
    """One object and the default --test-objects 0.2 hold out nothing: the build and the
    export each say so in one line naming --test-settings, not an empty test.txt alone."""
    from blurset.services.demo import make_demo_objects

    glb = make_demo_objects(tmp_path / "models", seed=0)[0]
    b = tmp_path / "b"
    p = run_cli("build", "--objects", str(glb), "--views", "4", "--levels", "1", "--latents",
                "2", "--samples", "2", "--resolution", "32", "--settings-per-object", "2",
                "--quiet", "--blender", str(standin_blender), "--out", str(b))  # fmt: skip
    assert json.loads((b / "splits.json").read_text())["test"] == []
    assert "the test split is empty" in p.stderr and "--test-settings N" in p.stderr, p.stderr
    e = export(b, tmp_path / "data")
    assert (tmp_path / "data" / "test.txt").read_text() == ""
    warn = [ln for ln in e.stderr.splitlines() if "test.txt is empty" in ln]
    assert len(warn) == 1 and "--test-settings N" in warn[0], e.stderr
