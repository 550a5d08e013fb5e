"""--denoise oidn (issue 28): a blurry image is denoised once, after averaging its latent
frames' colour and guides; the sharp image the same way. Real Blender renders at tiny
sizes; nothing here asserts a timing."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from tests.conftest import needs_bpy, run_cli, shared

LUMA = np.array([0.2126, 0.7152, 0.0722], np.float32)


def _setting(out: Path) -> Path:
    (s,) = [d for d in out.iterdir() if (d / ".complete").exists()]
    return s


# -- options ----------------------------------------------------------------------------


def test_bad_denoise_option_is_one_line(tmp_path):
    p = run_cli("build", "--demo", "--out", str(tmp_path / "o"), "--denoise", "nlm", check=False)
    # argparse's choice check, as for every choice flag: usage, then the one error line.
    last = p.stderr.strip().splitlines()[-1]
    assert p.returncode == 2 and "--denoise" in last and "'oidn'" in last, p.stderr
    toml = tmp_path / "c.toml"
    toml.write_text('denoise = "optix"\n')
    p = run_cli("build", "--demo", "--out", str(tmp_path / "o"), "--config", str(toml), check=False)
    assert p.returncode == 2 and "denoise" in p.stderr and "none, oidn" in p.stderr, p.stderr
    assert len(p.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "o").exists()


def test_missing_oidn_library_is_one_line_before_anything_is_written(tmp_path):
    import os

    env = dict(os.environ, BLURSET_OIDN_LIBRARY=str(tmp_path / "libnothing.so"))
    out = tmp_path / "o"
    p = run_cli("build", "--demo", "--out", str(out), "--denoise", "oidn", env=env, check=False)
    assert p.returncode == 2, p.stderr
    assert p.stderr.strip().startswith("blurset build: error: --denoise oidn: cannot load"), (
        p.stderr
    )
    assert len(p.stderr.strip().splitlines()) == 1
    assert not out.exists()


def test_denoiser_on_arrays_keeps_a_flat_image_and_checks_shapes():
    needs_bpy()  # OIDN comes with the bpy wheel
    from blurset.services.denoise import denoiser

    d = denoiser("cpu")
    assert d.device_type == "CPU" and d.record()["library"] == "OpenImageDenoise"
    rng = np.random.default_rng(0)
    color = (0.4 + 0.05 * rng.standard_normal((24, 32, 3))).astype(np.float32)
    albedo = np.full((24, 32, 3), 0.8, np.float32)
    normal = np.zeros((24, 32, 3), np.float32)
    normal[..., 2] = 1.0
    out = d.denoise(color, albedo, normal)
    assert out.shape == color.shape and out.dtype == np.float32
    assert out.std() < color.std() / 3 and abs(out.mean() - 0.4) < 0.02
    with pytest.raises(ValueError, match="albedo"):
        d.denoise(color, albedo[:, :-1], normal)


# -- a denoised pair at zero motion ------------------------------------------------------


@pytest.mark.blender
def test_denoised_pair_keeps_parity_at_zero_motion(tmp_path):
    """No motion (delta0 = 0): a blurry image's frames are the blocks of the sharp
    image's own sample sequence (need budget: factor 1), so the mean of their colour AND
    of their guides is the sharp render's, and denoising the mean once gives the denoised
    sharp image. Denoising each frame, or one frame's guides, would not."""
    glb = shared("glb", "sketchfab_MapPin.glb")
    toml = tmp_path / "c.toml"
    toml.write_text("delta0 = 0.0\n")
    out = tmp_path / "out"
    run_cli("build", "--objects", str(glb), "--out", str(out), "--config", str(toml),
            "--views", "2", "--levels", "1,4", "--resolution", "48", "--settings-per-object",
            "1", "--latents", "4", "--samples", "8", "--blur-budget", "need",
            "--denoise", "oidn", "--blurry-test-views", "--keep-linear", "--quiet")  # fmt: skip
    s = _setting(out)
    meta = json.loads((s / "meta.json").read_text())
    assert meta["render"]["denoise"] == "oidn" and meta["render"]["denoiser"]["device"] == "CPU"
    assert json.loads((out / "dataset.json").read_text())["config"]["denoise"] == "oidn"
    from blurset.image import read_exr

    for v in meta["views"]:
        name = f"{v['index']:03d}.exr"
        sharp = read_exr(s / "sharp" / "linear" / name)
        assert sharp[..., 3].max() > 0.5  # the object is there
        for lvl, lp in v["levels"].items():
            # Zero motion: the need budget buys nothing, the frames split the sharp budget.
            assert lp["motion_px"] == 0.0 and lp["samples_per_frame"] * 4 == 32
            blur = read_exr(s / f"blur_{lvl}" / "linear" / name)
            err = np.abs(blur - sharp).max()
            assert err < 1e-4, (lvl, err)


# -- denoising keeps the blur ------------------------------------------------------------


