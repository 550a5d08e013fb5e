"""LLFF pose files (`poses_bounds.npy`, N × 17 float64) through blurset-core: read with
a PoseFormatError naming the file and reason, written atomically (non-finite refused)."""

from __future__ import annotations

from blurset._core import read_poses_bounds, write_poses_bounds

__all__ = ["read_poses_bounds", "write_poses_bounds"]
