"""Issue 49: no image crosses to NumPy inside a build or its target loop. The accumulators,
the two halves of a targeted image, their noise estimate and render QA all stay in the
core; the builder only moves paths and records.

The proof runs real builds (the stand-in worker: real orchestration, analytic renders)
in a process whose profiler sees every call into blurset._core, and checks none of
them is one whose signature in _core.pyi takes or returns an ndarray."""

from __future__ import annotations

import ast
import json
import subprocess
import sys
from pathlib import Path

import pytest

from tests.conftest import ROOT, STANDIN_ARGS

STUB = ROOT / "python" / "blurset" / "_core.pyi"

# Arrays of the array API that are not images: the object's vertices (N, 3) the plan
# bounds its views with.
NOT_IMAGES = {"plan_setting"}

# Run `blurset build ARGV` in this process with every call into blurset._core recorded
# (each thread's profiler: the worker's frames arrive on a reader thread), then write
# the names called, methods qualified by their class, to OUT.
PROBE = """
import json, sys, threading
from blurset import _core, cli

called = set()

def probe(frame, event, arg):
    if event != "c_call":
        return
    owner = getattr(arg, "__self__", None)
    if type(owner).__module__ == "blurset._core":
        called.add(f"{type(owner).__name__}.{arg.__name__}")
    elif getattr(arg, "__module__", None) == "blurset._core":
        called.add(arg.__name__)

threading.setprofile(probe)
sys.setprofile(probe)
code = cli.main(json.loads(sys.argv[2]))
sys.setprofile(None)
threading.setprofile(None)
open(sys.argv[1], "w").write(json.dumps(sorted(called)))
sys.exit(code)
"""


def array_api() -> set[str]:
    """Every function and method of _core.pyi that takes or returns an ndarray (with
    NOT_IMAGES, whose arrays are not images)."""
    out: set[str] = set()

    def visit(body: list[ast.stmt], prefix: str) -> None:
        for node in body:
            if isinstance(node, ast.ClassDef):
                visit(node.body, f"{node.name}.")
            elif isinstance(node, ast.FunctionDef) and "NDArray" in ast.unparse(node.args) + (
                ast.unparse(node.returns) if node.returns else ""
            ):
                out.add(prefix + node.name)

    visit(ast.parse(STUB.read_text()).body, "")
    return out


def calls_of_build(tmp_path: Path, blender: Path, *args: str) -> set[str]:
    """The _core functions and methods one stand-in build called."""
    out, record = tmp_path / "b", tmp_path / "called.json"
    argv = ["build", *args, "--blender", str(blender), "--out", str(out)]
    proc = subprocess.run(
        [sys.executable, "-c", PROBE, str(record), json.dumps(argv)],
        capture_output=True,
        text=True,
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert list(out.glob("*/meta.json")), "the build wrote no setting"
    return set(json.loads(record.read_text()))


def test_the_array_api_is_read_from_the_stub() -> None:
    api = array_api()
    # The calls that once carried a build's images to NumPy and back: the check knows them.
    for name in ("Accumulator.mean", "Accumulator.add", "read_exr", "frame_qa", "half_noise_bound"):
        assert name in api, name
    assert "Accumulator.write_png" not in api and "Session.next_renders" not in api
    assert NOT_IMAGES <= api  # an exception that is no longer one is dropped


# The stand-in build's options, and the same to a render-noise target (no sample count).
FIXED = STANDIN_ARGS
i = FIXED.index("--samples")
TARGETED = (*FIXED[:i], *FIXED[i + 2 :], "--target-psnr", "30", "--target-max-samples", "64")


@pytest.mark.parametrize("args", [FIXED, TARGETED], ids=["fixed", "target"])
def test_no_image_crosses_to_numpy_in_a_build(tmp_path, standin_blender, args) -> None:
    called = calls_of_build(tmp_path, standin_blender, *args)
    # The probe sees the core: the session that renders and writes every image, fixed
    # counts or a target, is there.
    assert {"Session.next_renders", "Session.add_exr", "plan_setting"} <= called, sorted(called)
    crossed = called & (array_api() - NOT_IMAGES)
    assert not crossed, f"the build moved images through NumPy: {sorted(crossed)}"


def test_the_probe_catches_an_image_that_crosses(tmp_path) -> None:
    """The same probe around a call that does hand an image to NumPy records it."""
    code = PROBE.replace("code = cli.main(json.loads(sys.argv[2]))", (
        "import numpy as np\n"
        "a = _core.Accumulator(2, 2)\n"
        "a.add(np.zeros((2, 2, 4), np.float32))\n"
        "_core.frame_qa(a.mean())\n"
        "code = 0"
    ))  # fmt: skip
    record = tmp_path / "called.json"
    subprocess.run([sys.executable, "-c", code, str(record), "[]"], check=True)
    called = set(json.loads(record.read_text()))
    assert {"Accumulator.add", "Accumulator.mean", "frame_qa"} <= called & array_api()
