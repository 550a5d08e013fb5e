"""`--for nerfstudio`: `OUT/<scene>/` with transforms.json, which nerfstudio takes as
`--data` (docs/training/nerfstudio.md); it reads the split from each transforms.json.

With depth or masks among the passes a scene gets a transforms.json of its own, whose
frames name them: depth as 16-bit millimetre PNGs in depths/ (nerfstudio's default
unit, `depth_file_path`) and the masks (`mask_path`), which its parser looks up in
depths_<f>/ and masks_<f>/ when it downscales.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from blurset import _core, layout
from blurset.commands.export.rules import SceneFolders, StagedScene, Target
from blurset.commands.export.scene import level_of, write_files, write_passes

if TYPE_CHECKING:
    from blurset import _records


def _write(s: StagedScene) -> None:
    passes = set(s.doc.get("passes") or [])
    own = bool({"depth", "mask"} & passes)
    write_files(s, transforms=not own)
    write_passes(s)
    if own:
        _write_transforms(s, passes)


def _write_transforms(s: StagedScene, passes: set[str]) -> None:
    """The level's transforms.json with each frame's depth and mask, and the depth PNGs
    it names, made from the build's depth EXRs."""
    setting, level = level_of(s)
    own = layout.level_masks(layout.read_json(setting / layout.META, layout.META))
    tf = layout.read_json(s.src / layout.TRANSFORMS, layout.TRANSFORMS)
    for frame in tf["frames"]:
        name = Path(frame["file_path"]).name
        if "depth" in passes:
            frame["depth_file_path"] = f"{layout.nerfstudio_depth_dir(1)}/{name}"
        if "mask" in passes:
            frame["mask_path"] = f"{layout.pass_dir('mask', 1)}/{name}"
    if "depth" in passes:
        depths = setting / layout.pass_level("depth", level, own)
        for f in [1, *s.doc["factors"]]:
            sub = layout.nerfstudio_depth_dir(f)
            (s.path / sub).mkdir()
            for frame in tf["frames"]:
                name = Path(frame["file_path"]).name
                exr = depths / layout.pass_dir("depth", f) / layout.pass_file("depth", name)
                _core.write_depth_millimetres(exr, s.path / sub / name)
    layout.write_json(s.path / layout.TRANSFORMS, tf)


def _hint(doc: _records.ExportDoc, root: Path) -> str:
    # Its default center_method `poses` throws a ±7.5° setting out of its box (DESIGN §12).
    return (
        f"splits in each transforms.json: ns-train nerfacto --data {root}/<scene> "
        "nerfstudio-data --center-method focus"
    )


TARGET = Target(
    name="nerfstudio",
    help="OUT/<scene>/ with transforms.json",
    docs="training/nerfstudio.md",
    output=SceneFolders(folder=".", write=_write, hint=_hint),
)
