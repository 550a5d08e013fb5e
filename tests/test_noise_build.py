"""`blurset noise BUILD_DIR` (issue 9) on a real tiny Blender build made with
`--keep-linear`: layout mirrored, poses and splits preserved, noise statistics of both
sources (linear EXR and sRGB PNG) on their own clean reference, the measured difference
between the sources, reproducibility against the single-scene command, resume rules,
and bad input."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import OpenEXR
import pytest
from blurset.noise.model import noise_scene_seed
from PIL import Image

from tests.conftest import run_cli

pytestmark = pytest.mark.blender

GAINS = ("1", "16")
SEED = "5"
EDGES = np.array([0.0, 0.01, 0.03, 0.1, 0.3, 0.6, 0.9, 1.01])


def read_exr(path: Path) -> np.ndarray:
    ch = OpenEXR.File(str(path)).channels()
    key = "RGBA" if "RGBA" in ch else "RGB"
    return np.asarray(ch[key].pixels, dtype=np.float64)


def srgb_decode(x: np.ndarray) -> np.ndarray:
    return np.where(x <= 0.04045, x / 12.92, ((x + 0.055) / 1.055) ** 2.4)


def srgb_encode(y: np.ndarray) -> np.ndarray:
    y = np.clip(y, 0, 1)
    return np.where(y <= 0.0031308, 12.92 * y, 1.055 * y ** (1 / 2.4) - 0.055)


def settings(build: Path) -> list[Path]:
    return sorted(d for d in build.iterdir() if (d / ".complete").is_file())


def levels(build: Path) -> list[str]:
    return json.loads((build / "dataset.json").read_text())["levels"]


def units(out: Path, gain: str) -> list[Path]:
    return sorted(out.glob(f"*/*/gain_{gain}"))


def files_state(root: Path) -> dict[str, tuple[int, bytes]]:
    return {
        str(p.relative_to(root)): (p.stat().st_mtime_ns, p.read_bytes())
        for p in sorted(root.rglob("*"))
        if p.is_file()
    }


def block_mean(a: np.ndarray, f: int) -> np.ndarray:
    h, w = a.shape[:2]
    return a.reshape(h // f, f, w // f, f, -1).mean(axis=(1, 3))


def clean_reference(
    build: Path, unit: Path, meta: dict, stem: str, source: str, factor: int = 1
) -> np.ndarray:
    """The clean linear y of one view, computed here in NumPy from the build's files, at
    full size or clipped and area-averaged `factor` times in linear light."""
    wb = meta["white_balance"]
    scale = np.array([1 / wb["red"], 1.0, 1 / wb["blue"]]) if wb else np.ones(3)
    level_dir = build / meta["source"]["setting"] / meta["source"]["level"]
    if source == "linear":
        rgba = read_exr(level_dir / "linear" / f"{stem}.exr")
        bg = np.array(meta["source"]["background"])
        lin = rgba[..., :3] + (1 - np.clip(rgba[..., 3:], 0, 1)) * bg
    else:
        x = np.asarray(Image.open(level_dir / "images" / f"{stem}.png"), np.float64) / 255
        lin = srgb_decode(x)
    lin = np.clip(lin, 0, 1)
    if factor > 1:
        lin = block_mean(lin, factor)
    return lin * scale * meta["white_level"]


@pytest.fixture(scope="module")
def noised(linear_build, tmp_path_factory):
    root = tmp_path_factory.mktemp("noised")
    lin, png = root / "lin", root / "png"
    run_cli("noise", str(linear_build), "--out", str(lin), "--gains", *GAINS, "--seed", SEED)
    run_cli("noise", str(linear_build), "--out", str(png), "--gains", *GAINS, "--seed", SEED,
            "--source", "png")  # fmt: skip
    return linear_build, lin, png


def test_keep_linear_stores_every_view_and_level(linear_build, tmp_path):
    cfg = json.loads((linear_build / "dataset.json").read_text())["config"]
    assert cfg["write_linear"] is True and cfg["previews"] is True
    for s in settings(linear_build):
        meta = json.loads((s / "meta.json").read_text())
        bg = np.array(meta["render"]["background"])
        for lvl in levels(linear_build):
            pngs = sorted((s / lvl / "images").iterdir())
            exrs = sorted((s / lvl / "linear").iterdir())
            assert [p.stem for p in exrs] == [p.stem for p in pngs]
            # The PNG is the EXR composited over the background, sRGB-encoded, rounded.
            rgba = read_exr(exrs[3])
            lin = rgba[..., :3] + (1 - np.clip(rgba[..., 3:], 0, 1)) * bg
            png = np.asarray(Image.open(pngs[3]), np.float64)
            assert np.abs(np.round(srgb_encode(lin) * 255) - png).max() <= 1
    # The name in a TOML config too (the old write-linear still works).
    from blurset.services.config import load_toml

    for key in ("keep-linear", "keep_linear", "write-linear"):
        (tmp_path / "c.toml").write_text(f"{key} = true\n")
        assert load_toml(tmp_path / "c.toml") == {"write_linear": True}


def test_layout_mirrored_poses_and_splits_preserved(noised):
    build, lin, png = noised
    for out, kind in ((lin, "linear"), (png, "png")):
        doc = json.loads((out / "noise_dataset.json").read_text())
        assert doc["params"]["source"] == kind and doc["params"]["gamma"] == "srgb"
        assert doc["params"]["seed"] == int(SEED)
        assert (out / "splits.json").read_bytes() == (build / "splits.json").read_bytes()
        assert not list(out.rglob("*.partial")), "no partial unit may remain"
        seeds = set()
        for s in settings(build):
            for lvl in levels(build):
                seed = noise_scene_seed(int(SEED), s.name, lvl)
                assert doc["seeds"][s.name][lvl] == seed
                seeds.add(seed)
                want = sorted(p.name for p in (s / lvl / "images").iterdir())
                for g in GAINS:
                    d = out / s.name / lvl / f"gain_{g}"
                    assert (d / ".complete").is_file()
                    # What an IBRNet / NAN LLFF loader reads: sorted images, N x 17 poses.
                    assert sorted(p.name for p in (d / "images").iterdir()) == want
                    for sub in ("linear", "linear_4"):
                        assert sorted(p.name for p in (d / sub).iterdir()) == [
                            w.replace(".png", ".exr") for w in want
                        ]
                    assert sorted(p.name for p in (d / "images_4").iterdir()) == want
                    # NAN's protocol: the held-out views stay clean (the level's files).
                    for sub in ("images", "images_4"):
                        for i, name in enumerate(want):
                            same = (d / sub / name).read_bytes() == (
                                s / lvl / sub / name
                            ).read_bytes()
                            assert same == (i in (0, 16)), (d, sub, name)
                    tf = json.loads((d / "transforms.json").read_text())
                    assert tf["test_filenames"] == ["images/000.png", "images/016.png"]
                    assert all((d / f["file_path"]).is_file() for f in tf["frames"])
                    np.testing.assert_array_equal(
                        np.load(d / "poses_bounds.npy"), np.load(s / lvl / "poses_bounds.npy")
                    )
                    meta = json.loads((d / "noise.json").read_text())
                    assert meta["seed"] == seed and meta["gain"] == int(g)
                    assert meta["source"]["kind"] == kind
                    assert meta["source"]["setting"] == s.name and meta["source"]["level"] == lvl
                    img = np.asarray(Image.open(d / "images" / want[0]))
                    assert img.shape == (64, 64, 3) and img.dtype == np.uint8
        assert len(seeds) == len(settings(build)) * len(levels(build)), "seeds must differ"
        assert doc["counts"]["units"] == len(seeds) * len(GAINS)


@pytest.mark.parametrize("source", ["linear", "png"])
def test_noise_statistics_on_own_clean_reference(noised, source):
    """Residual (noisy - clean linear) mean ~ 0 and variance sigma_r^2 + sigma_s^2 y
    within 4 % in every brightness bin with >= 20000 values, per gain, pooled over every
    setting and level; the clean y is computed here from the build's own files."""
    build, lin, png = noised
    out = lin if source == "linear" else png
    nb = len(EDGES) - 1
    for g in GAINS:
        n, s1, s2, pred = (np.zeros(nb) for _ in range(4))
        negative = 0
        for unit in units(out, g):
            meta = json.loads((unit / "noise.json").read_text())
            sr, ss = meta["sigma_read"], meta["sigma_shot"]
            for f in meta["files"]:
                y = clean_reference(build, unit, meta, Path(f["image"]).stem, source)
                noisy = read_exr(unit / f["linear"])
                assert noisy.shape == y.shape and np.isfinite(noisy).all()
                if f.get("clean"):  # a held-out target: no noise at all
                    np.testing.assert_allclose(noisy, y, rtol=1e-6, atol=1e-7)
                    continue
                negative += int((noisy < 0).sum())
                r, yy = (noisy - y).ravel(), y.ravel()
                b = np.clip(np.digitize(yy, EDGES) - 1, 0, nb - 1)
                n += np.bincount(b, minlength=nb)
                s1 += np.bincount(b, r, minlength=nb)
                s2 += np.bincount(b, r * r, minlength=nb)
                pred += np.bincount(b, sr**2 + ss**2 * yy, minlength=nb)
        tested = 0
        for i in np.nonzero(n >= 20_000)[0]:
            mean, want = s1[i] / n[i], pred[i] / n[i]
            var = s2[i] / n[i] - mean**2
            assert abs(mean) < 5 * np.sqrt(want / n[i]), (source, g, EDGES[i], mean)
            assert abs(var / want - 1) < 0.04, (source, g, EDGES[i], var, want)
            tested += 1
        assert tested >= 3, f"too few populated brightness bins: {n}"
        if g == "16":
            assert negative > 0, "negative linear values must survive"


