"""`--for geonerf`: `OUT/geonerf/train/<scene>/` (a train setting's views) and
`OUT/geonerf/test/<scene>__v<view>/` (one sharp target and its 7 nearest degraded
sources), which GeoNeRF's LLFF dataset reads (docs/training/geonerf.md).

GeoNeRF (data/llff.py) holds out every 8th image of a scene (hard-coded) and draws a
target's sources from all the others: a test scene is its target and the 7 nearest
train views, so the target is its only held-out view and every source is degraded.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from blurset import _core, layout
from blurset.commands.export.rules import SceneFolders, SceneSource, StagedScene, Target
from blurset.exceptions import InputError

if TYPE_CHECKING:
    from blurset import _records

IMAGES = 8  # the images of a scene: GeoNeRF holds every 8th out
FACTOR = 4  # GeoNeRF's LLFF dataset reads images_4/
DIR = layout.images_dir(FACTOR)


def _split(s: SceneSource) -> list[tuple[str, list[int] | None]]:
    """A train setting's train views (its held-out views too unless they hold clean
    copies: sharp in a blur level, noise-free in a gain scene, sharp level's included), or
    per held-out view of a test setting, that view and its 7 nearest train views by
    camera centre (GeoNeRF's own `dist`). A held-out view that holds a clean copy is
    never a source: GeoNeRF trains on every view of a train scene."""
    rows = np.asarray(_core.read_poses_bounds(s.src / layout.POSES_BOUNDS), dtype=np.float64)
    n = len(rows)
    train = [v for v in range(n) if v not in s.held_out]
    if not s.is_test:
        return [(f"train/{s.scene}", train if s.clean_held else list(range(n)))]
    centres = rows[:, [3, 8, 13]]
    out: list[tuple[str, list[int] | None]] = []
    for v in s.held_out:
        d = np.linalg.norm(centres[train] - centres[v], axis=1)
        near = [train[i] for i in np.argsort(d, kind="stable")[: IMAGES - 1]]
        if len(near) < IMAGES - 1:
            raise InputError(
                f"--for geonerf: {s.scene} has {len(train)} train views, a test scene needs "
                f"{IMAGES - 1}: {s.src}"
            )
        out.append((f"test/{s.scene}__v{v:03d}", [v, *near]))
    return out


def _write(s: StagedScene) -> None:
    """The scene's views' images_4/ files (renamed 000.png … in its order) and their
    poses_bounds.npy rows; a test scene's target image is the sharp level's."""
    views = s.doc.get("views")
    assert views is not None  # a GeoNeRF export's plan lists every scene's views
    vs = views[s.name]
    rows = np.asarray(_core.read_poses_bounds(s.src / layout.POSES_BOUNDS), dtype=np.float64)
    images = sorted(p for p in (s.src / DIR).iterdir() if p.suffix == ".png")
    if len(images) != len(rows):
        raise InputError(f"{len(images)} images for {len(rows)} pose rows: {s.src / DIR}")
    setting = s.doc["scenes"][s.name].split("/", 1)[0]
    sharp = s.build / setting / layout.SHARP / DIR
    (s.path / DIR).mkdir(parents=True)
    for k, v in enumerate(vs):
        test_target = k == 0 and s.name.startswith("test/")
        image = sharp / layout.image_name(v, len(rows)) if test_target else images[v]
        s.put(image, f"{DIR}/{k:03d}.png")
    _core.write_poses_bounds(s.path / layout.POSES_BOUNDS, rows[vs])


def _hint(doc: _records.ExportDoc, root: Path) -> str:
    return (
        f"GeoNeRF: --llff_path {root / 'train'} --llff_test_path {root / 'test'}, "
        "--nb_views 6 at most"
    )


TARGET = Target(
    name="geonerf",
    help="OUT/geonerf/train/<scene>/ (train views only) and OUT/geonerf/test/<scene>__v<view>/ "
    "(one sharp target, 7 nearest degraded sources)",
    docs="training/geonerf.md",
    output=SceneFolders(
        folder="geonerf",
        write=_write,
        hint=_hint,
        split=_split,
        # Its LLFF reader has no depth input; it reads one image per view, at FACTOR.
        passes=False,
        one_frame=True,
        factor=FACTOR,
        reader="GeoNeRF",
    ),
)
