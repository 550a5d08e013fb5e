"""Issue 48, round five: no command deletes a file it did not write (a note in a noise
gain folder, tradeoff's scratch beside a user's `.work/`), the export's own files are
its own (a `--passes` build's pass links, a killed export's temp lists), and the small
ones: choices in any case, licence skips said as skips, a bad fault spec named, and an
export without masks. Real commands; the builds are stand-in builds (no Blender render)."""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

import pytest
from blurset import layout
from blurset.services import outputs

from tests.conftest import copy_build, one_error_line, run_cli, shared, standin_build, tree

PASSES = ("--passes", "depth,normal,mask")


@pytest.fixture
def b(standin_build_dir, tmp_path) -> Path:
    return copy_build(standin_build_dir, tmp_path / "b")


@pytest.fixture(scope="module")
def passes_build(tmp_path_factory, standin_blender) -> Path:
    out = tmp_path_factory.mktemp("passes") / "b"
    standin_build(out, standin_blender, *PASSES)
    return out


def dead_pid() -> int:
    """The pid of a process that has ended (a killed run's, as far as a temp name says)."""
    p = subprocess.Popen(["true"])
    p.wait()
    return p.pid


# -- noise --overwrite never deletes a file inside a gain folder it did not write -----------


def a_gain(noise: Path) -> Path:
    return sorted(noise.glob("*/*/gain_1"))[0]


def test_noise_overwrite_names_a_users_file_in_a_gain_folder(b, tmp_path):
    n = tmp_path / "n"
    run_cli("noise", str(b), "--gains", "1", "--out", str(n))
    gain = a_gain(n)
    (gain / "mynote.txt").write_text("n")
    before = tree(n)
    proc = run_cli("noise", str(b), "--gains", "1", "--out", str(n), "--seed", "5",
                   "--overwrite", check=False)  # fmt: skip
    line = one_error_line(proc, "--out", f"{gain.relative_to(n)}/mynote.txt", "move it out")
    assert "nothing was changed" in line
    assert tree(n) == before
    (gain / "mynote.txt").unlink()
    run_cli("noise", str(b), "--gains", "1", "--out", str(n), "--seed", "5", "--overwrite")
    assert outputs.read_record(n / layout.NOISE_DATASET)["params"]["seed"] == 5


def test_noise_overwrite_of_one_scene_names_a_users_file_in_a_gain_folder(b, tmp_path):
    scene = sorted(b.glob("*/blur_1"))[0]
    n = tmp_path / "n"
    run_cli("noise", str(scene), "--factor", "1", "--gains", "1", "--out", str(n))
    (n / "gain_1" / "images" / "notes.txt").write_text("n")
    before = tree(n)
    proc = run_cli("noise", str(scene), "--factor", "1", "--gains", "1", "--out", str(n),
                   "--seed", "5", "--overwrite", check=False)  # fmt: skip
    one_error_line(proc, "--out", "gain_1/images/notes.txt")
    assert tree(n) == before


def test_a_noise_rerun_names_a_users_file_in_a_partial_unit_it_would_remove(b, tmp_path):
    n = tmp_path / "n"
    run_cli("noise", str(b), "--gains", "1", "--out", str(n))
    gain = a_gain(n)
    partial = gain.with_name("gain_1.partial")
    gain.rename(partial)  # what a killed run leaves: the unit not published
    (partial / "README").write_text("mine")
    before = tree(n)
    one_error_line(run_cli("noise", str(b), "--gains", "1", "--out", str(n), check=False),
                   "gain_1.partial/README")  # fmt: skip
    assert tree(n) == before
    # A unit that is not complete is redone: the same.
    partial.rename(gain)
    (gain / layout.MARKER).unlink()
    before = tree(n)
    one_error_line(run_cli("noise", str(b), "--gains", "1", "--out", str(n), check=False),
                   "gain_1/README")  # fmt: skip
    assert tree(n) == before


# -- tradeoff never uses or removes a `.work` of the user's ---------------------------------


def tradeoff(out: Path, glb: Path, *extra: str):
    # A Blender that does not exist: the run fails at the worker, after it has made its
    # scratch folder and the worker's log.
    return run_cli("tradeoff", "--object", str(glb), "--out", str(out), "--quick",
                   "--blender", str(glb.parent / "no-blender"), *extra, check=False)  # fmt: skip


