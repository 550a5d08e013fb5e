"""Issue 34, the findings left after round three: a value that starts with '-', a user's
file in a setting a rerun supersedes, `out` in a config file that is a link to nothing,
pose bounds that are no depth interval, and GLB headers that lie about their sizes.
Real commands; the builds are stand-in builds (no Blender render)."""

from __future__ import annotations

import json
import shutil
import struct
from pathlib import Path

import numpy as np
import pytest
from blurset import layout
from blurset.services.preflight import PreflightError, glb_inspect

from tests.conftest import copy_build, one_error_line, run_cli, standin_build, tree


@pytest.fixture
def b(standin_build_dir, tmp_path) -> Path:
    return copy_build(standin_build_dir, tmp_path / "b")


# -- a value that starts with '-' reaches its option's own check ----------------------------


@pytest.mark.parametrize(
    ("argv", "words"),
    [
        (["build", "--shard", "-1/2"], ["--shard", "-1/2", "i/N"]),
        (["build", "--resolution", "-5"], ["--resolution", "-5", "8..=16384"]),
        (["build", "--latents", "-inf"], ["--latents", "-inf"]),
    ],
)
def test_a_value_starting_with_a_dash_is_checked_by_its_option(argv, words, tmp_path):
    out = tmp_path / "o"
    proc = run_cli(*argv, "--demo", "--out", str(out), check=False)
    line = one_error_line(proc, *words)
    assert "expected one argument" not in line
    # The same line as the value written with `=`, which argparse always took as a value.
    flag, value = argv[1], argv[2]
    same = run_cli(argv[0], f"{flag}={value}", "--demo", "--out", str(out), check=False)
    assert same.stderr == proc.stderr
    assert not out.exists()


def test_a_dashed_value_in_a_list_option_is_checked_by_its_option(b, tmp_path):
    out = tmp_path / "n"
    for gains in (["-1"], ["1", "-1e-3"], ["-2", "4"]):
        proc = run_cli("noise", str(b), "--out", str(out), "--gains", *gains, check=False)
        line = one_error_line(proc, "--gains", gains[-1] if "-" in gains[-1] else gains[0])
        assert "expected at least one argument" not in line
        assert "unrecognized arguments" not in line
        assert not out.exists()


def test_an_option_after_an_option_missing_its_value_is_still_an_option(tmp_path):
    # `--shard --quiet`: --quiet is an option of build, not a value of --shard.
    proc = run_cli("build", "--demo", "--out", str(tmp_path / "o"), "--shard", "--quiet",
                   check=False)  # fmt: skip
    assert proc.returncode == 2
    assert "--shard: expected one argument" in proc.stderr
    assert not (tmp_path / "o").exists()


# -- a user's file inside a setting a rerun supersedes -------------------------------------


def supersede(build: Path) -> Path:
    """An extra complete setting made from demo_box.glb under an id that file no longer
    has: the next run of the build removes it (`_core.superseded_settings`)."""
    src = build / "demo_box_000"
    old = build / "old_box_000"
    shutil.copytree(src, old)
    meta = json.loads((old / layout.META).read_text())
    meta["uid"] = "old_box"
    (old / layout.META).write_text(json.dumps(meta))
    return old


def test_a_superseded_setting_holding_a_users_file_is_refused_by_name(b, standin_blender):
    old = supersede(b)
    (old / "notes.txt").write_text("my notes")
    before = tree(b)
    line = one_error_line(
        standin_build(b, standin_blender, check=False), "old_box_000", "notes.txt"
    )
    assert "move it out" in line
    assert tree(b) == before  # nothing removed, nothing written
    (old / "notes.txt").unlink()
    proc = standin_build(b, standin_blender)
    assert "removed old_box_000" in proc.stderr
    assert not old.exists()


