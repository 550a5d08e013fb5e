"""Nothing lost, nothing orphaned (issue 14): each reproduction of the hostile user's
report, as a test. Outputs never overlap inputs; signals stop a command within about a
second and leave no Blender process behind; a full disk is named, not a traceback."""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from blurset import layout
from blurset.services.demo import make_demo_objects
from PIL import Image

from tests.conftest import (
    one_error_line,
    run_cli,
    shared,
    skip_or_fail_in_ci,
    wait_until,
    worker_pids,
)


def tree(path: Path) -> dict[str, bytes]:
    return {
        str(p.relative_to(path)): p.read_bytes() for p in sorted(path.rglob("*")) if p.is_file()
    }


@pytest.fixture
def fern_copy(tmp_path) -> Path:
    f1 = tmp_path / "f1"
    shutil.copytree(shared("llff", "fern"), f1)
    return f1


# -- outputs never overlap inputs (D1, D2, D9) -------------------------------------------


@pytest.mark.parametrize("where", ["scene", "images_8", "parent"])
def test_noise_out_over_its_scene_is_refused_and_the_scene_kept(fern_copy, where):
    before = tree(fern_copy.parent)
    out = {"scene": fern_copy, "images_8": fern_copy / "images_8", "parent": fern_copy.parent}[
        where
    ]
    proc = run_cli("noise", str(fern_copy), "--factor", "8", "--gains", "1", "--out", str(out),
                   "--overwrite", check=False)  # fmt: skip
    one_error_line(proc, "--out")
    assert tree(fern_copy.parent) == before


def test_noise_gains_that_share_a_folder_are_refused(fern_copy, tmp_path):
    proc = run_cli("noise", str(fern_copy), "--factor", "8", "--gains", "1", "1.0000001",
                   "--any-gain", "--out", str(tmp_path / "n"), check=False)  # fmt: skip
    one_error_line(proc, "gain_1/")
    assert not (tmp_path / "n").exists()


def test_a_killed_noise_runs_temp_tree_is_removed_by_the_next_run(fern_copy, tmp_path):
    out = tmp_path / "n"
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()  # a pid that is no longer alive, as a SIGKILLed run's
    # What SIGKILL leaves: OUT with the run's lock file and its staging tree.
    stale = out / f".noise.tmp{dead.pid}"
    (stale / "gain_1" / "images").mkdir(parents=True)
    (out / ".noise.lock").write_text(f"pid {dead.pid}")
    mine = out / ".notes.tmp1"  # the user's, not ours: kept
    mine.write_text("keep me")
    run_cli("noise", str(fern_copy), "--factor", "8", "--gains", "1", "--out", str(out))
    assert not stale.exists() and mine.read_text() == "keep me"
    # An old gain a killed run had moved aside while replacing it goes with the rerun.
    aside = out / f".gain_1.tmp{dead.pid}"
    (aside / "images").mkdir(parents=True)
    run_cli("noise", str(fern_copy), "--factor", "8", "--gains", "1", "--out", str(out),
            "--overwrite")  # fmt: skip
    assert not aside.exists() and mine.read_text() == "keep me"
    assert sorted(p.name for p in out.iterdir()) == [".notes.tmp1", "gain_1", "noise_scene.json"]


def test_sigterm_during_noise_leaves_nothing(fern_copy, tmp_path):
    """A stop does not wait for the core's noise call. Timed against the call itself, in
    the same run (the machine may be busy): the stop takes a small part of the time the
    rest of the call would."""
    out = tmp_path / "n"
    proc = subprocess.Popen(
        [sys.executable, "-m", "blurset.cli", "noise", str(fern_copy), "--factor", "8",
         "--frames", "40", "--out", str(out)],
        stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    total = 20 * 40 * 6  # views x frames x gains

    def written() -> int:
        return sum(1 for _ in out.glob(f".noise.tmp{proc.pid}/gain_*/images_8/*.png"))

    assert wait_until(lambda: written() >= 20 or proc.poll() is not None, 600)
    t_a, n_a = time.monotonic(), written()
    assert wait_until(lambda: written() >= n_a + 40 or proc.poll() is not None, 600)
    t_b, n_b = time.monotonic(), written()
    assert proc.poll() is None, "the noise run ended before it could be stopped"
    rest_s = (total - n_b) * (t_b - t_a) / max(1, n_b - n_a)
    t0 = time.monotonic()
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=600)
    took = time.monotonic() - t0
    assert took < rest_s / 4, f"SIGTERM took {took:.1f} s; the rest of the call ~{rest_s:.0f} s"
    assert proc.returncode == 128 + signal.SIGTERM, err
    assert "interrupted (SIGTERM)" in err
    assert not out.exists()
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []


@pytest.mark.blender
def test_previews_and_stats_never_write_into_a_setting(demo_build, tmp_path):
    setting = layout.complete_settings(demo_build)[0]
    image = setting / "sharp" / "images" / "000.png"
    before = tree(setting)
    proc = run_cli("preview", str(setting), "--out", str(image), check=False)
    one_error_line(proc, "inside the build setting")
    proc = run_cli("stats", str(demo_build), "--out", str(setting / "sharp" / "images"),
                   check=False)  # fmt: skip
    one_error_line(proc, "inside the build setting")
    assert tree(setting) == before
    # A figure is written in the format its name says.
    jpg = tmp_path / "fig.jpg"
    run_cli("preview", str(setting), "--out", str(jpg))
    assert Image.open(jpg).format == "JPEG"


@pytest.mark.blender
def test_noise_of_a_build_into_its_parent_is_refused(demo_build):
    before = sorted(p.name for p in demo_build.iterdir())
    proc = run_cli("noise", str(demo_build), "--gains", "1", "--out", str(demo_build.parent),
                   "--overwrite", check=False)  # fmt: skip
    one_error_line(proc, "contains the input")
    assert sorted(p.name for p in demo_build.iterdir()) == before


# -- the build's OUT (D8) ------------------------------------------------------------------

TINY = ("--views", "2", "--levels", "1", "--latents", "2", "--samples", "2",
        "--resolution", "16", "--settings-per-object", "1", "--quiet")  # fmt: skip


def test_a_folder_that_is_not_a_build_is_refused(tmp_path):
    glb = make_demo_objects(tmp_path / "objs", seed=0)[0]
    out = tmp_path / "mine"
    out.mkdir()
    (out / "thesis.tex").write_text("years of work")
    proc = run_cli("build", "--objects", str(glb), "--out", str(out), *TINY, check=False)
    one_error_line(proc, "not a blurset build")
    assert sorted(p.name for p in out.iterdir()) == ["thesis.tex"]
    proc = run_cli("build", "--objects", str(tmp_path / "objs"), "--out",
                   str(tmp_path / "objs" / "out"), *TINY, check=False)  # fmt: skip
    one_error_line(proc, "inside the input")


@pytest.mark.blender
def test_a_build_keeps_the_users_dotfiles_in_out(tmp_path):
    glb = make_demo_objects(tmp_path / "objs", seed=0)[0]
    out = tmp_path / "out"
    run_cli("build", "--objects", str(glb), "--out", str(out), *TINY)
    kept = {".notes.tmp1": "a", ".config.tmpl": "b", ".dataset.json.tmp1": "c"}
    for name, text in kept.items():
        (out / name).write_text(text)
    run_cli("build", "--objects", str(glb), "--out", str(out), *TINY)
    for name, text in kept.items():
        assert (out / name).read_text() == text, name


# -- signals: stop within ~1 s, no Blender left (H1, H2) -----------------------------------


@pytest.fixture(scope="module")
def objs(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("objs")
    make_demo_objects(d, seed=0)
    return d


def start_build(objs: Path, out: Path, *extra: str) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-m", "blurset.cli", "build", "--objects", str(objs), "--out", str(out),
         "--views", "4", "--levels", "1", "--latents", "6", "--samples", "32",
         "--resolution", "64", "--settings-per-object", "1", "--quiet", *extra],
        stderr=subprocess.PIPE, text=True,
    )  # fmt: skip


@pytest.mark.blender
@pytest.mark.parametrize(("sig", "workers", "rerun"), [(signal.SIGINT, "2", True),
                         (signal.SIGTERM, "1", False), (signal.SIGHUP, "2", False)])  # fmt: skip
