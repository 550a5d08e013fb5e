"""Shared fixtures. Tests that need third-party data read it from ../shared/data (see
_shared_data for a clone made elsewhere) and skip
with a reason when it is absent (a user's clone); CI always has it, so under CI=true a
missing ../shared/data or bpy fails the run instead of skipping it.

Markers: `blender` (renders with bpy; also given to every test that uses a build
fixture), `slow` (long end-to-end runs), `packaging` (builds a release wheel: its own
make target). `make test-fast` runs what is neither blender nor packaging."""

from __future__ import annotations

import atexit
import importlib
import importlib.util
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]


def _shared_data() -> Path:
    """../shared/data beside this checkout; for a clone made elsewhere (`git clone .
    $(mktemp -d)`), the one beside the checkout it was cloned from; BLURSET_SHARED_DATA
    names another place."""
    if env := os.environ.get("BLURSET_SHARED_DATA"):
        return Path(env)
    here = ROOT.parent / "shared" / "data"
    if here.exists():
        return here
    try:
        origin = subprocess.run(
            ["git", "-C", str(ROOT), "config", "--get", "remote.origin.url"],
            capture_output=True, text=True, check=False,
        ).stdout.strip()  # fmt: skip
    except OSError:
        return here
    beside = Path(origin).parent / "shared" / "data" if origin.startswith("/") else None
    return beside if beside is not None and beside.exists() else here


SHARED_DATA = _shared_data()
HAS_BPY = importlib.util.find_spec("bpy") is not None
# In CI nothing may be skipped for want of bpy or the shared data: a hole there would
# leave the run green with its render tests never run.
IN_CI = os.environ.get("CI", "").strip().lower() in ("1", "true", "yes")


# The builder's absolute paths go to the user's state directory (blurset.services.publish):
# a test run keeps its own, never the user's ~/.local/state.
def temp_home(variable: str, prefix: str) -> None:
    """`variable` names a temp folder of this process's own, removed when it exits,
    unless it is set already (an xdist worker inherits the controller's)."""
    if variable not in os.environ:
        os.environ[variable] = home = tempfile.mkdtemp(prefix=prefix)
        atexit.register(shutil.rmtree, home, True)


temp_home("BLURSET_STATE_DIR", "blurset-state-")
# Fixtures that render a build: a test using one needs bpy.
BUILD_FIXTURES = {"demo_build", "linear_build", "noised", "demo_setting"}


def skip_or_fail_in_ci(msg: str) -> None:
    """Skip a test whose means this machine lacks; under CI, which has them all, fail."""
    if IN_CI:
        pytest.fail(f"CI=true: {msg}")
    pytest.skip(msg)


def shared(*parts: str) -> Path:
    """A path under ../shared/data, or skip the test when it is absent (fail under CI)."""
    p = SHARED_DATA.joinpath(*parts)
    if not p.exists():
        msg = f"real data {p} is absent (it ships with CI, not with a clone)"
        if IN_CI:
            pytest.fail(f"CI=true: {msg}")
        pytest.skip(msg)
    return p


def shared_if_present(*parts: str) -> Path | None:
    """A path under ../shared/data, or None when it is absent (fail under CI): for tests
    that check more when the real data is there."""
    p = SHARED_DATA.joinpath(*parts)
    if not p.exists():
        if IN_CI:
            pytest.fail(f"CI=true: real data {p} is absent")
        return None
    return p


def needs_bpy() -> None:
    """Skip (fail under CI) a test or fixture that renders when bpy cannot be imported."""
    if not HAS_BPY:
        if IN_CI:
            pytest.fail("CI=true: bpy cannot be imported, so the render tests cannot run")
        pytest.skip("bpy cannot be imported")


def pytest_collection_modifyitems(config, items):
    for item in items:
        if BUILD_FIXTURES & set(getattr(item, "fixturenames", ())):
            item.add_marker(pytest.mark.blender)
    if HAS_BPY:
        return
    if IN_CI:
        raise pytest.UsageError("CI=true but bpy cannot be imported: the render tests must run")
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
    needs_bpy()
    out = tmp_path_factory.mktemp("demo") / "out"
    run_cli("build", *DEMO_ARGS, "--out", str(out))
    return out


@pytest.fixture(scope="session")
def linear_build(tmp_path_factory):
    """The demo build of DEMO_ARGS with `--keep-linear --previews` (issue 9): linear EXRs
    of every view and level, and a preview.png per setting."""
    needs_bpy()
    out = tmp_path_factory.mktemp("demo_linear") / "out"
    run_cli("build", *DEMO_ARGS, "--keep-linear", "--previews", "--out", str(out))
    return out


