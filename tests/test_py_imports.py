"""The Python package's modules import one another without a circle, counting the
imports inside functions too: moving an import into a function hides a circle from
Python at import time, not from a reader (issue 36). Read from the sources' ASTs."""

from __future__ import annotations

import ast
from pathlib import Path

from tests.test_layers import circles

PKG = Path(__file__).resolve().parents[1] / "python" / "blurset"


def _modules() -> dict[str, Path]:
    out = {}
    for p in PKG.rglob("*.py"):
        parts = p.relative_to(PKG.parent).with_suffix("").parts
        out[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = p
    return out


def _edges() -> dict[str, set[str]]:
    """Module -> the package modules it imports anywhere in its file."""
    mods = _modules()
    edges: dict[str, set[str]] = {m: set() for m in mods}
    for m, p in mods.items():
        for node in ast.walk(ast.parse(p.read_text())):
            targets: list[str] = []
            if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                # `from blurset import layout` imports the module blurset.layout;
                # `from blurset.layout import X` the module blurset.layout.
                targets = [
                    f"{node.module}.{a.name}" if f"{node.module}.{a.name}" in mods else node.module
                    for a in node.names
                ]
            elif isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            edges[m] |= {t for t in targets if t in mods and t != m}
    return edges


def test_no_circles_between_modules() -> None:
    assert not circles(_edges()), circles(_edges())


def test_the_check_sees_the_imports() -> None:
    """The reader finds top-level and function-level imports (a circle would not hide
    behind it)."""
    edges = _edges()
    assert "blurset.layout" in edges["blurset.services.outputs"]  # top level
    assert (
        "blurset.services.denoise" in edges["blurset.commands.builder.setting"]
    )  # inside a function
    assert "blurset.exceptions" in edges["blurset.layout"]
