"""The length limit of `make lint` (scripts/check_lengths.py, the Python half; clippy's
too_many_lines the Rust half): a function over 60 code lines fails it, and blank lines,
comments and the docstring do not count."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _checker():
    spec = importlib.util.spec_from_file_location(
        "check_lengths", ROOT / "scripts/check_lengths.py"
    )
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    sys.modules["check_lengths"] = mod
    spec.loader.exec_module(mod)
    return mod


def _function(code_lines: int) -> str:
    """A function of `code_lines` code lines, padded with what must not count."""
    body = [f"    x{i} = {i}" for i in range(code_lines - 2)]
    padded = []
    for line in body:
        padded += [line, "", "    # a comment"]
    return "\n".join(['def f():', '    """A docstring', "", '    of three lines."""', *padded,
                      "    return x0", ""])  # fmt: skip


def test_a_function_over_the_limit_fails_the_lint(tmp_path: Path) -> None:
    check = _checker()
    at, over = tmp_path / "at.py", tmp_path / "over.py"
    at.write_text(_function(check.LIMIT))
    over.write_text(_function(check.LIMIT + 1))
    assert list(check.long_functions(at)) == []
    assert list(check.long_functions(over)) == [(1, "f", check.LIMIT + 1)]
    assert check.main([str(at)]) == 0
    assert check.main([str(tmp_path)]) == 1


def test_the_product_code_holds_the_limit(capsys) -> None:
    assert _checker().main([]) == 0, capsys.readouterr().out
