"""Nothing a user keeps is ever deleted: one owner for every output (blurset.services.outputs,
blurset-core dataset::outputs), readers that check what they read. Each reproduction of
the hostile user's report is a test here; the builds are real `blurset build` runs with
the stand-in worker (tests/standin_worker.py), so none of them renders with Blender."""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest
from blurset import layout
from blurset.services import outputs, publish
from blurset.services.demo import make_demo_objects

from tests.conftest import (
    ROOT,
    copy_build,
    one_error_line,
    run_cli,
    shared,
    standin_build,
    tree,
    wait_for,
    wait_until,
    worker_pids,
)


@pytest.fixture
def b(standin_build_dir, tmp_path) -> Path:
    """A finished stand-in build of 6 settings that the test may change."""
    return copy_build(standin_build_dir, tmp_path / "b")


# -- export lives beside what else its folder holds -------------------------------------


def test_export_keeps_what_lives_beside_it(b, tmp_path):
    data = tmp_path / "data"
    (data / "nerf_llff_data" / "fern" / "images_4").mkdir(parents=True)
    (data / "nerf_llff_data" / "fern" / "poses_bounds.npy").write_bytes(b"the user's fern")
    run_cli("export", str(b), "--out", str(data))
    (data / "other_set").mkdir()
    (data / "other_set" / "x.txt").write_text("keep")
    (data / "model.pth").write_bytes(b"weights")
    mine = tree(data / "nerf_llff_data" / "fern") | {"model": b"weights"}
    run_cli("export", str(b), "--out", str(data), "--levels", "blur_2")
    assert (data / "other_set" / "x.txt").read_text() == "keep"
    assert (data / "model.pth").read_bytes() == b"weights"
    assert tree(data / "nerf_llff_data" / "fern") | {"model": b"weights"} == mine
    scenes = sorted(p.name for p in (data / "nerf_llff_data").iterdir())
    want = ["fern"] + [f"{s.name}__blur_2" for s in layout.complete_settings(b)]
    assert scenes == sorted(want)
    doc = json.loads((data / "export.json").read_text())
    assert doc["build"] == "b" and "owns" not in doc and "state" not in doc


def test_export_refuses_to_write_over_what_it_did_not_write(b, tmp_path):
    data = tmp_path / "data"
    data.mkdir()
    (data / "train.txt").write_text("the user's list\n")
    before = tree(data)
    one_error_line(run_cli("export", str(b), "--out", str(data), check=False), "train.txt")
    assert tree(data) == before
    (data / "train.txt").unlink()
    name = f"{layout.complete_settings(b)[0].name}__sharp"
    (data / "nerf_llff_data" / name).mkdir(parents=True)
    one_error_line(run_cli("export", str(b), "--out", str(data), check=False), name)


def test_export_of_another_build_needs_overwrite_and_keeps_the_rest(b, tmp_path):
    data = tmp_path / "data"
    run_cli("export", str(b), "--out", str(data), "--levels", "sharp")
    other = copy_build(b, tmp_path / "other")
    (data / "notes.txt").write_text("keep")
    one_error_line(
        run_cli("export", str(other), "--out", str(data), check=False), "'b'", "--overwrite"
    )
    run_cli("export", str(other), "--out", str(data), "--levels", "blur_1", "--overwrite")
    assert (data / "notes.txt").read_text() == "keep"
    assert all(p.name.endswith("__blur_1") for p in (data / "nerf_llff_data").iterdir())


def test_a_noise_export_does_not_replace_the_clean_one_by_itself(b, tmp_path):
    """IBRNet and GNT read one root's data/ only: the blur + noise scenes go to a second
    root. An export with another --noise (or none) where the clean one is names that
    root and --overwrite, and changes nothing; the second root takes it."""
    data, noise = tmp_path / "root" / "data", tmp_path / "n"
    run_cli("noise", str(b), "--out", str(noise), "--gains", "4", "--levels", "blur_1",
            "--quiet")  # fmt: skip
    run_cli("export", str(b), "--out", str(data), "--levels", "blur_1")
    clean = sorted(p.name for p in (data / "nerf_llff_data").iterdir())
    line = one_error_line(
        run_cli("export", str(b), "--noise", str(noise), "--out", str(data), check=False),
        "without --noise", "'n'", "ROOTN/data", "--rootdir ROOTN", "--overwrite",
    )  # fmt: skip
    assert str(data) in line
    assert sorted(p.name for p in (data / "nerf_llff_data").iterdir()) == clean
    run_cli("export", str(b), "--noise", str(noise), "--out", str(tmp_path / "rootn" / "data"))
    noisy = sorted(p.name for p in (tmp_path / "rootn" / "data" / "nerf_llff_data").iterdir())
    assert noisy == [f"{n}__gain_4" for n in clean]
    # The reverse too, and --overwrite replaces.
    rootn = tmp_path / "rootn" / "data"
    one_error_line(run_cli("export", str(b), "--out", str(rootn), check=False), "'n'")
    run_cli("export", str(b), "--out", str(rootn), "--levels", "blur_1", "--overwrite")
    assert sorted(p.name for p in (rootn / "nerf_llff_data").iterdir()) == clean


