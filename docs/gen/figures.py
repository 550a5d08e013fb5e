"""Benchmark figures quoted in README.md and docs/guide/*.md come from bench/results.json.

A measured figure in those pages is written as a marker around its value:

    <!-- fig NAME FIELD FORMAT -->59.9<!-- /fig -->

NAME is a result of bench/results.json, FIELD one of its fields (a dotted path into
nested records, `per_object.sketchfab_MapPin.render_psnr_blur_db`, or an arithmetic
expression of fields without spaces, `cycles_denoise_s-plain_s`), FORMAT a Python format
spec (`.1f`, `.0%`, `,.0f`). `make docs` (docs/gen/bench.py) rewrites every marker's value
from the results; tests/test_docs.py fails when a marker's value differs from what the
results give, and when a benchmark-looking number (a figure in dB, a ratio ×, a share
in %, a time in s, settings per hour) stands outside a marker and outside ALLOWED, the
short list of numbers that are definitions rather than measurements.
"""

from __future__ import annotations

import ast
import json
import operator
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
RESULTS = ROOT / "bench" / "results.json"

MARKER = re.compile(
    r"<!-- fig (?P<name>\S+) (?P<field>\S+) (?P<fmt>\S+) -->(?P<value>.*?)<!-- /fig -->", re.S
)
# A number (or a range of numbers) followed by a unit a benchmark reports. A × between
# two numbers is a size or a product (96 × 96 px, 34 × 32 samples), not a ratio.
NUMBER = r"\d[\d,]*(?:\.\d+)?"
FIGURE = re.compile(
    rf"(?<![\w.·/^]){NUMBER}(?:\s*(?:–|-|to)\s*{NUMBER})?\s*"
    r"(?:dB\b|×(?!\s*\d)|x\b(?!\s*\d)|%|ms\b|s\b(?! per pixel)|min\b|minutes\b|seconds\b|"
    r"hours?\b|settings per hour|settings/h)"
)

# Numbers that are definitions, not measurements: each entry a pattern and why it is
# not a figure of a benchmark. An entry that matches nothing fails the test (stale).
ALLOWED: list[tuple[str, str]] = [
    (r"58\.92? dB", "the 8-bit floor: 1/(255²·12) in MSE, a definition"),
    (r"(?<![.\d])(?:40|50) dB", "the targets of fast and balanced, set and not measured"),
    (r"10·log10\(1/coverage\) dB", "the coverage correction, a formula"),
    (r"\b3 dB at half coverage", "10·log10(2), arithmetic"),
    (r"within 0\.5 dB of\s+the target", "the bar an image is judged by"),
    (r"within 1 dB\b", "the bar an estimate is judged by"),
    (r"\(600 s\)", "the default of --timeout"),
    (r"1\.05 × the\s+bounding sphere", "a guard constant of the trajectory"),
    (r"< 0\.2 % of the pixels|> 2 % of the frame border", "preview's thresholds"),
    (r"at least 90 % of the cases", "check-poses' sensitivity threshold"),
    (r"A 4× downsample|about\s+4×", "a 4× area average cuts σ 4×: arithmetic"),
    (r"within 10 % of", "a tested bound of the denoiser"),
    (r"459 s in\s+tools/DEVICE\.md", "the kernel compile on an H200, measured by tools/DEVICE.md"),
    (
        r"\| (?:18\.75|37\.5|75|150) \| (?:0\.375|0\.75|1\.5|3) s \|",
        "shake levels as exposures: the reciprocal rule's arithmetic (shake.rs), not a timing",
    ),
]


# ------------------------------------------------------------------------------ values

_OPS = {
    ast.Add: operator.add,
    ast.Sub: operator.sub,
    ast.Mult: operator.mul,
    ast.Div: operator.truediv,
}


def _field(entry: dict, node: ast.AST) -> object:
    if isinstance(node, ast.Name):
        return entry[node.id]
    if isinstance(node, ast.Attribute):
        return _field(entry, node.value)[node.attr]  # type: ignore[index]
    if isinstance(node, ast.Subscript):  # a list field's item: range[0]
        return _field(entry, node.value)[_field(entry, node.slice)]  # type: ignore[index]
    if isinstance(node, ast.Constant) and isinstance(node.value, (int, float)):
        return node.value
    if isinstance(node, ast.BinOp) and type(node.op) in _OPS:
        return _OPS[type(node.op)](_field(entry, node.left), _field(entry, node.right))
    if isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.USub):
        return -_field(entry, node.operand)  # type: ignore[operator]
    raise ValueError(f"not a field or arithmetic of fields: {ast.unparse(node)}")


def value(results: dict[str, dict], name: str, field: str, fmt: str) -> str:
    """What the marker `name field fmt` shows; ValueError names what is missing."""
    if name not in results:
        raise ValueError(f"no result {name!r} in bench/results.json")
    try:
        v = _field(results[name], ast.parse(field, mode="eval").body)
    except (KeyError, TypeError, SyntaxError) as e:
        raise ValueError(f"{name} has no field {field!r} ({e})") from None
    if not isinstance(v, (int, float)) or isinstance(v, bool):
        raise ValueError(f"{name}.{field} is {v!r}, not a number")
    return format(v, fmt)


