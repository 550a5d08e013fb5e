"""The plan of a setting (DESIGN §2): the build config, the sampling config, a setting's
seeded plan (views, trajectories, levels, latent frames, seeds) with its render list and
its writers (poses, transforms.json, meta.json), the seeds and the splits.

The public face of these blurset-core bindings for scripts, tests and benchmarks."""

from __future__ import annotations

from blurset._core import (
    BuildConfig,
    Plan,
    SamplingConfig,
    Splits,
    check_theta0_deg,
    default_sampling_config,
    make_splits,
    plan_setting,
    preset_values,
    seed_for,
    seeded_subset,
    target_next_round,
    test_views,
)

__all__ = [
    "BuildConfig",
    "Plan",
    "SamplingConfig",
    "Splits",
    "check_theta0_deg",
    "default_sampling_config",
    "make_splits",
    "plan_setting",
    "preset_values",
    "seed_for",
    "seeded_subset",
    "target_next_round",
    "test_views",
]
