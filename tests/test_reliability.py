"""Reliability of `blurset build` (issue 7, DESIGN §10) on real renders: broken GLBs of
every known class fail with their reason while good objects complete; a hanging worker
is killed at its timeout; transient crashes are retried; a build killed with SIGKILL
three times and resumed equals an uninterrupted one, with no temp files left behind."""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from blurset import layout
from blurset.services.demo import make_demo_objects
from blurset.services.objects import resolve_objects, sanitize, setting_name
from blurset.services.preflight import glb_inspect

from tests.conftest import run_cli, shared_if_present, wait_for

pytestmark = pytest.mark.blender

TINY = (
    "--views", "4", "--levels", "1", "--latents", "2", "--samples", "2",
    "--resolution", "32", "--settings-per-object", "2", "--quiet",
)  # fmt: skip

# name -> (stage, words of the reason)
BROKEN = {
    "zero": ("preflight", "empty file"),
    "random": ("preflight", "not a glTF/GLB file"),
    "truncated": ("preflight", "truncated"),
    "badjson": ("preflight", "not valid JSON"),
    "meshopt": ("preflight", "EXT_meshopt_compression"),
    "missing_texture": ("preflight", "missing texture"),
    "empty_scene": ("preflight", "no triangles"),
    "hangs": ("load", "did not reply within 15 s"),
}


def rewrite_json(src: Path, dst: Path, edit) -> None:
    doc, bin_chunk = glb_inspect.read_glb(str(src))
    edit(doc)
    glb_inspect.write_glb(str(dst), doc, bin_chunk)


def setting_dirs(out: Path) -> list[str]:
    return [d.name for d in layout.complete_settings(out)]


def assert_complete_means_whole(out: Path) -> None:
    """What every reader (finalize, noise, preview, stats) counts as complete is whole:
    never a `.partial`, never a setting missing a file (issue 14)."""
    from blurset.commands.stats import load_stats  # stats' own scan, in Rust

    names = setting_dirs(out)
    assert not any(n.endswith(".partial") for n in names), names
    # The marker is written last: a setting cut short never holds one.
    marked = [p.name for p in out.glob("*.partial") if (p / layout.MARKER).exists()]
    assert marked == [], marked
    for n in names:
        assert layout.setting_problem(out / n) is None, (n, layout.setting_problem(out / n))
    if (out / "dataset.json").exists() or names:
        stats = load_stats(out)
        assert stats["counts"]["settings"] == len(names), stats["counts"]


def failures(out: Path) -> dict[str, dict]:
    lines = (out / "failures.jsonl").read_text().splitlines()
    return {r.get("setting") or r["uid"]: r for r in map(json.loads, lines)}


@pytest.fixture(scope="module")
def demo_glbs(tmp_path_factory) -> list[Path]:
    return make_demo_objects(tmp_path_factory.mktemp("demo"), seed=0)


