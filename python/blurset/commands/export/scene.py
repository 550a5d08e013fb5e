"""The files of an exported LLFF scene folder, which the `llff` and `nerfstudio` targets
(blurset.commands.export.targets) both write: the level's images at every size, its poses and its
transforms.json, and beside them the build's `--passes` (DESIGN §12).
"""

from __future__ import annotations

from pathlib import Path

from blurset import layout
from blurset.commands.export.rules import StagedScene
from blurset.exceptions import InputError


def level_of(s: StagedScene) -> tuple[Path, str]:
    """The build's setting folder the scene is made from, and its level."""
    setting, level = s.doc["scenes"][s.name].split("/")[:2]
    return s.build / setting, level


def write_files(s: StagedScene, transforms: bool, optional: tuple[str, ...] = ()) -> None:
    """The scene folder: `images/`, each `images_<f>/`, `poses_bounds.npy` and (with
    `transforms`) the level's `transforms.json`, all from the level; a part named in
    `optional` that the level lacks is left out, any other is refused."""
    s.path.mkdir(parents=True)
    parts = [layout.IMAGES, *(layout.images_dir(f) for f in s.doc["factors"])]
    parts += [layout.POSES_BOUNDS] + ([layout.TRANSFORMS] if transforms else [])
    for part in parts:
        src = s.src / part
        if not src.exists():
            if part in optional:
                continue
            raise InputError(f"missing {part} in the scene to export: {s.src}")
        s.put(src, part)


def write_passes(s: StagedScene) -> None:
    """The build's `--passes` beside the scene's images: the folders (depth/, normals/,
    masks/ and their _<f> sizes; LLFF loaders ignore them) of the sharp level, but a blur
    level's own masks (`layout.pass_level`)."""
    setting, level = level_of(s)
    own = layout.level_masks(layout.read_json(setting / layout.META, layout.META))
    for kind in s.doc.get("passes") or []:
        for f in [1, *s.doc["factors"]]:
            sub, holder = layout.pass_dir(kind, f), setting / layout.pass_level(kind, level, own)
            if not (holder / sub).is_dir():
                raise InputError(f"missing {sub} in the build's {holder.name} level: {holder}")
            s.put(holder / sub, sub)