def test_export_out_as_a_dangling_link_is_one_line(b, tmp_path):
    link = tmp_path / "gone"
    link.symlink_to(tmp_path / "nowhere")
    one_error_line(run_cli("export", str(b), "--out", str(link), check=False), "--out", "link")
    assert link.is_symlink() and not (tmp_path / "nowhere").exists()


def test_export_stopped_half_way_still_owns_its_entries(b, tmp_path):
    """An export.json left by a stop while replacing names every entry it may have put
    in place: the rerun replaces them instead of refusing them as foreign."""
    data = tmp_path / "data"
    run_cli("export", str(b), "--out", str(data), "--levels", "sharp")
    doc = json.loads((data / "export.json").read_text())
    extra = "nerf_llff_data/half_written__blur_9"
    (data / extra).mkdir()
    (data / "export.json").write_text(
        json.dumps(
            {
                "kind": "blurset export",
                "state": "replacing",
                "build": "b",
                "scenes_dir": "nerf_llff_data",
                "scenes": {},
                "owns": sorted(f"nerf_llff_data/{s}" for s in doc["scenes"]) + [extra],
            }
        )
    )
    run_cli("export", str(b), "--out", str(data), "--levels", "blur_1")
    assert not (data / extra).exists()
    assert json.loads((data / "export.json").read_text())["levels"] == ["blur_1"]


def test_export_records_no_builder_path_and_the_builds_llffhold(standin_blender, tmp_path):
    out = tmp_path / "stride"
    standin_build(out, standin_blender, "--views", "9", "--test-view-stride", "8")
    data = tmp_path / "data"
    p = run_cli("export", str(out), "--out", str(data))
    assert "use llffhold 8" in p.stdout
    doc = json.loads((data / "export.json").read_text())
    assert doc["llffhold"] == 8
    text = (data / "export.json").read_text()
    assert str(tmp_path) not in text and str(Path.home()) not in text
    for src in doc["scenes"].values():
        assert not Path(src).is_absolute() and ".." not in Path(src).parts


# -- noise --overwrite replaces a noise output, nothing else -------------------------------


def test_noise_overwrite_refuses_a_build_and_a_foreign_folder(b, tmp_path):
    other = copy_build(b, tmp_path / "other")
    before = tree(other)
    line = one_error_line(
        run_cli("noise", str(b), "--out", str(other), "--overwrite", check=False), "build"
    )
    assert tree(other) == before
    thesis = tmp_path / "thesis"
    thesis.mkdir()
    (thesis / "thesis.tex").write_text("\\documentclass{article}")
    line = one_error_line(
        run_cli("noise", str(b), "--out", str(thesis), "--overwrite", check=False),
        "not a blurset noise output",
    )
    assert "--overwrite" not in line  # the refusal does not advise deleting the folder
    assert (thesis / "thesis.tex").read_text() == "\\documentclass{article}"


def test_noise_overwrite_keeps_the_users_files_in_a_noise_output(b, tmp_path):
    out = tmp_path / "noisy"
    run_cli("noise", str(b), "--out", str(out), "--gains", "1", "--levels", "blur_1", "--quiet")
    setting = layout.complete_settings(b)[0].name
    (out / "my_notes.md").write_text("keep")
    (out / setting / "notes.txt").write_text("keep too")
    run_cli("noise", str(b), "--out", str(out), "--gains", "4", "--levels", "blur_1",
            "--overwrite", "--quiet")  # fmt: skip
    assert (out / "my_notes.md").read_text() == "keep"
    assert (out / setting / "notes.txt").read_text() == "keep too"
    assert sorted(p.name for p in (out / setting / "blur_1").iterdir()) == ["gain_4"]
    # The user's notes are not the output's files: notes of verify, not damage.
    assert run_cli("verify", str(out), check=False).returncode == 0