@pytest.fixture(scope="module")
def objects(tmp_path_factory, demo_glbs) -> Path:
    """Two good objects and one of each broken class (Draco too, when the shared data is
    here: it either builds or fails with its reason)."""
    d = tmp_path_factory.mktemp("objects")
    box, cyl = demo_glbs[0], demo_glbs[1]
    shutil.copy(box, d / "box.glb")
    shutil.copy(cyl, d / "cylinder.glb")
    (d / "zero.glb").write_bytes(b"")
    (d / "random.glb").write_bytes(np.random.default_rng(1).bytes(3000))
    data = box.read_bytes()
    (d / "truncated.glb").write_bytes(data[: len(data) // 2])
    (d / "badjson.glb").write_bytes(data[:20] + b"{" * 64 + data[84:])

    def meshopt(doc):
        doc.setdefault("extensionsUsed", []).append("EXT_meshopt_compression")

    def external_texture(doc):
        img = doc["images"][0]
        img.pop("bufferView")
        img["uri"] = "textures/gone.png"

    rewrite_json(box, d / "meshopt.glb", meshopt)
    rewrite_json(box, d / "missing_texture.glb", external_texture)
    rewrite_json(box, d / "empty_scene.glb", lambda doc: doc.pop("meshes"))
    shutil.copy(box, d / "hangs.glb")
    draco = shared_if_present("glb", "edge_BoxTextured_draco.glb")
    if draco is not None:
        shutil.copy(draco, d / "draco.glb")
    return d


@pytest.fixture(scope="module")
def broken_build(objects, tmp_path_factory):
    out = tmp_path_factory.mktemp("broken") / "out"
    proc = run_cli(
        "build", "--objects", str(objects), "--out", str(out), *TINY,
        "--timeout", "15", "--retries", "0",
        env={"BLURSET_WORKER_FAULT": "hang:hangs.glb"}, check=False,
    )  # fmt: skip
    return out, proc


def test_each_broken_class_fails_with_its_reason_good_objects_complete(broken_build):
    out, proc = broken_build
    assert proc.returncode == 0, proc.stderr  # failures within --max-failure-rate (1.0)
    fails = failures(out)
    for name, (stage, words) in BROKEN.items():
        rec = fails.pop(name)
        assert rec["stage"] == stage and words in rec["reason"], rec
        assert rec["path"].endswith(f"{name}.glb") and rec["seconds"] >= 0
    done = setting_dirs(out)
    for good in ("box", "cylinder"):
        assert [setting_name(good, t) for t in (0, 180)] == [d for d in done if d.startswith(good)]
    if "draco" in fails:  # failing is allowed, silently is not
        assert "Draco" in fails.pop("draco")["reason"]
    elif shared_if_present("glb", "edge_BoxTextured_draco.glb") is not None:
        assert {"draco_000", "draco_180"} <= set(done)
    assert not fails, fails
    n_failed = len(BROKEN)
    assert f"{n_failed} of " in proc.stderr and "objects failed" in proc.stderr
    assert "hangs: load: Blender worker did not reply within 15 s" in proc.stderr
    # Nothing of the builder's machine under OUT: its absolute paths live elsewhere.
    leftovers = [p.name for p in out.iterdir() if p.name.startswith(".") and p.name != ".lock"]
    assert leftovers == [], leftovers


def test_rerun_retries_failed_objects_and_max_failure_rate_fails_the_build(broken_build, objects):
    out, _ = broken_build
    before = setting_dirs(out)
    # Without the injected hang, `hangs` (a good box) now builds and leaves failures.jsonl;
    # the seven broken files still fail: 7 of 10+ objects is above a 0.2 ceiling.
    objects_dir = objects  # dataset.json names inputs without their path (issue 19)
    proc = run_cli(
        "build", "--objects", str(objects_dir), "--out", str(out), *TINY,
        "--max-failure-rate", "0.2", check=False,
    )  # fmt: skip
    assert proc.returncode == 1, proc.stderr
    assert "more than --max-failure-rate 0.2" in proc.stderr
    fails = failures(out)
    assert "hangs" not in fails and {"hangs_000", "hangs_180"} <= set(setting_dirs(out))
    assert set(before) <= set(setting_dirs(out))
    assert {k for k in fails if k != "draco"} == set(BROKEN) - {"hangs"}


def test_transient_crash_is_retried(demo_glbs, tmp_path):
    out = tmp_path / "out"
    flag = tmp_path / "crashed-once"
    proc = run_cli(
        "build", "--objects", str(demo_glbs[2]), "--out", str(out), *TINY, "--retries", "1",
        env={"BLURSET_WORKER_FAULT": f"crash_once:demo_vase:{flag}"}, check=False,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    assert flag.exists(), "the fault was not injected: the test would prove nothing"
    assert "retrying demo_vase (attempt 2) after: Blender worker exited with code -9" in (
        proc.stderr
    )
    assert setting_dirs(out) == ["demo_vase_000", "demo_vase_180"]
    assert (out / "failures.jsonl").read_text() == ""


def test_object_timeout_is_a_budget_not_retried(demo_glbs, tmp_path):
    out = tmp_path / "out"
    t0 = time.monotonic()
    proc = run_cli(
        "build", "--objects", str(demo_glbs[0]), "--out", str(out), *TINY,
        "--object-timeout", "4", "--retries", "3",
        env={"BLURSET_WORKER_FAULT": "hang:demo_box"}, check=False,
    )  # fmt: skip
    assert time.monotonic() - t0 < 60
    assert proc.returncode == 1  # nothing was built
    rec = failures(out)["demo_box"]
    assert "exceeded its time budget (--object-timeout)" in rec["reason"]
    assert rec["attempts"] == 1 and 3.5 < rec["seconds"] < 30


def test_saturated_views_fail_their_setting_with_the_reason(demo_glbs, tmp_path):
    """A glowing object passes the load checks but every sharp view is clipped: each
    setting fails render QA on its own, recorded with its name; nothing half-written."""

    def glow(doc):
        for m in doc["materials"]:
            m["emissiveFactor"] = [1.0, 1.0, 1.0]
            m.setdefault("extensions", {})["KHR_materials_emissive_strength"] = {
                "emissiveStrength": 50.0
            }
        doc.setdefault("extensionsUsed", []).append("KHR_materials_emissive_strength")

    glb = tmp_path / "glow.glb"
    rewrite_json(demo_glbs[1], glb, glow)
    out = tmp_path / "out"
    proc = run_cli("build", "--objects", str(glb), "--out", str(out), *TINY, check=False)
    assert proc.returncode == 1, proc.stderr
    fails = failures(out)
    assert set(fails) == {"glow_000", "glow_180"}
    for name, rec in fails.items():
        assert rec["stage"] == "qa" and rec["setting"] == name and rec["uid"] == "glow"
        assert "render QA: view 0 is saturated" in rec["reason"]
    assert [p.name for p in out.iterdir() if p.name.startswith("glow")] == []
    assert "2 settings failed QA" in proc.stderr


# --------------------------------------------------------------------------- kill -9


def run_build(objects: Path, out: Path, env=None) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-m", "blurset.cli", "build", "--objects", str(objects),
         "--out", str(out), *TINY],
        stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, env={**os.environ, **(env or {})},
        start_new_session=True,  # its own process group: the kill takes Blender too
    )  # fmt: skip


def tree(out: Path) -> dict[str, bytes]:
    return {
        str(p.relative_to(out)): p.read_bytes()
        for p in sorted(out.rglob("*"))
        if p.is_file() and p.name != ".lock" and ".locks" not in p.parts
    }


def without_timings(name: str, data: bytes):
    if name.endswith(".complete"):
        return "marker"  # holds the time it was written
    if name.endswith("meta.json"):
        meta = json.loads(data)
        meta.pop("timings")
        return meta
    if name == "dataset.json":
        ds = json.loads(data)
        for k in ("created", "seconds"):
            ds.pop(k)
        ds["config"].pop("out")
        return ds
    if name == "MANIFEST.sha256":  # hashes meta.json timings: the files it lists
        return [line.split("  ", 1)[1] for line in data.decode().splitlines()]
    if name == "failures.jsonl":
        recs = [json.loads(line) for line in data.decode().splitlines()]
        return [{k: v for k, v in r.items() if k not in ("seconds", "time")} for r in recs]
    return data


def test_killed_three_times_then_resumed_equals_an_uninterrupted_build(objects, tmp_path):
    # Broken objects of every class, good ones, and no injected hang.
    objs = tmp_path / "objs"
    shutil.copytree(objects, objs, ignore=shutil.ignore_patterns("hangs.glb"))
    clean, killed = tmp_path / "clean", tmp_path / "killed"
    p = run_build(objs, clean)
    _, err = p.communicate(timeout=600)
    assert p.returncode == 0, err.decode()[-2000:]

    def partial_exists():
        # A setting in progress: its .partial folder lives for the whole setting, a
        # frame's EXR only until the driver adds it (missed between polls when idle).
        return killed.exists() and any(killed.glob("*.partial"))

    def one_more_complete(n):
        return lambda: killed.exists() and len(setting_dirs(killed)) > n

    kill_points = [
        partial_exists,  # mid-render of the first setting
        one_more_complete(0),  # right after a setting was renamed into place
        partial_exists,  # mid-render again, after a resume
    ]
    for cond in kill_points:
        n_before = len(setting_dirs(killed)) if killed.exists() else 0
        p = run_build(objs, killed)
        if cond is kill_points[1]:
            cond = one_more_complete(n_before)
        wait_for(cond, p, 120.0)
        os.killpg(p.pid, signal.SIGKILL)
        p.wait()
        p.stderr.close()
        assert_complete_means_whole(killed)
    # The kills did leave debris for the resume to clean up.
    debris = [n for n in tree(killed) if ".partial" in n or ".work-" in n]
    assert debris
    n_done = len(setting_dirs(killed))
    p = run_build(objs, killed)
    _, err = p.communicate(timeout=600)
    assert p.returncode == 0, err.decode()[-2000:]
    # The rerun says that it resumed, and what it found.
    assert f"resuming: {n_done} of " in err.decode(), err.decode()[-2000:]

    a, b = tree(clean), tree(killed)
    assert sorted(a) == sorted(b), set(a) ^ set(b)
    for name in a:
        assert without_timings(name, a[name]) == without_timings(name, b[name]), name
    temp = [
        n
        for n in b
        if ".tmp" in n or ".partial" in n or ".work-" in n or n.startswith(".")
        or ("/." in n and not n.endswith("/.complete"))
    ]  # fmt: skip
    assert temp == []
    assert setting_dirs(killed) == setting_dirs(clean) != []


# --------------------------------------------------------------------------- untrusted


def test_object_names_cannot_escape_out(tmp_path):
    """Output directories come from sanitized ids, never from file or list contents."""
    src = tmp_path / "a" / "b"
    src.mkdir(parents=True)
    names = ["..glb", "...glb", "x y;rm -rf ~.glb", "çà.glb", "-.glb"]
    for n in names:
        (src / n).write_bytes(b"glTF")
    listing = tmp_path / "list.txt"
    listing.write_text("".join(f"a/b/../b/{n}\n" for n in names))
    out = tmp_path / "out"
    for spec in resolve_objects([str(listing)]):
        assert spec.uid == sanitize(spec.uid) and "/" not in spec.uid and spec.uid.strip(".")
        d = (out / setting_name(spec.uid, 90.0)).resolve()
        assert d.parent == out.resolve()
    assert sanitize("../../etc/passwd") == "etc_passwd"


@pytest.mark.parametrize(
    "args, words",
    [
        (("--retries", "-1"), "--retries"),
        (("--max-failure-rate", "2"), "--max-failure-rate"),
        (("--object-timeout", "-5"), "--object-timeout"),
        (("--config", "/no/such/build.toml"), "/no/such/build.toml"),
        (("--objects", "/no/such/dir"), "/no/such/dir"),
    ],
)
def test_bad_options_one_line_nonzero_nothing_written(tmp_path, args, words):
    out = tmp_path / "out"
    base = () if "--objects" in args else ("--demo",)
    proc = run_cli("build", *base, "--out", str(out), *args, check=False)
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and words in lines[0] and "Traceback" not in proc.stderr
    assert not out.exists()
