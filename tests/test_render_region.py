"""Issue 16: Cycles traces only the pixels that can see the object (the core's
plan/region.rs). A render restricted to its region must have a whole render's pixels,
bit for bit: on real GLBs (many parts, an unlit one), with every frame of a setting's
blur levels sharing one region per image. Real bpy renders at tiny sizes."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from blurset.image import Accumulator
from blurset.plan import BuildConfig, plan_setting
from blurset.services.worker_client import Worker

from tests.conftest import shared
from tests.test_worker import read_exr

pytestmark = pytest.mark.blender

RES = 40


def render(w, frames, out: Path, tag: str) -> list[np.ndarray]:
    fr = [dict(f, out=str(out / f"{k:03d}_{tag}.exr")) for k, f in enumerate(frames)]
    reply = w.render(fr, resolution=RES, fov_deg=40.0, samples=2)
    assert reply["done"] == len(fr)
    return [read_exr(f["out"]) for f in fr]


@pytest.mark.parametrize("name", ["khronos_2CylinderEngine.glb", "sketchfab_MazdaRX7Stylised.glb"])
def test_a_render_in_its_region_has_the_pixels_of_a_whole_render(name, tmp_path):
    glb = shared("glb", name)
    with Worker(threads=2, timeout=300) as w:
        info = w.load(glb, tmp_path / "v.npy")
        verts = np.ascontiguousarray(np.load(tmp_path / "v.npy"), dtype=np.float32)
        cfg = BuildConfig(views=3, levels=[1, 4], latents=3, samples=2, resolution=RES)
        p = plan_setting(cfg, uid="t", theta0_deg=10.0, seed=3, bbox_dims=info["bbox_dims"],
                         vertices=verts)  # fmt: skip
        frames = p.renders(tmp_path / "plan", cfg.cycles_samples)
        regions = [f.get("region") for f in frames]
        # The test means something only if regions cut the image for most frames.
        cut = [r for r in regions if r is not None]
        assert len(cut) >= len(frames) // 2, regions
        assert all((r[2] - r[0]) * (r[3] - r[1]) < RES * RES for r in cut)
        whole = [{k: v for k, v in f.items() if k != "region"} for f in frames]
        a = render(w, frames, tmp_path, "region")
        b = render(w, whole, tmp_path, "whole")
        # Rows count from the top: every object pixel of a whole render lies in its
        # region, and some regions sit well off the centre row (a flip would show).
        for f, y in zip(frames, b, strict=True):
            if f.get("region") is not None:
                x0, y0, x1, y1 = f["region"]
                ys, xs = np.nonzero(y[..., 3] > 0)
                assert x0 <= xs.min() and xs.max() < x1 and y0 <= ys.min() and ys.max() < y1
        assert max(abs(r[1] - (RES - r[3])) for r in cut) >= 4, cut
        for k, (x, y) in enumerate(zip(a, b, strict=True)):
            assert np.array_equal(x, y), (
                f"frame {k} ({frames[k]['level']}): max {np.abs(x - y).max()}"
            )
        # Can fail: a region one pixel inside the object's own pixels loses some.
        sharp = next(k for k, f in enumerate(frames) if f["level"] == "sharp" and f.get("region"))
        ys, xs = np.nonzero(b[sharp][..., 3] > 0)
        tight = dict(frames[sharp], region=[xs.min() + 1, ys.min() + 1, xs.max(), ys.max()])
        (t,) = render(w, [tight], tmp_path, "tight")
        assert not np.array_equal(t, b[sharp])

        # Cropped to its call's region, as a build writes them: only that rectangle's
        # pixels cross the disk, and placed at the reply's origin they are the whole
        # render, bit for bit; so is the blurry image the accumulator makes of them.
        crop = [dict(f, out=str(tmp_path / f"{k:03d}_crop.exr")) for k, f in enumerate(frames)]
        got: list[tuple] = []
        w.render(crop, resolution=RES, fov_deg=40.0, samples=2, crop=True,
                 on_frame=lambda *a: got.append(a))  # fmt: skip
        assert [g[0] for g in got] == list(range(len(frames)))
        sizes = []
        images: dict[tuple, list] = {}
        for (k, path, origin), y in zip(got, b, strict=True):
            x = read_exr(path)
            if frames[k].get("region") is None:
                assert origin is None and x.shape == y.shape
                placed = x
            else:
                x0, y0 = origin
                h, wd = x.shape[:2]
                sizes.append(h * wd)
                placed = np.zeros_like(y)
                placed[y0 : y0 + h, x0 : x0 + wd] = x
            assert np.array_equal(placed, y), f"frame {k}: max {np.abs(placed - y).max()}"
            images.setdefault((frames[k]["view"], frames[k]["level"]), []).append(
                (path, origin, tmp_path / f"{k:03d}_whole.exr")
            )
        # The test means something only if the crops are smaller than the image.
        assert sizes and max(sizes) < RES * RES, sizes
        for key, parts in images.items():
            a_crop, a_whole = Accumulator(RES, RES), Accumulator(RES, RES)
            for path, origin, whole_path in parts:
                a_crop.add_exr(path, origin)
                a_whole.add_exr(whole_path)
            assert np.array_equal(a_crop.mean(), a_whole.mean()), key
