"""The hand shake's render cost against the shake it replaced, at equal ghost gap
(issue 61).

For VIEWS views at 512 px and shake levels 1-4, under latents auto at each ghost bound
of the accuracy presets (`--max-ghost-px` 1 for balanced and floor, 2 for fast): the
frames each model takes to hold it, and the motion steps of its one motion-blur render.

- The hand shake (today's, issue 61): the core's plan (`blurset.plan.plan_setting`),
  its gap measured at the image centre and corners, as a build measures it.
- The harmonics before it (issue 49): bench/shake_paths.py's port of shake.rs at
  1c923e5^ (three whole-period sinusoids per axis, largest displacement 2^(l+1) px at
  512 px, the gap at the image centre), its draws from NumPy's generator (the same
  distributions as the core's stream, not the same numbers).

Frames become seconds through the unit costs bench_blur_cost measured on this machine
(its `blur_cost_vs_sharp` row, 512 px on the CPU, read from bench/results.json): an
image of m averaged frames renders the sharp image's sample budget S spread over them,
at least one sample a frame (m · ⌈S / m⌉ samples at the sharp image's time per sample),
plus m − 1 times the measured overhead of one more frame. An estimate from measured
unit costs, not a timed render. On a GPU a preset renders a shake image as one
motion-blur render, whatever the frame count.

Rows `shake_cost_ghost<g>px_level<l>`: `ratio` the hand shake's median frame count
over the harmonics', with the seconds and their ratio beside it.
"""

from __future__ import annotations

import json
import math
import os

import numpy as np
import shake_paths as sp
from harness import RESULTS

LEVELS = [1, 2, 3, 4]
GHOSTS = (1.0, 2.0)
VIEWS = int(os.environ.get("BLURSET_BENCH_SHAKE_VIEWS", "60"))
SEED = 5
UNIT_COSTS = "blur_cost_vs_sharp"
# Views whose paths through frames KEY_GHOST_PX apart measure the motion keys' error.
KEY_VIEWS = int(os.environ.get("BLURSET_BENCH_SHAKE_KEY_VIEWS", "10"))
KEY_GHOST_PX = 0.05


def image_seconds(m: int, unit: dict) -> float:
    """Estimated seconds of a blurry image of m averaged frames (see the module docs)."""
    s = unit["samples_total"]
    return unit["sharp_s"] * m * math.ceil(s / m) / s + (m - 1) * unit["per_render_overhead_s"]


def unit_costs() -> dict | None:
    rows = {r["name"]: r for r in json.loads(RESULTS.read_text())} if RESULTS.exists() else {}
    return rows.get(UNIT_COSTS)


def _peak_over_mean(path: np.ndarray) -> float:
    """The image centre's fastest step over its mean step, along points at equal times."""
    steps = np.hypot(*np.diff(path, axis=0).T)
    return float(steps.max() / steps.mean())


def frames(ghost_px: float) -> dict[str, dict[int, list[float]]]:
    """Per model and level: each view's frame count, its extent and path length (px)."""
    plan = sp.plan_shake(VIEWS, LEVELS, resolution=sp.REFERENCE_PX, ghost_px=ghost_px,
                         seed=SEED)  # fmt: skip
    new = {lv: [float(len(v["shake"][str(lv)]["poses"])) for v in plan["views"]] for lv in LEVELS}
    new_path = {lv: [v["shake"][str(lv)]["path_px"] for v in plan["views"]] for lv in LEVELS}
    f = sp.focal_px(sp.REFERENCE_PX, plan["fov_deg"])
    new_speed = {lv: [_peak_over_mean(sp.centre_path(v["shake"][str(lv)]["poses"], f))
                      for v in plan["views"]] for lv in LEVELS}  # fmt: skip
    rng = np.random.default_rng(SEED)
    draws = [sp.old_draw(rng) for _ in range(VIEWS)]
    old = {lv: [float(sp.old_frames(sp.old_level(h, lv, sp.REFERENCE_PX), ghost_px))
                for h in draws] for lv in LEVELS}  # fmt: skip
    grid = np.linspace(0, 1, sp.OLD_GRID + 1)
    old_extent = {lv: [sp.extent(sp.old_level(h, lv, sp.REFERENCE_PX)(grid)) for h in draws]
                  for lv in LEVELS}  # fmt: skip
    old_path = {lv: [sp.polyline_length(sp.old_level(h, lv, sp.REFERENCE_PX)(grid)) for h in draws]
                for lv in LEVELS}  # fmt: skip
    old_speed = {lv: [_peak_over_mean(sp.old_level(h, lv, sp.REFERENCE_PX)(grid)) for h in draws]
                 for lv in LEVELS}  # fmt: skip
    return {"new": new, "old": old, "old_extent": old_extent, "new_path": new_path,
            "old_path": old_path, "new_speed": new_speed, "old_speed": old_speed}  # fmt: skip


