"""blurset-core is layered: ground utilities (error, rng, ground/: atomic writes, names,
licence ids) under plan, plan under image, image under noise and metrics, and all of
them under dataset; no module imports one above it, and no two files import each other
(directly or round a circle). Read from the sources' `crate::`/`super::` paths."""

from __future__ import annotations

import re
from pathlib import Path

SRC = Path(__file__).resolve().parents[1] / "rust" / "core" / "src"

# Top-level module -> layer; a module may use its own layer and those below.
LAYERS = {
    "error": 0,
    "rng": 0,
    "ground": 0,
    "plan": 1,
    "image": 2,
    "noise": 3,
    "metrics": 3,
    "dataset": 4,
}

PATH = re.compile(r"\b(crate|super)::((?:\{[^}]*\})|[A-Za-z_][\w:]*)")


def _module_of(file: Path) -> tuple[str, ...]:
    parts = file.relative_to(SRC).with_suffix("").parts
    return parts[:-1] if parts[-1] == "mod" else parts


def _code(file: Path) -> str:
    """The file without comments and without its `#[cfg(test)] mod tests` block."""
    text = re.sub(r"//[^\n]*", "", file.read_text())
    m = re.search(r"#\[cfg\(test\)\]\s*mod tests\b", text)
    return text[: m.start()] if m else text


def _files() -> dict[tuple[str, ...], Path]:
    return {_module_of(f): f for f in sorted(SRC.rglob("*.rs")) if f.name != "lib.rs"}


def _edges() -> dict[tuple[str, ...], set[tuple[str, ...]]]:
    files = _files()
    out: dict[tuple[str, ...], set[tuple[str, ...]]] = {m: set() for m in files}
    for mod, f in files.items():
        parent = mod[:-1]
        for root, rest in PATH.findall(_code(f)):
            heads = [h.strip() for h in rest[1:-1].split(",")] if rest.startswith("{") else [rest]
            for head in heads:
                names = [n for n in head.split("::") if n and n != "self" and n != "*"]
                base = () if root == "crate" else parent
                target = base
                for n in names:  # the longest prefix that is a file module
                    if (*target, n) in files:
                        target = (*target, n)
                    else:
                        break
                if target and target != mod and target in files:
                    out[mod].add(target)
    return out


def test_no_module_imports_a_layer_above_it() -> None:
    bad = []
    for mod, deps in _edges().items():
        for d in deps:
            if LAYERS[d[0]] > LAYERS[mod[0]]:
                bad.append(f"{'/'.join(mod)} uses {'::'.join(d)}")
    assert not bad, bad


def circles(graph: dict[str, set[str]]) -> list[str]:
    """Every circle a depth-first walk of `graph` (node -> the nodes it uses) meets, as
    "a -> b -> a" (the one walk for the core, the bindings and the Python package)."""
    found: list[str] = []
    state: dict[str, int] = {}

    def visit(n: str, stack: list[str]) -> None:
        state[n] = 1
        stack.append(n)
        for d in sorted(graph.get(n, ())):
            if state.get(d) == 1:
                found.append(" -> ".join([*stack[stack.index(d) :], d]))
            elif d not in state:
                visit(d, stack)
        stack.pop()
        state[n] = 2

    for n in sorted(graph):
        if n not in state:
            visit(n, [])
    return found


def test_no_circles_between_files() -> None:
    edges = _edges()
    # A module's own mod.rs (its parent) holds shared items, not a dependency circle.
    graph = {"/".join(m): {"/".join(d) for d in ds if d != m[: len(d)]} for m, ds in edges.items()}
    assert not circles(graph), circles(graph)


def test_the_check_sees_the_imports() -> None:
    """The parser finds what it must (a circle or a climb would not hide behind it)."""
    edges = _edges()
    assert ("ground", "atomic") in edges[("dataset", "layout")]
    assert ("plan", "spec") in edges[("plan", "config")]
    assert ("plan", "sampling_config") in edges[("plan", "config")]
    assert ("plan", "camera") in edges[("image", "qa")]
    assert ("plan", "sampling_config") in edges[("plan", "degradation")]
    assert set(LAYERS) == {p.name if p.is_dir() else p.stem for p in SRC.iterdir()} - {"lib"}


PY_SRC = SRC.parents[1] / "py" / "src"


def test_no_circles_between_binding_files() -> None:
    """The bindings (rust/py/src) too: a file uses another's items (`crate::<file>::`),
    never round a circle (config.rs and sampling.rs once used each other's)."""
    files = {p.stem for p in PY_SRC.glob("*.rs")} - {"lib"}
    graph = {
        f: set(re.findall(r"\bcrate::(\w+)", (PY_SRC / f"{f}.rs").read_text())) & files - {f}
        for f in files
    }
    assert "config" in graph["sampling"]  # the reader sees the uses
    assert not circles(graph), circles(graph)
