"""`--for llff` (the default): `OUT/nerf_llff_data/<scene>/`, the folder IBRNet's, NAN's,
GNT's and Deblur-NeRF's LLFF loaders read (docs/training/index.md).

IBRNet's `<rootdir>/data/nerf_llff_data/<scene>` and NAN's
`DATA_DIR/nerf_llff_data/<scene>` list every entry of that folder as a scene, so nothing
else may lie there; each loader holds views out itself (`llffhold`).
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from blurset import layout
from blurset.commands.export.rules import SceneFolders, StagedScene, Target
from blurset.commands.export.scene import write_files, write_passes

if TYPE_CHECKING:
    from blurset import _records


def _write(s: StagedScene) -> None:
    # A build from before per-level transforms.json has none: LLFF loaders do not read it.
    write_files(s, transforms=True, optional=(layout.TRANSFORMS,))
    write_passes(s)


def _hint(doc: _records.ExportDoc, root: Path) -> str:
    lists = root.parent
    return (
        f"use llffhold {doc['llffhold']}: train.py --rootdir {lists.parent} --llffhold "
        f"{doc['llffhold']} --train_dataset llff_test --train_scenes $(cat {lists}/train.txt) "
        f"--eval_dataset llff_test --eval_scenes $(cat {lists}/test.txt)"
    )


TARGET = Target(
    name="llff",
    help="OUT/nerf_llff_data/<scene>/ (IBRNet, NAN, GNT)",
    docs="training/index.md",
    output=SceneFolders(folder="nerf_llff_data", write=_write, hint=_hint),
)