@pytest.mark.parametrize("source", ["linear", "png"])
def test_images_4_noise_has_the_sigma_of_its_own_size(noised, source, record_property):
    """images_4 / linear_4 of a gain: the residual against the clean image of the same
    size (area mean in linear light) has the model's variance per brightness bin; noise
    drawn at full size and then averaged (what a loader's resize does) has ~1/16 of it."""
    build, lin, png = noised
    out = lin if source == "linear" else png
    nb = len(EDGES) - 1
    for g in GAINS:
        n, s1, s2, pred = (np.zeros(nb) for _ in range(4))
        averaged = full_pred = 0.0
        for unit in units(out, g):
            meta = json.loads((unit / "noise.json").read_text())
            sr, ss = meta["sigma_read"], meta["sigma_shot"]
            for f in meta["files"]:
                if f.get("clean"):
                    continue
                stem = Path(f["image"]).stem
                y4 = clean_reference(build, unit, meta, stem, source, factor=4)
                noisy4 = read_exr(unit / "linear_4" / f"{stem}.exr")
                assert noisy4.shape == (16, 16, 3)
                r, yy = (noisy4 - y4).ravel(), y4.ravel()
                b = np.clip(np.digitize(yy, EDGES) - 1, 0, nb - 1)
                n += np.bincount(b, minlength=nb)
                s1 += np.bincount(b, r, minlength=nb)
                s2 += np.bincount(b, r * r, minlength=nb)
                pred += np.bincount(b, sr**2 + ss**2 * yy, minlength=nb)
                y = clean_reference(build, unit, meta, stem, source)
                resized = block_mean(read_exr(unit / f["linear"]) - y, 4)
                averaged += float((resized**2).sum())
                full_pred += float((sr**2 + ss**2 * block_mean(y, 4)).sum())
        tested = 0
        for i in np.nonzero(n >= 5_000)[0]:
            mean, want = s1[i] / n[i], pred[i] / n[i]
            var = s2[i] / n[i] - mean**2
            assert abs(mean) < 5 * np.sqrt(want / n[i]), (source, g, EDGES[i], mean)
            assert abs(var / want - 1) < 0.06, (source, g, EDGES[i], var / want)
            record_property(f"var_ratio_images_4_{source}_gain{g}_bin{EDGES[i]}", var / want)
            tested += 1
        assert tested >= 3, f"too few populated brightness bins: {n}"
        ratio = averaged / full_pred
        record_property(f"var_ratio_resized_full_{source}_gain{g}", ratio)
        assert ratio < 0.1, ratio  # a resize of the full-size noise: about 1/16


