"""The sensor noise model of blurset-core (DESIGN §5): the σ(gain) table, white balance,
the seeded keys, one noisy frame (from 8/16-bit images or from a build's linear light)
and the writers of noisy scenes.

The public face of these bindings for scripts, tests and benchmarks."""

from __future__ import annotations

from blurset._core import (
    noise_clean_from_linear,
    noise_clean_linear,
    noise_default_levels,
    noise_image,
    noise_image_linear,
    noise_key,
    noise_levels_from_kpn,
    noise_scene_seed,
    noise_sigmas,
    noise_white_balance,
    noise_write_variants,
    noise_write_variants_linear,
    read_linear_composited,
)

__all__ = [
    "noise_clean_from_linear",
    "noise_clean_linear",
    "noise_default_levels",
    "noise_image",
    "noise_image_linear",
    "noise_key",
    "noise_levels_from_kpn",
    "noise_scene_seed",
    "noise_sigmas",
    "noise_white_balance",
    "noise_write_variants",
    "noise_write_variants_linear",
    "read_linear_composited",
]
