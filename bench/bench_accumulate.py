"""Accumulation benchmark (DESIGN §9): m latent EXR frames -> one blurry sRGB PNG.

`accumulate_vs_numpy` accumulates what a build accumulates: 34 latent frames of a demo
object rendered by the Blender worker at 512² (its codec, its alpha). The random-frame
entries are the worst case for both readers: float noise does not compress, so every
block is inflated at full size.

Baseline: the OpenEXR package reads each frame into NumPy, the mean is taken in float64,
composited over white, sRGB-encoded and written with Pillow. Contender:
`blurset.image.Accumulator` (read, accumulate, encode and write in Rust). Both stream
the frames (one frame in memory at a time) and produce the same image.
"""

from __future__ import annotations

import os
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np
import OpenEXR
from blurset.image import Accumulator
from harness import median_times
from PIL import Image

FRAMES = 34  # the paper's m
SIZE = 512
REPEATS = 5


def make_frames(
    directory: Path, n: int = FRAMES, size: int = SIZE, compression=OpenEXR.ZIP_COMPRESSION
) -> list[Path]:
    """Random premultiplied RGBA float32 frames, ZIP-compressed like Blender's default
    (random mantissas barely compress: each ZIP block is inflated, at full size)."""
    rng = np.random.default_rng(0)
    header = {"compression": compression, "type": OpenEXR.scanlineimage}
    paths = []
    for i in range(n):
        alpha = rng.random((size, size, 1), dtype=np.float32)
        rgba = np.concatenate([rng.random((size, size, 3), dtype=np.float32) * alpha, alpha], 2)
        path = directory / f"{i:03d}.exr"
        with OpenEXR.File(header, {"RGBA": np.ascontiguousarray(rgba)}) as f:
            f.write(str(path))
        paths.append(path)
    return paths


def render_frames(directory: Path, n: int = FRAMES, size: int = SIZE) -> list[Path]:
    """n latent frames of the demo box along a short orbit, rendered by the worker."""
    import math

    from blurset.services.demo import make_demo_objects
    from blurset.services.worker_client import Worker

    glb = make_demo_objects(directory / "objs", seed=0)[0]
    frames: list[dict[str, Any]] = []
    for i in range(n):
        theta = math.radians(30.0 + 4.0 * i / n)  # a level-4-sized sweep
        phi, r = math.radians(60.0), 2.6
        pos = [r * math.sin(phi) * math.cos(theta), r * math.sin(phi) * math.sin(theta),
               r * math.cos(phi)]  # fmt: skip
        back = np.asarray(pos) / r
        right = np.cross([0.0, 0.0, 1.0], back)
        right /= np.linalg.norm(right)
        c2w = np.eye(4)
        c2w[:3, 0], c2w[:3, 1], c2w[:3, 2], c2w[:3, 3] = right, np.cross(back, right), back, pos
        frames.append({"c2w": c2w, "seed": i, "out": directory / f"{i:03d}.exr"})
    with Worker(timeout=600) as w:
        w.load(glb, directory / "v.npy")
        w.render(frames, resolution=size, fov_deg=40.0, samples=4)
    return [f["out"] for f in frames]


def baseline(paths: list[Path], out: Path, background=(1.0, 1.0, 1.0)) -> None:
    acc = None
    for p in paths:
        with OpenEXR.File(str(p)) as f:
            rgba = f.channels()["RGBA"].pixels
        if acc is None:
            acc = np.zeros(rgba.shape, np.float64)
        acc += rgba
    assert acc is not None  # at least one frame
    mean = acc / len(paths)
    rgb = mean[..., :3] + (1.0 - np.clip(mean[..., 3:], 0.0, 1.0)) * np.asarray(background)
    x = np.clip(rgb, 0.0, 1.0)
    enc = np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)
    Image.fromarray(np.round(enc * 255.0).astype(np.uint8)).save(out)


def contender(paths: list[Path], out: Path, size: int = SIZE) -> None:
    acc = Accumulator(size, size)
    for p in paths:
        acc.add_exr(p)
    acc.write_png(out)


def baseline_stages(paths: list[Path]) -> dict:
    """Where the baseline's time goes (one extra run, not part of the ratio)."""
    t0 = time.perf_counter()
    read = 0.0
    acc = None
    for p in paths:
        a = time.perf_counter()
        with OpenEXR.File(str(p)) as f:
            rgba = f.channels()["RGBA"].pixels
        read += time.perf_counter() - a
        if acc is None:
            acc = np.zeros(rgba.shape, np.float64)
        acc += rgba
    total = time.perf_counter() - t0
    return {"baseline_openexr_read_s": read, "baseline_read_and_sum_s": total}


def measure(name: str, codec: str, compression=None) -> dict:
    """compression None: frames rendered by the Blender worker, else random frames."""
    with tempfile.TemporaryDirectory(prefix="blurset-bench-acc-") as tmp:
        d = Path(tmp)
        if compression is None:
            paths = render_frames(d)
            with OpenEXR.File(str(paths[0])) as f:
                codec = f"{codec}: {f.header()['compression']}".replace("Compression.", "")
        else:
            paths = make_frames(d, compression=compression)
        # Warm the page cache and check both sides agree before timing them.
        baseline(paths, d / "base.png")
        contender(paths, d / "rust.png")
        a = np.asarray(Image.open(d / "base.png"), dtype=int)
        b = np.asarray(Image.open(d / "rust.png"), dtype=int)
        max_diff = int(np.abs(a - b).max())
        cpu: dict = {}
        t_base, t_rust = median_times(
            lambda: baseline(paths, d / "base.png"),
            lambda: contender(paths, d / "rust.png"),
            REPEATS,
            cpu=cpu,
        )
        stages = baseline_stages(paths)
        frame_bytes = sum(p.stat().st_size for p in paths)
        png_bytes = (d / "rust.png").stat().st_size, (d / "base.png").stat().st_size
    return {
        "name": name,
        "ratio": t_base / t_rust,
        "contender": f"blurset Accumulator {t_rust:.3f} s",
        "baseline": f"OpenEXR+NumPy+Pillow {t_base:.3f} s",
        "contender_s": t_rust,
        "baseline_s": t_base,
        "frames": FRAMES,
        "size": SIZE,
        "repeats": REPEATS,
        "max_png_code_diff": max_diff,
        "exr_codec": codec,
        "exr_mb_read": frame_bytes / 1e6,
        "contender_cpu_s": cpu["b"],
        "baseline_cpu_s": cpu["a"],
        "cpu_ratio": cpu["a"] / cpu["b"],
        **stages,
        "png_bytes_contender_baseline": list(png_bytes),
        "loadavg_1min": os.getloadavg()[0],
    }


def run() -> list[dict]:
    # The goal is stated for the frames a build accumulates; random frames (ZIP and raw)
    # are the incompressible worst case and show what the codec costs both sides.
    return [
        measure("accumulate_vs_numpy", "Blender worker frames"),
        measure("accumulate_vs_numpy_random_zip", "random, ZIP", OpenEXR.ZIP_COMPRESSION),
        measure("accumulate_vs_numpy_random_none", "random, NONE", OpenEXR.NO_COMPRESSION),
    ]


if __name__ == "__main__":
    for r in run():
        print(r)