def test_a_second_noise_run_into_the_same_out_is_refused_while_one_writes(b, tmp_path):
    out = tmp_path / "noisy"
    # The lock a noise run holds, taken here by the owner's own code: deterministic.
    with outputs.lock(out, outputs.OutputKind.NOISE):
        one_error_line(
            run_cli("noise", str(b), "--out", str(out), "--gains", "1", check=False),
            "being written by another blurset run",
        )
    assert not (out / "noise_dataset.json").exists()
    run_cli("noise", str(b), "--out", str(out), "--gains", "1", "--quiet")


def test_scene_noise_overwrite_replaces_only_its_gains(tmp_path):
    fern = shared("llff", "fern")
    out = tmp_path / "n"
    run_cli("noise", str(fern), "--factor", "8", "--gains", "1", "--out", str(out))
    (out / "README.txt").write_text("keep")
    run_cli("noise", str(fern), "--factor", "8", "--gains", "2", "--out", str(out), "--overwrite")
    assert sorted(p.name for p in out.iterdir()) == ["README.txt", "gain_2", "noise_scene.json"]


def test_noise_refuses_poses_without_a_focal_length(tmp_path):
    scene = tmp_path / "scene"
    shutil.copytree(shared("llff", "fern"), scene)
    rows = np.load(scene / "poses_bounds.npy")
    rows[3, 14] = 0.0
    np.save(scene / "poses_bounds.npy", rows)
    proc = run_cli("noise", str(scene), "--factor", "8", "--gains", "1",
                   "--out", str(tmp_path / "n"), check=False)  # fmt: skip
    one_error_line(proc, "row 3: focal 0", "poses_bounds.npy")
    assert not (tmp_path / "n").exists()


def test_huge_gains_name_the_option(b, tmp_path):
    fern = shared("llff", "fern")
    proc = run_cli("noise", str(fern), "--factor", "8", "--gains", "1e308", "--any-gain",
                   "--out", str(tmp_path / "n"), check=False)  # fmt: skip
    one_error_line(proc, "--gains")
    assert not (tmp_path / "n").exists()


# -- a provisional build is refused by its readers, or described as such ------------------


def test_readers_refuse_a_build_whose_rerun_is_running(b, tmp_path):
    """A rerun in flight: an object's lock and a partial setting (what a running build
    holds), and a complete setting that splits.json does not list yet."""
    (b / ".lock-demo_box").write_text("pid 1 on host x\n")
    for cmd in (["export", str(b), "--out", str(tmp_path / "e")],
                ["noise", str(b), "--out", str(tmp_path / "n")],
                ["card", str(b)]):  # fmt: skip
        one_error_line(run_cli(*cmd, check=False), "not finished", "demo_box")
    assert not (tmp_path / "e").exists() and not (tmp_path / "n").exists()
    assert not (b / "README.md").exists()
    p = run_cli("stats", str(b), "--out", str(tmp_path / "s"))
    assert "not finished" in p.stdout
    assert "not finished" in (tmp_path / "s" / "report.md").read_text()


def test_export_never_puts_a_test_setting_in_train(b, tmp_path):
    """The old export sent every complete setting that splits.json did not list to train:
    a setting finished after splits.json was written (an interrupted rerun)."""
    splits = json.loads((b / "splits.json").read_text())
    late = splits["test"].pop()
    (b / "splits.json").write_text(json.dumps(splits))
    one_error_line(
        run_cli("export", str(b), "--out", str(tmp_path / "e"), check=False), late, "not finished"
    )


