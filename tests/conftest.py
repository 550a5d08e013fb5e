"""Shared fixtures. Tests that need third-party data read it from ../shared/data and skip
with a reason when it is absent (a user's clone); CI always has it."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
SHARED_DATA = ROOT.parent / "shared" / "data"
HAS_BPY = importlib.util.find_spec("bpy") is not None


def shared(*parts: str) -> Path:
    """A path under ../shared/data, or skip the test when it is absent."""
    p = SHARED_DATA.joinpath(*parts)
    if not p.exists():
        pytest.skip(f"real data {p} is absent (it ships with CI, not with a clone)")
    return p


def pytest_collection_modifyitems(config, items):
    if HAS_BPY:
        return
    skip = pytest.mark.skip(reason="bpy cannot be imported")
    for item in items:
        if "blender" in item.keywords:
            item.add_marker(skip)


@pytest.fixture
def rng():
    return np.random.default_rng(0)


def run_cli(*args: str, env: dict | None = None, check: bool = True):
    """Run `blurset ARGS` in a subprocess, as a user would."""
    import os
    import subprocess
    import sys

    full_env = dict(os.environ, **(env or {}))
    proc = subprocess.run(
        [sys.executable, "-m", "blurset.cli", *args],
        capture_output=True,
        text=True,
        env=full_env,
    )
    if check and proc.returncode != 0:
        raise AssertionError(
            f"blurset {' '.join(args)} exited {proc.returncode}\n{proc.stderr[-3000:]}"
        )
    return proc


# A tiny real demo build shared by the build tests (real Blender renders).
DEMO_ARGS = (
    "--demo", "--views", "17", "--latents", "4", "--samples", "4", "--sharp-samples", "4",
    "--resolution", "64", "--seed", "3", "--quiet",
)  # fmt: skip


@pytest.fixture(scope="session")
def demo_build(tmp_path_factory):
    if not HAS_BPY:
        pytest.skip("bpy cannot be imported")
    out = tmp_path_factory.mktemp("demo") / "out"
    run_cli("build", *DEMO_ARGS, "--out", str(out))
    return out


@pytest.fixture(scope="session")
def linear_build(tmp_path_factory):
    """The demo build of DEMO_ARGS with `--keep-linear --previews` (issue 9): linear EXRs
    of every view and level, and a preview.png per setting."""
    if not HAS_BPY:
        pytest.skip("bpy cannot be imported")
    out = tmp_path_factory.mktemp("demo_linear") / "out"
    run_cli("build", *DEMO_ARGS, "--keep-linear", "--previews", "--out", str(out))
    return out
