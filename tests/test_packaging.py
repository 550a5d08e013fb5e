"""A wheel (`pip install .`, not the editable `make venv`) carries the bpy-side scripts and
finds them: the worker and the GLB pre-flight must not depend on a source checkout."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

from tests.conftest import IN_CI, ROOT

# A release build of the wheel takes minutes: `make test-packaging`, which CI runs.
pytestmark = [pytest.mark.packaging, pytest.mark.blender]

SCRIPTS = {"blender_scripts/worker.py", "blender_scripts/blender_scene.py",
           "blender_scripts/glb_inspect.py"}  # fmt: skip


@pytest.fixture(scope="module")
def installed_wheel(tmp_path_factory) -> Path:
    tmp = tmp_path_factory.mktemp("wheel")
    maturin = Path(sys.executable).with_name("maturin")
    if not maturin.exists():
        if IN_CI:
            pytest.fail(f"CI=true: {maturin} is absent (make venv installs it)")
        pytest.skip(f"{maturin} is absent (make venv installs it)")
    subprocess.run([str(maturin), "build", "--release", "-q", "-o", str(tmp / "dist")],
                   cwd=ROOT, check=True, capture_output=True)  # fmt: skip
    (whl,) = (tmp / "dist").glob("*.whl")
    names = set(zipfile.ZipFile(whl).namelist())
    assert SCRIPTS <= names, sorted(n for n in names if "blender" in n)
    site = tmp / "site"
    subprocess.run([sys.executable, "-m", "pip", "install", "-q", "--no-deps", "--target",
                    str(site), str(whl)], check=True, capture_output=True)  # fmt: skip
    return site


def _run(site: Path, cwd: Path, code: str) -> subprocess.CompletedProcess:
    env = dict(os.environ, PYTHONPATH=str(site))
    return subprocess.run([sys.executable, "-c", code], cwd=cwd, env=env, capture_output=True,
                          text=True, timeout=600)  # fmt: skip


def test_installed_wheel_uses_its_own_scripts(installed_wheel, tmp_path):
    p = _run(installed_wheel, tmp_path, (
        "import json, blurset, blurset.services.preflight as pf, blurset.services.worker_client as wc\n"
        "print(json.dumps([blurset.__file__, str(wc.WORKER_SCRIPT), str(pf._GLB_INSPECT)]))"
    ))  # fmt: skip
    assert p.returncode == 0, p.stderr
    package, worker, inspect = (Path(x) for x in json.loads(p.stdout))
    site = installed_wheel.resolve()
    for path in (package, worker, inspect):
        assert path.is_relative_to(site), (path, site)  # not the source tree's copy
    assert worker.is_file() and inspect.is_file()


@pytest.mark.blender
def test_installed_wheel_builds(installed_wheel, tmp_path):
    out = tmp_path / "out"
    p = _run(installed_wheel, tmp_path, (
        "import sys\nfrom blurset.cli import main\n"
        f"sys.argv = ['blurset', 'build', '--demo', '--out', {str(out)!r}, '--views', '2',"
        " '--levels', '1', '--latents', '2', '--samples', '2', '--resolution', '32',"
        " '--settings-per-object', '1', '--quiet']\nsys.exit(main())"
    ))  # fmt: skip
    assert p.returncode == 0, p.stderr
    done = sorted(d.name for d in out.iterdir() if (d / ".complete").exists())
    assert len(done) == 3, (done, p.stderr)
