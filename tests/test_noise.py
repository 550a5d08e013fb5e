"""`blurset noise` (issue 3, DESIGN §5): noise statistics on real LLFF data, determinism
across thread counts, extremes, input formats, bad input, and loader compatibility."""

from __future__ import annotations

import json
import os
import shutil
import struct
import subprocess
import sys
import zlib
from pathlib import Path

import numpy as np
import OpenEXR
import pytest
from blurset.image import read_image
from blurset.noise.model import noise_default_levels, noise_image, noise_key, noise_sigmas
from PIL import Image

from tests.conftest import run_cli, shared

ALL_GAINS = ("1", "2", "4", "8", "16", "20")


def blurset_noise(*args, threads: int | None = None) -> subprocess.CompletedProcess:
    env = dict(os.environ)
    if threads is not None:
        env["RAYON_NUM_THREADS"] = str(threads)
    return subprocess.run(
        [sys.executable, "-m", "blurset.cli", "noise", *map(str, args)],
        capture_output=True,
        text=True,
        env=env,
    )


def ok(proc: subprocess.CompletedProcess) -> subprocess.CompletedProcess:
    assert proc.returncode == 0, proc.stderr
    return proc


def read_exr(path: Path) -> np.ndarray:
    ch = OpenEXR.File(str(path)).channels()
    key = "RGBA" if "RGBA" in ch else "RGB"
    return np.asarray(ch[key].pixels, dtype=np.float32)