def test_a_killed_rerun_is_provisional_until_a_rerun_finishes(tmp_path, standin_blender):
    """The real sequence: a rerun that adds objects hangs on one (the stand-in's fault
    injection), so it holds that object's lock; export refuses while it runs and after
    it is killed; the next rerun finishes and export takes the test settings to test."""
    out = tmp_path / "b"
    standin_build(out, standin_blender)
    extra = tmp_path / "extra"
    extra.mkdir()
    shutil.copy(shared("glb", "khronos_BoxTextured.glb"), extra / "late.glb")
    env = dict(os.environ, BLURSET_STANDIN_FAULT="hang:late.glb")
    cmd = [sys.executable, "-m", "blurset.cli", "build", "--demo", "--objects", str(extra),
           *STANDIN_REST, "--blender", str(standin_blender), "--out", str(out)]  # fmt: skip
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    try:
        wait_for(lambda: (out / ".lock-late").exists(), proc)
        one_error_line(run_cli("export", str(out), "--out", str(tmp_path / "e"), check=False),
                       "late", "not finished")  # fmt: skip
    finally:
        proc.kill()
        proc.wait()
    assert (out / ".lock-late").exists()  # SIGKILL leaves it: the build is interrupted
    # The worker dies with its build (PR_SET_PDEATHSIG), the stand-in as the real one.
    assert wait_until(lambda: not worker_pids(out)), worker_pids(out)
    one_error_line(run_cli("export", str(out), "--out", str(tmp_path / "e"), check=False),
                   "not finished")  # fmt: skip
    run_cli("build", "--demo", "--objects", str(extra), *STANDIN_REST,
            "--blender", str(standin_blender), "--out", str(out))  # fmt: skip
    run_cli("export", str(out), "--out", str(tmp_path / "e"))
    splits = json.loads((out / "splits.json").read_text())
    test = (tmp_path / "e" / "test.txt").read_text().split()
    assert {t.split("__")[0] for t in test} == set(splits["test"])


STANDIN_REST = ("--views", "4", "--levels", "1,2", "--latents", "2", "--samples", "2",
                "--resolution", "32", "--settings-per-object", "2", "--quiet")  # fmt: skip


def test_export_refuses_a_damaged_setting(b, tmp_path):
    s = layout.complete_settings(b)[1]
    victim = sorted((s / "blur_1" / "images").iterdir())[-1]
    victim.unlink()
    line = one_error_line(run_cli("export", str(b), "--out", str(tmp_path / "e"), check=False),
                          s.name, "damaged")  # fmt: skip
    assert "images" in line
    assert not (tmp_path / "e").exists()


# -- readers check the shape of what they read -----------------------------------------------


@pytest.mark.parametrize(
    ("file", "text", "field"),
    [
        ("splits.json", "[]", "not a JSON object"),
        ("splits.json", "[1, 2]", "not a JSON object"),
        ("splits.json", '{"train": 5}', "train"),
        ("dataset.json", '{"name": "blurset Objaverse-Blur", "config": []}', None),
        ("meta", "[]", "meta.json"),
        ("meta", '{"uid": "x"}', "meta.json"),
    ],
)
def test_a_record_of_the_wrong_shape_is_one_line_never_an_internal_error(
    b, tmp_path, file, text, field
):
    setting = layout.complete_settings(b)[0]
    path = setting / "meta.json" if file == "meta" else b / file
    path.write_text(text)
    cmds = [
        ["export", str(b), "--out", str(tmp_path / "e")],
        ["noise", str(b), "--out", str(tmp_path / "n"), "--gains", "1"],
        ["card", str(b), "--out", str(tmp_path / "card.md")],
    ]
    if file == "meta":
        cmds.append(["preview", str(setting), "--out", str(tmp_path / "p.png")])
    for cmd in cmds:
        proc = run_cli(*cmd, check=False)
        assert proc.returncode == 2, (cmd, proc.stderr)
        assert "internal error" not in proc.stderr and "Traceback" not in proc.stderr
        line = one_error_line(proc)
        assert path.name in line or "not a blurset build" in line, line
        if field:
            assert field in line, line


# -- card, preview, stats never replace a user's file ------------------------------------------


def test_card_keeps_an_edited_or_foreign_readme(b):
    run_cli("card", str(b))
    card = b / "README.md"
    run_cli("card", str(b))  # its own, unedited: replaced
    card.write_text(card.read_text().replace("## Citation", "## My notes\n\n## Citation"))
    edited = card.read_bytes()
    line = one_error_line(run_cli("card", str(b), check=False), "edited", "--force")
    assert card.read_bytes() == edited, line
    run_cli("card", str(b), "--force")
    assert (b / "README.md.bak").read_bytes() == edited
    assert b"## My notes" not in card.read_bytes()
    card.write_text("# my own dataset\n")
    one_error_line(run_cli("card", str(b), check=False), "not written by blurset card")
    assert card.read_text() == "# my own dataset\n"


