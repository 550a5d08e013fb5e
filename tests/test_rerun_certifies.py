"""Issue 48, "a rerun never certifies what it did not make": a rerun of `build` or
`noise` redoes what no longer is what MANIFEST.sha256 certifies (an EXR cut short or
with a flipped byte, a valid file copied over another) instead of hashing it anew;
`verify` after a rerun says what it said before of every file the rerun did not write;
a user's file kept in a redone setting is never listed; `stats` of a damaged build does
name each damaged setting. Real commands on stand-in builds (no Blender render)."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest
from blurset import layout
from blurset.services import publish

from tests.conftest import copy_build, run_cli, standin_build

# Every kind of EXR a setting can hold: linear colour, depth and normals at two sizes.
PASSES = ("--passes", "depth,normal,mask", "--keep-linear")


@pytest.fixture(scope="module")
def certified(tmp_path_factory, standin_blender) -> Path:
    """A finished stand-in build with passes and linear EXRs (6 settings), and its
    manifest; tests work on a copy."""
    out = tmp_path_factory.mktemp("certified") / "b"
    standin_build(out, standin_blender, *PASSES)
    return out


@pytest.fixture
def b(certified, tmp_path) -> Path:
    return copy_build(certified, tmp_path / "b")


MISMATCH = "checksum mismatch (MANIFEST.sha256)"


def verify_lines(build: Path) -> dict[str, list[str]]:
    """`blurset verify`'s findings: relative path → what is wrong with it."""
    proc = run_cli("verify", str(build), check=False)
    found: dict[str, list[str]] = {}
    for line in proc.stdout.splitlines():
        path, _, what = line.partition(": ")
        found.setdefault(Path(path).relative_to(build).as_posix(), []).append(what)
    assert (proc.returncode == 0) == (not found), proc.stdout + proc.stderr
    return found


def listed(build: Path) -> set[str]:
    text = (build / publish.MANIFEST).read_text()
    return {line.split("  ", 1)[1] for line in text.splitlines()}