def test_linear_vs_png_source_measured_difference(noised, record_property):
    """Both sources model the same image and share their draws; what differs is what the
    8-bit PNG did to the clean image. Measured here: PSNR between the two sources' noisy
    linear images per gain (~67 dB on this build), far above the noise's own PSNR."""
    build, lin, png = noised
    report = []
    for g in GAINS:
        se = se_noise = count = 0.0
        worst_code = 0.0
        for unit in units(lin, g):
            other = png / unit.relative_to(lin)
            meta = json.loads((unit / "noise.json").read_text())
            sr, ss = meta["sigma_read"], meta["sigma_shot"]
            for f in meta["files"]:
                stem = Path(f["image"]).stem
                y_lin = clean_reference(build, unit, meta, stem, "linear")
                y_png = clean_reference(build, unit, meta, stem, "png")
                a, b = read_exr(unit / f["linear"]), read_exr(other / f["linear"])
                # Shared draws: the same standard normal behind both noisy values.
                za = (a - y_lin) / np.sqrt(sr**2 + ss**2 * y_lin)
                zb = (b - y_png) / np.sqrt(sr**2 + ss**2 * y_png)
                np.testing.assert_allclose(za, zb, atol=2e-3)
                # The build's PNG is the composite of its EXR, sRGB-encoded and rounded.
                wb = meta["white_balance"]
                scale = np.array([1 / wb["red"], 1.0, 1 / wb["blue"]])
                codes = srgb_encode(y_lin / scale) * 255
                png_codes = srgb_encode(y_png / scale) * 255
                worst_code = max(worst_code, float(np.abs(codes - png_codes).max()))
                se += float(((a - b) ** 2).sum())
                se_noise += float(((a - y_lin) ** 2).sum())
                count += a.size
        between = 10 * np.log10(count / se)
        noise_psnr = 10 * np.log10(count / se_noise)
        report.append((g, between, noise_psnr))
        record_property(f"psnr_between_sources_gain{g}_db", round(between, 2))
        assert worst_code <= 0.5 + 1e-3, worst_code
        assert between > 50, between
        assert between - noise_psnr > 20, (between, noise_psnr)
    print("\nlinear vs png source (PSNR between noisy linear images; noise PSNR):")
    for g, between, noise_psnr in report:
        print(f"  gain {g}: {between:.1f} dB between sources; noise itself {noise_psnr:.1f} dB")