def test_card_refuses_another_builds_noise(b, tmp_path):
    other = copy_build(b, tmp_path / "other")
    run_cli("noise", str(other), "--out", str(tmp_path / "n"), "--gains", "1", "--levels",
            "sharp", "--quiet")  # fmt: skip
    one_error_line(run_cli("card", str(b), "--noise", str(tmp_path / "n"), check=False),
                   "'other'", "--noise")  # fmt: skip


def test_preview_keeps_a_users_image_and_names_a_missing_level(b, tmp_path):
    setting = layout.complete_settings(b)[0]
    photo = tmp_path / "holiday.png"
    from PIL import Image

    Image.new("RGB", (4, 4), (200, 10, 10)).save(photo)
    before = photo.read_bytes()
    one_error_line(run_cli("preview", str(setting), "--out", str(photo), check=False), "--force")
    assert photo.read_bytes() == before
    run_cli("preview", str(setting), "--out", str(tmp_path / "fig.png"))
    run_cli("preview", str(setting), "--out", str(tmp_path / "fig.png"))  # its own: replaced
    shutil.rmtree(setting / "sharp" / "images")
    one_error_line(run_cli("preview", str(setting), "--out", str(tmp_path / "f2.png"),
                           check=False), "sharp")  # fmt: skip


def test_stats_refuses_a_folder_that_is_not_its_own(b, tmp_path):
    notes = tmp_path / "notes"
    notes.mkdir()
    (notes / "report.md").write_text("my report")
    one_error_line(run_cli("stats", str(b), "--out", str(notes), check=False), "not a blurset")
    assert (notes / "report.md").read_text() == "my report"
    run_cli("stats", str(b), "--out", str(tmp_path / "s"))
    run_cli("stats", str(b), "--out", str(tmp_path / "s"))  # its own: rewritten


# -- builds: one source file, one set of settings; a second build never deletes the first's work --


def test_a_name_collision_that_appears_on_a_rerun_leaves_one_set_per_file(
    tmp_path, standin_blender
):
    models = tmp_path / "models"
    models.mkdir()
    shutil.copy(shared("glb", "khronos_BoxTextured.glb"), models / "with_space.glb")
    out = tmp_path / "b"
    run_cli("build", "--objects", str(models), *STANDIN_REST, "--blender", str(standin_blender),
            "--out", str(out))  # fmt: skip
    assert [s.name for s in layout.complete_settings(out)] == ["with_space_000", "with_space_180"]
    shutil.copy(shared("glb", "sketchfab_MapPin.glb"), models / "with space.glb")
    p = run_cli("build", "--objects", str(models), *STANDIN_REST,
                "--blender", str(standin_blender), "--out", str(out))  # fmt: skip
    assert "removed with_space_000" in p.stderr
    by_source: dict[str, set[str]] = {}
    for s in layout.complete_settings(out):
        meta = json.loads((s / "meta.json").read_text())
        by_source.setdefault(meta["object"]["path"], set()).add(meta["uid"])
    assert sorted(by_source) == ["with space.glb", "with_space.glb"]
    assert all(len(ids) == 1 for ids in by_source.values()), by_source
    assert len(layout.complete_settings(out)) == 4
    assert run_cli("verify", str(out), check=False).returncode == 0


def test_verify_finds_two_ids_made_from_one_file(b):
    s = layout.complete_settings(b)[0]
    meta = json.loads((s / "meta.json").read_text())
    twin = b / s.name.replace(meta["uid"], "twin")
    shutil.copytree(s, twin)
    meta["uid"] = "twin"
    (twin / "meta.json").write_text(json.dumps(meta))
    proc = run_cli("verify", str(b), check=False)
    assert proc.returncode == 1 and "one source file made the settings of 2 ids" in proc.stdout


def test_verify_calls_a_finished_build_without_its_manifest_damaged(b):
    (b / "MANIFEST.sha256").unlink()
    s = layout.complete_settings(b)[0] / "sharp" / "images"
    a, c = sorted(s.iterdir())[:2]
    da, dc = a.read_bytes(), c.read_bytes()
    a.write_bytes(dc)
    c.write_bytes(da)
    proc = run_cli("verify", str(b), check=False)
    assert proc.returncode == 1 and "MANIFEST.sha256: missing" in proc.stdout, proc.stdout


