"""Checking a scene or a build setting: COLMAP, a second opinion when its model contradicts most views, the report."""

from __future__ import annotations

import tempfile
import time
from collections.abc import Sequence
from pathlib import Path
from typing import cast

from blurset import layout
from blurset.commands.check_poses.align import _align
from blurset.commands.check_poses.colmap import _Colmap
from blurset.commands.check_poses.model import _Model
from blurset.commands.check_poses.report import ColmapRun, PoseReport
from blurset.commands.check_poses.scene import _load_scene, exposure_ends, mean_latent_poses
from blurset.commands.check_poses.thresholds import (
    CENTER_THRESHOLD_REL,
    MIN_REGISTERED_FRACTION,
    MIN_REGISTERED_VIEWS,
    RERUN_SEEDS,
    ROT_THRESHOLD_DEG,
)
from blurset.commands.check_poses.verdict import _beside_written, _finite, _fmt, _report
from blurset.exceptions import ConfigError, InputError


def check_scene(
    scene_dir: Path, *, factor: int | None = None, workdir: Path | None = None
) -> PoseReport:
    """Run COLMAP on one LLFF scene and compare its poses with `poses_bounds.npy`.

    Returns the JSON report: registered, total, median_features, colmap_mean_reproj_px,
    views [{index, name, registered, rot_err_deg, center_err_rel, reproj_px, ok, ...}],
    median errors, pass, verdict ("pass", "fail", "not checkable: N features", "not
    checkable: a 5° error would pass", "not checkable: degenerate COLMAP model"),
    meaning (what the verdict says about the poses, in one sentence), reason, planted
    (the 5° sensitivity test of a pass), colmap_runs (the seeds mapped), thresholds,
    seconds, pose_reference ("written" or "mean_latent"). A blur level of a build
    setting is compared with its mean latent poses (meta.json); then `written_pose`
    holds the written pose's errors and verdict, and each view its `written_*` errors
    and `written_to_mean_deg` / `written_to_mean_rel`. `workdir` keeps COLMAP's
    database and sparse models (a temporary directory otherwise). Raises InputError /
    ConfigError for a scene that cannot be read.
    """
    scene_dir = Path(scene_dir)
    t0 = time.perf_counter()
    image_dir, names, intr, rot_ours, c_ours = _load_scene(scene_dir, factor)
    mean = mean_latent_poses(scene_dir, len(names))
    decisive = mean if mean is not None else (rot_ours, c_ours)
    streaks = exposure_ends(scene_dir, mean) if mean is not None else None
    with tempfile.TemporaryDirectory(prefix="blurset-colmap-") as tmp:
        wd = Path(workdir) if workdir is not None else Path(tmp)
        wd.mkdir(parents=True, exist_ok=True)
        session = _Colmap(image_dir, names, intr, wd)
        model = _Model(session.map(0), names)
        t1 = time.perf_counter()
        report, model, t_map = _decide(session, model, names, decisive, streaks)
        if mean is not None:
            written = _report(names, session.features, model, rot_ours, c_ours, plant=False)
            report = _beside_written(report, written, (rot_ours, c_ours), mean)
        else:
            report["pose_reference"] = "written"
    report["scene"] = str(scene_dir)
    report["image_dir"] = image_dir.name
    report["intrinsics"] = {"w": intr[0], "h": intr[1], "focal": intr[2]}
    report["seconds"] = {
        "colmap": round(t1 - t0 + t_map, 3),
        "compare": round(time.perf_counter() - t1 - t_map, 3),
    }
    return cast(PoseReport, _finite(report))


def _decide(
    session: _Colmap, model: _Model, names: list[str], ours, streaks=None
) -> tuple[PoseReport, _Model, float]:
    """The report of `ours` against COLMAP's model, with a second opinion when most views
    contradict it: COLMAP maps again (RERUN_SEEDS, same database). A run that confirms
    every registered view decides (a degenerate first model must not fail good poses);
    runs that agree with one another confirm the contradiction (fail: the poses are
    wrong); otherwise COLMAP has no stable answer (not checkable, never fail).
    Returns the report, the model it used and the seconds spent mapping again."""
    report = _report(names, session.features, model, *ours, plant=False, streaks=streaks)
    if not _wholesale(report):
        report = _report(names, session.features, model, *ours, streaks=streaks)
        report["colmap_runs"] = [{"seed": 0, "consistent": report.get("consistent")}]
        return report, model, 0.0
    t0 = time.perf_counter()
    models = [(0, model, report)]
    for seed in RERUN_SEEDS:
        m = _Model(session.map(seed), names)
        models.append(
            (seed, m, _report(names, session.features, m, *ours, plant=False, streaks=streaks))
        )
    t_map = time.perf_counter() - t0
    runs: list[ColmapRun] = [
        {"seed": seed, "registered": r["registered"], "consistent": r.get("consistent")}
        for seed, _, r in models
    ]
    first = (
        f"COLMAP's first model (seed 0) contradicted {report['registered'] - report['consistent']}"
        f"/{report['registered']} registered views (median centre error "
        f"{_fmt(report['median_center_err_rel'], '.0%')})"
    )
    best_seed, best, best_report = max(models[1:], key=lambda x: x[2].get("consistent") or 0)
    # Only a run that confirms every registered view outweighs the first: COLMAP has
    # shown it is unstable here, so a run that still rejects some views proves nothing.
    if (
        best_report["registered_fraction"] >= MIN_REGISTERED_FRACTION
        and best_report.get("consistent") == best_report["registered"]
    ):
        final = _report(names, session.features, best, *ours, streaks=streaks)
        final["colmap_runs"] = runs
        final["colmap_seed"] = best_seed
        final["reason"] += f"; {first}; mapped again with seed {best_seed}, which decides"
        final["meaning"] += (
            f" (COLMAP's first model was degenerate; its run with seed {best_seed} decides)"
        )
        return final, best, t_map
    report["colmap_runs"] = runs
    _contradicted(report, len(models), _runs_agree([m for _, m, _ in models]), first)
    return report, model, t_map


