"""Layout names have one owner (issue 27): the file and folder names of what blurset
writes are spelled in blurset-core (ground::names::files) and reach Python through
`blurset.layout` only. A string literal of one of them anywhere else in the package is a
second spelling that can drift; this test names each such place."""

from __future__ import annotations

import ast
from pathlib import Path

from blurset import layout

PACKAGE = Path(__file__).resolve().parents[1] / "python" / "blurset"
NAMES = {
    layout.META, layout.DATASET, layout.SPLITS, layout.FAILURES, layout.POSES_BOUNDS,
    layout.TRANSFORMS, layout.NOISE, layout.NOISE_DATASET, layout.NOISE_SCENE,
    layout.EXPORT, layout.STATS, layout.IMAGES, layout.LINEAR, layout.MANIFEST,
}  # fmt: skip
# f-strings that build a downsampled folder's name by hand (`images_{f}`).
PREFIXES = (f"{layout.IMAGES}_", f"{layout.LINEAR}_")


# Folder names that are also words of the records (`meta["render"]["linear"]`, the
# `images` field of noise_scene.json): a second spelling only as a path part.
FOLDERS = {layout.IMAGES, layout.LINEAR}


def second_spellings(source: str) -> list[tuple[int, str]]:
    """(line, literal) of every string constant equal to a layout file name, of a folder
    name joined onto a path (`d / "images"`, a list of sub-folders), and of every
    f-string whose literal head is `images_` or `linear_`."""
    tree = ast.parse(source)
    as_path: set[int] = set()
    choices: set[int] = set()  # an option's values (`--source linear`), not a folder
    for node in ast.walk(tree):
        if isinstance(node, ast.keyword) and node.arg == "choices":
            choices |= {id(e) for e in getattr(node.value, "elts", [])}
        if isinstance(node, ast.BinOp) and isinstance(node.op, ast.Div):
            as_path |= {id(node.left), id(node.right)}
        elif isinstance(node, ast.List | ast.Tuple | ast.Set):
            as_path |= {id(e) for e in node.elts}
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.JoinedStr) and node.values:
            head = node.values[0]
            if isinstance(head, ast.Constant) and str(head.value).endswith(PREFIXES):
                found.append((node.lineno, f"f{head.value!r}…"))
        elif isinstance(node, ast.Constant) and isinstance(node.value, str):
            named = node.value in NAMES - FOLDERS
            if named or (node.value in FOLDERS and id(node) in as_path - choices):
                found.append((node.lineno, repr(node.value)))
    return sorted(found)


def test_the_names_come_from_the_core():
    assert layout.META == "meta.json" and layout.POSES_BOUNDS == "poses_bounds.npy"
    assert [layout.images_dir(f) for f in (1, 4)] == ["images", "images_4"]
    assert [layout.linear_dir(f) for f in (1, 8)] == ["linear", "linear_8"]


def test_the_scan_sees_a_second_spelling():
    src = (
        'a = d / "meta.json"\nb = f"images_{f}"\nc = "meta.json is named in text"\n'
        'd = s / "images" / n\ne = meta["render"]["linear"]\n'
    )
    assert second_spellings(src) == [(1, "'meta.json'"), (2, "f'images_'…"), (4, "'images'")]


def test_no_layout_name_is_spelled_outside_the_layout_face():
    offenders = [
        f"{path.relative_to(PACKAGE)}:{line}: {text}"
        for path in sorted(PACKAGE.rglob("*.py"))
        if path.name != "layout.py"
        for line, text in second_spellings(path.read_text())
    ]
    assert not offenders, "\n".join(offenders)
