"""The report check-poses writes (`--json`) and prints, as types: a user reads it and
tests and the card read its fields, so its shape is declared here once, not implied by
the dicts that build it. `pass` is a Python keyword, hence the functional syntax."""

from __future__ import annotations

from typing import NotRequired, TypedDict


class ViewResult(TypedDict):
    """One view: registered by COLMAP or not, and for a registered one its errors."""

    index: int
    name: str
    features: int
    registered: bool
    rot_err_deg: float | None
    center_err_rel: float | None
    ok: bool
    reproj_px: NotRequired[float | None]
    colmap_reproj_px: NotRequired[float | None]
    agrees_with_colmap: NotRequired[bool]
    # A blur level (judged against its mean latent poses): the written pose's errors.
    written_rot_err_deg: NotRequired[float | None]
    written_center_err_rel: NotRequired[float | None]
    written_ok: NotRequired[bool]
    written_to_mean_deg: NotRequired[float | None]
    written_to_mean_rel: NotRequired[float | None]


class PlantedMiss(TypedDict):
    view: int
    axis: str


class Planted(TypedDict):
    """The sensitivity test of a pass: a `deg` rotation planted in one pose at a time."""

    deg: float
    tried: int
    caught: int
    fraction: float
    by_axis: dict[str, str]
    missed: list[PlantedMiss]


class ColmapRun(TypedDict):
    """One COLMAP mapping of the same database (seed 0 first)."""

    seed: int
    consistent: int | None
    registered: NotRequired[int]


class Intrinsics(TypedDict):
    w: float
    h: float
    focal: float


class Seconds(TypedDict):
    colmap: float
    compare: float


class Thresholds(TypedDict):
    """The bars the verdict applied, with the rules in words."""

    reproj_ratio: float
    reproj_slack_px: float
    streak_forgiven: float
    rule: str
    rot_err_deg: float
    center_err_rel: float
    agreement: str
    registered_fraction: float
    min_registered_views: int
    planted_deg: float
    planted_caught_fraction: float
    sensitivity: str
    degenerate: str


WrittenPose = TypedDict(
    "WrittenPose",
    {
        "verdict": str | None,
        "pass": bool | None,
        "median_rot_err_deg": float | None,
        "median_center_err_rel": float | None,
        "median_reproj_px": float | None,
        "agree_with_colmap": int | None,
        "failed_views": list[str] | None,
        "reason": str | None,
        "ok_views": int,
    },
)
"""The written pose's verdict and medians beside a blur level's (mean latent) verdict."""


PoseReport = TypedDict(
    "PoseReport",
    {
        "registered": int,
        "total": int,
        "registered_fraction": float,
        "median_features": int,
        "colmap_mean_reproj_px": float | None,
        "views": list[ViewResult],
        "median_rot_err_deg": float | None,
        "median_center_err_rel": float | None,
        "failed_views": list[str],
        "unregistered_views": list[str],
        "pass": bool,
        "verdict": str,
        "reason": str,
        "thresholds": Thresholds,
        "meaning": NotRequired[str],
        "median_reproj_px": NotRequired[float | None],
        "median_colmap_reproj_px": NotRequired[float | None],
        "agree_with_colmap": NotRequired[int],
        "consistent": NotRequired[int],
        "scene_distance": NotRequired[float | None],
        "planted": NotRequired[Planted],
        "colmap_runs": NotRequired[list[ColmapRun]],
        "colmap_seed": NotRequired[int],
        "written_pose": NotRequired[WrittenPose],
        "pose_reference": NotRequired[str],
        "median_written_to_mean_deg": NotRequired[float | None],
        "median_written_to_mean_rel": NotRequired[float | None],
        "scene": NotRequired[str],
        "image_dir": NotRequired[str],
        "intrinsics": NotRequired[Intrinsics],
        "seconds": NotRequired[Seconds],
    },
)
"""One scene's (or one level's) verdict on its poses: what `check_scene` returns."""