def test_tradeoff_keeps_a_users_dot_work_and_writes_nothing_through_a_link(tmp_path):
    glb = tmp_path / "obj.glb"
    glb.write_bytes(b"glTF")
    out = tmp_path / "out"
    (out / ".work").mkdir(parents=True)
    (out / ".work" / "mine.txt").write_text("keep")
    proc = tradeoff(out, glb)
    assert proc.returncode != 0 and "Traceback" not in proc.stderr, proc.stderr
    assert (out / ".work" / "mine.txt").read_text() == "keep"
    assert sorted(p.name for p in (out / ".work").iterdir()) == ["mine.txt"]
    # `.work` a link out of --out: nothing is written where it points.
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    out2 = tmp_path / "out2"
    out2.mkdir()
    (out2 / ".work").symlink_to(elsewhere)
    proc = tradeoff(out2, glb)
    assert proc.returncode != 0 and "Traceback" not in proc.stderr, proc.stderr
    assert list(elsewhere.iterdir()) == []
    assert (out2 / ".work").is_symlink()


def test_tradeoff_removes_the_scratch_a_killed_run_left(tmp_path):
    glb = tmp_path / "obj.glb"
    glb.write_bytes(b"glTF")
    out = tmp_path / "out"
    stale = out / f".work.tmp{dead_pid()}"
    (stale / "scratch").mkdir(parents=True)
    tradeoff(out, glb)
    assert not stale.exists()


def test_tradeoff_latent_sampling_takes_any_case(tmp_path):
    glb = tmp_path / "obj.glb"
    glb.write_bytes(b"glTF")
    out = tmp_path / "out"
    # SUBSETS is parsed as subsets: the refusal is the next option's.
    one_error_line(tradeoff(out, glb, "--latent-sampling", "SUBSETS", "--level", "0"), "--level")
    proc = tradeoff(out, glb, "--latent-sampling", "halves")
    assert proc.returncode == 2 and "--latent-sampling: invalid choice: 'halves'" in proc.stderr
    assert not out.exists()


# -- export: the pass links are its own, a killed export's temp lists go ---------------------


def test_reexport_of_a_passes_build_with_other_options_replaces_its_own_links(
    passes_build, tmp_path
):
    data = tmp_path / "data"
    run_cli("export", str(passes_build), "--out", str(data))
    scene = sorted((data / "nerf_llff_data").iterdir())[0]
    assert (scene / "depth").is_symlink()
    run_cli("export", str(passes_build), "--out", str(data), "--levels", "sharp")
    assert outputs.read_record(data / "export.json")["levels"] == ["sharp"]
    # nerfstudio's own folders (depths/, its transforms.json) are its own too.
    ns = tmp_path / "ns"
    run_cli("export", str(passes_build), "--for", "nerfstudio", "--out", str(ns))
    run_cli("export", str(passes_build), "--for", "nerfstudio", "--out", str(ns), "--copy")
    scene = sorted(p for p in ns.iterdir() if p.is_dir())[0]
    assert not (scene / "masks").is_symlink() and (scene / "depths").is_dir()
    # Still, a note in a pass folder is named, never deleted with the scene.
    (scene / "depths" / "notes.txt").write_text("mine")
    before = tree(ns)
    proc = run_cli("export", str(passes_build), "--for", "nerfstudio", "--out", str(ns),
                   check=False)  # fmt: skip
    one_error_line(proc, "--out", f"{scene.name}/depths/notes.txt")
    assert tree(ns) == before


def test_an_up_to_date_export_removes_a_killed_exports_temp_lists(b, tmp_path):
    data = tmp_path / "data"
    run_cli("export", str(b), "--out", str(data))
    pid = dead_pid()
    stale = [data / f".{name}.tmp{pid}" for name in ("test.txt", "train.txt", "export.json")]
    for p in stale:
        p.write_text("half")
    live = data / ".test.txt.tmp1"  # a live pid's (init): not a killed run's, kept
    live.write_text("x")
    proc = run_cli("export", str(b), "--out", str(data))
    assert "up to date" in proc.stdout
    assert [p for p in stale if p.exists()] == [] and live.exists()


# -- export --no-masks ---------------------------------------------------------------------


