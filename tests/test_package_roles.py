"""python/blurset is grouped by role (issue 49): the public faces at the package's top
(what users, scripts and benches import: `blurset.data`, `blurset.plan`, `blurset.image`,
`blurset.llff`, `blurset.layout`, `blurset.noise.model`, and `cli`, the command line),
`commands/` (one module or package per subcommand) and `services/` (what commands share).
A command may import anything; a face or a service never imports a command, so a
command can be moved, split or dropped without touching what the others are. Read from
the sources (every import, a function's too), no Blender, no build."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PKG = Path(__file__).resolve().parents[1] / "python" / "blurset"
ROLES = ("commands", "services")
# The faces at the package's top; a new top-level module is a decision, made here.
FACES = {"__init__", "cli", "data", "exceptions", "image", "layout", "llff", "plan", "noise"}


def role(module: str) -> str:
    """'commands', 'services' or 'faces' of a dotted name under blurset."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 and parts[1] in ROLES else "faces"


def module_of(path: Path) -> str:
    rel = path.relative_to(PKG.parent).with_suffix("")
    parts = list(rel.parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def imports(path: Path) -> list[tuple[int, str]]:
    """(line, dotted module) of every import of a blurset module in one file; `from x
    import y` counts as x.y where y may be a module."""
    tree = ast.parse(path.read_text(), str(path))
    pkg = module_of(path) if path.name == "__init__.py" else module_of(path).rpartition(".")[0]
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out += [(node.lineno, a.name) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                up = pkg.split(".")
                base = ".".join(up[: len(up) - node.level + 1] + ([base] if base else []))
            out += [(node.lineno, f"{base}.{a.name}") for a in node.names]
    return [(n, m) for n, m in out if m.startswith("blurset.")]


def sources() -> list[Path]:
    return sorted(p for p in PKG.rglob("*.py") if "__pycache__" not in p.parts)


def test_every_top_level_module_is_a_face_or_a_role_folder():
    top = {p.stem if p.is_file() else p.name for p in PKG.iterdir()}
    top = {n for n in top if not n.startswith(("_core", "_records", "py", "__pycache__"))}
    assert top - FACES - set(ROLES) == set(), "new top-level module: a face? (FACES)"


@pytest.mark.parametrize("path", sources(), ids=lambda p: str(p.relative_to(PKG)))
def test_faces_and_services_import_no_command(path: Path):
    own = role(module_of(path))
    if own == "commands":
        return
    bad = [f"line {n}: {m}" for n, m in imports(path) if role(m) == "commands"]
    assert not bad, f"{own[:-1] if own != 'faces' else 'a face'} imports a command: {bad}"


def test_the_check_reads_imports():
    # The rule is only as good as the import reading: it sees a function's import,
    # `from blurset.commands import x` and a relative one.
    src = PKG / "services" / "stop.py"
    found = imports(src)
    assert all(m.startswith("blurset.") for _, m in found)
    probe = ast.parse("def f():\n    from blurset.commands import stats\n")
    node = probe.body[0].body[0]  # type: ignore[attr-defined]
    assert isinstance(node, ast.ImportFrom) and role(f"{node.module}.stats") == "commands"
    assert role("blurset.services.outputs") == "services" and role("blurset.data") == "faces"
