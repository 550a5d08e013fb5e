"""One image rendered and accumulated as the build does (Blender worker → EXR → Rust
accumulator), with its timings; the seeds and budgets of the converged references."""

from __future__ import annotations

import os
import time
from pathlib import Path
from typing import Any

import numpy as np

from blurset import _core

# The reference's frames get other Cycles seeds than the candidates' (which share the
# plan's seeds frame by frame): render noise common to both would flatter the candidates.
REFERENCE_SEED_SALT = 0x5BD1E995
# Converged renders of render_psnr / sharp_render_psnr: this many times the largest
# budget, so their own noise adds at most 1/8 of a candidate's MSE (≤ 0.5 dB), alike
# for the blurry and the sharp column.
RENDER_REFERENCE_FACTOR = 8
# A denoised image is scored against converged undenoised renders of at least 32 times
# its samples (issue 28): its error can sit far below the raw render noise.
DENOISED_REFERENCE_FACTOR = 32


def _proc_cpu(pid: int | None) -> float:
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
    except (OSError, IndexError, ValueError):
        return float("nan")


def _own_cpu() -> float:
    return time.process_time()


def render_image(
    worker, frames: list[dict], lp: dict, res: int, fov: float, salt: int = 0, **render_kw: Any
) -> tuple[Any, dict]:
    """Render and accumulate one blurry image as the build does; (mean, timings)."""
    for f in frames:
        f["seed"] = (f["seed"] ^ salt) & 0x7FFFFFFF
    acc = _core.Accumulator(res, res)

    def on_frame(_i: int, path: str, origin: tuple[int, int] | None) -> None:
        acc.add_exr(path, origin)
        os.unlink(path)

    pid = worker._proc.pid if worker._proc is not None else None
    c0, o0, t0 = _proc_cpu(pid), _own_cpu(), time.perf_counter()
    worker.render(
        frames,
        resolution=res,
        fov_deg=fov,
        samples=lp["samples_per_frame"],
        on_frame=on_frame,
        crop=True,
        **render_kw,
    )
    mean = acc.mean()
    seconds = time.perf_counter() - t0
    cpu = _proc_cpu(pid) - c0 + _own_cpu() - o0
    return mean, {"seconds": seconds, "cpu_seconds": cpu, "frames": len(frames)}


def render_denoised(
    worker, frames: list[dict], lp: dict, res: int, fov: float, denoiser: Any
) -> tuple[Any, Any, dict]:
    """Render one image with its guide passes, as a --denoise oidn build does:
    (undenoised mean, denoised mean, timings)."""
    acc = _core.Accumulator(res, res, guides=True)

    def on_frame(_i: int, path: str, origin: tuple[int, int] | None) -> None:
        acc.add_exr(path, origin)
        os.unlink(path)

    t0 = time.perf_counter()
    worker.render(frames, resolution=res, fov_deg=fov, samples=lp["samples_per_frame"],
                  on_frame=on_frame, crop=True, guides=True)  # fmt: skip
    raw = acc.mean()
    acc.denoise(denoiser)
    return raw, acc.mean(), {"seconds": time.perf_counter() - t0, "frames": len(frames)}


def sharp_frames(view: dict, samples: int, work: Path) -> tuple[list[dict], dict]:
    """The sharp render of a view at `samples`, as (frames, level) for render_image."""
    frame = {"c2w": view["c2w"], "seed": view["sharp_seed"], "out": str(work / "s.exr")}
    return [frame], {"samples_per_frame": samples}


def save_png(mean: Any, path: Path, res: int) -> None:
    acc = _core.Accumulator(res, res)
    acc.add(np.ascontiguousarray(mean, dtype=np.float32))
    acc.write_png(path)
