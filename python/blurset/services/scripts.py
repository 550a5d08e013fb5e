"""Where the bpy-side scripts (blender_scripts/) are: beside the package in an installed
wheel (maturin's `include` puts them at the wheel's top level), or at the top of the
source tree for an editable install."""

from __future__ import annotations

from pathlib import Path

_PACKAGE = Path(__file__).resolve().parents[1]  # python/blurset, or the wheel's blurset/
_CANDIDATES = (_PACKAGE.parent / "blender_scripts", _PACKAGE.parents[1] / "blender_scripts")


def blender_script(name: str) -> Path:
    """The path of blender_scripts/<name>; the source tree's when neither exists, so the
    caller's error names the place a checkout would have it."""
    for d in _CANDIDATES:
        if (d / name).is_file():
            return d / name
    return _CANDIDATES[-1] / name