def load(path: Path = RESULTS) -> dict[str, dict]:
    return {r["name"]: r for r in json.loads(path.read_text())}


def pages() -> list[Path]:
    """The pages whose figures are checked: the README and the guides."""
    return [ROOT / "README.md", *sorted((ROOT / "docs" / "guide").glob("*.md"))]


# --------------------------------------------------------------------- rewrite, check


def rewrite(text: str, results: dict[str, dict]) -> tuple[str, list[str]]:
    """The text with every marker's value from the results, and the markers that could
    not be filled (kept as they were)."""
    problems: list[str] = []

    def fill(m: re.Match) -> str:
        try:
            v = value(results, m["name"], m["field"], m["fmt"])
        except ValueError as e:
            problems.append(f"line {_line(text, m.start())}: {e}")
            return m.group(0)
        return f"<!-- fig {m['name']} {m['field']} {m['fmt']} -->{v}<!-- /fig -->"

    return MARKER.sub(fill, text), problems


def _line(text: str, pos: int) -> int:
    return text.count("\n", 0, pos) + 1


def stale(text: str, results: dict[str, dict]) -> list[str]:
    """Markers whose value is not what the results give (or that name nothing)."""
    out = []
    for m in MARKER.finditer(text):
        try:
            v = value(results, m["name"], m["field"], m["fmt"])
        except ValueError as e:
            out.append(f"line {_line(text, m.start())}: {e}")
            continue
        if m["value"] != v:
            out.append(
                f"line {_line(text, m.start())}: {m['name']} {m['field']} is {v}, "
                f"the page says {m['value']!r} (run `make docs`)"
            )
    return out


def _blank(m: re.Match) -> str:
    """A span replaced by as many spaces (newlines kept), so positions and lines hold."""
    return re.sub(r"[^\n]", " ", m.group(0))


def prose(text: str) -> str:
    """The text a reader takes as prose: markers, code blocks, inline code and HTML
    comments blanked out."""
    text = MARKER.sub(_blank, text)
    text = re.sub(r"^(```|~~~).*?^\1", _blank, text, flags=re.S | re.M)
    text = re.sub(r"`[^`\n]*`", _blank, text)
    return re.sub(r"<!--.*?-->", _blank, text, flags=re.S)


def strays(text: str, allowed: list[tuple[str, str]] | None = None) -> list[str]:
    """Benchmark-looking numbers outside markers and outside the allowed definitions."""
    body = prose(text)
    ok: list[tuple[int, int]] = []
    for pattern, _ in ALLOWED if allowed is None else allowed:
        ok += [m.span() for m in re.finditer(pattern, body)]
    out = []
    for m in FIGURE.finditer(body):
        if any(a <= m.start() and m.end() <= b for a, b in ok):
            continue
        out.append(f"line {_line(body, m.start())}: {m.group(0)!r}")
    return out


def unused_allowed(texts: list[str]) -> list[str]:
    """Entries of ALLOWED that match no page (a stale allowance is a hole)."""
    bodies = [prose(t) for t in texts]
    return [
        f"ALLOWED {p!r} ({why}) matches no page"
        for p, why in ALLOWED
        if not any(re.search(p, b) for b in bodies)
    ]


def _rel(path: Path) -> Path:
    return path.relative_to(ROOT) if path.is_relative_to(ROOT) else path


def problems(paths: list[Path] | None = None, results: dict[str, dict] | None = None) -> list[str]:
    results = load() if results is None else results
    paths = pages() if paths is None else paths
    out = []
    texts = []
    for path in paths:
        text = path.read_text()
        texts.append(text)
        rel = _rel(path)
        out += [f"{rel}: {p}" for p in stale(text, results)]
        out += [
            f"{rel}: {p}: a benchmark figure outside a marker "
            "(<!-- fig NAME FIELD FORMAT -->…<!-- /fig -->, docs/gen/figures.py)"
            for p in strays(text)
        ]
    return out


def update(paths: list[Path] | None = None, results: dict[str, dict] | None = None) -> list[str]:
    """Rewrite the markers of the pages from the results (a page is written only when it
    changes); returns the markers that could not be filled."""
    results = load() if results is None else results
    out = []
    for path in pages() if paths is None else paths:
        text = path.read_text()
        new, bad = rewrite(text, results)
        out += [f"{_rel(path)}: {b}" for b in bad]
        if new != text:
            path.write_text(new)
            print(f"figures: rewrote {_rel(path)}", file=sys.stderr)
    return out


def main() -> int:
    bad = update()
    bad += problems()
    for b in bad:
        print(f"figures: {b}", file=sys.stderr)
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
