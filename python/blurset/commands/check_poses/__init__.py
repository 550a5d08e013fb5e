"""Cross-check a scene's poses with COLMAP (DESIGN §6).

COLMAP sees only the images and the shared pinhole intrinsics (held fixed); it recovers
its own poses and feature tracks. A view passes when our pose explains its features (the
tracks re-triangulated with our poses) about as well as COLMAP's own model does; its
rotation and centre errors against COLMAP's poses, after a similarity alignment, are
reported beside. The verdict says what it means about the poses (`meaning`):

- "pass": every registered view is consistent, and the check is sensitive here: a 5°
  error planted in any one pose (about each camera axis, against the same COLMAP model,
  which does not depend on our poses) is caught. Where it is not, the scene is "not
  checkable" at its image size and view count, never a pass that means nothing.
- "fail": views contradict the images while COLMAP's model is confirmed — by the other
  views, or, when most views contradict it, by COLMAP mapping again and agreeing with
  itself.
- "not checkable": too little texture for SfM, a partial registration, a check too weak
  to catch a 5° error, or a degenerate COLMAP model (most views contradict it and its
  runs disagree with one another): no verdict on the poses either way.

A blurry image shows its exposure, whose content is centred on the mean latent pose, not
on the written pose p (the exposure's start under the paper's `--trajectory start`). A
blur level of a build setting is therefore checked against the mean latent poses that
meta.json records per view and level (computed by blurset-core with the plan); the
written pose's errors and its offset to the mean latent pose (under `start`, the
start-to-mean offset: half the blur) are reported beside them (DESIGN §6, §12). Its
features, though, lie anywhere on the streaks the exposure draws (SIFT lands on a ghost
copy or off the middle of a smear): the part of a feature's offset along its streak (its
projections at the first and last latent frame), up to a quarter of the streak's length
either way (STREAK_FORGIVEN), is no error; the part across it is counted whole.

Conventions: LLFF rows are camera-to-world with columns [down, right, backwards]; COLMAP

The package: `thresholds` (the calibrated limits, exit codes), `scene` (reading a scene
and its mean latent poses), `colmap` (running COLMAP), `align` (the similarity
alignment), `model` (a COLMAP model and its tracks), `judge` (our poses against a model,
planted errors), `verdict` (the report), `check` (a scene or a setting, with COLMAP's
second opinion), `cli` (the command).
"""

from __future__ import annotations

from blurset.commands.check_poses.align import _align, _angle_deg
from blurset.commands.check_poses.check import check_scene, check_setting, is_setting
from blurset.commands.check_poses.cli import _summary, _table, add_arguments, is_report, run
from blurset.commands.check_poses.colmap import COLMAP_DATABASE, _Colmap
from blurset.commands.check_poses.judge import _judge, planted_errors
from blurset.commands.check_poses.model import _Model, _streak_residuals, _Tracks
from blurset.commands.check_poses.report import PoseReport, ViewResult
from blurset.commands.check_poses.scene import _load_scene, exposure_ends, mean_latent_poses
from blurset.commands.check_poses.thresholds import (
    CENTER_THRESHOLD_REL,
    EXIT_FAIL,
    EXIT_NOT_CHECKABLE,
    EXIT_PASS,
    MIN_REGISTERED_FRACTION,
    MIN_REGISTERED_VIEWS,
    OUTLIER_PX,
    PLANT_AXES,
    PLANT_DEG,
    PLANT_MIN_CAUGHT,
    REPROJ_RATIO,
    REPROJ_SLACK_PX,
    RERUN_SEEDS,
    ROT_THRESHOLD_DEG,
    STREAK_FORGIVEN,
)
from blurset.commands.check_poses.verdict import _report, exit_code

__all__ = [
    "CENTER_THRESHOLD_REL",
    "COLMAP_DATABASE",
    "EXIT_FAIL",
    "EXIT_NOT_CHECKABLE",
    "EXIT_PASS",
    "MIN_REGISTERED_FRACTION",
    "MIN_REGISTERED_VIEWS",
    "OUTLIER_PX",
    "PLANT_AXES",
    "PLANT_DEG",
    "PLANT_MIN_CAUGHT",
    "PoseReport",
    "REPROJ_RATIO",
    "REPROJ_SLACK_PX",
    "RERUN_SEEDS",
    "ROT_THRESHOLD_DEG",
    "STREAK_FORGIVEN",
    "ViewResult",
    "_Colmap",
    "_Model",
    "_Tracks",
    "_align",
    "_angle_deg",
    "_judge",
    "_load_scene",
    "_report",
    "_streak_residuals",
    "_summary",
    "_table",
    "add_arguments",
    "check_scene",
    "check_setting",
    "exit_code",
    "exposure_ends",
    "is_report",
    "is_setting",
    "mean_latent_poses",
    "planted_errors",
    "run",
]
