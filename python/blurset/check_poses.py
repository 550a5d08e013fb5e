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
poses are OpenCV world-to-camera (x right, y down, z forward).
"""

from __future__ import annotations

import argparse
import re
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from blurset import _core, layout, outputs
from blurset._core import read_poses_bounds
from blurset.exceptions import ConfigError, InputError

# Calibrated on fern images_8 (COLMAP-made poses) and on rendered demo builds; see the
# module tests. A 5° perturbation of one view is far outside, correct poses far inside.
ROT_THRESHOLD_DEG = 1.5
CENTER_THRESHOLD_REL = 0.03
MIN_REGISTERED_FRACTION = 0.8
# A view COLMAP places elsewhere still passes when our pose reprojects its features
# about as well as COLMAP's own solution does (median px per view).
REPROJ_RATIO = 1.5
REPROJ_SLACK_PX = 0.25
OUTLIER_PX = 2.0
# A feature of a blurry image lies somewhere on the streak its exposure draws (from the
# first to the last latent frame), not exactly where the mean latent pose projects it:
# SIFT on a blur, and on the ghost copies of a few latent frames, lands off the middle
# along the streak, the more so the longer the streak (measured on the demo box, blur_3
# at 192 px, 6 latent frames: one view's features 1.9 px along its streak on average, 0.4
# px across; a tenth of the features more than 0.35-0.45 of their streak's length off the
# mean pose's projection, i.e. on the first or last ghost). Along the streak, an offset
# up to this fraction of the streak's length (first to last latent frame, projected
# through our poses, per feature) either way is no error; across it, all of it is.
# Measured on the demo box, blur_3, 128 and 192 px, 17-34 views: 0.25 and 0.5 leave the
# same margin under the threshold (0.2-0.4 px) on correct poses, but 0.5 lets a 5° roll
# pass more often (128 px: 10-22 of 15-34 planted rolls caught, against 11-30 at 0.25),
# so a quarter. Errors across the motion keep their full weight, and the planted 5°
# errors say whether the check is still sensitive.
STREAK_FORGIVEN = 0.25
# Fewer registered views than this cannot fix a similarity robustly.
MIN_REGISTERED_VIEWS = 3
# The sensitivity of a pass: a PLANT_DEG rotation planted in one pose (each registered
# view, about each camera axis) must be caught in PLANT_MIN_CAUGHT of the cases, or the
# scene is "not checkable" at its size and view count (bench/check_poses_sensitivity.py).
PLANT_DEG = 5.0
PLANT_AXES = ("tilt", "pan", "roll")
PLANT_MIN_CAUGHT = 0.9
# When most views contradict COLMAP's model, it maps again with these seeds.
RERUN_SEEDS = (1, 2)

IMAGE_SUFFIXES = {".png", ".jpg", ".jpeg"}

EXIT_PASS, EXIT_FAIL, EXIT_NOT_CHECKABLE = 0, 1, 3

# Set by `--verbose` to let COLMAP's own log through.
_VERBOSE = False


# --------------------------------------------------------------------------- scene input


def _image_dir(scene_dir: Path, factor: int | None) -> tuple[Path, int]:
    """The image directory and its downsampling factor, chosen as the LLFF loaders do:
    `images_<F>` for factor F, else `images`; a scene shipping a single `images_<F>`
    (fern) uses it without being told."""
    if factor is not None:
        if factor < 1:
            raise ConfigError(f"--factor must be >= 1, got {factor}")
        d = scene_dir / layout.images_dir(factor)
        if not d.is_dir():
            raise InputError(f"no image directory for --factor {factor}: {d}")
        return d, factor
    if (scene_dir / layout.IMAGES).is_dir():
        return scene_dir / layout.IMAGES, 1
    if layout.is_level_dir(scene_dir.name) and (scene_dir.parent / layout.META).is_file():
        # A build writes images/ in every level: without it the setting is damaged, and
        # its small images_<f>/ copies would only measure "too little texture".
        raise InputError(
            f"no {layout.IMAGES}/ in this level of a build setting (damaged: rerun the "
            f"build to redo it, or give --factor to check images_<f>/): {scene_dir}"
        )
    found = sorted(
        (int(m.group(1)), p)
        for p in scene_dir.glob("images_*")
        if p.is_dir() and (m := re.fullmatch(r"images_(\d+)", p.name))
    )
    if len(found) == 1:
        return found[0][1], found[0][0]
    if not found:
        raise InputError(f"no images/ directory in {scene_dir}")
    raise InputError(
        f"several image directories ({', '.join(p.name for _, p in found)}); "
        f"pick one with --factor: {scene_dir}"
    )


def _load_scene(scene_dir: Path, factor: int | None):
    pb_path = scene_dir / layout.POSES_BOUNDS
    if not pb_path.is_file():
        raise InputError(f"no poses_bounds.npy in {scene_dir}")
    rows = np.asarray(read_poses_bounds(pb_path), dtype=np.float64)
    image_dir, factor = _image_dir(scene_dir, factor)
    names = sorted(p.name for p in image_dir.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES)
    if len(names) != len(rows):
        raise InputError(f"{len(names)} images in {image_dir} but {len(rows)} poses in {pb_path}")
    if not names:
        raise InputError(f"no images in {image_dir}")

    from PIL import Image

    with Image.open(image_dir / names[0]) as im:
        w, h = im.size
    hwf = rows[0, [4, 9, 14]]
    # The LLFF loaders take h, w from the image and divide only the focal by the factor.
    if abs(hwf[0] / factor - h) > 1.0 or abs(hwf[1] / factor - w) > 1.0:
        raise InputError(
            f"image size {w}x{h} does not match hwf {hwf[1]:g}x{hwf[0]:g} / factor {factor} "
            f"(wrong --factor?): {image_dir / names[0]}"
        )
    focal = float(hwf[2]) / factor
    mats = rows[:, :15].reshape(-1, 3, 5)
    # OpenCV camera-to-world: x = right = col 1, y = down = col 0, z = forward = -col 2.
    rot_c2w = np.stack([mats[:, :, 1], mats[:, :, 0], -mats[:, :, 2]], axis=2)
    centers = mats[:, :, 3]
    return image_dir, names, (w, h, focal), rot_c2w, centers


def mean_latent_poses(scene_dir: Path, n: int):
    """OpenCV camera-to-world rotations and centres of the mean latent poses of a blur
    level of a build setting (`SETTING/blur_<l>`, from `SETTING/meta.json`, read by the
    core), or None for a sharp level, a plain LLFF scene, or a build from before meta.json
    recorded them."""
    level = scene_dir.name
    if level == layout.SHARP or not layout.is_level_dir(level):
        return None
    if not (scene_dir.parent / layout.META).is_file():
        return None
    poses = layout.mean_poses(scene_dir.parent, level)
    if poses is None:
        return None
    if len(poses) != n:
        raise InputError(
            f"{len(poses)} views in meta.json but {n} images in {level}: "
            f"{scene_dir.parent / layout.META}"
        )
    c2w = np.asarray(poses, dtype=np.float64)
    # OpenGL (right, up, backwards) → OpenCV (right, down, forward).
    return c2w[:, :3, :3] * np.array([1.0, -1.0, -1.0]), c2w[:, :3, 3]


def exposure_ends(scene_dir: Path, mean):
    """OpenCV ((rotations, centres) at the first latent frame, (…) at the last) of each
    view's exposure in a blur level of a build setting (meta.json, read by the core), where
    the streaks a blurry image shows begin and end (the first and last motion key under
    the motion blur method); the mean latent pose for a view whose image is a sharp copy
    or that has neither (no streak). None when meta.json does not say."""
    level = _core.parse_level_dir(scene_dir.name)
    if level is None:
        return None
    ends = _core.read_exposure_ends(scene_dir.parent / layout.META, level)
    if ends is None:
        return None
    rot_mean, c_mean = mean
    out = [(rot_mean.copy(), c_mean.copy()), (rot_mean.copy(), c_mean.copy())]
    for i, pair in enumerate(ends):
        if pair is None:
            continue
        for (rot, c), rows in zip(out, pair, strict=True):
            c2w = np.asarray(rows, dtype=np.float64)
            # OpenGL (right, up, backwards) → OpenCV (right, down, forward).
            rot[i] = c2w[:3, :3] * np.array([1.0, -1.0, -1.0])
            c[i] = c2w[:3, 3]
    return out


# --------------------------------------------------------------------------- COLMAP


class _Colmap:
    """COLMAP on one scene: SIFT + exhaustive matching once, with the shared pinhole
    intrinsics held fixed; incremental mapping on demand (`map(seed)`), so a second
    opinion costs a mapping, not a new database."""

    def __init__(self, image_dir: Path, names: list[str], intrinsics, workdir: Path):
        import pycolmap

        self.pycolmap, self.image_dir, self.workdir = pycolmap, image_dir, workdir
        self.db_path = workdir / COLMAP_DATABASE
        _refuse_used_workdir(workdir)
        w, h, f = intrinsics
        with self._quiet():
            pycolmap.set_random_seed(0)
            reader = pycolmap.ImageReaderOptions()
            reader.camera_model = "PINHOLE"
            reader.camera_params = f"{f!r},{f!r},{w / 2!r},{h / 2!r}"
            extraction = pycolmap.FeatureExtractionOptions()
            extraction.use_gpu = False
            pycolmap.extract_features(
                self.db_path,
                image_dir,
                image_names=names,
                camera_mode=pycolmap.CameraMode.SINGLE,
                reader_options=reader,
                extraction_options=extraction,
                device=pycolmap.Device.cpu,
            )
            matching = pycolmap.FeatureMatchingOptions()
            matching.use_gpu = False
            pycolmap.match_exhaustive(
                self.db_path, matching_options=matching, device=pycolmap.Device.cpu
            )
        self.features: dict[str, int] = {}
        with pycolmap.Database.open(self.db_path) as db:
            for image in db.read_all_images():
                self.features[image.name] = int(db.num_keypoints_for_image(image.image_id))

    def _quiet(self):
        """COLMAP logs every step at INFO; the report says what matters."""
        import contextlib

        pycolmap = self.pycolmap

        @contextlib.contextmanager
        def quiet():
            level = pycolmap.logging.minloglevel
            if not _VERBOSE:
                pycolmap.logging.minloglevel = 3
            try:
                yield
            finally:
                pycolmap.logging.minloglevel = level

        return quiet()

    def map(self, seed: int = 0):
        """The largest reconstruction of incremental mapping with `seed`, or None."""
        pycolmap = self.pycolmap
        sparse = self.workdir / ("sparse" if seed == 0 else f"sparse_seed{seed}")
        sparse.mkdir(parents=True, exist_ok=True)
        opts = pycolmap.IncrementalPipelineOptions()
        opts.random_seed = seed
        opts.multiple_models = False
        # The intrinsics are under test together with the poses: never refine them.
        opts.ba_refine_focal_length = False
        opts.ba_refine_principal_point = False
        opts.ba_refine_extra_params = False
        opts.mapper.abs_pose_refine_focal_length = False
        opts.mapper.abs_pose_refine_extra_params = False
        opts.mapper.random_seed = seed
        opts.triangulation.random_seed = seed
        with self._quiet():
            if seed:
                pycolmap.set_random_seed(seed)
            recs = pycolmap.incremental_mapping(self.db_path, self.image_dir, sparse, options=opts)
        return max(recs.values(), key=lambda r: r.num_reg_images(), default=None)


COLMAP_DATABASE = "database.db"


def _refuse_used_workdir(workdir: Path) -> None:
    """ConfigError naming --workdir when `workdir` already holds a COLMAP database or
    sparse model: check-poses writes its own there and never deletes one (it may be the
    user's own COLMAP workspace, or a model they kept)."""
    if not workdir.is_dir():
        return
    used = sorted(
        p.name
        for p in workdir.iterdir()
        if p.name == COLMAP_DATABASE or (p.is_dir() and p.name.startswith("sparse"))
    )
    if used:
        raise ConfigError(
            f"--workdir {workdir}: already holds {', '.join(used)} (check-poses writes a new "
            "COLMAP database and model there and deletes none): name a new folder, or "
            "remove them yourself"
        )


# --------------------------------------------------------------------------- alignment


def _project_so3(m: np.ndarray) -> np.ndarray:
    u, _, vt = np.linalg.svd(m)
    d = np.sign(np.linalg.det(u @ vt))
    return u @ np.diag([1.0, 1.0, d]) @ vt


def _angle_deg(r: np.ndarray) -> np.ndarray:
    """Rotation angle of (a stack of) rotation matrices, in degrees."""
    tr = np.trace(r, axis1=-2, axis2=-1)
    return np.degrees(np.arccos(np.clip((tr - 1.0) / 2.0, -1.0, 1.0)))


def _fit_similarity(rot_ours, c_ours, rot_col, c_col, use):
    """X_ours = s R X_colmap + t, from the views in `use`: R is the chordal L2 mean of
    R_ours R_colmapᵀ (camera-to-world), s and t least squares on the centres given R."""
    rot = _project_so3(np.einsum("nij,nkj->ik", rot_ours[use], rot_col[use]))
    y = c_col[use] @ rot.T
    x = c_ours[use]
    yc, xc = y - y.mean(0), x - x.mean(0)
    denom = float((yc * yc).sum())
    s = float((yc * xc).sum()) / denom if denom > 0 else 1.0
    t = x.mean(0) - s * y.mean(0)
    return s, rot, t


def _align(rot_ours, c_ours, rot_col, c_col, depth_col):
    """Robust similarity and per-view errors. A medoid of the per-view rotation
    candidates and a median of pairwise distance ratios give a start no single wrong
    view can move; least squares is then refit on the views that agree with it."""
    n = len(rot_ours)
    cand = np.einsum("nij,nkj->nik", rot_ours, rot_col)
    pair = _angle_deg(np.einsum("aji,bjk->abik", cand, cand))
    medoid = cand[int(np.argmin(np.median(pair, axis=1)))]
    iu = np.triu_indices(n, 1)
    d_ours = np.linalg.norm(c_ours[:, None] - c_ours[None], axis=-1)[iu]
    d_col = np.linalg.norm(c_col[:, None] - c_col[None], axis=-1)[iu]
    ok_pairs = d_col > 1e-12
    s = float(np.median(d_ours[ok_pairs] / d_col[ok_pairs])) if ok_pairs.any() else 1.0
    t = np.median(c_ours - s * c_col @ medoid.T, axis=0)
    rot = medoid
    use = np.ones(n, dtype=bool)
    for _ in range(4):
        rot_err, cen_err, scale = _errors(rot_ours, c_ours, rot_col, c_col, depth_col, s, rot, t)
        new_use = (rot_err <= ROT_THRESHOLD_DEG) & (cen_err <= CENTER_THRESHOLD_REL)
        if new_use.sum() < MIN_REGISTERED_VIEWS:
            # Nothing agrees: fit all, so the reported errors are those of the best fit.
            new_use = np.ones(n, dtype=bool)
        if _ > 0 and np.array_equal(new_use, use):
            break
        use = new_use
        s, rot, t = _fit_similarity(rot_ours, c_ours, rot_col, c_col, use)
    rot_err, cen_err, scale = _errors(rot_ours, c_ours, rot_col, c_col, depth_col, s, rot, t)
    return rot_err, cen_err, scale, s


def _errors(rot_ours, c_ours, rot_col, c_col, depth_col, s, rot, t):
    rot_err = _angle_deg(np.einsum("ij,njk,nlk->nil", rot, rot_col, rot_ours))
    # Centre errors relative to the mean distance from the cameras to what they see,
    # which is defined for object-centric and forward-facing scenes alike.
    scale = abs(s) * float(np.mean(depth_col))
    cen = np.linalg.norm(c_col @ (s * rot).T + t - c_ours, axis=1)
    return rot_err, cen / scale, scale


# --------------------------------------------------------------------------- report


def _thresholds() -> dict:
    return {
        "reproj_ratio": REPROJ_RATIO,
        "reproj_slack_px": REPROJ_SLACK_PX,
        "streak_forgiven": STREAK_FORGIVEN,
        "rule": "a registered view is ok when the median reprojection error of its COLMAP "
        "features under our poses is <= reproj_ratio * COLMAP's own + reproj_slack_px; "
        "in a blurry image, an offset along the feature's streak (its projections at the "
        "exposure's first and last latent frame) up to streak_forgiven of the streak's "
        "length is not counted",
        "rot_err_deg": ROT_THRESHOLD_DEG,
        "center_err_rel": CENTER_THRESHOLD_REL,
        "agreement": "rot_err_deg and center_err_rel (relative to the mean camera-to-scene "
        "distance) against COLMAP's poses after a similarity alignment; reported per view",
        "registered_fraction": MIN_REGISTERED_FRACTION,
        "min_registered_views": MIN_REGISTERED_VIEWS,
        "planted_deg": PLANT_DEG,
        "planted_caught_fraction": PLANT_MIN_CAUGHT,
        "sensitivity": f"a pass needs a {PLANT_DEG:g} deg rotation planted in one pose (each "
        "registered view in turn, about the camera's x, y and z axes) to be caught in at "
        f"least {PLANT_MIN_CAUGHT:.0%} of the cases, against the same COLMAP model; "
        "otherwise the scene is not checkable at its size and view count",
        "degenerate": f"when most registered views contradict COLMAP's model, COLMAP maps "
        f"again with seeds {', '.join(map(str, RERUN_SEEDS))}: a run that confirms every "
        "registered view decides; runs that agree with one another make it a fail; "
        "otherwise the model is degenerate (not checkable)",
    }


def check_scene(scene_dir: Path, *, factor: int | None = None, workdir: Path | None = None) -> dict:
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
    return _finite(report)


def _decide(
    session: _Colmap, model: _Model, names: list[str], ours, streaks=None
) -> tuple[dict, _Model, float]:
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
    runs = [
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
    stable = _runs_agree([m for _, m, _ in models])
    report["colmap_runs"] = runs
    if stable:
        report["reason"] += (
            f"; {len(models)} COLMAP runs (seeds 0, {', '.join(map(str, RERUN_SEEDS))}) "
            "agree with one another, so the contradiction is in the poses"
        )
        report["meaning"] = (
            f"the poses are wrong: {report['registered'] - report['consistent']}/"
            f"{report['registered']} views cannot place the features where "
            f"{len(models)} agreeing COLMAP runs put them"
        )
        return report, model, t_map
    report.update(
        verdict="not checkable: degenerate COLMAP model",
        failed_views=[],
        reason=f"{first}; COLMAP mapped again with seeds "
        f"{', '.join(map(str, RERUN_SEEDS))} and the runs disagree with one another and "
        f"with our poses ({', '.join(_fmt(r['consistent'], 'd') for r in runs)} of "
        f"{report['registered']} views consistent)",
        meaning="no verdict on the poses: COLMAP found no stable model of these images "
        "(its runs disagree with one another), so a disagreement with it says nothing",
    )
    return report, model, t_map


def _wholesale(report: dict) -> bool:
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


class _Model:
    """What one COLMAP reconstruction says, whatever our poses are: which views it
    registered, its camera poses and scene depths, and its feature tracks."""

    def __init__(self, rec, names: list[str]):
        self.rec = rec
        id_by_name = {}
        if rec is not None:
            for image_id in rec.reg_image_ids():
                id_by_name[rec.image(image_id).name] = image_id
        self.id_by_name = id_by_name
        self.reg_idx = [i for i, nm in enumerate(names) if nm in id_by_name]
        self.image_ids = [id_by_name[names[i]] for i in self.reg_idx]
        self.mean_reproj_px = float(rec.compute_mean_reprojection_error()) if self.reg_idx else None
        if len(self.reg_idx) >= MIN_REGISTERED_VIEWS:
            self.rot, self.c, self.depth = _camera_poses(rec, self.image_ids)
            self.tracks = _Tracks(rec, self.image_ids)


def _camera_poses(rec, image_ids):
    """Camera-to-world rotations, centres and median scene depth of COLMAP images."""
    rots, centers, depths = [], [], []
    for image_id in image_ids:
        image = rec.image(image_id)
        cam_from_world = image.cam_from_world()
        r = np.asarray(cam_from_world.rotation.matrix())
        tvec = np.asarray(cam_from_world.translation)
        rots.append(r.T)
        centers.append(-r.T @ tvec)
        pts = [rec.point3D(p.point3D_id).xyz for p in image.points2D if p.has_point3D()]
        z = (np.asarray(pts) @ r.T + tvec)[:, 2] if pts else np.array([np.nan])
        depths.append(float(np.median(z)))
    d = np.asarray(depths)
    if not np.isfinite(d).any():
        d[:] = 1.0
    d = np.where(np.isfinite(d), d, np.nanmedian(d))
    return np.asarray(rots), np.asarray(centers), d


def _reproject(proj, x, xy) -> float:
    p = proj @ x
    # A point behind the camera is no explanation at all.
    return float(np.linalg.norm(p[:2] / p[2] - xy)) if p[2] * x[3] > 0 else np.inf


def _reproject_all(projs: np.ndarray, x: np.ndarray, xys: np.ndarray) -> np.ndarray:
    """`_reproject` of one point into several views: (m, 3, 4) projections, (m, 2) px."""
    p = projs @ x
    with np.errstate(divide="ignore", invalid="ignore"):
        err = np.linalg.norm(p[:, :2] / p[:, 2:] - xys, axis=1)
    return np.where(p[:, 2] * x[3] > 0, err, np.inf)


def _streak_residuals(projs, first, last, x, xys) -> np.ndarray:
    """`_reproject_all` for blurry images: the error of each observation against the
    projection under the mean latent pose (`projs`), without the part along the
    feature's streak (its projections under the exposure's `first` and `last` latent
    frames) up to STREAK_FORGIVEN of the streak's length. A sharp image (no streak)
    keeps the whole error."""
    p, a, b = projs @ x, first @ x, last @ x
    with np.errstate(divide="ignore", invalid="ignore"):
        e = p[:, :2] / p[:, 2:] - xys
        s = b[:, :2] / b[:, 2:] - a[:, :2] / a[:, 2:]
        length = np.linalg.norm(s, axis=1)
        d = s / length[:, None]
        along = np.abs((e * d).sum(axis=1))
        across = e[:, 0] * d[:, 1] - e[:, 1] * d[:, 0]
        along = np.maximum(along - STREAK_FORGIVEN * length, 0.0)
        err = np.where(length > 1e-9, np.hypot(along, across), np.linalg.norm(e, axis=1))
    return np.where((p[:, 2] * x[3] > 0) & np.isfinite(err), err, np.inf)


def _triangulate_robust(projs: np.ndarray, xys: np.ndarray) -> np.ndarray:
    """Linear triangulation that drops the worst observation while one misses by more
    than OUTLIER_PX, so a single wrong pose cannot drag the points of its neighbours."""
    keep = np.arange(len(projs))
    while True:
        pm, xy = projs[keep], xys[keep]
        rows = np.stack(
            [xy[:, :1] * pm[:, 2] - pm[:, 0], xy[:, 1:] * pm[:, 2] - pm[:, 1]], axis=1
        ).reshape(-1, 4)
        x = np.linalg.svd(rows)[2][-1]
        errs = _reproject_all(pm, x, xy)
        worst = int(np.argmax(errs))
        if errs[worst] <= OUTLIER_PX or len(keep) <= 2:
            return x
        keep = np.delete(keep, worst)


class _Tracks:
    """COLMAP's feature tracks over the registered views (those reaching two of them),
    with two explanations of the same image evidence: COLMAP's own poses and points
    (fixed), and a set of our poses with each track re-triangulated (linear, robust).
    Per view, the median reprojection error (px) of each."""

    def __init__(self, rec, image_ids):
        index = {image_id: k for k, image_id in enumerate(image_ids)}
        self.n = len(image_ids)
        self.k_mats = [rec.image(i).camera.calibration_matrix() for i in image_ids]
        theirs = [
            k @ rec.image(i).cam_from_world().matrix()
            for k, i in zip(self.k_mats, image_ids, strict=True)
        ]
        self.views: list[np.ndarray] = []
        self.xys: list[np.ndarray] = []
        res_theirs: list[list[float]] = [[] for _ in image_ids]
        for point_id in rec.point3D_ids():
            point = rec.point3D(point_id)
            obs = [
                (index[el.image_id], rec.image(el.image_id).points2D[el.point2D_idx].xy)
                for el in point.track.elements
                if el.image_id in index
            ]
            if len(obs) < 2:
                continue
            x_theirs = np.append(point.xyz, 1.0)
            for k, xy in obs:
                res_theirs[k].append(_reproject(theirs[k], x_theirs, xy))
            self.views.append(np.array([k for k, _ in obs]))
            self.xys.append(np.array([xy for _, xy in obs], dtype=np.float64))
        self.px_theirs = np.array([float(np.median(v)) if v else np.nan for v in res_theirs])
        self.by_view: list[list[int]] = [[] for _ in image_ids]
        for t, vs in enumerate(self.views):
            for k in vs:
                self.by_view[k].append(t)
        # The observations of all tracks grouped by view, for the per-view medians.
        flat = np.concatenate(self.views) if self.views else np.zeros(0, dtype=int)
        self._order = np.argsort(flat, kind="stable")
        bounds = np.searchsorted(flat[self._order], np.arange(self.n + 1))
        self._spans = list(zip(bounds[:-1], bounds[1:], strict=True))

    def projections(self, rot_c2w, centers) -> np.ndarray:
        out = []
        for k_mat, r, c in zip(self.k_mats, rot_c2w, centers, strict=True):
            out.append(k_mat @ np.hstack([r.T, (-r.T @ c)[:, None]]))
        return np.asarray(out)

    def residuals(self, projs, changed: int | None = None, base=None, streaks=None) -> list[Any]:
        """Per track, the reprojection errors of its observations under `projs`; with
        `base` (the residuals of other poses), only the tracks through view `changed`
        are computed again. `streaks`: the projections at each exposure's first and
        last latent frame, for the along-streak allowance of blurry images."""
        out = list(base) if base is not None else [None] * len(self.views)
        which = range(len(self.views)) if base is None or changed is None else self.by_view[changed]
        for t in which:
            vs, xys = self.views[t], self.xys[t]
            ps = projs[vs]
            x = _triangulate_robust(ps, xys)
            if streaks is None:
                out[t] = _reproject_all(ps, x, xys)
            else:
                out[t] = _streak_residuals(ps, streaks[0][vs], streaks[1][vs], x, xys)
        return out

    def medians(self, per_track: list[np.ndarray]) -> np.ndarray:
        if not per_track:
            return np.full(self.n, np.nan)
        res = np.concatenate(per_track)[self._order]
        return np.array([float(np.median(res[a:b])) if b > a else np.nan for a, b in self._spans])


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
) -> dict:
    """Whether the check catches a `deg` rotation error in one pose: each registered view
    in turn is turned by `deg` about its camera's x (tilt), y (pan) and z (roll: the
    optical axis) axes and judged against the same COLMAP model (which sees only the
    images, so it is the model a wrong pose would meet). Caught: that view is no longer
    consistent with the images. `base` is the judgement of the unchanged poses."""
    caught: dict[str, list[Any]] = {axis: [] for axis in PLANT_AXES}
    missed = []
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


def _report(
    names, features, model: _Model, rot_ours, c_ours, *, plant: bool = True, streaks=None
) -> dict:
    """The verdict on our poses from COLMAP's model of the same images: not checkable
    (too few views registered, or a planted error would pass), fail (a view contradicts
    the images), or pass."""
    report, views = _empty_report(names, features, model)
    n, reg = len(names), len(model.reg_idx)
    if reg < MIN_REGISTERED_VIEWS:
        report["reason"] = (
            f"COLMAP registered {reg}/{n} views (median {report['median_features']} SIFT "
            "features per image): too little texture or overlap for structure from motion"
        )
        report["meaning"] = (
            "no verdict on the poses: COLMAP cannot reconstruct these images, so there is "
            "nothing to compare them with"
        )
        return report
    j = _judge(model, rot_ours, c_ours, streaks=streaks)
    failed = _measure(report, views, model.reg_idx, j)
    disagreement = ", ".join(
        f"{views[i]['name']} (#{i}: features off by {views[i]['reproj_px']:.2f} px "
        f"vs COLMAP's {views[i]['colmap_reproj_px']:.2f} px; COLMAP pose "
        f"{views[i]['rot_err_deg']:.2f} deg, {views[i]['center_err_rel']:.1%} away)"
        for i in failed
    )
    if reg / n < MIN_REGISTERED_FRACTION:
        # Registration does not depend on our poses, only on the images: a partial
        # model is weak evidence (measured: a 5-view model of a plain vase put correct
        # poses 4 deg off), so it can neither pass nor fail the scene.
        report["reason"] = (
            f"only {reg}/{n} views registered (< {MIN_REGISTERED_FRACTION:.0%}, "
            f"median {report['median_features']} SIFT features per image)"
            + (f"; in that partial model: {disagreement}" if failed else "")
        )
        report["meaning"] = (
            f"no verdict on the poses: COLMAP reconstructed only {reg}/{n} views, too "
            "few to judge the scene"
        )
    elif failed:
        report["verdict"] = "fail"
        report["reason"] = f"{len(failed)} view(s) contradict the images: {disagreement}"
        report["meaning"] = (
            f"the poses are wrong: {len(failed)} view(s) cannot place their features where "
            f"the images show them, while {reg - len(failed)}/{reg} views agree with "
            "COLMAP's model"
        )
    else:
        _judge_consistent(report, model, rot_ours, c_ours, j, streaks, plant=plant)
    return report


def _empty_report(names, features, model: _Model) -> tuple[dict[str, Any], list[dict]]:
    """The report before any pose is judged (not checkable, nothing measured) and its
    per-view entries."""
    n = len(names)
    feats = np.array([features.get(nm, 0) for nm in names])
    median_feats = int(np.median(feats))
    views = [
        {
            "index": i,
            "name": nm,
            "features": int(feats[i]),
            "registered": nm in model.id_by_name,
            "rot_err_deg": None,
            "center_err_rel": None,
            "ok": False,
        }
        for i, nm in enumerate(names)
    ]
    report: dict[str, Any] = {
        "registered": len(model.reg_idx),
        "total": n,
        "registered_fraction": len(model.reg_idx) / n,
        "median_features": median_feats,
        # COLMAP's own mean reprojection error over all its observations: how well its
        # reconstruction explains the features, independent of our poses.
        "colmap_mean_reproj_px": model.mean_reproj_px,
        "views": views,
        "median_rot_err_deg": None,
        "median_center_err_rel": None,
        "failed_views": [],
        "unregistered_views": [nm for nm in names if nm not in model.id_by_name],
        "pass": False,
        "verdict": f"not checkable: {median_feats} features",
        "reason": "",
        "thresholds": _thresholds(),
    }
    return report, views


def _measure(report: dict, views: list[dict], reg_idx, j: dict) -> list[int]:
    """Each registered view's errors and the medians into the report; the views that
    contradict the images, worst first."""
    rot_err, cen_err, px_ours, px_colmap = j["rot_err"], j["cen_err"], j["px_ours"], j["px_colmap"]
    for k, i in enumerate(reg_idx):
        views[i].update(
            rot_err_deg=float(rot_err[k]),
            center_err_rel=float(cen_err[k]),
            reproj_px=float(px_ours[k]),
            colmap_reproj_px=float(px_colmap[k]),
            agrees_with_colmap=bool(j["agrees"][k]),
            ok=bool(j["ok"][k]),
        )
    failed = [i for i in reg_idx if not views[i]["ok"]]
    report.update(
        median_rot_err_deg=float(np.median(rot_err)),
        median_center_err_rel=float(np.median(cen_err)),
        median_reproj_px=float(np.nanmedian(px_ours)),
        median_colmap_reproj_px=float(np.nanmedian(px_colmap)),
        agree_with_colmap=int(j["agrees"].sum()),
        consistent=len(reg_idx) - len(failed),
        scene_distance=j["scale"],
    )
    failed.sort(key=lambda i: -np.nan_to_num(views[i]["reproj_px"], nan=np.inf))
    report["failed_views"] = [views[i]["name"] for i in failed]
    return failed


def _judge_consistent(
    report: dict, model: _Model, rot_ours, c_ours, j: dict, streaks, *, plant: bool
) -> None:
    """Every registered view is consistent with the images: a pass if a planted error
    of PLANT_DEG would be caught (the check is sensitive here), else not checkable."""
    n, reg = report["total"], report["registered"]
    unregistered = (
        f"; the {n - reg} view(s) COLMAP did not register are not checked" if reg < n else ""
    )
    report["reason"] = (
        f"{reg}/{n} views registered and consistent with the images; "
        f"{report['agree_with_colmap']}/{reg} within {ROT_THRESHOLD_DEG} deg and "
        f"{CENTER_THRESHOLD_REL:.0%} of COLMAP's own poses"
    )
    colmap = _colmap_vs_ours(report, reg)
    if not plant:
        report["pass"] = True
        report["verdict"] = "pass"
        report["meaning"] = f"our poses explain the images in {reg}/{reg} views; {colmap}"
        return
    planted = planted_errors(model, rot_ours, c_ours, j, PLANT_DEG, streaks)
    report["planted"] = planted
    axes = ", ".join(f"{a} {c}" for a, c in planted["by_axis"].items())
    sensitivity = (
        f"a {PLANT_DEG:g}° error planted in one pose is caught in "
        f"{planted['caught']}/{planted['tried']} cases ({axes})"
    )
    if planted["fraction"] >= PLANT_MIN_CAUGHT:
        report["pass"] = True
        report["verdict"] = "pass"
        report["meaning"] = (
            f"our poses explain the images as well as COLMAP's own model in {reg}/{reg} "
            f"registered views, and {sensitivity}{unregistered}; {colmap}"
        )
    else:
        report["verdict"] = f"not checkable: a {PLANT_DEG:g}° error would pass"
        report["reason"] += f"; but {sensitivity}"
        report["meaning"] = (
            f"no verdict on the poses: they are consistent with the images, but at "
            f"this image size and view count {sensitivity} (< {PLANT_MIN_CAUGHT:.0%}), "
            "so a pass would not mean they are right"
        )


def _colmap_vs_ours(report: dict, reg: int) -> str:
    """How COLMAP's own poses compare with ours, in words."""
    agree = report["agree_with_colmap"]
    if 2 * agree > reg:
        return f"COLMAP's own poses agree ({agree}/{reg} within {ROT_THRESHOLD_DEG:g}° and {CENTER_THRESHOLD_REL:.0%})"
    return (
        f"COLMAP's own poses are {report['median_rot_err_deg']:.1f}° off ours "
        f"({agree}/{reg} within {ROT_THRESHOLD_DEG:g}°): its model is weaker than our poses "
        "here, so the verdict rests on how well each explains the features"
    )


def _beside_written(report: dict, written: dict, ours, mean) -> dict:
    """The mean-pose report (it decides), with the written pose's errors and the offset
    from the written pose to the mean latent pose beside it, per view and as medians."""
    (rot_w, c_w), (rot_m, c_m) = ours, mean
    offset_deg = _angle_deg(np.einsum("nji,njk->nik", rot_w, rot_m))
    # Relative to the camera distance from the object centre (the world origin).
    distance = float(np.mean(np.linalg.norm(c_w, axis=1))) or 1.0
    offset_rel = np.linalg.norm(c_m - c_w, axis=1) / distance
    for v, w, deg, rel in zip(
        report["views"], written["views"], offset_deg, offset_rel, strict=True
    ):
        v.update(
            written_rot_err_deg=w["rot_err_deg"],
            written_center_err_rel=w["center_err_rel"],
            written_ok=w["ok"],
            written_to_mean_deg=float(deg),
            written_to_mean_rel=float(rel),
        )
    keep = (
        "verdict pass median_rot_err_deg median_center_err_rel median_reproj_px "
        "agree_with_colmap failed_views reason"
    ).split()
    report["written_pose"] = {k: written.get(k) for k in keep}
    report["written_pose"]["ok_views"] = sum(bool(v["ok"]) for v in written["views"])
    report["pose_reference"] = "mean_latent"
    report["median_written_to_mean_deg"] = float(np.median(offset_deg))
    report["median_written_to_mean_rel"] = float(np.median(offset_rel))
    if report["registered"] >= MIN_REGISTERED_VIEWS:
        report["reason"] += (
            f" (against the mean latent poses; the written poses are "
            f"{_fmt(written.get('median_rot_err_deg'), '.2f')} deg off, "
            f"{report['written_pose']['ok_views']}/{written['registered']} consistent; "
            f"written-to-mean offset median {report['median_written_to_mean_deg']:.2f} deg)"
        )
    return report


def _finite(x):
    """JSON has no inf or NaN: a value that is not finite is reported as null."""
    if isinstance(x, float):
        return x if np.isfinite(x) else None
    if isinstance(x, dict):
        return {k: _finite(v) for k, v in x.items()}
    if isinstance(x, list):
        return [_finite(v) for v in x]
    return x


def exit_code(report: dict) -> int:
    """0 pass, 1 fail (poses disagree), 3 not checkable."""
    if report["pass"]:
        return EXIT_PASS
    return EXIT_FAIL if report["verdict"] == "fail" else EXIT_NOT_CHECKABLE


# --------------------------------------------------------------------------- settings


def is_setting(path: Path) -> bool:
    """A build setting directory holds level directories, not a scene of its own."""
    path = Path(path)
    return not (path / layout.POSES_BOUNDS).exists() and any(
        (path / lv / layout.POSES_BOUNDS).exists() for lv in layout.setting_levels(path)
    )


def check_setting(
    setting_dir: Path, levels: Sequence[str] = ("sharp",), *, factor: int | None = None
) -> dict[str, dict]:
    """`check_scene` on each requested level directory of a build setting."""
    setting_dir = Path(setting_dir)
    out = {}
    for level in levels:
        _check_level_name(level)
        scene = setting_dir / level
        if not scene.is_dir():
            raise InputError(f"no level directory {level} in setting {setting_dir}")
        out[level] = check_scene(scene, factor=factor)
    return out


def _check_level_name(level: str) -> None:
    if not layout.is_level_dir(level):
        raise ConfigError(f"--level must be sharp, blur_<l> (l in 1..64) or all, got {level!r}")


# --------------------------------------------------------------------------- CLI


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("path", type=Path, help="a build setting directory or an LLFF scene")
    parser.add_argument(
        "--level",
        default="sharp",
        help="level directory of a build setting to check: sharp, blur_<l> (default sharp; a "
        "blur level is compared with its mean latent poses from meta.json); `all` checks "
        "every level and prints how blur degrades SfM (the exit code follows sharp)",
    )
    parser.add_argument(
        "--factor",
        type=int,
        default=None,
        help="use images_<F>/ and divide the focal length by F, as the LLFF loaders do "
        "(default: images/)",
    )
    parser.add_argument(
        "--json",
        type=Path,
        default=None,
        help="write the JSON report here (default: none); a file already there is replaced "
        "only when it is an earlier check-poses report",
    )
    parser.add_argument(
        "--workdir",
        type=Path,
        default=None,
        help="keep COLMAP's database and model here, in a folder that holds none yet "
        "(default: a temporary directory)",
    )
    parser.add_argument("--verbose", action="store_true", help="show COLMAP's own log")


def _fmt(x, spec: str) -> str:
    return "-" if x is None else format(x, spec)


def _summary(label: str, r: dict) -> str:
    """The verdict and what it means on the first line, then the numbers and the reason."""
    secs = sum(r["seconds"].values())
    against = " (vs mean latent pose)" if r.get("pose_reference") == "mean_latent" else ""
    return (
        f"{label}: {r['verdict']} — {r.get('meaning', '')}\n"
        f"  {r['registered']}/{r['total']} registered, "
        f"median rotation error{against} {_fmt(r['median_rot_err_deg'], '.3f')} deg, "
        f"median centre error {_fmt(r['median_center_err_rel'], '.2%')}, "
        f"median reprojection {_fmt(r.get('median_reproj_px'), '.2f')} px "
        f"({secs:.1f} s)\n  {r['reason']}"
    )


def _change(level: str, x, ref, ratio: bool) -> str:
    """A blur level's value against the sharp level's: a percentage, or a factor."""
    if level == layout.SHARP or x is None or not ref:
        return ""
    return f" (×{x / ref:.1f})" if ratio else f" ({x / ref - 1:+.0%})"


TABLE_COLUMNS = [
    ("level", "<8"),
    ("registered", ">10"),
    ("SIFT/image", ">13"),
    ("COLMAP reproj px", ">16"),
    ("rot err deg", ">11"),
    ("written deg", ">11"),
    ("p→mean deg", ">10"),
    ("centre err", ">10"),
]


def _table(reports: dict[str, dict]) -> str:
    """What blur changes in SfM first (registered views, SIFT features per image, COLMAP's
    own reprojection error, each against sharp), then the pose errors: against the mean
    latent pose (which decides a blur level), against the written pose, and the offset
    from the one to the other."""
    head = " ".join(format(name, spec) for name, spec in TABLE_COLUMNS) + "  verdict"
    rows = [head, "-" * len(head)]
    sharp = reports.get(layout.SHARP, {})
    for level, r in reports.items():
        written = r.get("written_pose", {}).get("median_rot_err_deg", r["median_rot_err_deg"])
        feats, reproj = r["median_features"], r.get("colmap_mean_reproj_px")
        enough = r["registered"] >= MIN_REGISTERED_FRACTION * r["total"]
        cells = [
            level,
            f"{r['registered']}/{r['total']}",
            f"{feats}{_change(level, feats, sharp.get('median_features'), False)}",
            _fmt(reproj, ".2f")
            # A model of a few registered views has a small error of its own: no ratio.
            + (_change(level, reproj, sharp.get("colmap_mean_reproj_px"), True) if enough else ""),
            _fmt(r["median_rot_err_deg"], ".3f"),
            _fmt(written, ".3f"),
            _fmt(r.get("median_written_to_mean_deg"), ".3f"),
            _fmt(r["median_center_err_rel"], ".2%"),
        ]
        rows.append(
            " ".join(format(c, spec) for c, (_, spec) in zip(cells, TABLE_COLUMNS, strict=True))
            + f"  {r['verdict']}"
        )
    rows.append(
        "rot err: median against each blurry exposure's mean latent pose (the written pose "
        "for sharp); it decides the verdict. written: against the written pose p. "
        "p→mean: from p to the mean latent pose (half the blur under --trajectory start)."
    )
    return "\n".join(rows)


def is_report(doc: Any) -> bool:
    """A JSON report check-poses wrote: one scene's ({verdict, pass, …}) or one per
    level ({level: {verdict, pass, …}})."""

    def one(d: Any) -> bool:
        return isinstance(d, dict) and "verdict" in d and "pass" in d

    return one(doc) or (isinstance(doc, dict) and bool(doc) and all(one(v) for v in doc.values()))


def _write_json(path: Path, data) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    layout.write_json(path, data, indent=2)


def run(args: argparse.Namespace) -> int:
    global _VERBOSE
    _VERBOSE = bool(getattr(args, "verbose", False))
    path = Path(args.path)
    if not path.is_dir():
        raise InputError(f"not a directory: {path}")
    workdir = getattr(args, "workdir", None)
    if workdir:
        # COLMAP's database and model go into a folder of their own: never into the
        # scene or setting checked (its images_<f>/ …), nor into any blurset output.
        outputs.refuse_overlap(workdir, [path], "--workdir")
        outputs.refuse_inside_output(workdir, "--workdir", include_self=True)
        _refuse_used_workdir(workdir)
    if args.json:
        # Before COLMAP runs: a report never replaces a file it did not write, nor lands
        # in what it checks or in any blurset output.
        outputs.claim_report(args.json, is_report, "--json")
        outputs.refuse_overlap(args.json, [path], "--json")
        outputs.refuse_inside_output(args.json, "--json")
    if is_setting(path):
        if args.level != "all":
            _check_level_name(args.level)
        levels = layout.setting_levels(path) if args.level == "all" else [args.level]
        if workdir:
            # Every level's folder before the first COLMAP run: nothing half done.
            for level in levels:
                _refuse_used_workdir(workdir / level)
        reports = {}
        for level in levels:
            scene = path / level
            if not scene.is_dir():
                raise InputError(f"no level directory {level} in setting {path}")
            wd = workdir / level if workdir else None
            reports[level] = check_scene(scene, factor=args.factor, workdir=wd)
            print(_summary(level, reports[level]), flush=True)
        if args.level == "all":
            print(_table(reports))
            data = reports
            # Every level carries the same poses; blurred levels measure SfM, not the
            # poses, so the sharp level decides.
            decisive = reports.get("sharp") or next(iter(reports.values()))
        else:
            data = decisive = reports[args.level]
    else:
        if args.level not in ("sharp", "all"):
            raise ConfigError(f"--level {args.level}: {path} is an LLFF scene without levels")
        if workdir:
            _refuse_used_workdir(workdir)
        data = decisive = check_scene(path, factor=args.factor, workdir=workdir)
        print(_summary(path.name, decisive))
    if args.json:
        _write_json(args.json, data)
    return exit_code(decisive)