def motion_steps() -> dict[str, dict[int, list[int]]]:
    """Per model and level: each view's motion steps (one motion-blur render)."""
    plan = sp.plan_shake(VIEWS, LEVELS, resolution=sp.REFERENCE_PX, ghost_px=1.0, seed=SEED,
                         method="motion_blur")  # fmt: skip
    rng = np.random.default_rng(SEED)
    draws = [sp.old_draw(rng) for _ in range(VIEWS)]
    return {
        "new": {lv: [v["shake"][str(lv)]["motion_steps"] for v in plan["views"]] for lv in LEVELS},
        "old": {lv: [sp.old_motion_steps(sp.old_level(h, lv, sp.REFERENCE_PX)) for h in draws]
                for lv in LEVELS},
    }  # fmt: skip


def key_errors(steps: dict[int, list[int]]) -> dict[int, list[float]]:
    """Per level: for KEY_VIEWS views, how far the hand shake's motion keys (its planned
    steps) stray from its path at the image centre (px)."""
    paths = sp.model_paths(KEY_VIEWS, LEVELS, ghost_px=KEY_GHOST_PX, seed=SEED)
    return {
        lv: [sp.key_midpoint_error(v["path"], np.array([q["t"] for q in v["record"]["poses"]]),
                                   steps[lv][i]) for i, v in enumerate(paths[lv])]
        for lv in LEVELS
    }  # fmt: skip


def run() -> list[dict]:
    unit = unit_costs()
    steps = motion_steps()
    keys = key_errors(steps["new"])
    top = sp.MOTION_STEPS_RANGE[1]
    rows = []
    for g in GHOSTS:
        f = frames(g)
        for lv in LEVELS:
            new, old = f["new"][lv], f["old"][lv]
            mn, mo = float(np.median(new)), float(np.median(old))
            row = {
                "name": f"shake_cost_ghost{g:g}px_level{lv}",
                "ratio": mn / mo,
                "ratio_is": "the hand shake's frames over the harmonics' (before issue 61) "
                "at equal --max-ghost-px (medians over views)",
                "contender": f"hand shake level {lv}: {mn:g} frames",
                "baseline": f"three harmonics level {lv}: {mo:g} frames",
                "level": lv,
                "ghost_px": g,
                "views": VIEWS,
                "resolution": sp.REFERENCE_PX,
                "seed": SEED,
                "frames_new_median": mn,
                "frames_old_median": mo,
                "frames_new_range": [min(new), max(new)],
                "frames_old_range": [min(old), max(old)],
                "frames_ratio_per_view_median": float(np.median(np.array(new) / np.array(old))),
                "extent_new_px": 2.0 ** (lv + 2),
                "extent_old_px_median": float(np.median(f["old_extent"][lv])),
                # The image centre's path: the hand shake's through its frames, the
                # harmonics' over the exposure.
                "path_new_px_median": float(np.median(f["new_path"][lv])),
                "path_old_px_median": float(np.median(f["old_path"][lv])),
                # Evenly spread frames are as far apart as the path is fast: the hand
                # shake's particle moves at constant speed, the harmonics' does not.
                "speed_peak_over_mean_new_median": float(np.median(f["new_speed"][lv])),
                "speed_peak_over_mean_old_median": float(np.median(f["old_speed"][lv])),
                "motion_steps_new_median": float(np.median(steps["new"][lv])),
                "motion_steps_old_median": float(np.median(steps["old"][lv])),
                # At the top of the range the keys may stray more than 0.02 px from the path.
                "motion_steps_new_at_top_share": float(np.mean(np.array(steps["new"][lv]) == top)),
                "motion_steps_old_at_top_share": float(np.mean(np.array(steps["old"][lv]) == top)),
                "motion_key_error_px_median": float(np.median(keys[lv])),
                "motion_key_error_px_max": float(np.max(keys[lv])),
                "motion_key_error_views": KEY_VIEWS,
            }
            if unit is not None:
                sn = float(np.median([image_seconds(int(m), unit) for m in new]))
                so = float(np.median([image_seconds(int(m), unit) for m in old]))
                row |= {
                    "seconds_new_median": sn,
                    "seconds_old_median": so,
                    "seconds_ratio": sn / so,
                    "seconds_from": f"{UNIT_COSTS}: {unit['resolution']} px, "
                    f"{unit['samples_total']} samples, "
                    + ", ".join(unit.get("device", {}).get("devices", [])),
                }
            rows.append(row)
    return rows


if __name__ == "__main__":
    for r in run():
        print({k: v for k, v in r.items() if not isinstance(v, list)})
