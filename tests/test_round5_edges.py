"""Issue 60, the edges: a lock file that is a link is never followed, --workers-per-gpu
on a Ray cluster without GPUs is refused as the local executor refuses it, a GLB whose
vertex buffer holds NaN or Inf is that object's failure, and tradeoff's scratch folder
never takes a user's `work/`; and issue 72's: no export or noise run writes through a
link it did not make under --out, and a rerun removes no folder it did not write. Real
commands; the builds are stand-in builds (no Blender render)."""

from __future__ import annotations

import json
import math
import shutil
import struct
from pathlib import Path

import pytest
from blurset import layout
from blurset.exceptions import ConfigError, InputError
from blurset.services import outputs

from tests.conftest import copy_build, one_error_line, run_cli, standin_build


@pytest.fixture
def b(standin_build_dir, tmp_path) -> Path:
    return copy_build(standin_build_dir, tmp_path / "b")


# -- tradeoff's scratch is its temp name, never a user's `work/` (a planted bug) ------------


def test_tradeoff_never_takes_a_users_work_folder_for_its_scratch(tmp_path):
    """A tradeoff folder of an earlier run may hold the user's own `work/notes.txt`: the
    run's scratch is `.work.tmp<pid>`, made and removed beside it, never `work/`."""
    glb = tmp_path / "obj.glb"
    glb.write_bytes(b"glTF")
    out = tmp_path / "out"
    (out / "work").mkdir(parents=True)
    (out / "work" / "notes.txt").write_text("keep")
    (out / outputs.TRADEOFF_RECORD).write_text(json.dumps({"kind": outputs.TRADEOFF_KIND}))
    # A Blender that does not exist: the run fails at the worker, after it has made its
    # scratch folder and the worker's log.
    proc = run_cli("tradeoff", "--object", str(glb), "--out", str(out), "--quick",
                   "--blender", str(tmp_path / "no-blender"), check=False)  # fmt: skip
    assert proc.returncode != 0 and "Traceback" not in proc.stderr, proc.stderr
    assert "no-blender" in proc.stderr, proc.stderr  # it got as far as the worker
    assert (out / "work" / "notes.txt").read_text() == "keep"
    assert sorted(p.name for p in (out / "work").iterdir()) == ["notes.txt"]
    # The scratch it made (a failed run's, which the next run removes) is its own name.
    assert len(list(out.glob(".work.tmp*"))) == 1


# -- a lock file that is a link is never followed --------------------------------------------


def _linked_lock(out: Path, name: str, target: Path) -> None:
    out.mkdir(parents=True, exist_ok=True)
    (out / name).symlink_to(target)


@pytest.mark.parametrize("held", ["pid 12345\n", ""])
def test_an_export_lock_that_is_a_link_is_refused_and_its_target_untouched(b, tmp_path, held):
    outside = tmp_path / "outside.txt"
    outside.write_text(held)
    out = tmp_path / "e"
    _linked_lock(out, ".export.lock", outside)
    for how in ([], ["--for", "hub"]):
        proc = run_cli("export", str(b), "--out", str(out), *how, check=False)
        one_error_line(proc, str(out / ".export.lock"), "link")
        assert outside.read_text() == held
        assert sorted(p.name for p in out.iterdir()) == [".export.lock"]
        assert (out / ".export.lock").is_symlink()


def test_a_build_or_noise_lock_that_is_a_link_is_refused(b, tmp_path, standin_blender):
    # The build's shared lock, a link to nothing: following it would create the file.
    objs = tmp_path / "objs"
    objs.mkdir()
    shutil.copy(sorted(b.glob(f"{layout.DEMO_OBJECTS}/*.glb"))[0], objs / "a.glb")
    nowhere = tmp_path / "nowhere" / "made.txt"
    nowhere.parent.mkdir()
    out = tmp_path / "out"
    _linked_lock(out, layout.BUILD_LOCK, nowhere)
    proc = standin_build(out, standin_blender, "--objects", str(objs), check=False)
    one_error_line(proc, str(out / layout.BUILD_LOCK), "link")
    assert not nowhere.exists() and list(nowhere.parent.iterdir()) == []
    assert sorted(p.name for p in out.iterdir()) == [layout.BUILD_LOCK]
    # The noise lock, a link to a file holding a pid.
    outside = tmp_path / "outside.txt"
    outside.write_text("pid 12345\n")
    n = tmp_path / "n"
    _linked_lock(n, ".noise.lock", outside)
    proc = run_cli("noise", str(b), "--out", str(n), "--gains", "1", check=False)
    one_error_line(proc, str(n / ".noise.lock"), "link")
    assert outside.read_text() == "pid 12345\n"
    assert sorted(p.name for p in n.iterdir()) == [".noise.lock"]