def write_synthetic_build(
    out: Path,
    n_settings: int,
    *,
    views: int = 34,
    levels: tuple[int, ...] = (1, 2, 3, 4),
    latents: int = 34,
    latent_frames: bool = False,
    settings_per_object: int = 4,
    templates: int = 200,
    seed: int = 0,
) -> None:
    """A build of `n_settings` complete settings without rendering: meta.json with the
    schema `blurset build` writes (DESIGN §4) and plausible numbers (F, R, O, w_u and
    w_l follow their formulas). Setting bodies are drawn from `templates` distinct
    random ones (fast to write at 10,000 settings); uid and θ0 are each setting's own.
    `latent_frames=True` adds the per-frame records and the other per-view fields, so
    files have a real build's size and structure. splits.json puts every 5th object in
    test; failures.jsonl logs one failed object."""
    import json

    g = np.random.default_rng(seed)
    out.mkdir(parents=True, exist_ok=True)
    bodies = []
    for _ in range(min(templates, n_settings)):
        dims = [1.0, *g.uniform(0.05, 1.0, 2).tolist()]
        near = g.uniform(1.2, 2.5, views)
        far = near + g.uniform(0.2, 1.2, views)
        orient = 1.0 / min(dims)
        view_txt = []
        for i in range(views):
            n, f = float(near[i]), float(far[i])
            flat, rng_ = f - n, f / n
            w_u = (flat * rng_ * orient) ** (1 / 3)
            lv = []
            for lvl in levels:
                w_l = float(g.uniform(0.9, 1.1)) * w_u * lvl
                frames = ""
                if latent_frames:
                    ts = np.sort(g.uniform(0, 1, latents)).tolist()
                    frames = (
                        ',"latent_frames":['
                        + ",".join(
                            f'{{"t":{t!r},"r":{3 + t!r},"phi_deg":{60 + t!r},"theta_deg":{t!r},'
                            f'"seed":{int(t * 1e9)}}}'
                            for t in ts
                        )
                        + "]"
                    )
                lv.append(
                    f'"{lvl}":{{"w_l":{w_l!r},"latents":{latents},"motion_px":{10 * w_l!r},'
                    f'"max_gap_px":{10 * w_l / latents!r}{frames}}}'
                )
            extra = ""
            if latent_frames:
                extra = (
                    '"r":3.0,"phi_deg":60.0,"theta_deg":0.0,'
                    '"trajectory":{"dr":1.5,"dphi_deg":-2.0,"dtheta_deg":1.25},'
                    f'"sharp_seed":{i},"c2w":[[1,0,0,0],[0,1,0,0],[0,0,1,3],[0,0,0,1]],'
                )
            view_txt.append(
                f'{{"index":{i},{extra}"near":{n!r},"far":{f!r},"flatness":{flat!r},'
                f'"depth_range":{rng_!r},"orientation":{orient!r},"w_u":{w_u!r},'
                f'"levels":{{{",".join(lv)}}}}}'
            )
        level_dirs = ["sharp", *(f"blur_{lvl}" for lvl in levels)]
        bodies.append(
            f'"resolution":[512,512],"fov_deg":40.0,"bbox_dims":{json.dumps(dims)},'
            f'"views":[{",".join(view_txt)}],'
            f'"test_views":{json.dumps(list(range(0, views, 16)))},'
            f'"levels":{json.dumps(level_dirs)}}}'
        )
    names = []
    for s in range(n_settings):
        uid = f"obj{s // settings_per_object:05d}"
        theta0 = 90 * (s % settings_per_object)
        name = f"{uid}_{theta0:03d}"
        names.append((name, uid))
        d = out / name
        d.mkdir()
        head = f'{{"uid":"{uid}","theta0_deg":{theta0}.0,"seed":{s},'
        (d / "meta.json").write_text(head + bodies[s % len(bodies)])
        (d / ".complete").write_text("synthetic\n")
    objects = sorted({u for _, u in names})
    test_objects = set(objects[::5])
    splits = {
        "view_stride": 16,
        "train": [n for n, u in names if u not in test_objects],
        "test": [n for n, u in names if u in test_objects],
        "test_views": {n: list(range(0, views, 16)) for n, _ in names},
    }
    (out / "splits.json").write_text(json.dumps(splits))
    (out / "failures.jsonl").write_text(
        json.dumps({"uid": "broken", "stage": "load", "reason": "synthetic failure"}) + "\n"
    )


# -- the stand-in worker: real orchestration, analytic renders (tests/standin_worker.py) --

STANDIN_ARGS = (
    "--demo", "--views", "4", "--levels", "1,2", "--latents", "2", "--samples", "2",
    "--resolution", "32", "--settings-per-object", "2", "--quiet",
)  # fmt: skip