def png16(path: Path, a: np.ndarray) -> None:
    """A minimal 16-bit PNG writer (so the input does not come from our own encoder)."""
    h, w = a.shape[:2]
    c = 1 if a.ndim == 2 else a.shape[2]
    color = {1: 0, 2: 4, 3: 2, 4: 6}[c]
    rows = a.reshape(h, w * c).astype(">u2").tobytes()
    stride = w * c * 2
    raw = b"".join(b"\x00" + rows[i * stride : (i + 1) * stride] for i in range(h))

    def chunk(tag: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + tag + data + struct.pack(">I", zlib.crc32(tag + data))

    ihdr = struct.pack(">IIBBBBB", w, h, 16, color, 0, 0, 0)
    path.write_bytes(
        b"\x89PNG\r\n\x1a\n"
        + chunk(b"IHDR", ihdr)
        + chunk(b"IDAT", zlib.compress(raw))
        + chunk(b"IEND", b"")
    )


def pose_rows(n: int, h: int, w: int, focal: float) -> np.ndarray:
    rows = np.zeros((n, 17))
    for i in range(n):
        m = np.zeros((3, 5))
        m[:, :3] = np.eye(3)
        m[:, 3] = [0.1 * i, 0.0, 0.0]
        m[:, 4] = [h, w, focal]
        rows[i, :15] = m.ravel()
        rows[i, 15:] = [1.0, 10.0]
    return rows


def make_scene(root: Path, images: list[np.ndarray], ext: str = ".png", sub: str = "images_2"):
    """An LLFF scene of given arrays; poses describe the full resolution (factor 2)."""
    d = root / sub
    d.mkdir(parents=True)
    for i, a in enumerate(images):
        p = d / f"img{i:03d}{ext}"
        if a.dtype == np.uint16:
            png16(p, a)
        else:
            Image.fromarray(a).save(p, quality=95) if ext == ".jpg" else Image.fromarray(a).save(p)
    h, w = images[0].shape[:2]
    np.save(root / "poses_bounds.npy", pose_rows(len(images), 2 * h, 2 * w, 100.0))
    return root


def tree_bytes(root: Path) -> dict[str, bytes]:
    return {
        str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()
    }


@pytest.fixture(scope="module")
def fern_out(tmp_path_factory):
    fern = shared("llff", "fern")
    out = tmp_path_factory.mktemp("fern") / "fernN"
    # The guide's form: fern ships images_8/ alone, found without --factor.
    ok(blurset_noise(fern, "--seed", 11, "--out", out))
    return fern, out


# --- real data ----------------------------------------------------------------------


def test_fern_is_an_llff_scene_per_gain(fern_out):
    fern, out = fern_out
    src = np.load(fern / "poses_bounds.npy")
    assert sorted(p.name for p in out.iterdir()) == sorted(f"gain_{g}" for g in ALL_GAINS) + [
        "noise_scene.json"
    ]
    for g in ALL_GAINS:
        d = out / f"gain_{g}"
        # What an IBRNet / NAN LLFF loader at factor 8 does: sorted png/jpg files of
        # images_8/, N x 17 poses whose hwf (the full size) it divides by 8.
        files = [f for f in sorted(os.listdir(d / "images_8")) if f.endswith(("png", "jpg"))]
        pb = np.load(d / "poses_bounds.npy")
        assert pb.shape == (20, 17) and pb.dtype == np.float64
        assert len(files) == pb.shape[0]
        assert files == sorted(os.listdir(fern / "images_8"))
        np.testing.assert_array_equal(pb, src)
        # llffhold 8: views 0, 8, 16 are the source's bytes, every other view noisy.
        same = [
            (d / "images_8" / f).read_bytes() == (fern / "images_8" / f).read_bytes() for f in files
        ]
        assert [i for i, s in enumerate(same) if s] == [0, 8, 16]
        meta = json.loads((d / "noise.json").read_text())
        for key in (
            "gain",
            "seed",
            "sigma_read",
            "sigma_shot",
            "gamma",
            "white_balance",
            "white_level",
            "frames",
            "files",
        ):
            assert key in meta
        assert meta["gain"] == int(g) and meta["seed"] == 11 and meta["frames"] == 1
        assert [f["image"] for f in meta["files"]] == [f"images_8/{f}" for f in files]
        assert meta["clean_views"] == [0, 8, 16]
        assert sorted(os.listdir(d / "linear_8")) == [f.replace(".png", ".exr") for f in files]
        assert np.asarray(Image.open(d / "images_8" / files[0])).shape == (378, 504, 3)
    assert json.loads((out / "noise_scene.json").read_text())["llffhold"] == 8


def test_fern_noise_statistics_per_gain_and_brightness(fern_out):
    """Residual mean ~ 0 and variance sigma_r^2 + sigma_s^2 y within 3 % in every
    brightness bin, computed independently in NumPy from the clean PNG."""
    fern, out = fern_out
    edges = np.array([0.0, 0.002, 0.005, 0.01, 0.02, 0.05, 0.1, 0.2, 0.35, 0.6, 1.01])
    sigmas = []
    for g in ALL_GAINS:
        d = out / f"gain_{g}"
        meta = json.loads((d / "noise.json").read_text())
        sr, ss, wb = meta["sigma_read"], meta["sigma_shot"], meta["white_balance"]
        sigmas.append((sr, ss))
        scale = np.array([1 / wb["red"], 1.0, 1 / wb["blue"]])
        n = np.zeros(len(edges) - 1)
        s1, s2, pred = np.zeros_like(n), np.zeros_like(n), np.zeros_like(n)
        negative = 0
        for f in (f for f in meta["files"] if not f.get("clean")):
            x = np.asarray(Image.open(fern / "images_8" / f["source"]), dtype=np.float64) / 255
            y = x**2.2 * scale
            lin = read_exr(d / f["linear"]).astype(np.float64)
            assert np.isfinite(lin).all()
            negative += int((lin < 0).sum())
            r = (lin - y).ravel()
            yy = y.ravel()
            b = np.digitize(yy, edges) - 1
            n += np.bincount(b, minlength=len(n))
            s1 += np.bincount(b, r, minlength=len(n))
            s2 += np.bincount(b, r * r, minlength=len(n))
            pred += np.bincount(b, sr**2 + ss**2 * yy, minlength=len(n))
            # The PNG is the forward processing of the same noisy values.
            png = np.asarray(Image.open(d / f["image"]), dtype=np.float64)
            want = np.round(255 * np.clip(lin / scale, 0, 1) ** (1 / 2.2))
            assert np.abs(png - want).max() <= 1
        assert negative > 0, f"gain {g}: negative linear values were clipped"
        for i in np.nonzero(n >= 20_000)[0]:
            mean, var, want = s1[i] / n[i], s2[i] / n[i] - (s1[i] / n[i]) ** 2, pred[i] / n[i]
            assert abs(mean) < 5 * np.sqrt(want / n[i]), (g, edges[i], mean)
            assert abs(var / want - 1) < 0.03, (g, edges[i], var, want)
    assert sigmas == sorted(sigmas), "sigma must grow with gain"


def test_api_reproduces_cli_bits(fern_out):
    fern, out = fern_out
    meta = json.loads((out / "gain_4" / "noise.json").read_text())
    wb = meta["white_balance"]
    view = 5
    img = read_image(fern / "images_8" / meta["files"][view]["source"])
    lin, proc = noise_image(
        img,
        sigma_read=meta["sigma_read"],
        sigma_shot=meta["sigma_shot"],
        key=noise_key(11, 4.0),
        view=view,
        white_balance=(wb["red"], wb["blue"]),
    )
    np.testing.assert_array_equal(lin, read_exr(out / "gain_4" / meta["files"][view]["linear"]))
    np.testing.assert_array_equal(
        proc, np.asarray(Image.open(out / "gain_4" / meta["files"][view]["image"]))
    )


# --- determinism --------------------------------------------------------------------


@pytest.fixture
def small_scene(tmp_path, rng):
    imgs = [rng.integers(0, 256, (37, 53, 3), dtype=np.uint8) for _ in range(4)]
    return make_scene(tmp_path / "scene", imgs)


def test_same_seed_same_bytes_for_any_thread_count(small_scene, tmp_path):
    trees = []
    for threads, seed in [(1, 5), (2, 5), (2, 6)]:
        out = tmp_path / f"out_{threads}_{seed}"
        ok(
            blurset_noise(
                small_scene,
                "--factor",
                2,
                "--gains",
                1,
                20,
                "--frames",
                2,
                "--seed",
                seed,
                "--noisy-test-views",
                "--out",
                out,
                threads=threads,
            )
        )
        trees.append(tree_bytes(out))
    assert trees[0] == trees[1]
    assert trees[0].keys() == trees[2].keys()
    differs = [k for k in trees[0] if k.endswith((".exr", ".png")) and trees[0][k] != trees[2][k]]
    assert len(differs) == len([k for k in trees[0] if k.endswith((".exr", ".png"))])


def test_fern_same_bytes_with_one_and_two_threads(tmp_path):
    fern = shared("llff", "fern")
    a, b = tmp_path / "a", tmp_path / "b"
    ok(blurset_noise(fern, "--factor", 8, "--gains", 2, 16, "--seed", 3, "--out", a, threads=1))
    ok(blurset_noise(fern, "--factor", 8, "--gains", 2, 16, "--seed", 3, "--out", b, threads=2))
    assert tree_bytes(a) == tree_bytes(b)


# --- extremes -----------------------------------------------------------------------


def test_black_has_std_sigma_read():
    levels = noise_default_levels()
    for gain in (1.0, 20.0):
        sr, ss = noise_sigmas(gain, levels)
        black = np.zeros((400, 400, 3), np.uint8)
        lin, proc = noise_image(black, sigma_read=sr, sigma_shot=ss, key=noise_key(1, gain))
        assert abs(lin.std() / sr - 1) < 0.01
        assert abs(lin.mean()) < 5 * sr / np.sqrt(lin.size)
        assert (lin < 0).mean() == pytest.approx(0.5, abs=0.01)
        assert proc.min() == 0 and proc.dtype == np.uint8


def test_white_gain_20_and_tiny_white_level_stay_finite():
    sr, ss = noise_sigmas(20.0, noise_default_levels())
    white = np.full((300, 300, 3), 255, np.uint8)
    lin, _ = noise_image(white, sigma_read=sr, sigma_shot=ss, key=7)
    assert np.isfinite(lin).all()
    assert lin.var() == pytest.approx(sr**2 + ss**2, rel=0.02)
    for wl in (1e-6, 1e-3):
        lin, proc = noise_image(
            white, sigma_read=sr, sigma_shot=ss, key=7, white_level=wl, white_balance=(2.4, 1.9)
        )
        assert np.isfinite(lin).all() and proc.dtype == np.uint8
    with pytest.raises(ValueError, match="white level"):
        noise_image(white, sigma_read=sr, sigma_shot=ss, key=7, white_level=0.0)


def test_tiny_white_level_through_the_cli(small_scene, tmp_path):
    out = tmp_path / "out"
    ok(
        blurset_noise(
            small_scene, "--factor", 2, "--gains", 20, "--white-level", 1e-6, "--out", out
        )
    )
    lin = read_exr(out / "gain_20" / "linear_2" / "img000.exr")
    assert np.isfinite(lin).all()


def test_zero_noise_round_trips_every_depth():
    ramp8 = np.arange(256, dtype=np.uint8).reshape(16, 16)
    ramp16 = (np.arange(256 * 256, dtype=np.uint32)).astype(np.uint16).reshape(256, 256)
    for img in (ramp8, np.stack([ramp8] * 3, -1), ramp16):
        for gamma in ("2.2", "srgb"):
            _, proc = noise_image(img, sigma_read=0.0, sigma_shot=0.0, key=0, gamma=gamma)
            np.testing.assert_array_equal(proc.reshape(img.shape), img)


# --- input formats --------------------------------------------------------------------


@pytest.mark.parametrize(
    "kind", ["png8", "png16", "jpg", "rgba", "gray", "gray_alpha", "png16_rgba"]
)
def test_input_formats(kind, tmp_path, rng):
    h, w = 24, 32
    base = (np.linspace(0, 1, h * w).reshape(h, w, 1) * np.array([1.0, 0.7, 0.4])).astype(
        np.float64
    )
    alpha = rng.integers(0, 256, (h, w, 1), dtype=np.uint8)
    a = {
        "png8": (base * 255).round().astype(np.uint8),
        "jpg": (base * 255).round().astype(np.uint8),
        "png16": (base * 65535).round().astype(np.uint16),
        "rgba": np.concatenate([(base * 255).round().astype(np.uint8), alpha], -1),
        "gray": (base[..., 0] * 255).round().astype(np.uint8),
        "gray_alpha": np.concatenate([(base[..., :1] * 255).round().astype(np.uint8), alpha], -1),
        "png16_rgba": np.concatenate(
            [(base * 65535).round(), alpha.astype(np.float64) * 257], -1
        ).astype(np.uint16),
    }[kind]
    ext = ".jpg" if kind == "jpg" else ".png"
    scene = make_scene(tmp_path / "s", [a, a], ext=ext)
    out = tmp_path / "out"
    ok(blurset_noise(scene, "--factor", 2, "--gains", 1, "--out", out))
    d = out / "gain_1"
    # View 1: view 0 is a clean target (llffhold 8).
    src = read_image(scene / "images_2" / f"img001{ext}")
    proc = read_image(d / "images_2" / "img001.png")
    assert proc.shape == src.shape and proc.dtype == src.dtype
    channels = src.shape[2]
    if channels in (2, 4):
        np.testing.assert_array_equal(proc[..., -1], src[..., -1])
    lin = read_exr(d / "linear_2" / "img001.exr")
    assert lin.shape == (h, w, 4 if channels in (2, 4) else 3)
    if channels in (2, 4):
        np.testing.assert_allclose(lin[..., 3], src[..., -1] / np.iinfo(src.dtype).max, rtol=1e-6)
    # Gain 1 is mild: the processed image stays close to its source.
    top = float(np.iinfo(src.dtype).max)
    color = slice(0, 3 if channels >= 3 else 1)
    assert np.abs(proc[..., color] / top - src[..., color] / top).mean() < 0.03
    pb = np.load(d / "poses_bounds.npy")
    # hwf stays the full size: a loader at factor 2 divides it.
    np.testing.assert_allclose(pb[0, [4, 9, 14]], [2 * h, 2 * w, 100.0])


def test_burst_frames_sort_in_view_order(small_scene, tmp_path):
    out = tmp_path / "out"
    ok(blurset_noise(small_scene, "--factor", 2, "--gains", 8, "--frames", 3, "--out", out))
    d = out / "gain_8"
    files = sorted(os.listdir(d / "images_2"))
    meta = json.loads((d / "noise.json").read_text())
    assert [f["image"] for f in meta["files"]] == [f"images_2/{f}" for f in files]
    assert [(f["view"], f["frame"]) for f in meta["files"]] == [
        (v, k) for v in range(4) for k in range(3)
    ]
    pb = np.load(d / "poses_bounds.npy")
    src = np.load(small_scene / "poses_bounds.npy")
    assert pb.shape == (12, 17)
    np.testing.assert_array_equal(pb[:, 3], np.repeat(src[:, 3], 3))
    frames = [read_exr(d / f["linear"]) for f in meta["files"][3:6]]  # view 1: noisy
    assert not np.array_equal(frames[0], frames[1]) and not np.array_equal(frames[1], frames[2])


def test_the_core_plan_is_what_the_command_writes(small_scene, tmp_path):
    """The plan of a scene (issue 36) holds per gain the folder, key, sigmas and the
    whole noise.json; the command writes exactly that record, and the rng it names is
    the key the API reproduces."""
    from blurset.commands.noise.cli import NoiseConfig
    from blurset.commands.noise.params import planned
    from blurset.exceptions import ConfigError
    from blurset.noise.model import plan_noise_scene

    cfg = NoiseConfig(gains=["1", "8"], factor=2, seed=3, clean_views=2, frames=2)
    out = tmp_path / "out"
    plan = plan_noise_scene(small_scene, out, cfg, noise_default_levels())
    (unit,) = plan.units
    assert (plan.gamma, unit.seed, unit.images, unit.clean_views) == ("2.2", 3, 8, [0, 2])
    ok(blurset_noise(small_scene, "--factor", 2, "--gains", 1, 8, "--seed", 3,
                     "--clean-views", 2, "--frames", 2, "--out", out))  # fmt: skip
    for g in unit.gains:
        assert (g.key, (g.sigma_read, g.sigma_shot)) == (
            noise_key(3, g.gain),
            noise_sigmas(g.gain, noise_default_levels()),
        )
        written = json.loads((out / g.dir / "noise.json").read_text())
        assert written == json.loads(json.dumps(g.record))  # tuples as JSON arrays
        assert written["rng"].startswith("philox4x32-10, key derive_seed(seed, [fnv1a64('noise')")
    bad = NoiseConfig(gains=["1", "1.0000000001"], any_gain=True, factor=2)
    with pytest.raises(ConfigError, match=r"^--gains 1 and 1.0000000001: both .* gain_1/$"):
        planned(plan_noise_scene, small_scene, out, bad, noise_default_levels())


def test_kpn_levels_follow_nans_mapping(small_scene, tmp_path):
    # A file in KPN's layout (our own numbers: KPN's file is not redistributable).
    levels = 10.0 ** np.array([-3.1, -2.8, -2.4, -2.1, -1.8, -1.5])
    npz = tmp_path / "kpn.npz"
    np.savez(npz, sig_read=np.repeat(levels, 73), sig_shot=np.repeat(levels / 3, 73)[::-1])
    out = tmp_path / "out"
    ok(
        blurset_noise(
            small_scene,
            "--factor",
            2,
            "--gains",
            1,
            20,
            "--kpn-levels",
            npz,
            "--profile",
            "nan",
            "--out",
            out,
        )
    )
    for gain in (1, 20):
        meta = json.loads((out / f"gain_{gain}" / "noise.json").read_text())
        assert meta["white_balance"] is None
        for key, name in (("sigma_read", "sig_read"), ("sigma_shot", "sig_shot")):
            # NAN's code, verbatim in effect.
            lst = np.unique(np.load(npz)[name])[2:]
            log = np.log10(lst)
            want = 10 ** (log[0] + np.diff(log)[0] * np.log2(gain))
            assert meta[key] == pytest.approx(want, rel=1e-12)


# --- a scene as LLFF downloads ship it (issue 71) -----------------------------------


def ten_view_scene(root: Path, rng, sub: str = "images_8") -> Path:
    """Ten 16 x 12 views in `sub` alone, as fern ships images_8/ (views 0 and 8 are the
    held-out targets of llffhold 8)."""
    return make_scene(root, [rng.integers(0, 256, (12, 16, 3), dtype=np.uint8) for _ in range(10)],
                      sub=sub)  # fmt: skip


def test_the_one_factor_folder_is_read_and_written_under_its_name(tmp_path, rng):
    """No --factor: the scene's one images_8/ is read, each gain written to images_8/ with
    the scene's poses byte for byte (hwf the full size: a loader at factor 8 divides it),
    views i % 8 == 0 the source's own bytes and every other view noisy; --downsample 2
    is factor 16 beside it."""
    scene = ten_view_scene(tmp_path / "s", rng)
    out = tmp_path / "out"
    proc = ok(blurset_noise(scene, "--gains", 4, "--downsample", 2, "--out", out))
    assert "images_8/; views 0, 8 clean (llffhold 8)" in proc.stdout, proc.stdout
    g = out / "gain_4"
    assert sorted(p.name for p in g.iterdir()) == [
        "images_16", "images_8", "linear_16", "linear_8", "noise.json", "poses_bounds.npy"
    ]  # fmt: skip
    assert (g / "poses_bounds.npy").read_bytes() == (scene / "poses_bounds.npy").read_bytes()
    names = sorted(p.name for p in (scene / "images_8").iterdir())
    assert sorted(p.name for p in (g / "images_8").iterdir()) == names
    same = [(g / "images_8" / n).read_bytes() == (scene / "images_8" / n).read_bytes()
            for n in names]  # fmt: skip
    assert [i for i, s in enumerate(same) if s] == [0, 8]
    assert read_image(g / "images_16" / names[1]).shape == (6, 8, 3)
    meta = json.loads((g / "noise.json").read_text())
    assert meta["source"]["images"] == "images_8" and meta["clean_views"] == [0, 8]
    assert json.loads((out / "noise_scene.json").read_text())["llffhold"] == 8


def test_the_hold_is_an_option_and_noisy_test_views_noises_them_all(tmp_path, rng):
    scene = ten_view_scene(tmp_path / "s", rng)
    for extra, clean, hold in (
        (["--clean-views", 3], [0, 3, 6, 9], 3),
        (["--noisy-test-views"], [], None),
    ):
        out = tmp_path / f"out{len(clean)}"
        ok(blurset_noise(scene, "--gains", 8, "--out", out, *extra))
        g = out / "gain_8"
        same = [i for i in range(10)
                if (g / "images_8" / f"img{i:03d}.png").read_bytes()
                == (scene / "images_8" / f"img{i:03d}.png").read_bytes()]  # fmt: skip
        assert same == clean
        assert json.loads((out / "noise_scene.json").read_text()).get("llffhold") == hold


def test_no_linear_writes_the_same_pngs_and_no_exr(tmp_path, rng):
    scene = ten_view_scene(tmp_path / "s", rng)
    a, b = tmp_path / "a", tmp_path / "b"
    ok(blurset_noise(scene, "--gains", 4, 16, "--downsample", 2, "--out", a))
    ok(blurset_noise(scene, "--gains", 4, 16, "--downsample", 2, "--out", b, "--no-linear"))
    ta, tb = tree_bytes(a), tree_bytes(b)
    assert not [k for k in tb if k.endswith(".exr")] and not list(b.glob("*/linear*"))
    pngs = [k for k in ta if k.endswith(".png")]
    assert len(pngs) == 2 * 10 * 2 and all(ta[k] == tb[k] for k in pngs)
    files = json.loads((b / "gain_4" / "noise.json").read_text())["files"]
    assert all("linear" not in f for f in files)
    assert verify_cli(b).returncode == 0


def test_no_linear_in_build_mode_same_pngs_verified_and_kept(standin_build_dir, tmp_path):
    """A build's noise with --no-linear: no EXR, the same PNGs, verify and export read it,
    and a rerun that would add EXRs is refused (its options differ)."""
    a, n = tmp_path / "a", tmp_path / "n"
    args = ("noise", str(standin_build_dir), "--gains", "4", "--levels", "blur_1", "--quiet")
    run_cli(*args, "--out", str(a))
    run_cli(*args, "--out", str(n), "--no-linear")
    ta, tn = tree_bytes(a), tree_bytes(n)
    assert [k for k in ta if k.endswith(".exr")] and not [k for k in tn if k.endswith(".exr")]
    pngs = [k for k in ta if k.endswith(".png")]
    assert pngs and all(tn[k] == ta[k] for k in pngs)
    assert json.loads((n / "noise_dataset.json").read_text())["params"]["no_linear"] is True
    assert run_cli("verify", str(n)).returncode == 0
    again = run_cli(*args, "--out", str(n), check=False)
    assert again.returncode == 2 and "no_linear" in again.stderr, again.stderr
    run_cli("export", str(standin_build_dir), "--out", str(tmp_path / "e"), "--noise", str(n))
    assert list((tmp_path / "e").glob("nerf_llff_data/*__blur_1__gain_4/images/*.png"))


# --- blurset verify of a scene's noise -------------------------------------------------


def verify_cli(path: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "blurset.cli", "verify", str(path)],
                          capture_output=True, text=True)  # fmt: skip


