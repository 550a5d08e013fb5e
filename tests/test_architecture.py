"""ARCHITECTURE.md matches the tree: every source file of the folders it maps is named
there, every repository path it names exists, and each "Where to add" recipe names
files that exist.

The map sections are the `## <folder>` headings (`## rust/core/src`, `## python/blurset`
…). In one, a bullet that opens with a folder (`- \\`plan/\\` — …`) names files of that
folder, anything else names files of the section's folder; a named folder stands for its
`mod.rs` / `__init__.py`. Elsewhere a bare `.rs` name is under rust/core/src and a bare
`.py` or `.pyi` name under python/blurset, as the page says; a name that starts with a
top-level folder is from the repository root. Read from the text, no Blender, no build.
"""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
ARCH = ROOT / "ARCHITECTURE.md"
CORE = "rust/core/src"
PKG = "python/blurset"

# Mapped folder -> the source files it holds that ARCHITECTURE.md must name.
MAPS: dict[str, tuple[str, ...]] = {
    CORE: (".rs",),
    "rust/py/src": (".rs",),
    PKG: (".py", ".pyi"),
    "blender_scripts": (".py",),
    "bench": (".py",),
    "docs/gen": (".py",),
}
TOP = ("rust", "python", "bench", "blender_scripts", "docs", "tests", "schemas", "scripts",
       "examples")  # fmt: skip
SOURCE = (".rs", ".py", ".pyi", ".sh")
TICKED = re.compile(r"`([^`\n]+)`")
PLAIN = re.compile(r"[\w.-]+(?:/[\w.-]+)*/?")
BULLET_DIR = re.compile(r"^- `([\w/]+/)`")
MAKE = re.compile(r"^make ([\w-]+)$")
RECIPES = ("option", "build preset", "export target", "benchmark", "degradation")


def tree_files() -> set[str]:
    """Source files of the mapped folders, tracked or not (ignored files left out)."""
    try:
        out = subprocess.run(
            ["git", "ls-files", "--cached", "--others", "--exclude-standard", *MAPS],
            cwd=ROOT,
            capture_output=True,
            text=True,
            check=True,
        ).stdout.split("\n")
    except (OSError, subprocess.CalledProcessError):
        out = [str(p.relative_to(ROOT)) for d in MAPS for p in (ROOT / d).rglob("*")]
    files = set()
    for f in out:
        if not f or "__pycache__" in f or not (ROOT / f).is_file():
            continue
        for folder, exts in MAPS.items():
            if f.startswith(folder + "/") and f.endswith(exts):
                files.add(f)
    return files


def sections(text: str) -> dict[str, str]:
    """`## heading` -> its text (up to the next `## `)."""
    parts = re.split(r"^## (.+)$", text, flags=re.M)
    return {parts[i].strip(): parts[i + 1] for i in range(1, len(parts), 2)}


def _blocks(body: str) -> list[str]:
    """A section's top-level bullets and paragraphs."""
    blocks: list[list[str]] = []
    for line in body.split("\n"):
        if not line.strip():
            blocks.append([])
        elif line.startswith("- ") or not blocks:
            blocks.append([line])
        else:
            blocks[-1].append(line)
    return ["\n".join(b) for b in blocks if b]


def _pathlike(token: str) -> bool:
    """A name of a file or folder of the repository, not of what blurset writes
    (`meta.json`, `images_<f>/`, `OUT/.lock`)."""
    if not PLAIN.fullmatch(token) or token.startswith("."):
        return False
    return token.endswith(SOURCE) or token.split("/")[0] in TOP and "/" in token


# The pages `make docs` generates from code (git ignores them): a fresh clone has none
# until `make docs` runs, which CI does after the tests.
GENERATED = ("docs/reference/cli.md", "docs/formats/records", "docs/benchmarks")


def _exists(rel: str) -> bool:
    rel = rel.rstrip("/")
    made = any(rel == g or rel.startswith(g + "/") for g in GENERATED)
    return (ROOT / rel).exists() or made


def resolve(token: str, context: str | None = None) -> str | None:
    """The repository path a name in backticks stands for; None if there is none."""
    token = token.rstrip("/") if token.endswith("/") else token
    if token.split("/")[0] in TOP and _exists(token):
        return token
    bases = [context] if context else []
    if token.endswith(".rs"):
        bases.append(CORE)
    elif token.endswith((".py", ".pyi")):
        bases.append(PKG)
    elif context is None:
        bases += [CORE, PKG]
    for base in bases:
        if base and _exists(f"{base}/{token}"):
            return f"{base}/{token}"
    return None


def named_in_maps(text: str) -> tuple[set[str], list[str]]:
    """The paths the map sections name, and the names there that resolve to nothing."""
    named: set[str] = set()
    stale: list[str] = []
    for heading, body in sections(text).items():
        if heading not in MAPS:
            continue
        for block in _blocks(body):
            m = BULLET_DIR.match(block)
            context = f"{heading}/{m.group(1).rstrip('/')}" if m else heading
            for token in TICKED.findall(block):
                folder = token.endswith("/") and PLAIN.fullmatch(token) is not None
                if not (folder or _pathlike(token)):
                    continue
                path = resolve(token, context) or resolve(token, heading)
                if path is None:
                    stale.append(f"## {heading}: `{token}` is no file or folder of the tree")
                    continue
                named.add(path)
                if (ROOT / path).is_dir():
                    named |= {f"{path}/mod.rs", f"{path}/__init__.py"}
    return named, stale