def test_a_signal_stops_the_build_and_its_workers(objs, tmp_path, sig, workers, rerun):
    out = tmp_path / "out"
    proc = start_build(objs, out, "--workers", workers)
    assert wait_until(lambda: len(worker_pids(out)) == int(workers), 600), proc.stderr
    # Mid-build: a setting is in progress (an event, not a sleep). Its .partial folder
    # lives for the whole setting; a frame's EXR only until the driver adds it, which an
    # idle machine can finish between two polls.
    assert wait_until(lambda: any(out.glob("*.partial")), 600), proc.stderr
    proc.send_signal(sig)
    _, err = proc.communicate(timeout=600)
    assert proc.returncode == 128 + sig, err
    # The workers die with the stop; generous deadlines, CI's machine is busy.
    assert wait_until(lambda: worker_pids(out) == [], 120), worker_pids(out)
    # No failure was recorded for the objects that were stopped, and a rerun finishes.
    fails = out / "failures.jsonl"
    assert not fails.exists() or fails.read_text().strip() == ""
    if rerun:
        again = start_build(objs, out, "--workers", workers)
        _, err = again.communicate(timeout=600)
        assert again.returncode == 0, err
        assert len(layout.complete_settings(out)) == 3


@pytest.mark.blender
def test_a_killed_build_leaves_no_blender_behind(objs, tmp_path):
    out = tmp_path / "out"
    proc = start_build(objs, out)
    assert wait_until(lambda: len(worker_pids(out)) == 1, 600), proc.stderr
    proc.kill()  # SIGKILL: no handler runs; the worker must die with its parent
    proc.wait()
    assert wait_until(lambda: worker_pids(out) == [], 120), worker_pids(out)


def test_a_worker_flooding_stdout_still_times_out(tmp_path):
    """H3: `--blender` that prints endless non-protocol lines: the reply deadline holds
    and memory stays bounded (the pipe fills, the worker blocks)."""
    fake = tmp_path / "blender"
    fake.write_text("#!/bin/sh\nwhile :; do echo 'not json, never a reply'; done\n")
    fake.chmod(0o755)
    glb = make_demo_objects(tmp_path / "objs", seed=0)[0]
    t0 = time.monotonic()
    proc = run_cli("build", "--objects", str(glb), "--out", str(tmp_path / "out"), "--blender",
                   str(fake), "--timeout", "3", "--retries", "0", *TINY, check=False)  # fmt: skip
    assert time.monotonic() - t0 < 600  # the deadline holds: no endless wait
    assert proc.returncode == 1, proc.stderr
    rec = json.loads((tmp_path / "out" / "failures.jsonl").read_text().splitlines()[0])
    assert rec["stage"] == "start" and "within 3 s" in rec["reason"], rec


# -- a full disk (U4) ----------------------------------------------------------------------


@pytest.fixture
def small_disk(tmp_path):
    mnt = tmp_path / "disk"
    mnt.mkdir()
    r = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=3m", "tmpfs", str(mnt)],
                       capture_output=True, text=True)  # fmt: skip
    if r.returncode != 0:
        skip_or_fail_in_ci(f"cannot mount a small tmpfs here ({r.stderr.strip()})")
    yield mnt
    subprocess.run(["umount", "-l", str(mnt)], check=False)


@pytest.mark.blender
def test_a_full_disk_stops_the_build_naming_it(objs, small_disk):
    out = small_disk / "out"
    proc = subprocess.run(
        [sys.executable, "-m", "blurset.cli", "build", "--objects", str(objs), "--out", str(out),
         "--views", "4", "--levels", "1", "--latents", "4", "--samples", "2",
         "--resolution", "256", "--settings-per-object", "1", "--keep-linear", "--quiet"],
        capture_output=True, text=True, timeout=600,
    )  # fmt: skip
    assert proc.returncode != 0, proc.stderr
    assert "No space left on device" in proc.stderr, proc.stderr
    assert "Traceback" not in proc.stderr and "IndexError" not in proc.stderr, proc.stderr
    # Whatever is complete is whole: every image its meta.json promises is there.
    for s in layout.complete_settings(out):
        meta = json.loads((s / "meta.json").read_text())
        for lvl in meta["levels"]:
            assert len(list((s / lvl / "images").glob("*.png"))) == len(meta["views"])
    assert os.path.ismount(small_disk)


# -- one OUT, one object, two processes (D3); mixed options (D5); damage (D6) --------------