def _damage(out: Path, case: str) -> str:
    """Damage a good scene output one way; the file the verdict must name."""
    g = out / "gain_4"
    png, exr = g / "images_8" / "img003.png", g / "linear_8" / "img003.exr"
    if case == "png_missing":
        png.unlink()
    elif case == "png_cut":
        png.write_bytes(png.read_bytes()[:100])
    elif case == "png_size":
        Image.fromarray(np.zeros((6, 8, 3), np.uint8)).save(png)
    elif case == "exr_missing":
        exr.unlink()
        png = exr
    elif case == "small_missing":
        png = g / "images_16" / "img003.png"
        png.unlink()
    elif case == "poses_row":
        np.save(g / "poses_bounds.npy", np.load(g / "poses_bounds.npy")[:-1])
        return "gain_4/poses_bounds.npy"
    elif case == "gain_gone":
        shutil.rmtree(out / "gain_16")
        return "gain_16"
    elif case == "stray":
        png = g / "images_8" / "extra.png"
        shutil.copy(g / "images_8" / "img000.png", png)
    elif case == "record":
        (g / "noise.json").write_text("{}")
        return "gain_4/noise.json"
    return png.relative_to(out).as_posix()


VERIFY_DAMAGE = ["png_missing", "png_cut", "png_size", "exr_missing", "small_missing",
                 "poses_row", "gain_gone", "stray", "record"]  # fmt: skip