def problems(text: str, files: set[str]) -> list[str]:
    """What ARCHITECTURE.md says that the tree does not, and the reverse."""
    named, out = named_in_maps(text)
    missing = [f for f in sorted(files) if f not in named]
    out += [f"{f} is not named under ## {_folder(f)}" for f in missing]
    for token in TICKED.findall(text):
        if _pathlike(token) and resolve(token) is None and not _named_in_a_map(token, named):
            out.append(f"`{token}` names no file of the repository")
        if token.startswith("blurset.") and PLAIN.fullmatch(token):
            parts = token.split(".")
            mod = "/".join(["python", *parts[:2]])
            if not any(_exists(mod + s) for s in (".py", ".pyi", "/__init__.py")):
                out.append(f"`{token}`: no module {mod}")
        m = MAKE.match(token)
        if m and not re.search(rf"^{re.escape(m.group(1))}:", _makefile(), re.M):
            out.append(f"`{token}`: no such target in the Makefile")
    return out


def _named_in_a_map(token: str, named: set[str]) -> bool:
    """A bare name like `exr/read.rs` that a map section resolved by its context."""
    return any(p.endswith("/" + token.rstrip("/")) for p in named)


def _folder(f: str) -> str:
    return next(d for d in MAPS if f.startswith(d + "/"))


def _makefile() -> str:
    return (ROOT / "Makefile").read_text()


def test_architecture_names_every_file_and_no_missing_one() -> None:
    files = tree_files()
    assert len([f for f in files if f.startswith(CORE)]) >= 40, "the scan found too few"
    assert len([f for f in files if f.startswith(PKG)]) >= 60, "the scan found too few"
    assert problems(ARCH.read_text(), files) == []


def test_a_new_or_renamed_module_is_found() -> None:
    text = ARCH.read_text()
    files = tree_files()
    # A module added without a word on the page.
    for fake in (f"{PKG}/export_zarr.py", f"{CORE}/plan/vignette.rs", "bench/bench_new.py",
                 f"{PKG}/commands/builder/shard.py"):  # fmt: skip
        assert f"{fake} is not named under ## {_folder(fake)}" in problems(text, files | {fake})
    # A module renamed on the page (or in the tree): the old name is stale, the file unnamed.
    assert "`kernels.py`" in text
    found = problems(text.replace("`kernels.py`", "`kernel_cache.py`"), files)
    assert f"{PKG}/services/kernels.py is not named under ## {PKG}" in found
    assert any("`kernel_cache.py`" in p for p in found), found
    # A file of a folder renamed: `plan/` names `kinds.rs`, which must exist there.
    found = problems(text.replace("`kinds.rs`", "`lens.rs`", 1), files)
    assert f"{CORE}/plan/kinds.rs is not named under ## {CORE}" in found
    # A stale path, a stale module and a stale make target anywhere on the page.
    found = problems(text + "\n`bench/bench_gone.py`, `blurset.gone`, `make gone`\n", files)
    assert "`bench/bench_gone.py` names no file of the repository" in found
    assert "`blurset.gone`: no module python/blurset/gone" in found
    assert "`make gone`: no such target in the Makefile" in found


def test_every_where_to_add_recipe_names_files_that_exist() -> None:
    where = sections(ARCH.read_text())["Where to add"]
    recipes = re.split(r"^### (.+)$", where, flags=re.M)
    by_title = {recipes[i]: recipes[i + 1] for i in range(1, len(recipes), 2)}
    for topic in RECIPES:
        titles = [t for t in by_title if topic in t.lower()]
        assert titles, f"no recipe for a new {topic} under ## Where to add"
        paths = [resolve(t) for t in TICKED.findall(by_title[titles[0]]) if _pathlike(t)]
        assert len(paths) >= 3 and None not in paths, (topic, paths)
    # "Preset" is disambiguated, each meaning where it is declared.
    preset = next(b for t, b in by_title.items() if "preset" in t.lower() and "means" in t)
    for path, decl in (
        (f"{CORE}/plan/choices.rs", "enum Preset"),
        (f"{CORE}/plan/presets.rs", "fn preset_values"),
        ("bench/fixed_presets.py", "PRESETS = {"),
        (f"{PKG}/commands/tradeoff/grid.py", "PRESETS = {"),
    ):
        assert path.split("/", 3)[-1] in preset or path in preset, path
        assert decl in (ROOT / path).read_text(), (path, decl)


def test_parts_count_and_the_docs_page() -> None:
    """The count of parts is the table's, on this page and on the contributing page, and
    the docs site shows this page rather than a copy."""
    text = ARCH.read_text()
    words = {2: "two", 3: "three", 4: "four", 5: "five", 6: "six"}
    table = sections("## x\n" + text.split("\n## ", 1)[0])["x"]
    rows = [r for r in table.split("\n") if r.startswith("| `")]
    word = words[len(rows)]
    assert text.split("\n")[2].lower().startswith(f"{word} parts"), text.split("\n")[2]
    contributing = (ROOT / "docs" / "contributing" / "index.md").read_text()
    assert f"blurset is {word} parts" in contributing
    page = (ROOT / "docs" / "contributing" / "architecture.md").read_text()
    assert page.strip() == '--8<-- "ARCHITECTURE.md"'