def test_every_lock_opens_without_following_a_link(tmp_path):
    """flock_file (every output's lock, an object's, tradeoff's) and the build's shared
    lock refuse a link by the lock's name; a real lock file is taken as before."""
    from blurset.commands.builder.dataset import build_lock

    target = tmp_path / "target"
    (tmp_path / "l").symlink_to(target)
    with pytest.raises(InputError, match="is a link"), outputs.flock_file(tmp_path / "l"):
        pass
    (tmp_path / layout.BUILD_LOCK).symlink_to(target)
    with pytest.raises(InputError, match="is a link"), build_lock(tmp_path):
        pass
    assert not target.exists()
    with outputs.flock_file(tmp_path / "real.lock"):
        assert (tmp_path / "real.lock").read_text().startswith("pid ")
    assert not (tmp_path / "real.lock").exists()


# -- --workers-per-gpu on a Ray cluster without GPUs: the local executor's rule ------------


def test_workers_per_gpu_on_a_ray_cluster_without_gpus_is_refused_before_writing(
    tmp_path, standin_blender
):
    """A real local Ray cluster (this machine has no GPU), as --executor ray starts one;
    the same line as the local executor's, naming what the cluster has."""
    pytest.importorskip("ray")
    out = tmp_path / "out"
    proc = standin_build(out, standin_blender, "--workers-per-gpu", "2", "--executor", "ray",
                         check=False)  # fmt: skip
    # Ray says it started a local instance (its own log lines); then the one error.
    errors = [x for x in proc.stderr.splitlines() if "error" in x.lower()]
    assert proc.returncode == 2 and len(errors) == 1, proc.stderr
    assert errors[0] == proc.stderr.strip().splitlines()[-1], proc.stderr
    for words in ("--workers-per-gpu 2: rendering on the CPU", "Ray cluster", "0 GPUs"):
        assert words in errors[0], proc.stderr
    assert not out.exists()
    local = standin_build(out, standin_blender, "--workers-per-gpu", "2", check=False)
    assert one_error_line(local, "--workers-per-gpu 2: rendering on the CPU")
    assert not out.exists()


def test_the_ray_rule_is_the_local_one():
    from blurset.services import devices
    from blurset.services.config import make_config

    def cfg(**kw):
        return make_config({"executor": "ray", **kw}, {"demo": True, "out": "o"})

    for device in ("auto", "cuda"):
        with pytest.raises(ConfigError, match="--workers-per-gpu 4: rendering on the CPU"):
            devices.check_ray(cfg(workers_per_gpu=4, device=device), {"CPU": 8.0})
        devices.check_ray(cfg(workers_per_gpu=4, device=device), {"CPU": 8.0, "GPU": 2.0})
    devices.check_ray(cfg(), {"CPU": 8.0})  # no sharing asked: the CPU renders


# -- a GLB whose vertex buffer holds NaN or Inf is that object's failure --------------------


def triangle_glb(corner: float, *, sparse: bool = False) -> bytes:
    """One triangle whose third vertex has x = `corner`; the accessor's min/max say a
    finite unit triangle whatever the buffer holds. `sparse`: the buffer is finite and
    the accessor's sparse substitution carries `corner` instead."""
    verts = struct.pack("<9f", 0, 0, 0, 1, 0, 0, 1.0 if sparse else corner, 1, 0)
    acc: dict = {"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3",
                 "min": [0, 0, 0], "max": [1, 1, 0]}  # fmt: skip
    views = [{"buffer": 0, "byteOffset": 0, "byteLength": 36}]
    extra = b""
    if sparse:
        extra = struct.pack("<I3f", 2, corner, 1, 0)  # index 2, then its value
        views += [{"buffer": 0, "byteOffset": 36, "byteLength": 4},
                  {"buffer": 0, "byteOffset": 40, "byteLength": 12}]  # fmt: skip
        acc["sparse"] = {"count": 1, "indices": {"bufferView": 1, "componentType": 5125},
                         "values": {"bufferView": 2}}  # fmt: skip
    bin_ = verts + extra
    doc = {
        "asset": {"version": "2.0"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}}]}],
        "accessors": [acc],
        "bufferViews": views,
        "buffers": [{"byteLength": len(bin_)}],
    }
    text = json.dumps(doc).encode()
    text += b" " * (-len(text) % 4)
    chunks = struct.pack("<II", len(text), 0x4E4F534A) + text
    chunks += struct.pack("<II", len(bin_), 0x004E4942) + bin_
    return b"glTF" + struct.pack("<II", 2, 12 + len(chunks)) + chunks