def cut(p: Path) -> None:
    p.write_bytes(p.read_bytes()[: p.stat().st_size * 2 // 3])


def flip(p: Path) -> None:
    """One byte of the last block's compressed data flipped: the file keeps its size and
    header, only inflating the block finds it."""
    data = bytearray(p.read_bytes())
    data[-40] ^= 0x5A
    p.write_bytes(bytes(data))


# (folder of a setting, damage): one of each EXR kind, cut short or with a flipped byte.
EXR_DAMAGE = [
    ("sharp/depth", cut),
    ("sharp/depth_4", cut),
    ("sharp/normals", cut),
    ("blur_1/linear", cut),
    ("sharp/depth", flip),
    ("sharp/linear", flip),
]


def test_a_rerun_redoes_a_cut_or_flipped_exr_instead_of_certifying_it(b, standin_blender):
    settings = layout.complete_settings(b)
    assert len(settings) >= len(EXR_DAMAGE)
    whole, damaged = {}, []
    for setting, (folder, damage) in zip(settings, EXR_DAMAGE, strict=False):
        exr = sorted((setting / folder).glob("*.exr"))[1]
        whole[exr] = exr.read_bytes()
        damage(exr)
        damaged.append(exr.relative_to(b).as_posix())
    before = verify_lines(b)
    for rel in damaged:
        assert any(w.startswith("does not decode") for w in before[rel]), before
        assert MISMATCH in before[rel], before
    proc = standin_build(b, standin_blender, *PASSES)
    for rel in damaged:
        setting, inside = rel.split("/", 1)
        assert f"redoing {setting}: {inside} does not decode" in proc.stderr, proc.stderr
    # Redone (the stand-in renders the same bytes again), and the build whole again.
    for exr, data in whole.items():
        assert exr.read_bytes() == data, exr
    assert verify_lines(b) == {}


def test_a_valid_file_copied_over_another_is_redone_not_certified(b, standin_blender):
    s0, s1, s2 = layout.complete_settings(b)[:3]
    png = s0 / "sharp" / "images"
    first, second = sorted(png.iterdir())[:2]
    depth = sorted((s1 / "sharp" / "depth").iterdir())[:2]
    whole = {p: p.read_bytes() for p in [second, *depth]}
    shutil.copyfile(first, second)  # a PNG copied over another view's
    a, c = (p.read_bytes() for p in depth)  # two views' depth swapped
    depth[0].write_bytes(c)
    depth[1].write_bytes(a)
    before = verify_lines(b)
    for p in whole:
        assert before[p.relative_to(b).as_posix()] == [MISMATCH], before
    proc = standin_build(b, standin_blender, *PASSES)
    rel = second.relative_to(s0).as_posix()
    assert f"redoing {s0.name}: {rel}: checksum mismatch against MANIFEST.sha256" in proc.stderr
    assert f"redoing {s1.name}: " in proc.stderr, proc.stderr
    assert f"redoing {s2.name}" not in proc.stderr  # an untouched setting is reused
    for p, data in whole.items():
        assert p.read_bytes() == data, p
    assert verify_lines(b) == {}


def test_verify_after_a_rerun_says_what_it_said_of_files_the_rerun_did_not_write(
    b, standin_blender
):
    # A shard's rerun does not reuse (nor check) the other shard's settings: their
    # damage must stay what verify reported, not be hashed into the manifest.
    uids = sorted(
        {json.loads((s / layout.META).read_text())["uid"] for s in layout.complete_settings(b)}
    )
    other = next(s for s in layout.complete_settings(b) if s.name.startswith(uids[1]))
    img = sorted((other / "blur_1" / "images").iterdir())[0]
    shutil.copyfile(sorted((other / "blur_1" / "images").iterdir())[1], img)
    gone = sorted((other / "sharp" / "images_4").iterdir())[0]
    gone.unlink()
    before = verify_lines(b)
    standin_build(b, standin_blender, *PASSES, "--shard", "0/2")
    after = verify_lines(b)
    assert after == before
    assert after[img.relative_to(b).as_posix()] == [MISMATCH]
    assert gone.relative_to(b).as_posix() in after


def test_a_users_file_kept_in_a_redone_setting_is_not_listed(b, standin_blender):
    setting = layout.complete_settings(b)[0]
    (setting / "mynote.txt").write_text("mine")
    (setting / "sharp" / "README").write_text("about this level")
    cut(sorted((setting / "sharp" / "images").iterdir())[0])
    proc = standin_build(b, standin_blender, *PASSES)
    assert f"redoing {setting.name}" in proc.stderr
    assert (setting / "mynote.txt").read_text() == "mine"  # kept, never deleted
    names = listed(b)
    assert f"{setting.name}/mynote.txt" not in names
    assert f"{setting.name}/sharp/README" not in names
    assert f"{setting.name}/sharp/images/000.png" in names
    assert verify_lines(b) == {}


def test_stats_of_a_damaged_build_names_each_damaged_setting_in_stats_json(b, tmp_path):
    s0, s1 = layout.complete_settings(b)[:2]
    (s0 / "blur_1" / "images" / "001.png").unlink()
    cut(sorted((s1 / "sharp" / "normals").iterdir())[0])
    proc = run_cli("stats", str(b), "--out", str(tmp_path / "stats"))
    doc = json.loads((tmp_path / "stats" / layout.STATS).read_text())
    assert [d["setting"] for d in doc["damaged"]] == [s0.name, s1.name]
    assert doc["damaged"][0]["problem"] == "blur_1/images holds 3 of 4 images"
    assert doc["damaged"][1]["problem"].startswith("sharp/normals/000.exr does not decode")
    assert doc["counts"]["damaged_settings"] == 2
    assert "damaged settings" in proc.stdout + proc.stderr
    report = (tmp_path / "stats" / "report.md").read_text()
    assert f"`{s0.name}`: blur_1/images holds 3 of 4 images" in report


def test_a_noise_rerun_redoes_a_gain_file_copied_over_another(b, tmp_path):
    out = tmp_path / "n"
    noise = ("noise", str(b), "--gains", "1", "4", "--out", str(out))
    run_cli(*noise)
    gain = sorted(out.glob("*/blur_1/gain_4"))[0]
    first, second = sorted((gain / "images").iterdir())[:2]
    cut_png = sorted(out.glob("*/sharp/gain_1/images"))[0]
    cut_one = sorted(cut_png.iterdir())[0]
    whole = {second: second.read_bytes(), cut_one: cut_one.read_bytes()}
    shutil.copyfile(first, second)
    cut(cut_one)
    before = verify_lines(out)
    assert before[second.relative_to(out).as_posix()] == [MISMATCH]
    proc = run_cli(*noise)
    rel = gain.relative_to(out).as_posix()
    assert f"redoing {rel}: images/{second.name}: checksum mismatch" in proc.stderr, proc.stderr
    assert "2 scene(s) written" in proc.stdout, proc.stdout
    for p, data in whole.items():
        assert p.read_bytes() == data, p
    assert verify_lines(out) == {}


def test_a_users_file_in_a_noise_gain_is_not_listed(b, tmp_path):
    """A note kept in a noise unit's gain folder is the user's: neither the run that
    finds it nor verify certifies it as the noise output's."""
    out = tmp_path / "n"
    noise = ("noise", str(b), "--gains", "1", "--out", str(out))
    run_cli(*noise)
    gain = sorted(out.glob("*/blur_1/gain_1"))[0]
    (gain / "mynote.txt").write_text("mine")
    (gain / "images" / "notes.md").write_text("mine")
    run_cli(*noise)  # up to date: nothing written
    names = listed(out)
    rel = gain.relative_to(out).as_posix()
    assert f"{rel}/mynote.txt" not in names and f"{rel}/images/notes.md" not in names
    assert f"{rel}/noise.json" in names
    # A stray file among the images is named (a loader that lists images/ would read
    # it); the note beside them is the user's business.
    assert verify_lines(out) == {f"{rel}/images/notes.md": ["not a file of this images folder"]}
    assert (gain / "mynote.txt").read_text() == "mine"


def test_a_superseded_setting_of_a_passes_build_is_removed_not_refused(b, standin_blender):
    # Its depth/, normals/ and masks/ are the build's own (the one rule of what a build
    # writes in a setting), not a user's files that would make the rerun refuse.
    src = layout.complete_settings(b)[0]
    old = b / "old_box_000"
    shutil.copytree(src, old)
    meta = json.loads((old / layout.META).read_text())
    meta["uid"] = "old_box"
    (old / layout.META).write_text(json.dumps(meta))
    assert layout.not_written_by_build(old) == []
    (old / "sharp" / "depth" / "notes.txt").write_text("mine")
    assert layout.not_written_by_build(old) == ["sharp/depth/notes.txt"]
    (old / "sharp" / "depth" / "notes.txt").unlink()
    proc = standin_build(b, standin_blender, *PASSES)
    assert "removed old_box_000" in proc.stderr
    assert not old.exists()


def test_the_cheap_check_of_a_hostile_exr_stays_bounded(b, tmp_path, standin_blender):
    # The rerun's and stats' cheap check decodes EXRs: issue 48's 525 KB file with a
    # 16384² header is refused there too, under the address-space cap, by name, its
    # size read from the header before any decode (issue 60).
    from tests.test_bounded_memory import run_capped, tiny_blocks

    setting = layout.complete_settings(b)[0]
    exr = sorted((setting / "sharp" / "linear").glob("*.exr"))[0]
    exr.write_bytes(tiny_blocks())
    proc = run_capped("stats", str(b), "--out", str(tmp_path / "st"))
    assert proc.returncode == 0, proc.stderr[-2000:]
    doc = json.loads((tmp_path / "st" / layout.STATS).read_text())
    (damaged,) = doc["damaged"]
    assert damaged["setting"] == setting.name
    said = f"sharp/linear/{exr.name} is 16384x16384 px, not "
    assert damaged["problem"].startswith(said), damaged
    proc = standin_build(b, standin_blender, *PASSES)
    assert f"redoing {setting.name}: {said}" in proc.stderr
    assert verify_lines(b) == {}


def test_a_users_file_at_the_top_of_a_build_is_never_listed_by_a_rerun(b, standin_blender):
    (b / "notes.txt").write_text("mine")
    (b / "extra").mkdir()
    (b / "extra" / "plot.png").write_bytes(b"not the build's")
    standin_build(b, standin_blender, *PASSES)  # up to date: nothing rendered
    names = listed(b)
    assert "notes.txt" not in names and "extra/plot.png" not in names
    assert layout.DATASET in names
    assert (b / "notes.txt").read_text() == "mine"  # kept, never deleted


def test_a_kept_preview_is_never_rehashed_by_a_rerun(b, standin_blender):
    # The check of a reused setting skips its preview (drawn from the images): a preview
    # altered since keeps the manifest's line, so verify still says so after the rerun.
    standin_build(b, standin_blender, *PASSES, "--previews")  # draws them, and lists them
    preview = layout.complete_settings(b)[0] / layout.PREVIEW
    preview.write_bytes(preview.read_bytes() + b"tampered")
    before = verify_lines(b)
    standin_build(b, standin_blender, *PASSES, "--previews")
    assert verify_lines(b) == before
    assert before[preview.relative_to(b).as_posix()] == [MISMATCH]


def test_a_rerun_without_a_manifest_lists_what_it_checked_and_nothing_else(b, standin_blender):
    # As after a run killed before its last step: the rerun checks every complete
    # setting before reusing it, so those are listed; the user's file beside them is not.
    before = listed(b)
    (b / publish.MANIFEST).unlink()
    (b / "notes.txt").write_text("mine")
    setting = layout.complete_settings(b)[0]
    cut(sorted((setting / "sharp" / "depth").iterdir())[0])
    proc = standin_build(b, standin_blender, *PASSES)
    # No manifest to differ from, but the check decodes: the cut EXR's setting is
    # redone, and listed as written; the others as checked.
    assert f"redoing {setting.name}" in proc.stderr, proc.stderr
    names = listed(b)
    assert "notes.txt" not in names
    assert names == before
    assert publish.check_manifest(b) == [("notes.txt", "unlisted", "not in MANIFEST.sha256")]


def test_a_users_file_at_the_top_of_a_noise_output_is_never_listed(b, tmp_path):
    out = tmp_path / "n"
    noise = ("noise", str(b), "--gains", "1", "--out", str(out))
    run_cli(*noise)
    (out / "notes.txt").write_text("mine")
    run_cli(*noise)  # up to date
    assert "notes.txt" not in listed(out)
    run_cli(*noise, "--seed", "5", "--overwrite")  # every unit replaced
    names = listed(out)
    assert "notes.txt" not in names and "noise_dataset.json" in names
    assert (out / "notes.txt").read_text() == "mine"
    # Without a manifest (a killed run), a rerun lists the units it found complete and
    # whole; one with a PNG cut short is redone, not certified.
    (out / publish.MANIFEST).unlink()
    png = sorted(out.glob("*/blur_1/gain_1/images/*.png"))[0]
    whole = png.read_bytes()
    cut(png)
    proc = run_cli(*noise, "--seed", "5")
    assert f"redoing {png.parent.parent.relative_to(out).as_posix()}: images/" in proc.stderr
    assert png.read_bytes() == whole
    assert listed(out) == names


def test_verify_vouches_for_no_noise_run_that_was_killed(certified, tmp_path):
    """Issue 72: `verify` of a `noise BUILD` output said it was whole (exit 0) after a
    SIGKILL mid-run. At each stage a kill leaves (BLURSET_NOISE_FAULT: a known point, not
    a race) it exits 1 with one line: inside the first unit (the start record, partial
    gain folders), before any unit (the record alone), inside the second, between two
    units, a stale partial beside a finished output's units, and after the record but
    before the manifest. Finished by a rerun, it is whole."""
    import os
    import signal
    import subprocess
    import sys

    out = tmp_path / "n"
    noise = ("noise", str(certified), "--gains", "1", "4", "--out", str(out), "--quiet")

    def killed_in(k: int) -> None:
        shutil.rmtree(out, ignore_errors=True)
        env = dict(os.environ, BLURSET_NOISE_FAULT=f"kill_in:{k}")
        proc = subprocess.run([sys.executable, "-m", "blurset.cli", *noise], env=env,
                              capture_output=True, text=True)  # fmt: skip
        assert proc.returncode == -signal.SIGKILL, proc.stderr

    def no_partials() -> None:
        for p in list(out.glob("*/*/gain_*.partial")):
            shutil.rmtree(p)

    def one_line(said: str) -> None:
        proc = run_cli("verify", str(out), check=False)
        lines = proc.stdout.splitlines()
        assert proc.returncode == 1 and len(lines) == 1, (proc.stdout, proc.stderr)
        assert f"{out}/{said}" in lines[0], lines

    unfinished = f"{layout.NOISE_DATASET}: the run has not finished"
    killed_in(1)
    assert list(out.glob("*/*/gain_*.partial")) and not list(out.glob("*/*/gain_*/.complete"))
    one_line(unfinished)
    no_partials()
    one_line(unfinished)
    killed_in(2)
    assert list(out.glob("*/*/gain_*/.complete")) and list(out.glob("*/*/gain_*.partial"))
    one_line(unfinished)
    no_partials()
    one_line(unfinished)
    run_cli(*noise)
    assert run_cli("verify", str(out)).returncode == 0
    gain = sorted(out.glob("*/*/gain_1"))[0]
    stale = gain.with_name(gain.name + layout.PARTIAL_SUFFIX)
    shutil.copytree(gain, stale)
    (stale / layout.MARKER).unlink()
    one_line(unfinished)
    shutil.rmtree(stale)
    (out / publish.MANIFEST).unlink()
    one_line(f"{publish.MANIFEST}: missing")
