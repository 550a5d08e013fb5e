"""The robust similarity alignment of our poses to COLMAP's, and the per-view errors."""

from __future__ import annotations

import numpy as np

from blurset.commands.check_poses.thresholds import (
    CENTER_THRESHOLD_REL,
    MIN_REGISTERED_VIEWS,
    ROT_THRESHOLD_DEG,
)


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