def test_png_source_equals_the_single_scene_command(noised, tmp_path):
    """A unit's seed is the single-scene --seed: same bytes as `blurset noise LEVEL`."""
    build, _, png = noised
    s = settings(build)[1].name
    seed = noise_scene_seed(int(SEED), s, "blur_2")
    out = tmp_path / "single"
    run_cli("noise", str(build / s / "blur_2"), "--out", str(out), "--gains", "16",
            "--factor", "1", "--seed", str(seed), "--gamma", "srgb", "--clean-views", "16",
            "--downsample", "4")  # fmt: skip
    mine = png / s / "blur_2" / "gain_16"
    for sub in ("images", "linear", "images_4", "linear_4"):
        names = sorted(p.name for p in (mine / sub).iterdir())
        assert names == sorted(p.name for p in (out / "gain_16" / sub).iterdir())
        for name in names:
            assert (mine / sub / name).read_bytes() == (out / "gain_16" / sub / name).read_bytes()
    np.testing.assert_array_equal(
        np.load(mine / "poses_bounds.npy"), np.load(out / "gain_16" / "poses_bounds.npy")
    )


def test_rerun_skips_every_complete_unit(noised):
    build, lin, _ = noised
    before = {k: v for k, v in files_state(lin).items() if "/gain_" in k}
    p = run_cli("noise", str(build), "--out", str(lin), "--gains", *GAINS, "--seed", SEED)
    assert "0 scene(s) written, 30 complete skipped" in p.stdout, p.stdout
    after = {k: v for k, v in files_state(lin).items() if "/gain_" in k}
    assert before == after


