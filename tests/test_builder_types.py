"""The builder's functions are typed (issue 49): no parameter of python/blurset/commands/builder/
takes `Any`, and the worker it drives is the RenderWorker port, not a concrete class."""

from __future__ import annotations

import ast
from pathlib import Path

BUILDER = Path(__file__).resolve().parents[1] / "python" / "blurset" / "commands" / "builder"


def _any_parameters(source: str, name: str) -> list[str]:
    """'file:function(param)' for every parameter annotated with Any anywhere in it."""
    out = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef | ast.Lambda):
            a = node.args
            for arg in [*a.posonlyargs, *a.args, *a.kwonlyargs, a.vararg, a.kwarg]:
                ann = getattr(arg, "annotation", None) if arg is not None else None
                if ann is not None and any(
                    isinstance(n, ast.Name) and n.id == "Any" for n in ast.walk(ann)
                ):
                    fn = getattr(node, "name", "<lambda>")
                    out.append(f"{name}:{fn}({arg.arg})")
    return out


def test_no_builder_parameter_is_any() -> None:
    # The folder is there and holds the builder (a moved folder must not pass unseen).
    assert (BUILDER / "setting.py").is_file() and len(list(BUILDER.glob("*.py"))) >= 8
    found = [
        p for f in sorted(BUILDER.glob("*.py")) for p in _any_parameters(f.read_text(), f.name)
    ]
    assert found == [], found


def test_the_check_finds_an_any_parameter() -> None:
    planted = "def f(worker: Any, frames: list[Any], *, on: dict[str, int]) -> None: ..."
    assert _any_parameters(planted, "x.py") == ["x.py:f(worker)", "x.py:f(frames)"]


def test_the_builder_drives_the_port() -> None:
    for f in BUILDER.glob("*.py"):
        for line in f.read_text().splitlines():
            assert not line.strip().startswith("worker: Worker"), (f.name, line)
