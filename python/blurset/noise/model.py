"""The sensor noise model of blurset-core (DESIGN §5): the σ(gain) table, white balance,
the seeded keys, one noisy frame (from 8/16-bit images or from a build's linear light),
the writers of noisy scenes, and the plan `blurset noise` writes (its units and gains,
each gain's noise.json).

The public face of these bindings for scripts, tests and benchmarks."""

from __future__ import annotations

from os import PathLike
from typing import Any

import numpy as np
import numpy.typing as npt

from blurset._core import (
    noise_clean_from_linear,
    noise_clean_linear,
    noise_default_levels,
    noise_image,
    noise_image_model,
    noise_key,
    noise_levels_from_kpn,
    noise_scene_seed,
    noise_sigmas,
    noise_white_balance,
    noise_write_variants,
    plan_noise_build,
    plan_noise_scene,
    read_linear_composited,
)

__all__ = [
    "noise_clean_from_linear",
    "noise_clean_linear",
    "noise_default_levels",
    "noise_image",
    "noise_image_linear",
    "noise_image_model",
    "noise_key",
    "noise_levels_from_kpn",
    "noise_scene_seed",
    "noise_sigmas",
    "noise_white_balance",
    "noise_write_variants",
    "noise_write_variants_linear",
    "plan_noise_build",
    "plan_noise_scene",
    "read_linear_composited",
]


def noise_image_linear(
    image: npt.ArrayLike, **kw: Any
) -> tuple[npt.NDArray[np.float32], npt.NDArray[np.uint8]]:
    """One noisy frame from composited linear RGB (H, W, 3): `noise_image` on a float32
    image (the same standard normals for the same key/view/frame), processed to uint8."""
    linear, processed = noise_image(np.asarray(image, dtype=np.float32), **kw)
    return linear, processed.astype(np.uint8, copy=False)


def noise_write_variants_linear(
    sources: list[str | PathLike[str]],
    names: list[str],
    variants: list[tuple[str | PathLike[str], float, float, int]],
    *,
    background: tuple[float, float, float] = (1.0, 1.0, 1.0),
    **kw: Any,
) -> None:
    """`noise_write_variants` from a build's linear EXRs, composited over `background`."""
    noise_write_variants(sources, names, variants, background=background, **kw)
