"""The judgement of our poses against one COLMAP model, and the planted-error test of its sensitivity."""

from __future__ import annotations

from typing import Any

import numpy as np

from blurset.commands.check_poses.align import _align
from blurset.commands.check_poses.model import _Model
from blurset.commands.check_poses.report import Planted, PlantedMiss
from blurset.commands.check_poses.thresholds import (
    CENTER_THRESHOLD_REL,
    PLANT_AXES,
    REPROJ_RATIO,
    REPROJ_SLACK_PX,
    ROT_THRESHOLD_DEG,
)


def _judge(
    model: _Model, rot_ours, c_ours, base=None, changed: int | None = None, streaks=None
) -> dict:
    """Per registered view of `model`: our pose's rotation / centre error against COLMAP's
    after a robust similarity alignment, and whether our pose explains the view's
    features about as well as COLMAP's own solution (`ok`). `base` and `changed`: the
    track residuals of a judgement whose poses differ from these in view `changed` only.
    `streaks`: (rotations, centres) of each exposure's first and last latent frame (see
    `exposure_ends`), for blurry images."""
    reg = model.reg_idx
    ours = rot_ours[reg], c_ours[reg]
    rot_err, cen_err, scale, _ = _align(*ours, model.rot, model.c, model.depth)
    ends = None
    if streaks is not None:
        (rot_a, c_a), (rot_b, c_b) = streaks
        ends = (
            model.tracks.projections(rot_a[reg], c_a[reg]),
            model.tracks.projections(rot_b[reg], c_b[reg]),
        )
    per_track = model.tracks.residuals(model.tracks.projections(*ours), changed, base, ends)
    px_ours = model.tracks.medians(per_track)
    px_colmap = model.tracks.px_theirs
    agrees = (rot_err <= ROT_THRESHOLD_DEG) & (cen_err <= CENTER_THRESHOLD_REL)
    # The decisive test: does our pose put this view's features where the images show
    # them, about as well as COLMAP's own solution does? COLMAP's poses themselves are
    # no safe yardstick on weak geometry (few features, a ±7.5° window): there the
    # mapper slides along a near-flat, bas-relief-like valley by several degrees while
    # correct poses reproject better (measured on 160 px renders), whereas one wrong
    # pose of ours misplaces that view's features by pixels (5° ≈ 19 px at 160 px).
    with np.errstate(invalid="ignore"):
        explains = px_ours <= REPROJ_RATIO * px_colmap + REPROJ_SLACK_PX
    # No track of a view reaches another: only the aligned pose can speak.
    ok = np.where(np.isfinite(px_colmap), explains, agrees)
    return {
        "rot_err": rot_err,
        "cen_err": cen_err,
        "scale": scale,
        "px_ours": px_ours,
        "px_colmap": px_colmap,
        "agrees": agrees,
        "ok": ok,
        "per_track": per_track,
    }


def _axis_rotation(deg: float, axis: int) -> np.ndarray:
    a = np.radians(deg)
    c, s = np.cos(a), np.sin(a)
    i, j = [(1, 2), (2, 0), (0, 1)][axis]
    r = np.eye(3)
    r[i, i] = r[j, j] = c
    r[i, j], r[j, i] = -s, s
    return r


def planted_errors(
    model: _Model, rot_ours, c_ours, base: dict, deg: float = 5.0, streaks=None
) -> Planted:
    """Whether the check catches a `deg` rotation error in one pose: each registered view
    in turn is turned by `deg` about its camera's x (tilt), y (pan) and z (roll: the
    optical axis) axes and judged against the same COLMAP model (which sees only the
    images, so it is the model a wrong pose would meet). Caught: that view is no longer
    consistent with the images. `base` is the judgement of the unchanged poses."""
    caught: dict[str, list[Any]] = {axis: [] for axis in PLANT_AXES}
    missed: list[PlantedMiss] = []
    for k, i in enumerate(model.reg_idx):
        for a, axis in enumerate(PLANT_AXES):
            turn = _axis_rotation(deg, a)
            rot = rot_ours.copy()
            rot[i] = rot_ours[i] @ turn
            planted_streaks = None
            if streaks is not None:
                # The whole exposure turns with the pose.
                planted_streaks = []
                for r, c in streaks:
                    r = r.copy()
                    r[i] = r[i] @ turn
                    planted_streaks.append((r, c))
            j = _judge(model, rot, c_ours, base["per_track"], k, planted_streaks)
            hit = not bool(j["ok"][k])
            caught[axis].append(hit)
            if not hit:
                missed.append({"view": i, "axis": axis})
    tried = sum(len(v) for v in caught.values())
    n_caught = sum(sum(v) for v in caught.values())
    return {
        "deg": deg,
        "tried": tried,
        "caught": n_caught,
        "fraction": n_caught / tried if tried else 0.0,
        "by_axis": {axis: f"{sum(v)}/{len(v)}" for axis, v in caught.items()},
        "missed": missed,
    }
