"""Checks of the docs that mkdocs cannot make (run by `make docs` and tests/test_docs.py).

- Every `DESIGN §n` a comment cites (also `DESIGN §2, §12` and `DESIGN §2–4`) is a
  section `## n.` of docs/design.md, the design the code refers to.
- README.md stays a short first read (at most 200 lines), and its links to files of the
  repository point at files that exist.
- Pages a user reads (README.md and docs/, generated pages included) name no issue of
  the project, no date, no load average and no commit hash.
- No page a user reads (README.md, ARCHITECTURE.md, docs/ and the generators under
  docs/gen that write pages) spells an absolute path of the machine it was made on: a
  home or work folder, a user folder, or a nested or generated temporary folder. A
  transcript shows relative paths, or `~`, or `/path/to/...`; a single well-known file
  such as a lock directly under the temporary folder is an example, not a machine path.
"""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import FORBIDDEN  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
DESIGN = ROOT / "docs" / "design.md"
README_MAX_LINES = 200
CITE = re.compile(r"DESIGN(?:\.md)?\s*((?:§\s*\d+(?:\s*[–-]\s*\d+)?(?:\s*,\s*(?=§))?)+)")
SECTION = re.compile(r"§\s*(\d+)(?:\s*[–-]\s*(\d+))?")
HEADING = re.compile(r"^## (\d+)\. ", re.M)
LINK = re.compile(r"\]\(([^)#\s]+)(?:#[^)]*)?\)")
# Where the code cites the design.
CODE = ("rust", "python", "tests", "bench", "blender_scripts", "examples", "schemas", "docs")
CODE_FILES = ("Makefile", "pyproject.toml", "ARCHITECTURE.md", ".ci/run")


def _files() -> list[Path]:
    try:
        out = subprocess.run(
            ["git", "ls-files", "--cached", "--others", "--exclude-standard"],
            cwd=ROOT,
            capture_output=True,
            text=True,
            check=True,
        ).stdout.split("\n")
        return [ROOT / f for f in out if f]
    except (OSError, subprocess.CalledProcessError):
        return [p for p in ROOT.rglob("*") if p.is_file() and ".git" not in p.parts]


def cited_sections() -> dict[int, list[str]]:
    """Section number -> where it is cited (path:line)."""
    cites: dict[int, list[str]] = {}
    for path in _files():
        rel = path.relative_to(ROOT)
        if not (rel.parts[0] in CODE or str(rel) in CODE_FILES) or rel == DESIGN.relative_to(ROOT):
            continue
        if path.suffix in (".png", ".npy", ".glb", ".exr", ".jpg") or not path.is_file():
            continue
        try:
            text = path.read_text()
        except (UnicodeDecodeError, OSError):
            continue
        for m in CITE.finditer(text):
            line = text.count("\n", 0, m.start()) + 1
            for a, b in SECTION.findall(m.group(1)):
                for n in range(int(a), int(b or a) + 1):
                    cites.setdefault(n, []).append(f"{rel}:{line}")
    return cites


def design_sections() -> set[int]:
    return {int(n) for n in HEADING.findall(DESIGN.read_text())}


def missing_sections() -> list[str]:
    have = design_sections()
    return [
        f"DESIGN §{n} (cited at {', '.join(where[:3])}) is not a section of docs/design.md"
        for n, where in sorted(cited_sections().items())
        if n not in have
    ]


def readme_problems() -> list[str]:
    readme = ROOT / "README.md"
    text = readme.read_text()
    problems = []
    lines = text.count("\n")
    if lines > README_MAX_LINES:
        problems.append(f"README.md has {lines} lines (at most {README_MAX_LINES})")
    for target in LINK.findall(text):
        if re.match(r"[a-z]+:", target):  # a URL
            continue
        if not (ROOT / target).exists():
            problems.append(f"README.md links to {target}, which does not exist")
    return problems


def user_pages() -> list[Path]:
    pages = [ROOT / "README.md"] + sorted((ROOT / "docs").rglob("*.md"))
    return [p for p in pages if "gen" not in p.relative_to(ROOT).parts]


def history_problems() -> list[str]:
    problems = []
    for page in user_pages():
        text = page.read_text()
        for pattern, what in FORBIDDEN:
            for m in pattern.finditer(text):
                line = text.count("\n", 0, m.start()) + 1
                problems.append(
                    f"{page.relative_to(ROOT)}:{line}: {what} in user text: {m.group(0)!r}"
                )
    return problems


# An absolute path of a machine: not inside a longer word or path (`ROOT/data/...` is
# relative), starting at a folder that only exists on the machine that wrote it, the
# temporary folder included (a reader's may be elsewhere: docs show ~ or relative paths).
# ([f], [m]: so this source does not match.)
MACHINE_PATH = re.compile(
    r"(?<![\w.~/$}-])"
    r"(?:/(?:work|root|mnt|srv|Volumes|private|scratch)/[^\s`'\")\]]*"
    r"|/(?:home|Users)/[A-Za-z0-9_.-]+"
    r"|/var/[f]olders/"
    r"|/t[m]p/[^\s`'\")\]]*"
    r"|[A-Za-z]:\\Users\\)"
)


def machine_path_pages() -> list[Path]:
    docs = sorted((ROOT / "docs").rglob("*.md")) + sorted((ROOT / "docs" / "gen").glob("*.py"))
    return [ROOT / "README.md", ROOT / "ARCHITECTURE.md"] + docs


def machine_paths(text: str) -> list[tuple[int, str]]:
    """(line, path) of each absolute machine path in text."""
    return [(text.count("\n", 0, m.start()) + 1, m.group(0)) for m in MACHINE_PATH.finditer(text)]


def machine_path_problems(pages: list[Path] | None = None) -> list[str]:
    problems = []
    for page in machine_path_pages() if pages is None else pages:
        for line, path in machine_paths(page.read_text()):
            problems.append(
                f"{page.relative_to(ROOT) if page.is_relative_to(ROOT) else page}:{line}: "
                f"absolute machine path {path!r} (show a relative path, ~ or /path/to/...)"
            )
    return problems


def main() -> int:
    problems = missing_sections() + readme_problems() + history_problems() + machine_path_problems()
    for p in problems:
        print(f"docs check: {p}", file=sys.stderr)
    if not problems:
        n = sum(len(v) for v in cited_sections().values())
        print(
            f"docs check: {n} DESIGN § citations resolve; README and pages clean", file=sys.stderr
        )
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
