"""Depth and normals of every view (`--passes`, issue 35): one geometry render per view
and image size, at the sharp image's pose and seed, written beside the sharp images.

Masks need no render: they come from the sharp image's coverage (builder/setting.py).
"""

from __future__ import annotations

import os
import time
from pathlib import Path
from typing import TYPE_CHECKING

from blurset import _core, layout
from blurset.services.config import BuildConfig

if TYPE_CHECKING:
    from blurset._records import Render
    from blurset.commands.builder.ports import RenderWorker

# The passes a geometry render gives (the mask comes from the sharp image).
RENDERED = ("depth", "normal")


def render_geometry(
    cfg: BuildConfig,
    worker: RenderWorker,
    frames: list[Render],
    exr_dir: Path,
    sharp: Path,
    n_views: int,
) -> float:
    """The depth and/or normal files of every view at every size the build writes
    (`images/` and each `images_<f>/`): the seconds it took (0 when none is asked for).
    `frames` are the setting's renders: a view's first sharp frame gives its pose and
    seed, so the same command writes the same bytes."""
    wanted = [p for p in cfg.passes if p in RENDERED]
    if not wanted:
        return 0.0
    t0 = time.time()
    poses: dict[int, Render] = {}
    for f in frames:
        if f["level"] == layout.SHARP:
            poses.setdefault(int(f["view"]), f)
    views = sorted(poses)
    for factor in [1, *cfg.downsample]:
        for p in wanted:
            (sharp / layout.pass_dir(p, factor)).mkdir(parents=True, exist_ok=True)
        batch = [
            {
                "c2w": poses[v]["c2w"],
                "seed": poses[v]["seed"],
                "out": str(exr_dir / f"geometry_{factor}_{v}.exr"),
                "view": v,
                "level": "geometry",
            }
            for v in views
        ]

        def write(
            j: int,
            path: str,
            _origin: tuple[int, int] | None,
            factor: int = factor,
            views: list[int] = views,
        ) -> None:
            name = layout.image_name(views[j], n_views)
            out = {
                p: sharp / layout.pass_dir(p, factor) / layout.pass_file(p, name) for p in wanted
            }
            _core.write_geometry(Path(path), depth=out.get("depth"), normal=out.get("normal"))
            os.unlink(path)

        worker.render(
            batch,
            resolution=cfg.resolution // factor,
            fov_deg=cfg.fov_deg,
            samples=1,
            geometry=True,
            on_frame=write,
        )
    return time.time() - t0
