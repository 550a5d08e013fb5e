"""What one COLMAP reconstruction says: registered views, camera poses, depths, and its feature tracks re-triangulated under other poses."""

from __future__ import annotations

from typing import Any

import numpy as np

from blurset.commands.check_poses.thresholds import (
    MIN_REGISTERED_VIEWS,
    OUTLIER_PX,
    STREAK_FORGIVEN,
)


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