def test_partial_unit_redone_and_new_gain_added(noised, tmp_path):
    build, lin, _ = noised
    out = tmp_path / "lin"
    shutil.copytree(lin, out)
    unit = out / "demo_box_000" / "blur_3" / "gain_16"
    reference = files_state(lin / "demo_box_000" / "blur_3" / "gain_16")
    # A killed run: one unit lost its marker mid-way with a damaged image, and a stale
    # partial directory lies elsewhere.
    (unit / ".complete").unlink()
    (unit / "images" / "004.png").write_bytes(b"half")
    stale = out / "demo_vase_000" / "sharp" / "gain_1.partial"
    (stale / "images").mkdir(parents=True)
    others = {
        k: v for k, v in files_state(out).items() if "blur_3/gain_16" not in k and "/gain_" in k
    }
    p = run_cli("noise", str(build), "--out", str(out), "--gains", *GAINS, "--seed", SEED)
    assert "1 scene(s) written, 29 complete skipped" in p.stdout, p.stdout
    assert not stale.exists()
    redone = files_state(unit)
    assert {k: v[1] for k, v in redone.items() if k != ".complete"} == {
        k: v[1] for k, v in reference.items() if k != ".complete"
    }, "a redone unit must be byte-identical"
    assert {k: v for k, v in files_state(out).items() if k in others} == others
    # Adding a gain writes only the new units and leaves the others untouched.
    p = run_cli("noise", str(build), "--out", str(out), "--gains", "1", "4", "16", "--seed", SEED)
    assert "15 scene(s) written, 30 complete skipped" in p.stdout, p.stdout
    assert {k: v for k, v in files_state(out).items() if k in others} == others
    doc = json.loads((out / "noise_dataset.json").read_text())
    assert [g["gain"] for g in doc["gains"]] == [1, 4, 16]


def test_killed_run_resumes_to_the_same_bytes(noised, tmp_path):
    """SIGKILL inside the second unit (its noisy images written, no gain of it complete:
    BLURSET_NOISE_FAULT, a known point, not a race); the rerun finishes the rest, and the
    result equals an uninterrupted run byte for byte (markers aside)."""
    import os
    import signal
    import subprocess
    import sys

    build, lin, _ = noised
    out = tmp_path / "killed"
    args = [sys.executable, "-m", "blurset.cli", "noise", str(build), "--out", str(out),
            "--gains", *GAINS, "--seed", SEED, "--quiet"]  # fmt: skip
    env = dict(os.environ, BLURSET_NOISE_FAULT="kill_in:2")
    proc = subprocess.run(args, env=env, capture_output=True, text=True, timeout=600)
    assert proc.returncode == -signal.SIGKILL, proc.stderr
    # The first unit (one setting's level, every gain) is complete; the second is not.
    done = len(list(out.glob("*/*/gain_*/.complete")))
    assert done == len(GAINS), done
    assert list(out.rglob("*.partial")), "the killed unit left its partial folders"
    p = run_cli("noise", str(build), "--out", str(out), "--gains", *GAINS, "--seed", SEED)
    assert f"{30 - done} scene(s) written, {done} complete skipped" in p.stdout, p.stdout
    assert not list(out.rglob("*.partial"))
    want = {k: v[1] for k, v in files_state(lin).items() if "/gain_" in k and "complete" not in k}
    got = {k: v[1] for k, v in files_state(out).items() if "/gain_" in k and "complete" not in k}
    assert got == want


def test_levels_subset_and_changed_options_refused(noised, tmp_path):
    build, lin, _ = noised
    out = tmp_path / "sub"
    run_cli("noise", str(build), "--out", str(out), "--gains", "4", "--levels", "blur_4,sharp",
            "--source", "png", "--seed", SEED)  # fmt: skip
    assert sorted({p.parent.name for p in out.glob("*/*/gain_4")}) == ["blur_4", "sharp"]
    # The same (setting, level, gain) gets the same bytes whichever levels are chosen.
    full = tmp_path / "full"
    run_cli("noise", str(build), "--out", str(full), "--gains", "4", "--levels", "blur_4",
            "--source", "png", "--seed", SEED)  # fmt: skip
    a, b = out / "demo_box_000" / "blur_4" / "gain_4", full / "demo_box_000" / "blur_4" / "gain_4"
    assert (a / "linear" / "000.exr").read_bytes() == (b / "linear" / "000.exr").read_bytes()
    p = run_cli("noise", str(build), "--out", str(lin), "--gains", *GAINS, "--seed", "6",
                check=False)  # fmt: skip
    assert p.returncode == 2 and "seed" in p.stderr and "noise_dataset.json" in p.stderr


# --- bad input --------------------------------------------------------------------------


def one_line_error(p, *fragments: str) -> None:
    assert p.returncode == 2, p.stderr
    lines = p.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("blurset noise: error:"), p.stderr
    for f in fragments:
        assert f in lines[0], lines[0]