def test_a_second_build_waits_and_never_deletes_the_firsts_setting(tmp_path, standin_blender):
    """The start-up sweep used to remove `.work-<uid>` and `<setting>.partial` before
    taking the object's lock: a second build into the same OUT deleted the first's
    setting in progress. Now it waits on the object's lock, and the partial is kept."""
    out = tmp_path / "b"
    env = dict(os.environ, BLURSET_STANDIN_FAULT="hang_render:demo_vase")
    cmd = [sys.executable, "-m", "blurset.cli", "build", "--demo", *STANDIN_REST,
           "--blender", str(standin_blender), "--out", str(out)]  # fmt: skip
    first = subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    second = None
    said: list[str] = []
    try:
        wait_for(lambda: (out / "demo_vase_000.partial").is_dir(), first)
        second = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        reader = threading.Thread(target=lambda: said.extend(second.stderr), daemon=True)
        reader.start()
        # The second build's own event: past its start-up, waiting on the object's lock.
        wait_for(lambda: any("waiting:" in line for line in said), second)
        assert (out / "demo_vase_000.partial" / "sharp" / "images").is_dir()
        assert (out / ".work-demo_vase").is_dir()
        first.send_signal(signal.SIGTERM)
        assert first.wait(timeout=300) == 128 + signal.SIGTERM
        assert second.wait(timeout=300) == 0, "".join(said)[-2000:]
    finally:
        for p in (first, second):
            if p is not None and p.poll() is None:
                p.kill()
                p.wait()
    assert len(layout.complete_settings(out)) == 6
    assert run_cli("verify", str(out), check=False).returncode == 0


def test_a_killed_setting_never_leaves_a_marked_partial(tmp_path, standin_blender):
    """The `.complete` marker is written last: a setting killed half-way (its sharp
    images done, its blur renders hanging) holds no marker, and the rerun redoes it."""
    out = tmp_path / "b"
    env = dict(os.environ, BLURSET_STANDIN_FAULT="hang_render:demo_box")
    cmd = [sys.executable, "-m", "blurset.cli", "build", "--demo", *STANDIN_REST,
           "--blender", str(standin_blender), "--out", str(out)]  # fmt: skip
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    try:
        wait_for(lambda: any((out / "demo_box_000.partial" / "sharp" / "images").glob("*.png")),
                 proc)  # fmt: skip
    finally:
        proc.kill()
        proc.wait()
    partials = list(out.glob("*.partial"))
    assert partials and not any((p / layout.MARKER).exists() for p in partials)
    run_cli("build", "--demo", *STANDIN_REST, "--blender", str(standin_blender), "--out", str(out))
    assert len(layout.complete_settings(out)) == 6 and not list(out.glob("*.partial"))


# -- nothing of the builder's machine under OUT or an export ----------------------------------------


def test_no_builder_path_under_out_noise_export_or_stats(b, tmp_path, standin_build_dir):
    run_cli("stats", str(b), "--quiet")
    run_cli("card", str(b))
    run_cli("noise", str(b), "--out", str(tmp_path / "n"), "--gains", "1", "--levels", "blur_1",
            "--quiet")  # fmt: skip
    run_cli("export", str(b), "--out", str(tmp_path / "e"), "--copy")
    run_cli("export", str(b), "--out", str(tmp_path / "e2"), "--noise", str(tmp_path / "n"))
    needles = [str(tmp_path).encode(), str(Path.home()).encode(), str(ROOT).encode()]
    checked = 0
    for root in (b, tmp_path / "n", tmp_path / "e", tmp_path / "e2"):
        for p in root.rglob("*"):
            if p.is_symlink() or not p.is_file():
                continue
            data = p.read_bytes()
            assert not [n for n in needles if n in data], p
            checked += 1
    assert checked > 200
    assert not (b / ".local").exists()
    assert publish.local_paths_file(standin_build_dir).is_file()


# -- the builds' own invariants, which a planted bug once broke unseen ---------------------------


def test_the_manifest_lists_every_file_on_disk(b):
    listed = {line.split("  ", 1)[1] for line in (b / "MANIFEST.sha256").read_text().splitlines()}
    on_disk = {
        str(p.relative_to(b))
        for p in b.rglob("*")
        if p.is_file() and not any(part.startswith(".") for part in p.relative_to(b).parts)
    }
    on_disk.discard("MANIFEST.sha256")
    assert listed == on_disk
    assert any("/images_4/" in f for f in listed)