def test_a_users_file_in_a_level_of_a_superseded_setting_is_named_too(b, standin_blender):
    old = supersede(b)
    (old / "sharp" / "README").write_text("about this level")
    one_error_line(standin_build(b, standin_blender, check=False), "old_box_000", "sharp/README")
    assert (old / "sharp" / "README").read_text() == "about this level"


# -- `out` in a config file that is a link to nothing ----------------------------------------


def test_toml_out_a_dangling_link_is_refused_like_the_flag(tmp_path, standin_blender):
    link = tmp_path / "link"
    link.symlink_to(tmp_path / "elsewhere" / "deep")
    config = tmp_path / "c.toml"
    config.write_text(f'out = "{link}"\n')
    proc = run_cli("build", "--demo", "--config", str(config), "--quiet",
                   "--blender", str(standin_blender), check=False)  # fmt: skip
    line = one_error_line(proc, "c.toml", "out", "link to nothing", str(link))
    assert not (tmp_path / "elsewhere").exists()
    flag = one_error_line(standin_build(link, standin_blender, check=False), "--out")
    # One check: the same words after the option's name.
    assert line.split(" out ", 1)[1] == flag.split("--out ", 1)[1]


# -- pose bounds that are no depth interval ----------------------------------------------------


def test_noise_of_a_scene_with_unknown_bounds_names_the_view_and_writes_nothing(b, tmp_path):
    scene = tmp_path / "scene"
    shutil.copytree(b / "demo_box_000" / "sharp", scene)
    poses = scene / layout.POSES_BOUNDS
    rows = np.load(poses)
    rows[2, 15:] = -1.0  # near = far = -1: "unknown"
    np.save(poses, rows)
    out = tmp_path / "n"
    proc = run_cli("noise", str(scene), "--factor", "1", "--gains", "1", "--out", str(out),
                   check=False)  # fmt: skip
    one_error_line(proc, "row 2 (view 2)", "near -1", "poses_bounds.npy")
    assert not out.exists()


def test_export_of_a_build_with_reversed_bounds_does_not_pass_them_on(b, tmp_path):
    poses = b / "demo_box_000" / "sharp" / layout.POSES_BOUNDS
    rows = np.load(poses)
    rows[0, 15], rows[0, 16] = rows[0, 16], rows[0, 15]  # near > far
    np.save(poses, rows)
    data = tmp_path / "data"
    proc = run_cli("export", str(b), "--out", str(data), "--levels", "sharp", check=False)
    assert proc.returncode != 0, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "demo_box_000" in lines[0], proc.stderr
    exported = list(data.rglob(layout.POSES_BOUNDS)) if data.exists() else []
    for p in exported:
        r = np.load(p)
        assert (r[:, 15] > 0).all() and (r[:, 16] > r[:, 15]).all(), p


# -- GLB headers that lie about their sizes ----------------------------------------------------


def glb(header_total: int | None, chunks: list[tuple[int, int, bytes]]) -> bytes:
    """A GLB of (declared length, type, body) chunks; `header_total` None: the real size."""
    body = b"".join(struct.pack("<II", n, t) + data for n, t, data in chunks)
    total = 12 + len(body) if header_total is None else header_total
    return b"glTF" + struct.pack("<II", 2, total) + body


JSON, BIN = glb_inspect.CHUNK_JSON, glb_inspect.CHUNK_BIN
DOC = b'{"asset":{"version":"2.0"}}    '

HOSTILE = {
    "total_ffffffff": (glb(0xFFFFFFFF, [(len(DOC), JSON, DOC)]), "header declares 4294967295"),
    "json_longer_than_file": (glb(None, [(1000, JSON, DOC)]), "declares 1000 bytes"),
    "bin_longer_than_file": (
        glb(None, [(len(DOC), JSON, DOC), (0xFFFFFFFF, BIN, b"\0" * 8)]),
        "declares 4294967295 bytes",
    ),
    "truncated_header": (b"glTF" + struct.pack("<I", 2), "not a binary glTF"),
    "truncated_chunk_header": (glb(None, [(len(DOC), JSON, DOC)])[:16], "header declares"),
    "too_small_total": (glb(12, []), "too few"),
    "deep_json": (glb(None, [(80_000, JSON, b"[" * 80_000)]), "not valid JSON"),
}


