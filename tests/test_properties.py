"""Property tests over the whole config ranges (issue 7, DESIGN §2 guards): whatever the
options and the object, a plan and the pose files written from it hold no NaN or inf,
and a config outside the ranges is refused with a message naming the option."""

from __future__ import annotations

import math

import numpy as np
from blurset.llff import read_poses_bounds
from blurset.plan import SamplingConfig, default_sampling_config, plan_setting
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

DEFAULTS = default_sampling_config().to_dict()


def _finite(x) -> bool:
    if isinstance(x, float):
        return math.isfinite(x)
    if isinstance(x, dict):
        return all(_finite(v) for v in x.values())
    if isinstance(x, list):
        return all(_finite(v) for v in x)
    return True


configs = st.fixed_dictionaries(
    {
        "views": st.integers(1, 12),
        "phi0_deg": st.floats(8.0, 172.0),
        "window_deg": st.floats(0.0, 7.5),
        "fov_deg": st.floats(1.5, 149.0),
        "radius_margin": st.floats(1.0, 100.0),
        "delta0": st.floats(0.0, 45.0),
        "levels": st.lists(st.integers(1, 64), min_size=0, max_size=4, unique=True),
        "level_spread": st.floats(0.0, 0.99),
        "latents": st.integers(1, 12),
        "latent_positions": st.sampled_from(["random", "stratified"]),
        "trajectory": st.sampled_from(["start", "centered"]),
        "resolution": st.integers(8, 4096),
        "guards": st.fixed_dictionaries(
            {"orientation_max": st.floats(1.0, 1e6), "near_floor": st.floats(1e-9, 1.0)}
        ),
        # issue 6: per-level latent counts, sample budgets, the motion blur method
        "latents_auto": st.booleans(),
        "latents_max": st.integers(1, 64),
        "max_ghost_px": st.floats(0.01, 100.0),
        "blur_method": st.sampled_from(["average", "motion_blur"]),
        "samples": st.integers(1, 4096),
        "samples_total": st.one_of(st.none(), st.integers(1, 2**20)),
        "blur_budget": st.sampled_from(["parity", "flat"]),  # issue 15
    }
)

# Boxes from degenerate (a point, a plane, a needle) to ordinary; the normalizer scales
# the largest side to 1, so sides live in [0, 1].
sides = st.one_of(st.just(0.0), st.floats(1e-12, 1.0))
boxes = st.tuples(sides, sides, sides).map(lambda d: [1.0, d[1], d[2]] if d[0] < 1 else list(d))


@settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    cfg=configs,
    dims=boxes,
    theta0=st.floats(-720.0, 720.0),
    seed=st.integers(0, 2**64 - 1),
    n_vertices=st.sampled_from([0, 1, 8, 50]),
)
def test_plans_and_pose_files_are_finite_everywhere(
    cfg, dims, theta0, seed, n_vertices, tmp_path_factory
):
    # Cameras must not pass a pole: that is a refused config, tested below.
    cfg["window_deg"] = min(cfg["window_deg"], cfg["phi0_deg"] - 0.5, 179.5 - cfg["phi0_deg"])
    rng = np.random.default_rng(seed % 2**32)
    half = np.asarray(dims) / 2
    verts = (rng.uniform(-1, 1, (n_vertices, 3)) * half).astype(np.float32)
    setting = plan_setting(
        SamplingConfig(**cfg), uid="obj", theta0_deg=theta0, seed=seed, bbox_dims=dims,
        vertices=verts,
    )  # fmt: skip
    plan = setting.to_dict()
    assert _finite(plan)
    for v in plan["views"]:
        assert 0 < v["near"] < v["far"]
        assert v["w_u"] >= 0 and v["depth_range"] >= 1 and v["orientation"] >= 1
        for lvl in v["levels"].values():
            assert lvl["w_l"] >= 0 and lvl["samples_per_frame"] >= 1
            # Every latent position, motion key and the mean pose on the anchored segment.
            lo = -0.5 if cfg["trajectory"] == "centered" else 0.0
            keys = (lvl.get("motion_blur") or {}).get("keys", [])
            for x in [*lvl["latent_frames"], *keys, lvl["mean_pose"]]:
                assert lo <= x["t"] <= lo + 1.0
            if cfg["blur_method"] == "motion_blur":
                keys = lvl["motion_blur"]["keys"]
                assert lvl["latents"] == 1 and not lvl["latent_frames"]
                assert len(keys) == 2 ** lvl["motion_blur"]["motion_steps"] + 1
            elif cfg["latents_auto"]:
                assert 1 <= len(lvl["latent_frames"]) == lvl["latents"] <= cfg["latents_max"]
                assert (
                    lvl["max_gap_px"] <= cfg["max_ghost_px"] or lvl["latents"] == cfg["latents_max"]
                )
            else:
                assert len(lvl["latent_frames"]) == cfg["latents"]
    out = tmp_path_factory.mktemp("poses")
    levels = ["sharp"] + [f"blur_{lvl}" for lvl in cfg["levels"]]
    setting.write_poses(out, levels)
    for lvl in levels:
        pb = read_poses_bounds(out / lvl / "poses_bounds.npy")
        assert pb.shape == (cfg["views"], 17) and np.isfinite(pb).all()


@settings(max_examples=150, deadline=None)
@given(
    key=st.sampled_from(sorted(k for k in DEFAULTS if k != "guards")),
    value=st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.integers(-(2**31), 2**31)),
)
def test_any_config_is_finite_or_refused_naming_the_option(key, value):
    cfg = dict(DEFAULTS, views=3, latents=2)
    if key == "levels":
        cfg[key] = [value] if isinstance(value, int) else value
    elif key in ("latent_positions", "trajectory"):
        cfg[key] = str(value)
    else:
        cfg[key] = value
    try:
        plan = plan_setting(
            SamplingConfig(**cfg), uid="o", theta0_deg=0.0, seed=1, bbox_dims=[1.0, 0.5, 0.2],
            vertices=np.zeros((0, 3), np.float32),
        )  # fmt: skip
    except ValueError as e:
        assert key.rstrip("s") in str(e) or "sampling config" in str(e), str(e)
        return
    assert _finite(plan.to_dict())