def test_the_settings_of_an_object_have_seeds_of_their_own(b):
    by_uid: dict[str, list[dict]] = {}
    for s in layout.complete_settings(b):
        meta = json.loads((s / "meta.json").read_text())
        by_uid.setdefault(meta["uid"], []).append(meta)
    for uid, metas in by_uid.items():
        assert len(metas) == 2, uid
        a, c = metas
        assert a["seed"] != c["seed"], uid
        ta = [v["trajectory"] for v in a["views"]]
        tc = [v["trajectory"] for v in c["views"]]
        assert ta != tc, uid
        la = [v["levels"]["1"]["latent_frames"] for v in a["views"]]
        lc = [v["levels"]["1"]["latent_frames"] for v in c["views"]]
        assert [f["t"] for x in la for f in x] != [f["t"] for x in lc for f in x], uid


def test_a_setting_records_its_source_by_relative_path(b):
    for s in layout.complete_settings(b):
        path = json.loads((s / "meta.json").read_text())["object"]["path"]
        assert not Path(path).is_absolute() and ".." not in Path(path).parts, path


def test_the_preflight_budget_is_the_cores(tmp_path):
    from blurset.plan import BuildConfig
    from blurset.services import preflight

    cfg = BuildConfig(out=str(tmp_path), objects=["x.glb"])
    budget = preflight.Budget()
    assert budget.max_triangles == cfg.max_triangles
    assert budget.max_texture_pixels == cfg.max_texture_pixels


def test_objaverse_licence_code_by_is_cc_by_4(tmp_path):
    from blurset.services import attribution

    rec = attribution.from_objaverse_annotation({"license": "by", "name": "t", "user": {}})
    assert attribution.attribution(rec)["license"] == "CC-BY-4.0"