@pytest.mark.parametrize("sparse", [False, True])
def test_a_non_finite_vertex_is_refused_by_preflight(tmp_path, sparse):
    from blurset.services import preflight

    ok = tmp_path / "ok.glb"
    ok.write_bytes(triangle_glb(0.5, sparse=sparse))
    assert preflight.check(ok).triangles == 1
    for corner in (math.nan, math.inf, -math.inf):
        bad = tmp_path / "bad.glb"
        bad.write_bytes(triangle_glb(corner, sparse=sparse))
        with pytest.raises(preflight.PreflightError) as e:
            preflight.check(bad)
        msg = str(e.value)
        assert msg.startswith("non-finite vertex position: accessor 0") and "\n" not in msg
        assert repr(corner) in msg, msg


def test_a_gltf_with_a_non_finite_vertex_in_its_bin_file_is_refused(tmp_path):
    from blurset.services import preflight

    data = triangle_glb(math.nan)
    doc_len = struct.unpack_from("<I", data, 12)[0]
    doc = json.loads(data[20 : 20 + doc_len])
    doc["buffers"][0]["uri"] = "tri.bin"
    (tmp_path / "tri.bin").write_bytes(data[20 + doc_len + 8 :])
    (tmp_path / "tri.gltf").write_text(json.dumps(doc))
    with pytest.raises(preflight.PreflightError, match="non-finite vertex position"):
        preflight.check(tmp_path / "tri.gltf")


def test_a_build_records_a_non_finite_glb_by_its_file_and_goes_on(tmp_path, standin_blender):
    """Beside the demo objects, which build."""
    objs = tmp_path / "objs"
    objs.mkdir()
    (objs / "nan_vertex.glb").write_bytes(triangle_glb(math.nan))
    out = tmp_path / "out"
    proc = standin_build(out, standin_blender, "--objects", str(objs), check=False)
    assert proc.returncode == 0 and "Traceback" not in proc.stderr, proc.stderr
    assert "1 of 4 objects failed" in proc.stderr, proc.stderr
    recs = [json.loads(x) for x in (out / layout.FAILURES).read_text().splitlines()]
    assert [(r["uid"], r["stage"], r["path"]) for r in recs] == [
        ("nan_vertex", "preflight", "nan_vertex.glb")
    ], recs
    assert "non-finite vertex position" in recs[0]["reason"]
    assert not list(out.glob("nan_vertex_*")) and len(layout.complete_settings(out)) == 6


# -- issue 72: no command writes through a link it did not make under --out ----------------


@pytest.fixture(scope="module")
def bn(tmp_path_factory, standin_blender) -> tuple[Path, Path]:
    """A stand-in build of 17 views (GeoNeRF's test scenes need 7 train views) and its
    noise output."""
    d = tmp_path_factory.mktemp("links")
    standin_build(d / "b", standin_blender, "--views", "17")
    run_cli("noise", str(d / "b"), "--out", str(d / "n"), "--gains", "4", "--quiet")
    return d / "b", d / "n"


def _user_folder(path: Path) -> dict[str, bytes | None]:
    """A user's folder: a note and an empty folder, the state a test compares."""
    (path / "keep").mkdir(parents=True)
    (path / "note.txt").write_text("mine")
    return _state(path)


def _state(path: Path) -> dict[str, bytes | None]:
    return {str(p.relative_to(path)): p.read_bytes() if p.is_file() else None
            for p in sorted(path.rglob("*"))}  # fmt: skip


def _swap_for_link(out: Path, rel: str, user: Path) -> None:
    """`rel` of `out` (what a command wrote) moved away, a link to `user` in its place."""
    shutil.rmtree(out / rel)
    (out / rel).symlink_to(user)