def _edge_widths(img: np.ndarray, axis: int) -> list[float]:
    """Per line along `axis`, from either end: the 10–90 % rise distance (px,
    sub-pixel) of the premultiplied luma where the line first enters the object
    (transparent 0 before it), the plateau taken just past the first fully covered pixel."""
    a = img[..., 3]
    p = img[..., :3] @ LUMA
    if axis == 0:
        a, p = a.T, p.T
    a, p = np.concatenate([a, a[:, ::-1]]), np.concatenate([p, p[:, ::-1]])
    out = []
    for al, pl in zip(a, p, strict=True):
        inside = np.flatnonzero(al >= 0.999)
        if inside.size == 0 or inside[0] < 3 or inside[0] + 3 >= len(pl):
            continue
        x1 = inside[0]
        ref = float(np.median(pl[x1 : x1 + 3]))
        if ref < 0.05:
            continue

        def cross(frac: float, pl=pl, ref=ref, x1=x1) -> float | None:
            hit = np.flatnonzero(pl[: x1 + 1] >= frac * ref)
            if hit.size == 0 or hit[0] == 0:
                return None
            i = hit[0]
            lo, hi = pl[i - 1], pl[i]
            return i - 1 + (frac * ref - lo) / max(hi - lo, 1e-9)

        x10, x90 = cross(0.1), cross(0.9)
        if x10 is not None and x90 is not None and x90 > x10:
            out.append(x90 - x10)
    return out


@pytest.mark.blender
def test_denoising_keeps_the_motion_streak(tmp_path):
    """Level 4 of a textured object, its latent frames with their guides: the motion
    streak on the silhouette edge (10–90 % rise of the colour across it, along the axis
    the object moves) of the denoised mean stays within 10 % of the undenoised mean's."""
    from blurset.image import Accumulator
    from blurset.plan import BuildConfig, plan_setting
    from blurset.services.denoise import denoiser
    from blurset.services.worker_client import Worker

    glb = shared("glb", "sketchfab_MapPin.glb")
    res, view, level = 96, 1, 4
    cfg = BuildConfig(views=view + 1, levels=[level], resolution=res, latents=16,
                      latent_positions="stratified", samples=16)  # fmt: skip
    with Worker(timeout=300) as w:
        info = w.load(glb, tmp_path / "v.npy")
        verts = np.ascontiguousarray(np.load(tmp_path / "v.npy"), dtype=np.float32)
        setting = plan_setting(cfg, uid="t", theta0_deg=0.0, seed=3,
                               bbox_dims=info["bbox_dims"], vertices=verts)  # fmt: skip
        lp = setting.to_dict()["views"][view]["levels"][str(level)]
        frames = setting.level_renders(view, level, str(tmp_path / "f"))
        acc = Accumulator(res, res, guides=True)

        def on_frame(_i, p, origin):
            acc.add_exr(p, origin)
            Path(p).unlink()

        w.render(frames, resolution=res, fov_deg=cfg.fov_deg, samples=1, on_frame=on_frame,
                 crop=True, guides=True)  # fmt: skip
    assert acc.count == 16 and lp["motion_px"] > 8  # a real streak: many pixels
    raw = acc.mean()
    acc.denoise(denoiser("cpu"))
    den = acc.mean()
    assert acc.denoised and np.array_equal(raw[..., 3], den[..., 3])
    assert np.abs(den - raw)[..., :3].max() > 1e-3  # the denoiser did something
    # The axis of the streak: the one whose alpha ramps are wider.
    alpha_w = [np.median(_edge_widths(np.dstack([raw[..., 3:]] * 4), ax)) for ax in (0, 1)]
    axis = int(np.argmax(alpha_w))
    w_raw, w_den = _edge_widths(raw, axis), _edge_widths(den, axis)
    assert len(w_raw) >= 8 and len(w_den) >= 8, (w_raw, w_den)
    m_raw, m_den = float(np.median(w_raw)), float(np.median(w_den))
    assert m_raw > 2.0, m_raw  # a streak several pixels wide, not a sharp edge
    assert abs(m_den / m_raw - 1.0) <= 0.10, (m_raw, m_den, alpha_w)


@pytest.mark.blender
def test_tradeoff_measures_denoised_candidates(tmp_path):
    import csv

    glb = shared("glb", "sketchfab_MapPin.glb")
    out = tmp_path / "t"
    run_cli("tradeoff", "--object", str(glb), "--out", str(out), "--quick", "--resolution",
            "48", "--budgets", "16", "--latents", "4", "--reference", "16,8",
            "--denoise", "oidn", "--quiet")  # fmt: skip
    rows = [r for r in csv.DictReader((out / "tradeoff.csv").open()) if r["role"] == "candidate"]
    raw = [r for r in rows if r["denoise"] == "none"]
    den = [r for r in rows if r["denoise"] == "oidn"]
    assert raw and len(den) == len(raw)
    for r in den:
        assert r["label"].endswith("+oidn") and int(r["render_reference_factor"]) == 32
        assert 0.0 < float(r["detail_ratio"]) < 2.0 and 0.0 < float(r["sharp_detail_ratio"]) < 2.0
        assert 10.0 < float(r["render_psnr"]) < 100.0
    for r in raw:
        # Raw noise only adds high-frequency energy.
        assert float(r["detail_ratio"]) > 0.9
    setup = json.loads((out / "tradeoff.json").read_text())["setup"]
    assert setup["denoise"] == "oidn" and setup["denoised_reference_samples"] == 32 * 16