@pytest.fixture(scope="module")
def scene_noise(tmp_path_factory):
    root = tmp_path_factory.mktemp("scene_noise")
    scene = ten_view_scene(root / "s", np.random.default_rng(3))
    out = root / "out"
    ok(blurset_noise(scene, "--gains", 4, 16, "--downsample", 2, "--out", out))
    return out


def test_verify_vouches_for_a_scene_output(scene_noise):
    proc = verify_cli(scene_noise)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    # 2 gains x 10 views x (images_8, linear_8, images_16, linear_16)
    assert "is whole: 2 complete gains, 80 images decoded" in proc.stderr, proc.stderr


@pytest.mark.parametrize("case", VERIFY_DAMAGE)
def test_verify_names_each_damage_of_a_scene_output(case, scene_noise, tmp_path):
    out = tmp_path / "out"
    shutil.copytree(scene_noise, out)
    rel = _damage(out, case)
    proc = verify_cli(out)
    assert proc.returncode == 1, proc.stdout + proc.stderr
    lines = proc.stdout.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"{out}/{rel}: "), proc.stdout


def test_verify_vouches_for_the_fern_output(fern_out):
    _, out = fern_out
    proc = verify_cli(out)
    assert proc.returncode == 0 and "6 complete gains, 240 images decoded" in proc.stderr