_HUB, _LLFF = ["export", "{b}", "--for", "hub"], ["export", "{b}"]
_NOISE = ["noise", "{b}", "--gains", "4", "--quiet"]
# case: (the command, its first run that wrote the folder or None: new, the link's place)
LINK_CASES = {
    "hub data, new": (_HUB, None, "data"),
    "hub config, new": (_HUB, None, "data/sharp"),
    "hub data, rerun": ([*_HUB, "--levels", "sharp"], _HUB, "data"),
    "llff, new": (_LLFF, None, "nerf_llff_data"),
    "llff, rerun": ([*_LLFF, "--levels", "sharp"], _LLFF, "nerf_llff_data"),
    "geonerf, new": ([*_LLFF, "--for", "geonerf"], None, "geonerf"),
    "geonerf train, new": ([*_LLFF, "--for", "geonerf"], None, "geonerf/train"),
    "nerfstudio scene, new": ([*_LLFF, "--for", "nerfstudio"], None, "{setting}__sharp"),
    "noise setting, rerun": (_NOISE, _NOISE, "{setting}"),
    "noise level, rerun --overwrite": ([*_NOISE, "--overwrite"], _NOISE, "{setting}/sharp"),
}  # fmt: skip


@pytest.mark.parametrize("case", list(LINK_CASES))
def test_a_link_at_a_folder_a_command_writes_is_refused_and_its_target_untouched(
    bn, tmp_path, case
) -> None:
    """A link planted where a command writes a folder (a new output's, or in place of
    one an earlier run wrote) is refused by name before anything is written, and the
    user's folder it points to, its empty folder too, stays as it was: no shard, scene
    or unit written there, nothing removed there."""
    b, _ = bn
    args, first, rel = LINK_CASES[case]
    rel = rel.format(setting=json.loads((b / "splits.json").read_text())["train"][0])
    out, user = tmp_path / "out", tmp_path / "user"
    before = _user_folder(user)
    if first:
        # A first run wrote the folder, then it was swapped for the link.
        run_cli(*[a.format(b=b) for a in first], "--out", str(out))
        _swap_for_link(out, rel, user)
    else:
        (out / rel).parent.mkdir(parents=True, exist_ok=True)
        (out / rel).symlink_to(user)
    proc = run_cli(*[a.format(b=b) for a in args], "--out", str(out), check=False)
    one_error_line(proc, f"--out/{rel} is a link", "did not make")
    assert _state(user) == before
    assert (out / rel).is_symlink()


@pytest.mark.parametrize("where", ["{setting}", "{setting}.partial"])
def test_a_build_rerun_refuses_a_link_where_a_setting_goes(bn, standin_blender, tmp_path, where):
    """A link where a setting (or its staging folder) goes is refused by name before the
    sweep: a rerun neither removes it nor publishes the setting through or over it."""
    b, _ = bn
    out, user = copy_build(b, tmp_path / "b"), tmp_path / "user"
    before = _user_folder(user)
    rel = where.format(setting=json.loads((out / "splits.json").read_text())["train"][0])
    if (out / rel).exists():
        _swap_for_link(out, rel, user)
    else:
        (out / rel).symlink_to(user)
    proc = standin_build(out, standin_blender, "--views", "17", check=False)
    one_error_line(proc, f"--out/{rel} is a link", "blurset build did not make")
    assert _state(user) == before and (out / rel).is_symlink()


def test_a_noise_scene_overwrite_refuses_a_linked_gain_folder(bn, tmp_path) -> None:
    b, _ = bn
    setting = json.loads((b / "splits.json").read_text())["train"][0]
    scene, out, user = b / setting / "sharp", tmp_path / "out", tmp_path / "user"
    before = _user_folder(user)
    run_cli("noise", str(scene), "--factor", "1", "--out", str(out), "--gains", "4")
    _swap_for_link(out, "gain_4", user)
    proc = run_cli("noise", str(scene), "--factor", "1", "--out", str(out), "--gains", "4", "--overwrite",
                   check=False)  # fmt: skip
    one_error_line(proc, "--out/gain_4 is a link")
    assert _state(user) == before and (out / "gain_4").is_symlink()


@pytest.mark.parametrize("target", ["hub", "llff"])
def test_a_rerun_never_removes_a_folder_it_did_not_write(bn, tmp_path, target) -> None:
    """A user's empty folder beside the shards (data/notes) or the scenes survives a
    rerun that removes the entries of the levels it no longer exports."""
    b, _ = bn
    out = tmp_path / "out"
    run_cli("export", str(b), "--for", target, "--out", str(out))
    top = out / json.loads((out / "export.json").read_text())["scenes_dir"]
    if target == "hub":
        top = out / "data"
    (top / "notes").mkdir()
    run_cli("export", str(b), "--for", target, "--out", str(out), "--levels", "sharp")
    assert (top / "notes").is_dir() and not any((top / "notes").iterdir())
    assert not any("blur" in p.name for p in top.iterdir())  # the rerun did remove its own