def test_verify_decodes_a_cut_exr(standin_blender, tmp_path):
    out = tmp_path / "lin"
    standin_build(out, standin_blender, "--keep-linear")
    exr = sorted((layout.complete_settings(out)[0] / "blur_1" / "linear").iterdir())[0]
    exr.write_bytes(exr.read_bytes()[: exr.stat().st_size // 2])
    proc = run_cli("verify", str(out), check=False)
    assert proc.returncode == 1 and exr.name in proc.stdout, proc.stdout


def test_a_hash_in_a_listed_file_name_is_a_name(tmp_path, standin_blender):
    models = tmp_path / "models"
    make_demo_objects(models, seed=0)
    box = sorted(models.glob("*.glb"))[0]
    named = models / "a#b.glb"
    box.rename(named)
    lst = tmp_path / "list.txt"
    lst.write_text(f"# my models\n{named}   # the one with a hash\n")
    out = tmp_path / "b"
    run_cli("build", "--objects", str(lst), *STANDIN_REST, "--blender", str(standin_blender),
            "--out", str(out))  # fmt: skip
    assert [s.name for s in layout.complete_settings(out)] == ["a_b_000", "a_b_180"]


def test_an_id_never_starts_with_a_dash(tmp_path, standin_blender):
    models = tmp_path / "models"
    make_demo_objects(models, seed=0)
    box = sorted(models.glob("*.glb"))[0]
    box.rename(models / "-chair.glb")
    for p in models.glob("demo_*.glb"):
        p.unlink()
    out = tmp_path / "b"
    run_cli("build", "--objects", str(models), *STANDIN_REST, "--blender", str(standin_blender),
            "--out", str(out))  # fmt: skip
    names = [s.name for s in layout.complete_settings(out)]
    assert names == ["chair_000", "chair_180"]
    run_cli("preview", str(out))


def test_ctrl_c_while_the_command_starts_is_no_traceback(tmp_path):
    """The first second of a command imports every command module; Ctrl-C there used to
    print a traceback. The event: numpy is mapped (the command modules are importing),
    then the signal."""
    for k in range(3):
        proc = subprocess.Popen(
            [sys.executable, "-m", "blurset.cli", "build", "--demo", "--out", str(tmp_path / f"o{k}")],
            stderr=subprocess.PIPE, text=True,
        )  # fmt: skip

        def importing(pid: int = proc.pid) -> bool:
            try:
                return "_multiarray_umath" in Path(f"/proc/{pid}/maps").read_text()
            except OSError:
                return False

        wait_for(importing, proc)
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=600)
        assert "Traceback" not in err, err
        assert proc.returncode == 130, err
        assert "interrupted" in err


def test_export_beside_its_build_in_one_data_folder(standin_build_dir, tmp_path):
    data = tmp_path / "data"
    data.mkdir()
    b = copy_build(standin_build_dir, data / "b")
    before = tree(b)
    run_cli("export", str(b), "--out", str(data), "--levels", "sharp")
    assert tree(b) == before
    assert {p.name for p in data.iterdir()} == {
        "b", "nerf_llff_data", "train.txt", "test.txt", "export.json"
    }  # fmt: skip
    # But never where a loader would take the build for a scene, nor into the build.
    inside = copy_build(standin_build_dir, tmp_path / "d2" / "nerf_llff_data" / "b")
    one_error_line(run_cli("export", str(inside), "--out", str(tmp_path / "d2"), check=False),
                   "nerf_llff_data")  # fmt: skip
    one_error_line(run_cli("export", str(b), "--out", str(b / "x"), check=False), "--out")


def test_objects_left_out_by_licenses_are_not_failures(tmp_path, standin_blender):
    models = tmp_path / "models"
    models.mkdir()
    shutil.copy(shared("glb", "sketchfab_MapPin.glb"), models)  # CC-BY-4.0 in asset.extras
    shutil.copy(shared("glb", "khronos_BoxTextured.glb"), models)  # names no licence
    out = tmp_path / "b"
    p = run_cli("build", "--objects", str(models), *STANDIN_REST, "--licenses", "cc-by-4.0",
                "--max-failure-rate", "0", "--blender", str(standin_blender), "--out", str(out))  # fmt: skip
    assert "0 of 1 objects failed" in p.stderr and "1 skipped by --licenses" in p.stderr, p.stderr
    assert [s.name for s in layout.complete_settings(out)] == [
        "sketchfab_MapPin_000", "sketchfab_MapPin_180"
    ]  # fmt: skip


def test_geonerf_export_draws_no_sharp_source(standin_blender, tmp_path):
    """GeoNeRF (data/llff.py) holds out every 8th image of a scene and draws a target's
    sources from its nearest other images by camera centre. Its rule, restated here
    (its code needs torch): in the GeoNeRF export a degraded scene's sources are never a
    sharp image, and a test scene's only held-out image is the sharp target."""
    out = tmp_path / "b"
    standin_build(out, standin_blender, "--views", "17")
    data = tmp_path / "g"
    p = run_cli("export", str(out), "--out", str(data), "--for", "geonerf")
    assert "--llff_test_path" in p.stdout
    sharp_bytes = {
        q.read_bytes()
        for s in layout.complete_settings(out)
        for q in (s / "sharp" / "images_4").iterdir()
    }
    root = data / "geonerf"
    scenes = sorted(root.glob("*/*"))
    assert scenes
    for scene in scenes:
        if scene.name.rsplit("__", 1)[-1].startswith("sharp") or "__sharp" in scene.name:
            continue
        images = sorted((scene / "images_4").iterdir())
        rows = np.load(scene / "poses_bounds.npy")
        assert len(rows) == len(images)
        val_ids = list(range(0, len(images), 8))  # GeoNeRF's hold-out, hard-coded
        centres = rows[:, [3, 8, 13]]
        targets = val_ids if scene.parent.name == "test" else range(len(images))
        for t in targets:
            d = np.linalg.norm(centres - centres[t], axis=1)
            sources = [i for i in np.argsort(d, kind="stable") if i != t][:6]
            for s in sources:
                assert images[s].read_bytes() not in sharp_bytes, (scene.name, t, s)
        if scene.parent.name == "test":
            assert val_ids == [0] and images[0].read_bytes() in sharp_bytes


@pytest.mark.parametrize("target", ["llff", "nerfstudio", "geonerf"])
def test_every_exported_link_resolves(standin_blender, tmp_path, target):
    """Links are relative to where they end up (the scenes are staged elsewhere)."""
    out = tmp_path / "b"
    standin_build(out, standin_blender, "--views", "17")
    data = tmp_path / "data"
    run_cli("export", str(out), "--out", str(data), "--for", target)
    links = [p for p in data.rglob("*") if p.is_symlink()]
    assert links and all(p.exists() for p in links), [p for p in links if not p.exists()][:3]
    if target == "nerfstudio":
        doc = json.loads(next(data.glob("*__blur_1/transforms.json")).read_text())
        scene = next(data.glob("*__blur_1"))
        assert all((scene / f["file_path"]).is_file() for f in doc["frames"])