def _contradicted(report: PoseReport, n_models: int, stable: bool, first: str) -> None:
    """Most views contradict every COLMAP run: the poses are wrong when the runs agree
    with one another (`stable`), else COLMAP's model is degenerate (not checkable)."""
    if stable:
        report["reason"] += (
            f"; {n_models} COLMAP runs (seeds 0, {', '.join(map(str, RERUN_SEEDS))}) "
            "agree with one another, so the contradiction is in the poses"
        )
        report["meaning"] = (
            f"the poses are wrong: {report['registered'] - report['consistent']}/"
            f"{report['registered']} views cannot place the features where "
            f"{n_models} agreeing COLMAP runs put them"
        )
        return
    report.update(
        {
            "verdict": "not checkable: degenerate COLMAP model",
            "failed_views": [],
            "reason": f"{first}; COLMAP mapped again with seeds "
            f"{', '.join(map(str, RERUN_SEEDS))} and the runs disagree with one another and "
            f"with our poses ({', '.join(_fmt(r['consistent'], 'd') for r in report['colmap_runs'])} of "
            f"{report['registered']} views consistent)",
            "meaning": "no verdict on the poses: COLMAP found no stable model of these images "
            "(its runs disagree with one another), so a disagreement with it says nothing",
        }
    )


def _wholesale(report: PoseReport) -> bool:
    """Most registered views contradict COLMAP's model (of a checkable registration)."""
    reg = report["registered"]
    return (
        reg >= MIN_REGISTERED_VIEWS
        and report["registered_fraction"] >= MIN_REGISTERED_FRACTION
        and 2 * report.get("consistent", reg) < reg
    )


def _runs_agree(models: list[_Model]) -> bool:
    """Whether COLMAP's models place the cameras alike: after a similarity alignment of
    each later model to the first, most common views within the agreement thresholds."""
    base = models[0]
    for other in models[1:]:
        common = sorted(set(base.reg_idx) & set(other.reg_idx))
        if len(common) < MIN_REGISTERED_VIEWS:
            return False
        a = [base.reg_idx.index(i) for i in common]
        b = [other.reg_idx.index(i) for i in common]
        rot_err, cen_err, _, _ = _align(
            base.rot[a], base.c[a], other.rot[b], other.c[b], other.depth[b]
        )
        agree = (rot_err <= ROT_THRESHOLD_DEG) & (cen_err <= CENTER_THRESHOLD_REL)
        if 2 * int(agree.sum()) <= len(common):
            return False
    return True


def is_setting(path: Path) -> bool:
    """A build setting directory holds level directories, not a scene of its own."""
    path = Path(path)
    return not (path / layout.POSES_BOUNDS).exists() and any(
        (path / lv / layout.POSES_BOUNDS).exists() for lv in layout.setting_levels(path)
    )


def check_setting(
    setting_dir: Path, levels: Sequence[str] = ("sharp",), *, factor: int | None = None
) -> dict[str, PoseReport]:
    """`check_scene` on each requested level directory of a build setting."""
    setting_dir = Path(setting_dir)
    out: dict[str, PoseReport] = {}
    for level in levels:
        _check_level_name(level)
        scene = setting_dir / level
        if not scene.is_dir():
            raise InputError(f"no level directory {level} in setting {setting_dir}")
        out[level] = check_scene(scene, factor=factor)
    return out


def _check_level_name(level: str) -> None:
    if not layout.is_level_dir(level):
        raise ConfigError(
            f"--level must be sharp, blur_<l> or defocus_<l> (l in 1..64) or all, got {level!r}"
        )
