"""Fail when a Python function is longer than the project's limit in code lines.

Ruff has no rule for a function's length (clippy's `too_many_lines` holds the Rust side
at the same limit, clippy.toml): this is the Python half of `make lint`. A code line is
a line of the function that is neither blank, nor only a comment, nor part of its
docstring, counted as clippy counts them (nested functions are part of their parent).

    python scripts/check_lengths.py [PATH ...]   (default: the product code)
"""

from __future__ import annotations

import ast
import sys
from collections.abc import Iterator
from pathlib import Path

LIMIT = 60
ROOT = Path(__file__).resolve().parents[1]
# The code a user runs. Tests, benchmarks and these scripts are left out for now: they
# hold long scenario functions (see the closing notes of issue 59).
DEFAULT = ("python/blurset", "blender_scripts")


def _docstring_lines(node: ast.AST) -> set[int]:
    body = getattr(node, "body", None)
    if not body or ast.get_docstring(node, clean=False) is None:  # type: ignore[arg-type]
        return set()
    doc = body[0]
    return set(range(doc.lineno, (doc.end_lineno or doc.lineno) + 1))


def code_lines(lines: list[str], node: ast.FunctionDef | ast.AsyncFunctionDef) -> int:
    """Code lines of `node`: from its `def` (decorators left out) to its last line."""
    skip = _docstring_lines(node)
    n = 0
    for i in range(node.lineno, (node.end_lineno or node.lineno) + 1):
        text = lines[i - 1].strip()
        if i in skip or not text or text.startswith("#"):
            continue
        n += 1
    return n


def long_functions(path: Path, limit: int = LIMIT) -> Iterator[tuple[int, str, int]]:
    """(line, name, code lines) of each function of `path` over `limit`."""
    text = path.read_text(encoding="utf-8")
    lines = text.splitlines()
    for node in ast.walk(ast.parse(text, filename=str(path))):
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
            n = code_lines(lines, node)
            if n > limit:
                yield node.lineno, node.name, n


def main(argv: list[str]) -> int:
    roots = [Path(a) for a in argv] or [ROOT / d for d in DEFAULT]
    files = sorted(f for r in roots for f in ([r] if r.is_file() else r.rglob("*.py")))
    found = 0
    for f in files:
        for line, name, n in long_functions(f):
            shown = f.relative_to(ROOT) if f.is_relative_to(ROOT) else f
            print(f"{shown}:{line}: {name} has {n} code lines (at most {LIMIT})")
            found += 1
    return 1 if found else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