@pytest.fixture(scope="session")
def standin_blender(tmp_path_factory) -> Path:
    """A "Blender binary" that is the stand-in worker: `blurset build --blender` it."""
    import shlex
    import sys

    d = tmp_path_factory.mktemp("standin")
    wrapper = d / "blender"
    script = ROOT / "tests" / "standin_worker.py"
    wrapper.write_text(
        f'#!/bin/sh\nexec {shlex.quote(sys.executable)} {shlex.quote(str(script))} "$@"\n'
    )
    wrapper.chmod(0o755)
    return wrapper


def standin_build(
    out: Path, blender: Path, *args: str, check: bool = True, env: dict | None = None
):
    """`blurset build` of the demo objects (or `args`) with the stand-in worker."""
    return run_cli("build", *STANDIN_ARGS, *args, "--blender", str(blender), "--out", str(out),
                   check=check, env=env)  # fmt: skip


@pytest.fixture(scope="session")
def standin_build_dir(tmp_path_factory, standin_blender) -> Path:
    """A finished build of the three demo objects (6 settings) by the stand-in worker;
    tests that change it work on a copy (`copy_build`)."""
    out = tmp_path_factory.mktemp("standin_build") / "b"
    standin_build(out, standin_blender)
    return out


def copy_build(src: Path, dst: Path) -> Path:
    import shutil

    shutil.copytree(src, dst, symlinks=True)
    return dst


def help_text(parser, action) -> str:
    """The help line of `action` in `parser` as the user reads it (defaults expanded),
    whitespace folded."""
    return " ".join(parser._get_formatter()._expand_help(action).split())


# -- waiting on events: CI runs on a busy machine, so a test waits for what a process does
# (a file, a line), with a generous deadline, never for a fixed time.


def wait_until(cond, deadline_s: float = 300.0) -> bool:
    """Whether `cond()` came true within the deadline (polled every 50 ms)."""
    end = time.monotonic() + deadline_s
    while not cond() and time.monotonic() < end:
        time.sleep(0.05)
    return bool(cond())


def wait_for(cond, proc: subprocess.Popen, deadline_s: float = 300.0) -> None:
    """Wait for an event a running process causes; fails at once, with its stderr, if the
    process ended first, and after the deadline if the event never came."""
    end = time.monotonic() + deadline_s
    while not cond():
        if proc.poll() is not None:
            err = b""
            try:
                err = proc.communicate(timeout=30)[1] or b""
            except (ValueError, OSError, subprocess.TimeoutExpired):
                pass  # its stderr is being read elsewhere
            text = err.decode() if isinstance(err, bytes) else err
            raise AssertionError(f"process ended first ({proc.returncode}): {text[-2000:]}")
        if time.monotonic() > end:
            raise AssertionError(f"no event within {deadline_s} s")
        time.sleep(0.05)


def tree(path: Path) -> dict[str, bytes]:
    """Every file and link below `path` by its relative path: a file's bytes, a link's
    target."""
    return {
        str(p.relative_to(path)): (
            p.read_bytes() if not p.is_symlink() else os.readlink(p).encode()
        )
        for p in sorted(path.rglob("*"))
        if p.is_file() or p.is_symlink()
    }


def one_error_line(proc, *words: str, code: int = 2) -> str:
    """Exit `code` with one error line naming `words`: that line."""
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == code, proc.stderr
    assert len(lines) == 1 and "error:" in lines[0], proc.stderr
    for w in words:
        assert w in lines[0], proc.stderr
    return lines[0]


def worker_pids(out: Path) -> list[int]:
    """Pids of live worker processes (real or stand-in) working for the build at `out`."""
    pids = []
    for d in Path("/proc").iterdir():
        if not d.name.isdigit():
            continue
        try:
            cmd = (d / "cmdline").read_bytes().replace(b"\0", b" ").decode()
            state = (d / "stat").read_text().split(")")[-1].split()[0]
        except OSError:
            continue
        if "worker.py" in cmd and str(out) in cmd and state != "Z":
            pids.append(int(d.name))
    return pids


def bench_module(name: str):
    """A bench module, imported as bench/run.py imports it (bench/ on the path)."""
    bench = str(Path(__file__).resolve().parents[1] / "bench")
    sys.path.insert(0, bench)
    try:
        return importlib.import_module(name)
    finally:
        sys.path.remove(bench)


def gen_module(name: str):
    """A docs/gen script as a module (docs/gen on the path while it loads)."""
    gen = Path(__file__).resolve().parents[1] / "docs" / "gen"
    sys.path.insert(0, str(gen))
    try:
        spec = importlib.util.spec_from_file_location(f"docs_gen_{name}", gen / f"{name}.py")
        assert spec is not None and spec.loader is not None
        mod = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(mod)
        return mod
    finally:
        sys.path.remove(str(gen))