@pytest.mark.parametrize("name", sorted(HOSTILE))
def test_a_hostile_glb_header_is_one_preflight_line(name, tmp_path):
    data, words = HOSTILE[name]
    path = tmp_path / f"{name}.glb"
    path.write_bytes(data)
    with pytest.raises(glb_inspect.GlbError) as e:
        glb_inspect.read_glb(str(path))
    assert str(e.value).endswith(f": {path}") and words in e.value.reason, e.value
    with pytest.raises(PreflightError) as p:
        from blurset.services import preflight

        preflight.check(path)
    assert words in str(p.value) and "\n" not in str(p.value), p.value


def test_a_json_chunk_past_the_limit_is_refused_before_it_is_read(tmp_path, monkeypatch):
    big = glb_inspect.MAX_GLB_JSON_BYTES + 4
    path = tmp_path / "big_json.glb"
    with open(path, "wb") as f:
        f.write(glb(12 + 8 + big, [(big, JSON, b"")]))
        f.truncate(12 + 8 + big)  # sparse: the declared chunk is really there
    reads: list[int] = []
    real_open = open

    class Counting:
        def __init__(self, f):
            self.f = f

        def __enter__(self):
            return self

        def __exit__(self, *a):
            self.f.close()

        def read(self, n=-1):
            reads.append(n)
            return self.f.read(n)

        def __getattr__(self, name):
            return getattr(self.f, name)

    monkeypatch.setattr(glb_inspect, "open", lambda p, m="r": Counting(real_open(p, m)),
                        raising=False)  # fmt: skip
    with pytest.raises(glb_inspect.GlbError) as e:
        glb_inspect.read_glb(str(path))
    assert "MAX_GLB_JSON_BYTES" in e.value.reason and e.value.path == str(path)
    assert all(0 <= n <= 12 for n in reads), reads  # headers only, never the chunk


def test_a_build_records_a_hostile_glb_by_its_file_and_goes_on(tmp_path):
    objs = tmp_path / "objs"
    objs.mkdir()
    for name in ("total_ffffffff", "json_longer_than_file", "deep_json"):
        (objs / f"{name}.glb").write_bytes(HOSTILE[name][0])
    out = tmp_path / "out"
    proc = run_cli("build", "--objects", str(objs), "--out", str(out), "--views", "2",
                   "--levels", "none", "--resolution", "16", "--quiet", check=False)  # fmt: skip
    assert proc.returncode == 1, proc.stderr
    assert "internal error" not in proc.stderr and "Traceback" not in proc.stderr
    recs = [json.loads(line) for line in (out / layout.FAILURES).read_text().splitlines()]
    assert {r["uid"]: r["stage"] for r in recs} == {
        "total_ffffffff": "preflight",
        "json_longer_than_file": "preflight",
        "deep_json": "preflight",
    }
    for r in recs:
        assert r["path"].endswith(f"{r['uid']}.glb") and HOSTILE[r["uid"]][1] in r["reason"], r


# -- what the build capped is said on the command line (issue 36) --------------------------


def test_test_settings_capped_by_the_build_is_said(tmp_path, standin_blender):
    out = tmp_path / "t"
    proc = standin_build(out, standin_blender, "--test-settings", "52")
    test = json.loads((out / layout.SPLITS).read_text())["test"]
    assert len(test) == 5  # 6 settings: one stays train
    assert "--test-settings 52: 5 test settings, as the build has 6 complete" in proc.stderr
    proc = standin_build(tmp_path / "u", standin_blender, "--test-settings", "2")
    assert "--test-settings" not in proc.stderr