# --- bad input --------------------------------------------------------------------------


def _bad_cases(scene: Path, tmp: Path) -> dict[str, tuple[list, str]]:
    return {
        "missing_poses": (["--factor", 2], "poses_bounds.npy"),
        "count_mismatch": (["--factor", 2], "pose rows"),
        "different_sizes": (["--factor", 2], "img003.png"),
        "unknown_gain": (["--factor", 2, "--gains", 1, 3], "unknown gain '3'"),
        "not_a_gain": (["--factor", 2, "--gains", "x"], "unknown gain 'x'"),
        "unreadable_image": (["--factor", 2], "img002.png"),
        "truncated_image": (["--factor", 2], "img001.png"),
        "missing_factor_dir": (["--factor", 4], "images_4"),
        "bad_kpn_file": (["--factor", 2, "--kpn-levels", tmp / "nope.npz"], "nope.npz"),
        "several_folders": ([], "the scene holds images/, images_2/: pass --factor F"),
        "no_image_folder": ([], "no images/ or images_<f>/ directory"),
        "clean_and_noisy": (
            ["--factor", 2, "--clean-views", 2, "--noisy-test-views"],
            "--clean-views and --noisy-test-views",
        ),
    }


@pytest.mark.parametrize(
    "case",
    ["missing_poses", "count_mismatch", "different_sizes", "unknown_gain", "not_a_gain",
     "unreadable_image", "truncated_image", "missing_factor_dir", "bad_kpn_file",
     "several_folders", "no_image_folder", "clean_and_noisy"],
)  # fmt: skip
def test_bad_input_one_line_nothing_written(case, small_scene, tmp_path):
    args, fragment = _bad_cases(small_scene, tmp_path)[case]
    imgs = small_scene / "images_2"
    if case == "missing_poses":
        (small_scene / "poses_bounds.npy").unlink()
    elif case == "count_mismatch":
        (imgs / "img003.png").unlink()
    elif case == "different_sizes":
        Image.fromarray(np.zeros((10, 10, 3), np.uint8)).save(imgs / "img003.png")
    elif case == "unreadable_image":
        (imgs / "img002.png").write_bytes(b"\x89PNG\r\n\x1a\n truncated garbage")
    elif case == "truncated_image":
        # A valid header, so only decoding (inside the pixel work) finds the damage.
        data = (imgs / "img001.png").read_bytes()
        (imgs / "img001.png").write_bytes(data[: len(data) // 2])
    elif case == "several_folders":
        shutil.copytree(imgs, small_scene / "images")
    elif case == "no_image_folder":
        imgs.rename(small_scene / "pictures")
    (tmp_path / "nope.npz").write_bytes(b"not an npz")
    parent = tmp_path / "outs"
    parent.mkdir()
    proc = blurset_noise(small_scene, *args, "--out", parent / "out")
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("blurset noise: error:"), proc.stderr
    assert fragment in lines[0], lines[0]
    assert list(parent.iterdir()) == [], "nothing may be left behind"


def test_existing_out_is_refused_unless_overwrite(small_scene, tmp_path):
    out = tmp_path / "out"
    ok(blurset_noise(small_scene, "--factor", 2, "--gains", 1, "--out", out))
    proc = blurset_noise(small_scene, "--factor", 2, "--gains", 2, "--out", out)
    assert proc.returncode == 2 and "--overwrite" in proc.stderr
    ok(blurset_noise(small_scene, "--factor", 2, "--gains", 2, "--out", out, "--overwrite"))
    assert sorted(p.name for p in out.iterdir()) == ["gain_2", "noise_scene.json"]
