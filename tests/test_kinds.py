"""The degradation kinds beside motion blur are a registry (issue 59): each is its own
file in rust/core/src/plan/kinds/ and one line of `kinds!` in rust/core/src/plan/kinds.rs,
from which the core makes the kind's image variant, its option of `blurset build` (flag,
range check, help), its levels in the plan and in meta.json, its renders, its level
folders and its statistic; Python reads them from the core.

The proof: a copy of the core with a throwaway kind (tests/data/throwaway_kind.rs, the
camera rolled by 2·l degrees) added as its file and one line of the registry, nothing
else changed, compiles, and the kind's own tests build a setting with it (the option and
its range, the plan and its meta.json record, the renders, the images and level folders
the render session writes, its statistic)."""

from __future__ import annotations

import difflib
import os
import re
import shutil
import subprocess

import pytest
from blurset import cli
from blurset.commands import stats

from tests.conftest import ROOT

REGISTRY = ROOT / "rust" / "core" / "src" / "plan" / "kinds.rs"
KINDS_DIR = REGISTRY.with_suffix("")
THROWAWAY = ROOT / "tests" / "data" / "throwaway_kind.rs"
# A line of the registry: `module::Kind,`.
ENTRY = re.compile(r"^\s+([a-z_]+)::([A-Z]\w*),$", re.M)


def registered() -> list[str]:
    return [m[1] for m in ENTRY.finditer(REGISTRY.read_text())]


def test_the_registry_lists_each_kind_file_once_in_the_cores_order():
    files = sorted(p.stem for p in KINDS_DIR.glob("*.rs"))
    assert sorted(registered()) == files and files
    # The statistics read the kinds from the core, in its order.
    assert list(stats.KINDS.values()) == registered()


def test_python_takes_each_kinds_option_and_figure_from_the_core():
    parser = cli.make_parser()
    build = next(a for a in parser._actions if a.choices and "build" in a.choices)
    flags = {f for a in build.choices["build"]._actions for f in a.option_strings}
    for stat, kind in stats.KINDS.items():
        assert f"--{kind.replace('_', '-')}" in flags
        title, xlabel, ylabel = stats.FIGURES[stat]
        assert title and xlabel and ylabel == "views" and stat.startswith(f"{kind}_")
    # stats.py names no kind: a new one needs no edit there.
    source = (ROOT / "python" / "blurset" / "commands" / "stats.py").read_text()
    assert not [k for k in registered() if re.search(rf"\b{k}", source)]


@pytest.mark.rebuild
def test_a_throwaway_kind_is_its_file_and_one_line(tmp_path):
    copy = tmp_path / "blurset"
    copy.mkdir()
    for f in ("Cargo.toml", "Cargo.lock"):
        shutil.copy(ROOT / f, copy / f)
    for crate in ("core", "py"):
        shutil.copytree(ROOT / "rust" / crate, copy / "rust" / crate)
    registry = copy / REGISTRY.relative_to(ROOT)
    before = registry.read_text()
    last = list(ENTRY.finditer(before))[-1]
    after = before[: last.end()] + "\n            tilt::Tilt," + before[last.end() :]
    registry.write_text(after)
    shutil.copy(THROWAWAY, registry.with_suffix("") / "tilt.rs")
    changed = [
        d
        for d in difflib.unified_diff(before.splitlines(), after.splitlines(), lineterm="", n=0)
        if d[:1] in "+-" and d[:3] not in ("+++", "---")
    ]
    assert changed == ["+            tilt::Tilt,"]
    # The workspace's target: its dependencies are compiled already (make test-rust).
    env = {**os.environ, "CARGO_TARGET_DIR": str(ROOT / "target")}
    proc = subprocess.run(
        ["cargo", "test", "--release", "-p", "blurset-core", "--lib", "plan::kinds::tilt::"],
        cwd=copy, env=env, capture_output=True, text=True, timeout=1800,
    )  # fmt: skip
    out = proc.stdout + proc.stderr
    assert proc.returncode == 0, out[-4000:]
    assert "test result: ok. 2 passed" in proc.stdout, out[-4000:]