@pytest.mark.blender
def test_two_identical_builds_at_once_take_turns_per_object(objs, tmp_path):
    out = tmp_path / "out"
    first = start_build(objs, out)
    assert wait_until(lambda: len(worker_pids(out)) == 1, 120), first.stderr
    second = start_build(objs, out)
    _, err1 = first.communicate(timeout=900)
    _, err2 = second.communicate(timeout=900)
    assert first.returncode == 0 and second.returncode == 0, (err1, err2)
    assert "is being built by pid" in err1 + err2
    names = [d.name for d in layout.complete_settings(out)]
    assert len(names) == 3, names
    for n in names:
        assert layout.setting_problem(out / n) is None, n
    assert not (out / "failures.jsonl").read_text().strip()


@pytest.fixture
def one_glb(tmp_path) -> Path:
    return make_demo_objects(tmp_path / "objs", seed=0)[0]


@pytest.mark.blender
def test_a_rerun_with_other_options_is_refused_unless_mixing_is_allowed(one_glb, tmp_path):
    out = tmp_path / "out"
    run_cli("build", "--objects", str(one_glb), "--out", str(out), *TINY)
    before = tree(out)
    other = ["--views", "3", "--resolution", "24", "--levels", "1", "--latents", "2",
             "--samples", "2", "--settings-per-object", "1", "--quiet"]  # fmt: skip
    proc = run_cli("build", "--objects", str(one_glb), "--out", str(out), *other, check=False)
    one_error_line(proc, "--views 2", "--resolution 16", "--allow-mixed")
    assert tree(out) == before
    # Options that do not shape the files may change.
    run_cli("build", "--objects", str(one_glb), "--out", str(out), *TINY, "--workers", "2",
            "--timeout", "100")  # fmt: skip
    run_cli("build", "--objects", str(one_glb), "--out", str(out), *other, "--allow-mixed")


@pytest.mark.blender
def test_damage_in_a_complete_setting_is_named_and_redone(one_glb, tmp_path):
    out = tmp_path / "out"
    run_cli("build", "--objects", str(one_glb), "--out", str(out), *TINY)
    (setting,) = layout.complete_settings(out)
    whole = tree(setting)

    def truncate_png():
        p = setting / "sharp" / "images" / "000.png"
        p.write_bytes(p.read_bytes()[:40])

    damages = {
        "sharp/images/000.png is": truncate_png,
        "blur_1/poses_bounds.npy is missing": lambda: (
            setting / "blur_1" / "poses_bounds.npy"
        ).unlink(),
        "level folder blur_1/ is missing": lambda: shutil.rmtree(setting / "blur_1"),
        "meta.json is unreadable": lambda: (setting / "meta.json").write_text("[]"),
    }
    for words, damage in damages.items():
        damage()
        proc = run_cli("build", "--objects", str(one_glb), "--out", str(out), *TINY)
        assert f"redoing {setting.name}: {words}" in proc.stderr, proc.stderr
        assert layout.setting_problem(setting) is None
        again = tree(setting)
        assert sorted(again) == sorted(whole)
        for name in whole:
            if not name.endswith(("meta.json", ".complete")):
                assert again[name] == whole[name], name


def test_a_worker_that_fails_or_is_killed_leaves_nothing_in_the_temp_folder(
    tmp_path, standin_blender, monkeypatch
):
    """A worker without a log path or workdir keeps both in the temp folder: closing it
    removes them whether it never started, was killed mid-object or quit."""
    import tempfile

    from blurset.services.worker_client import Worker, WorkerError

    temp = tmp_path / "temp"
    temp.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(temp))
    mute = tmp_path / "mute"  # a "Blender" that exits before its ready line
    mute.write_text("#!/bin/sh\nexit 3\n")
    mute.chmod(0o755)
    for blender in (str(tmp_path / "no-such-blender"), str(mute)):
        with pytest.raises(WorkerError):
            Worker(blender=blender, timeout=600)
        assert not list(temp.iterdir()), blender
    glb = make_demo_objects(tmp_path / "objs")[0]
    with Worker(blender=str(standin_blender), timeout=600) as w:
        w.load(glb, tmp_path / "v.npy")
        assert len(list(temp.iterdir())) == 2  # its log and its scratch, while it runs
        w.kill()  # as a timeout does: the worker cleans up nothing itself
    assert not list(temp.iterdir())