def test_bad_input_one_line_nothing_written(linear_build, tmp_path):
    out = tmp_path / "out"
    cases = [
        ([str(tmp_path / "nope"), "--gains", "1"], ["nope"]),
        ([str(linear_build), "--gains", "1", "--levels", "sharp,blur_9"],
         ["unknown level 'blur_9'", "--levels"]),
        ([str(linear_build), "--gains", "1", "3"], ["unknown gain '3'", "--gains"]),
        ([str(linear_build), "--gains", "1", "--factor", "2"], ["--factor"]),
    ]  # fmt: skip
    for args, fragments in cases:
        one_line_error(run_cli("noise", *args, "--out", str(out), check=False), *fragments)
        assert not out.exists()
    # A build without one linear image is a damaged build: noise refuses it, naming the
    # setting and the folder that lacks the file (issue 34: damaged builds are refused).
    broken = tmp_path / "broken"
    shutil.copytree(linear_build, broken)
    (broken / "demo_box_000" / "blur_3" / "linear" / "005.exr").unlink()
    p = run_cli("noise", str(broken), "--out", str(out), "--gains", "1", "--source", "linear",
                check=False)  # fmt: skip
    one_line_error(p, "demo_box_000", "blur_3/linear", "16 of 17")
    assert not out.exists()
    # Whatever the source: a damaged build is not noised from its PNGs instead.
    p = run_cli("noise", str(broken), "--out", str(out), "--gains", "1", "--levels", "blur_3",
                check=False)  # fmt: skip
    one_line_error(p, "demo_box_000", "blur_3/linear")
    assert not out.exists()
    (broken / "dataset.json").write_text("{ not json")
    one_line_error(run_cli("noise", str(broken), "--out", str(out), check=False), "dataset.json")
    assert not out.exists()


def test_nan_in_a_linear_image_fails_cleanly(linear_build, tmp_path):
    """An error in the middle of the work: one clear line naming the file, no partial
    unit left, the units finished before it complete."""
    broken = tmp_path / "broken"
    shutil.copytree(linear_build, broken)
    bad = broken / "demo_cylinder_000" / "blur_1" / "linear" / "007.exr"
    rgba = read_exr(bad).astype(np.float32)
    rgba[10, 20, 1] = np.nan
    OpenEXR.File({"compression": OpenEXR.ZIP_COMPRESSION}, {"RGBA": rgba}).write(str(bad))
    out = tmp_path / "out"
    p = run_cli("noise", str(broken), "--out", str(out), "--gains", "1", "--source", "linear",
                check=False)  # fmt: skip
    one_line_error(p, "007.exr", "non-finite")
    assert not list(out.rglob("*.partial"))
    assert not (out / "demo_cylinder_000" / "blur_1" / "gain_1").exists()
    done = list(out.glob("*/*/gain_1"))
    assert done and all((d / ".complete").is_file() for d in done)


def test_open_scene_gives_noisy_sources_and_clean_pairs(noised):
    """`blurset.data.open_scene` with a gain: the gain's files at the size asked, the
    sharp images as `clean`, clean (level) images at the test views."""
    from blurset.data import open_scene

    build, _, png = noised
    s = settings(build)[2].name
    sc = open_scene(build, s, "blur_2", gain=16, noise=png, downsample=4)
    unit = png / s / "blur_2" / "gain_16"
    assert sc.noise["gain"] == 16 and sc.images.shape == (17, 16, 16, 3)
    for v in (0, 3):
        want = np.asarray(Image.open(unit / "images_4" / f"{v:03d}.png")) / 255
        np.testing.assert_allclose(sc.images[v], want, atol=1e-6)
        clean = np.asarray(Image.open(build / s / "sharp" / "images_4" / f"{v:03d}.png")) / 255
        np.testing.assert_allclose(sc.clean[v], clean, atol=1e-6)
    np.testing.assert_array_equal(sc.images[sc.test_views], sc.clean[sc.test_views])
    noise = sc.images[sc.train_views] - sc.clean[sc.train_views]
    assert noise.std() > 0.05  # gain 16 at 16 px: visibly noisy
    level = open_scene(build, s, "blur_2", downsample=4)
    np.testing.assert_array_equal(sc.c2w_opencv, level.c2w_opencv)
    np.testing.assert_array_equal(sc.intrinsics, level.intrinsics)
