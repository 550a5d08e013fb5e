"""Rendering each image of a setting to a render-noise target (`--target-psnr`, DESIGN §8).

The loop is the core's (`dataset/target_loop.rs`, `_core.TargetImages`): it holds both
halves of every image in flight, estimates their noise after each round, decides the
next one and merges an image that is done; no image leaves it between rounds. This
module only says "render these": it takes the renders of each round, has the worker
render them, hands the EXRs back, and passes each finished image on.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

from blurset import _core
from blurset.services.config import BuildConfig

if TYPE_CHECKING:
    from blurset._records import ImageRender
    from blurset.commands.builder.ports import RenderWorker
    from blurset.services.worker_client import RenderOptions

# An image of a setting: (view, level directory).
Key = tuple[int, str]


def render_to_target(
    plan: _core.Plan,
    cfg: BuildConfig,
    worker: RenderWorker,
    exr_dir: Path,
    sharp_views: list[int],
    keys: list[Key],
    finish: Callable[[Key, _core.Accumulator], None],
    on_render: Callable[[], None],
    common: RenderOptions,
) -> tuple[dict[Key, ImageRender], int]:
    """Render the images `keys` to the config's target; `finish(key, image)` gets each
    finished image (its halves merged) as soon as it is done. Returns each image's
    record and the renders made."""
    images = _core.TargetImages(plan, cfg, keys, exr_dir=exr_dir, sharp_views=sharp_views)

    def on_frame(i: int, path: str, origin: tuple[int, int] | None) -> None:
        images.add_exr(i, path, origin)
        on_render()

    n_renders = 0
    while True:
        renders = images.next_renders()
        for view, level, image in images.take_finished():
            finish((view, level), image)
        if not renders:
            break
        worker.render(renders, on_frame=on_frame, **common)
        n_renders += len(renders)
    return {(view, level): r for view, level, r in images.records()}, n_renders
