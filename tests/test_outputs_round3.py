"""Issue 34, "data lost or inputs changed": the commands outside the build path go
through the output owner too (blurset.services.outputs). Each case is the hostile user's
reproduction, with real commands; the builds are stand-in builds (no Blender render)."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from blurset import layout
from blurset.services import outputs

from tests.conftest import copy_build, one_error_line, run_cli, standin_build, tree


@pytest.fixture
def b(standin_build_dir, tmp_path) -> Path:
    return copy_build(standin_build_dir, tmp_path / "b")


@pytest.fixture
def b2(standin_build_dir, tmp_path) -> Path:
    return copy_build(standin_build_dir, tmp_path / "b2")


def a_setting(build: Path) -> Path:
    return layout.complete_settings(build)[0]


def fake_noise_output(path: Path) -> Path:
    path.mkdir(parents=True)
    counts = {"settings": 1, "units": 1, "images": 4}
    doc = {"build": "b", "params": {}, "counts": counts}
    (path / layout.NOISE_DATASET).write_text(json.dumps(doc))
    (path / "a_000" / "sharp" / "gain_1").mkdir(parents=True)
    (path / "a_000" / "sharp" / "gain_1" / layout.NOISE).write_text("{}")
    assert outputs.kind_of(path) is outputs.OutputKind.NOISE
    return path


# -- tradeoff --out ------------------------------------------------------------------


def tradeoff(out: Path, glb: Path, *extra: str):
    # A Blender that does not exist: an old tradeoff that accepted --out fails later, at
    # the worker, after it has touched the folder.
    return run_cli("tradeoff", "--object", str(glb), "--out", str(out), "--quick",
                   "--blender", str(glb.parent / "no-blender"), *extra, check=False)  # fmt: skip


def test_tradeoff_refuses_a_build_and_a_folder_it_does_not_own(b, tmp_path):
    glb = tmp_path / "obj.glb"
    glb.write_bytes(b"glTF")
    (b / ".work").mkdir()
    (b / ".work" / "mine.txt").write_text("keep")
    before = tree(b)
    one_error_line(tradeoff(b, glb), "--out", "build", str(b))
    assert tree(b) == before
    # Inside a build (not a setting): refused too.
    one_error_line(tradeoff(b / "sub", glb), "--out", "lies inside the blurset build")
    assert not (b / "sub").exists() and tree(b) == before
    # A folder of the user's: its .work and images/ are not tradeoff's.
    mine = tmp_path / "mine"
    (mine / ".work").mkdir(parents=True)
    (mine / ".work" / "notes.txt").write_text("keep")
    (mine / "images").mkdir()
    (mine / "images" / "reference.png").write_bytes(b"the user's picture")
    before = tree(mine)
    one_error_line(tradeoff(mine, glb), "--out", "folder with other files", str(mine))
    assert tree(mine) == before


def test_tradeoff_writes_into_a_new_or_its_own_folder(tmp_path):
    from blurset.commands import tradeoff as t

    t.claim(tmp_path / "new")
    (tmp_path / "empty").mkdir()
    t.claim(tmp_path / "empty")
    own = tmp_path / "own"
    own.mkdir()
    (own / "tradeoff.json").write_text(json.dumps({"kind": "blurset tradeoff", "rows": []}))
    (own / "images").mkdir()
    t.claim(own)
    assert outputs.enclosing_output(own / "x") == (own.resolve(), "tradeoff folder")


def test_tradeoff_zero_resolution_and_level_are_refused_and_choices_take_any_case(tmp_path):
    glb = tmp_path / "obj.glb"
    glb.write_bytes(b"glTF")
    out = tmp_path / "out"
    one_error_line(tradeoff(out, glb, "--resolution", "0"), "--resolution 0")
    one_error_line(tradeoff(out, glb, "--level", "0"), "--level")
    # --denoise OIDN is parsed as oidn (the refusal is the next option's).
    one_error_line(tradeoff(out, glb, "--denoise", "OIDN", "--level", "0"), "--level")
    assert not out.exists()


# -- check-poses --workdir / --json ----------------------------------------------------


def test_check_poses_never_writes_into_what_it_checks(b, tmp_path):
    s = a_setting(b)
    before = tree(b)
    one_error_line(run_cli("check-poses", str(s), "--workdir", str(s), check=False), "--workdir")
    one_error_line(
        run_cli("check-poses", str(s), "--workdir", str(b / "colmap"), check=False),
        "--workdir",
        "lies inside the blurset build",
    )
    one_error_line(
        run_cli("check-poses", str(s), "--json", str(s / "sharp" / "r.json"), check=False),
        "--json",
    )
    one_error_line(
        run_cli("check-poses", str(s), "--json", str(b / "r.json"), check=False), "--json"
    )
    # An LLFF scene (outside any build): its images_<f>/ is no workdir.
    scene = tmp_path / "scene"
    shutil.copytree(s / "sharp", scene)
    sub = next(p for p in scene.iterdir() if p.is_dir())
    one_error_line(
        run_cli("check-poses", str(scene), "--workdir", str(sub), check=False), "--workdir"
    )
    one_error_line(
        run_cli("check-poses", str(scene), "--json", str(sub / "r.json"), check=False), "--json"
    )
    assert tree(b) == before
    assert sorted(p.name for p in sub.iterdir()) == sorted(
        p.name for p in (s / "sharp" / sub.name).iterdir()
    )


def test_check_poses_refuses_a_workdir_holding_colmap_files_at_its_top(b, tmp_path):
    wd = tmp_path / "wd"
    (wd / "sparse" / "0").mkdir(parents=True)
    (wd / "database.db").write_bytes(b"the user's COLMAP database")
    before = tree(wd)
    line = one_error_line(
        run_cli("check-poses", str(a_setting(b)), "--workdir", str(wd), check=False), "--workdir"
    )
    assert "database.db" in line and tree(wd) == before


# -- one output inside another ------------------------------------------------------------


def test_a_build_inside_another_build_is_refused(b, standin_blender):
    before = tree(b)
    for out in (a_setting(b) / "sub", b / "sub"):
        proc = standin_build(out, standin_blender, check=False)
        one_error_line(proc, "--out", "lies inside the blurset build", str(b))
        assert not out.exists()
    assert tree(b) == before


def test_reports_of_one_build_are_never_written_into_another_output(b, b2, tmp_path):
    noise = fake_noise_output(tmp_path / "n")
    for other in (b2, noise):
        before = tree(other)
        one_error_line(run_cli("stats", str(b), "--out", str(other / "x"), check=False), "--out")
        one_error_line(
            run_cli("card", str(b), "--out", str(other / "README.md"), check=False),
            "--out",
            "lies inside the blurset",
        )
        one_error_line(
            run_cli("preview", str(b), "--out", str(other / "sheet.png"), check=False), "--out"
        )
        one_error_line(
            run_cli("preview", str(a_setting(b)), "--out", str(other / "p.png"), check=False),
            "--out",
        )
        assert tree(other) == before
    # Into the build they describe, as before.
    run_cli("stats", str(b), "--quiet")
    run_cli("card", str(b))
    run_cli("preview", str(b), "--out", str(b / "sheet.png"))
    assert (b / "stats" / "stats.json").is_file() and (b / "README.md").is_file()


# -- empty paths -----------------------------------------------------------------------------


@pytest.mark.parametrize(
    "argv",
    [
        # (a Blender that does not exist: a regression fails at once, renders nothing)
        ["build", "--demo", "--blender", "/nonexistent/blender", "--out", ""],
        ["noise", "SCENE", "--out", ""],
        ["export", "BUILD", "--out", ""],
        ["stats", "BUILD", "--out", ""],
        ["card", "BUILD", "--out", ""],
        ["check-poses", "BUILD", "--workdir", ""],
        ["check-poses", "BUILD", "--json", ""],
        ["tradeoff", "--object", "x.glb", "--out", ""],
        ["export", "BUILD", "--out="],
    ],
)
def test_an_empty_path_is_refused_by_name_not_taken_for_the_cwd(argv, tmp_path):
    proc = subprocess.run(
        [sys.executable, "-m", "blurset.cli", *argv],
        cwd=tmp_path,
        capture_output=True,
        text=True,
    )
    option = argv[-2] if argv[-1] == "" else argv[-1].rstrip("=")
    line = one_error_line(proc, option, "empty")
    assert line.startswith(f"blurset {argv[0]}: error:")
    assert list(tmp_path.iterdir()) == []


# -- export ---------------------------------------------------------------------------


def test_reexport_names_a_note_inside_a_scene_it_would_replace(b, tmp_path):
    data = tmp_path / "data"
    run_cli("export", str(b), "--out", str(data))
    scenes = data / "nerf_llff_data"
    blur = next(p for p in sorted(scenes.iterdir()) if "__blur_" in p.name)
    (blur / "notes.txt").write_text("my notes")
    before = tree(data)
    line = one_error_line(
        run_cli("export", str(b), "--out", str(data), "--levels", "sharp", check=False),
        "--out",
        "notes.txt",
    )
    assert blur.name in line
    assert tree(data) == before
    (blur / "notes.txt").unlink()
    run_cli("export", str(b), "--out", str(data), "--levels", "sharp")
    assert not blur.exists()


def test_an_up_to_date_export_removes_what_a_killed_export_left(b, tmp_path):
    data = tmp_path / "data"
    run_cli("export", str(b), "--out", str(data), "--for", "NERFSTUDIO")
    assert outputs.read_record(data / "export.json")["for"] == "nerfstudio"
    dead = subprocess.Popen(["true"])
    dead.wait()
    stale = data / f".export.old.tmp{dead.pid}"
    (stale / "0").mkdir(parents=True)
    (stale / "0" / "big.png").write_bytes(b"x" * 1000)
    # The old scene a killed export had moved aside while putting the new one in place.
    rec = outputs.read_record(data / "export.json")
    scene = sorted(rec["scenes"])[0]
    aside = data / rec["scenes_dir"] / f".{scene}.tmp{dead.pid}"
    (aside / "images").mkdir(parents=True)
    p = run_cli("export", str(b), "--out", str(data), "--for", "nerfstudio")
    assert "up to date" in p.stdout
    assert not stale.exists() and not aside.exists()


# -- a user's file inside a setting a rerun redoes ------------------------------------


def test_a_rerun_that_redoes_a_damaged_setting_keeps_a_users_files_in_it(b, standin_blender):
    s = a_setting(b)
    (s / "notes.txt").write_text("my notes")
    (s / "sharp" / "README").write_text("about this level")
    png = sorted((s / "sharp" / "images").iterdir())[0]
    png.write_bytes(b"not a png any more")
    assert layout.setting_problem(s) is not None
    assert layout.not_written_by_build(s) == ["notes.txt", "sharp/README"]
    proc = standin_build(b, standin_blender)
    assert f"redoing {s.name}" in proc.stderr
    assert layout.setting_problem(s) is None
    assert (s / "notes.txt").read_text() == "my notes"
    assert (s / "sharp" / "README").read_text() == "about this level"
    assert f"kept {s.name}/notes.txt" in proc.stderr


def test_a_rerun_removes_the_old_setting_a_killed_publish_left_aside(b, standin_blender):
    s = a_setting(b)
    dead = subprocess.Popen(["true"])
    dead.wait()
    # What a kill inside replace_dir leaves: the new setting in place, the old one aside.
    aside = b / f".{s.name}.tmp{dead.pid}"
    shutil.copytree(s, aside)
    mine = b / f".{s.name}.tmp1"  # a live pid's (init): not a killed run's, kept
    mine.mkdir()
    standin_build(b, standin_blender)
    assert not aside.exists() and mine.is_dir()
    assert layout.setting_problem(s) is None


def test_build_out_a_dangling_link_is_refused_and_its_target_not_made(tmp_path, standin_blender):
    link = tmp_path / "link"
    link.symlink_to(tmp_path / "elsewhere" / "deep")
    one_error_line(standin_build(link, standin_blender, check=False), "--out", "link to nothing")
    assert not (tmp_path / "elsewhere").exists()


# -- stats -----------------------------------------------------------------------------------


def test_a_stopped_stats_run_is_taken_back_by_its_rerun(b, tmp_path, monkeypatch):
    import errno

    from blurset import cli
    from blurset.commands import stats

    def full_disk(*_a, **_k):
        raise OSError(errno.ENOSPC, "No space left on device")

    out = tmp_path / "st"
    monkeypatch.setattr(stats, "write_csvs", full_disk)
    assert cli.main(["stats", str(b), "--out", str(out), "--quiet"]) == 2
    assert any(out.glob("*.png")) and not (out / "stats.json").exists()
    monkeypatch.undo()
    run_cli("stats", str(b), "--out", str(out), "--quiet")
    assert (out / "stats.json").is_file() and not (out / stats.UNFINISHED).exists()
    # A user's file in such a folder is still not stats': refused.
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "notes.txt").write_text("mine")
    (mine / stats.UNFINISHED).touch()
    one_error_line(
        run_cli("stats", str(b), "--out", str(mine), check=False), "--out", "other files"
    )


def test_stats_of_a_noise_output_says_it_is_not_a_build(tmp_path):
    noise = fake_noise_output(tmp_path / "n")
    line = one_error_line(run_cli("stats", str(noise), check=False), "noise output", "not a build")
    assert str(noise) in line and not (noise / "stats").exists()


def test_preview_gain_errors_name_gain(b, tmp_path):
    noise = fake_noise_output(tmp_path / "n")
    s = a_setting(b)
    out = str(tmp_path / "p.png")
    for gain in ("nan", "1e308"):
        line = one_error_line(run_cli("preview", str(s), "--noise", str(noise), "--gain", gain,
                               "--out", out, check=False), "--gain ", gain)  # fmt: skip
        assert "--gains" not in line and "Errno" not in line, line


def test_export_copy_on_a_full_disk_is_one_line(b, tmp_path, monkeypatch, capsys):
    import errno

    from blurset import cli

    def full(src, dst, *a, **k):
        raise OSError(errno.ENOSPC, "No space left on device", str(dst))

    monkeypatch.setattr(shutil, "copyfile", full)
    out = tmp_path / "data"
    assert cli.main(["export", str(b), "--out", str(out), "--copy"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "No space left on device" in err[0] and "--copy" in err[0], err
    assert "[(" not in err[0] and str(b) not in err[0]
    assert not (out / "nerf_llff_data").exists() and not (out / "export.json").exists()


def test_check_poses_of_a_setting_without_its_images_names_the_damage(b, tmp_path):
    s = a_setting(b)
    shutil.rmtree(s / "sharp" / "images")
    line = one_error_line(
        run_cli("check-poses", str(s), check=False), "no images/", str(s / "sharp")
    )
    assert "texture" not in line


# -- scripts/check_clients.py ----------------------------------------------------------------


def test_check_clients_bad_arguments_are_one_line(b, tmp_path):
    script = Path(__file__).resolve().parents[1] / "scripts" / "check_clients.py"

    def run(*args: str):
        return subprocess.run(
            [sys.executable, str(script), *args], capture_output=True, text=True, cwd=tmp_path
        )

    data = tmp_path / "data"
    run_cli("export", str(b), "--out", str(data))
    for args, words in [
        (("ibrnet", str(b), "--checkout", str(tmp_path), "--python", sys.executable),
         ("EXPORT", "export.json", str(b))),
        (("ibrnet", str(data), "--checkout", str(tmp_path / "none"), "--python", sys.executable),
         ("--checkout", str(tmp_path / "none"))),
        (("ibrnet", str(data), "--checkout", str(tmp_path), "--python", str(tmp_path / "py")),
         ("--python", str(tmp_path / "py"))),
    ]:  # fmt: skip
        proc = run(*args)
        lines = proc.stderr.strip().splitlines()
        assert proc.returncode == 2 and len(lines) == 1, proc.stderr
        assert "Traceback" not in proc.stderr and all(w in lines[0] for w in words), proc.stderr


# -- noise of another build of the same name -------------------------------------------------


def test_noise_of_another_build_of_the_same_name_is_refused(b, tmp_path, standin_blender):
    other = tmp_path / "other" / "b"
    standin_build(other, standin_blender, "--views", "5")
    theirs = tmp_path / "n_other"
    run_cli("noise", str(other), "--out", str(theirs), "--gains", "1", "--quiet")
    ours = tmp_path / "n"
    run_cli("noise", str(b), "--out", str(ours), "--gains", "1", "--quiet")
    s = a_setting(b)
    for argv in (
        ["export", str(b), "--out", str(tmp_path / "data"), "--noise", str(theirs)],
        ["card", str(b), "--out", str(tmp_path / "card.md"), "--noise", str(theirs)],
        ["preview", str(s), "--noise", str(theirs), "--gain", "1", "--out",
         str(tmp_path / "p.png")],
    ):  # fmt: skip
        one_error_line(run_cli(*argv, check=False), "--noise", "not a noise output of this build")
    assert not (tmp_path / "data").exists() and not (tmp_path / "p.png").exists()
    # The build's own noise passes.
    run_cli("export", str(b), "--out", str(tmp_path / "data"), "--noise", str(ours))
    run_cli("card", str(b), "--out", str(tmp_path / "card.md"), "--noise", str(ours))
    run_cli(
        "preview", str(s), "--noise", str(ours), "--gain", "1", "--out", str(tmp_path / "p.png")
    )


# -- a valid PNG of the wrong size ----------------------------------------------------------


def test_open_scene_names_an_image_of_the_wrong_size(b):
    from blurset.data import open_scene
    from blurset.exceptions import InputError
    from PIL import Image

    s = a_setting(b)
    png = sorted((s / "sharp" / "images").iterdir())[1]
    Image.new("RGB", (7, 5)).save(png)
    with pytest.raises(InputError, match=r"7x5 px.*" + png.name):
        open_scene(b, s.name, "sharp")
    with pytest.raises(InputError, match=png.name):
        open_scene(b, s.name, "blur_1")  # the sharp images are the clean ones


def test_noise_frames_past_the_limit_is_refused_before_anything(b, tmp_path):
    out = tmp_path / "n"
    line = one_error_line(
        run_cli("noise", str(b), "--out", str(out), "--frames", "100000000", check=False),
        "--frames 100000000",
    )
    assert "256" in line and not out.exists()


# -- readers of a damaged build ------------------------------------------------------------


def test_card_noise_and_stats_do_not_call_a_damaged_build_whole(b, tmp_path):
    s = a_setting(b)
    meta = json.loads((s / layout.META).read_text())
    meta["views"] = meta["views"] * 1000  # a meta.json promising 4000 views
    (s / layout.META).write_text(json.dumps(meta))
    for argv in (
        ["card", str(b), "--out", str(tmp_path / "card.md")],
        ["noise", str(b), "--out", str(tmp_path / "n"), "--gains", "1"],
    ):
        line = one_error_line(run_cli(*argv, check=False), "damaged setting", s.name)
        assert "4000" in line, line
    assert not (tmp_path / "card.md").exists() and not (tmp_path / "n").exists()
    p = run_cli("stats", str(b), "--out", str(tmp_path / "st"))
    assert f"damaged settings: {s.name}" in p.stdout
    assert "not finished" in (tmp_path / "st" / "report.md").read_text()


def test_a_valid_png_of_the_wrong_size_is_damage_the_rerun_redoes(b, tmp_path, standin_blender):
    from PIL import Image

    s = a_setting(b)
    png = sorted((s / "sharp" / "images").iterdir())[1]
    Image.new("RGB", (7, 5)).save(png)
    problem = f"sharp/images/{png.name} is 7x5 px, not 32x32"
    assert layout.setting_problem(s) == problem
    one_error_line(run_cli("export", str(b), "--out", str(tmp_path / "data"), check=False), s.name)
    assert not (tmp_path / "data").exists()
    proc = standin_build(b, standin_blender)
    assert f"redoing {s.name}: {problem}" in proc.stderr
    assert layout.setting_problem(s) is None