def test_export_without_masks_leaves_every_mask_out_and_says_so(passes_build, tmp_path):
    ns = tmp_path / "ns"
    run_cli("export", str(passes_build), "--for", "nerfstudio", "--out", str(ns), "--no-masks")
    doc = outputs.read_record(ns / "export.json")
    assert doc["passes"] == ["depth", "normal"]
    for scene in doc["scenes"]:
        tf = json.loads((ns / scene / layout.TRANSFORMS).read_text())
        assert all("mask_path" not in fr and "depth_file_path" in fr for fr in tf["frames"])
    assert not [p for p in ns.rglob("masks*")]
    again = run_cli("export", str(passes_build), "--for", "nerfstudio", "--out", str(ns),
                    "--no-masks")  # fmt: skip
    assert "up to date" in again.stdout
    # With masks: not up to date, the masks are put in.
    proc = run_cli("export", str(passes_build), "--for", "nerfstudio", "--out", str(ns))
    assert "written" in proc.stdout
    assert outputs.read_record(ns / "export.json")["passes"] == ["depth", "normal", "mask"]
    assert [p for p in ns.rglob("masks")]
    # LLFF: no masks/ folders either.
    ll = tmp_path / "ll"
    run_cli("export", str(passes_build), "--out", str(ll), "--no-masks")
    assert not list(ll.rglob("masks*")) and list(ll.rglob("normals_4"))


# -- licence skips are skips ----------------------------------------------------------------


STANDIN_REST = ("--views", "4", "--levels", "1,2", "--latents", "2", "--samples", "2",
                "--resolution", "32", "--settings-per-object", "2")  # fmt: skip


def test_objects_left_out_by_licenses_are_said_skipped_in_progress_and_stats(
    tmp_path, standin_blender
):
    models = tmp_path / "models"
    models.mkdir()
    shutil.copy(shared("glb", "sketchfab_MapPin.glb"), models)  # CC-BY-4.0 in asset.extras
    shutil.copy(shared("glb", "khronos_BoxTextured.glb"), models)  # names no licence
    out = tmp_path / "b"
    p = run_cli("build", "--objects", str(models), *STANDIN_REST, "--licenses", "cc-by-4.0",
                "--blender", str(standin_blender), "--out", str(out))  # fmt: skip
    assert "failed" not in p.stderr.replace("0 of 1 objects failed", ""), p.stderr
    assert "skipped khronos_BoxTextured (licence" in p.stderr, p.stderr
    assert "1 skipped (licence)" in p.stderr, p.stderr  # the progress lines
    s = run_cli("stats", str(out))
    assert "0 failed objects; 1 skipped by --licenses" in s.stdout, s.stdout
    doc = json.loads((out / "stats" / "stats.json").read_text())
    assert (doc["counts"]["failures"], doc["counts"]["licence_skipped"]) == (0, 1)
    assert doc["failures"] == [] and doc["licence_skipped"][0]["uid"] == "khronos_BoxTextured"
    report = (out / "stats" / "report.md").read_text()
    assert "- skipped object `khronos_BoxTextured` (licence" in report
    assert "failed object" not in report


# -- a bad fault spec is one line naming the variable ---------------------------------------


@pytest.mark.parametrize("spec", ["kill_in:²", "kill_in:x", "kill_in:"])
def test_a_bad_noise_fault_spec_is_one_line_naming_the_variable(b, tmp_path, spec):
    out = tmp_path / "n"
    proc = run_cli("noise", str(b), "--gains", "1", "--out", str(out), check=False,
                   env={"BLURSET_NOISE_FAULT": spec})  # fmt: skip
    one_error_line(proc, "BLURSET_NOISE_FAULT", "kill_in:K")
    assert "int()" not in proc.stderr and not out.exists()


def test_a_lock_file_a_user_wrote_is_refused_by_name_and_kept(tmp_path):
    """A lock file says which run holds it; a file of that name that says anything else
    (a user's `.tradeoff.lock`) is named and left as it is, never truncated or removed.
    One a killed run left (its holder line, or nothing) is taken over and removed."""
    from blurset.exceptions import InputError
    from blurset.services import outputs

    mine = tmp_path / outputs.TRADEOFF_LOCK
    mine.write_text("my notes\n")
    with pytest.raises(InputError, match=r"\.tradeoff\.lock is a file blurset did not write"):
        with outputs.flock_file(mine):
            pass
    assert mine.read_text() == "my notes\n"
    for stale in ("pid 4242 on host node-7\n", "pid 4242", ""):
        mine.write_text(stale)
        with outputs.flock_file(mine):
            assert mine.read_text().startswith("pid ")
        assert not mine.exists()
