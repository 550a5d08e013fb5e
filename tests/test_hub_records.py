"""The records of `blurset export --for hub` (issue 60): a rerun keeps a shard only when
its bytes are those a record it trusts lists (the build's rule: what a rerun reuses is
checked against its manifest and redone when it differs, never hashed anew), a stopped
run carries what it wrote or checked, `verify` reads every column a shard publishes, and
bad input (a shard size no record can hold, a full disk) gets one line naming it."""

from __future__ import annotations

import errno
import hashlib
import json
import math
import shutil
from pathlib import Path

import pytest
from blurset import cli
from blurset.commands.export import hub as export_hub

from tests.conftest import copy_build, one_error_line, run_cli, standin_build, tree

pa = pytest.importorskip("pyarrow")
pq = pytest.importorskip("pyarrow.parquet")

# Several shards per config and split, each holding whole settings.
ARGS = ("--for", "hub", "--levels", "sharp,blur_1", "--shard-size", "0.02")


@pytest.fixture(scope="module")
def whole(standin_build_dir, tmp_path_factory) -> Path:
    """An uninterrupted export of the stand-in build: the bytes every resume must give."""
    out = tmp_path_factory.mktemp("hub_records") / "whole"
    run_cli("export", str(standin_build_dir), "--out", str(out), *ARGS)
    return out


def _export(build: Path, out: Path, **kw):
    return run_cli("export", str(build), "--out", str(out), *ARGS, **kw)


def _copy(whole: Path, tmp_path: Path) -> tuple[Path, dict]:
    out = tmp_path / "hub"
    shutil.copytree(whole, out)
    return out, json.loads((out / "export.json").read_text())


def _flip(p: Path, at: int | None = None, n: int = 8) -> None:
    """Flip `n` bytes of a file in the middle of its data (the size stays)."""
    data = bytearray(p.read_bytes())
    at = len(data) // 3 if at is None else at
    for i in range(at, at + n):
        data[i] ^= 0xFF
    p.write_bytes(bytes(data))


def _rewrite(p: Path, change) -> None:
    """Rewrite a shard with pyarrow, its rows changed by `change`, under the same schema
    and footer key (one row group per setting, as the export writes it)."""
    f = pq.ParquetFile(p)
    groups = [f.read_row_group(g) for g in range(f.num_row_groups)]
    with pq.ParquetWriter(p, f.schema_arrow) as w:
        for t in groups:
            rows = t.to_pylist()
            change(rows)
            w.write_table(pa.Table.from_pylist(rows, schema=f.schema_arrow))


def _record_as_is(out: Path, name: str) -> None:
    """Record a shard's bytes in export.json as if an export had written them."""
    doc = json.loads((out / "export.json").read_text())
    p = out / "data" / name
    doc["shards"][name]["bytes"] = p.stat().st_size
    doc["shards"][name]["sha256"] = hashlib.sha256(p.read_bytes()).hexdigest()
    (out / "export.json").write_text(json.dumps(doc))


def test_a_shard_rewritten_under_its_key_is_redone_not_rehashed(standin_build_dir, whole, tmp_path):
    """J1a: a shard rewritten with pyarrow (one focal x 1.01, the same footer key) is
    written again from the build, never read into export.json."""
    out, doc = _copy(whole, tmp_path)
    name = sorted(doc["shards"])[1]

    def scale_focal(rows):
        rows[0]["focal"] *= 1.01

    _rewrite(out / "data" / name, scale_focal)
    proc = _export(standin_build_dir, out)
    assert f"redoing data/{name}" in proc.stderr
    assert tree(out) == tree(whole)
    assert run_cli("verify", str(out)).returncode == 0


def test_a_flipped_shard_is_redone_not_up_to_date(standin_build_dir, whole, tmp_path):
    """J1c: a rerun over a shard with flipped bytes (the same size) redoes it."""
    out, doc = _copy(whole, tmp_path)
    name = sorted(doc["shards"])[0]
    _flip(out / "data" / name)
    proc = _export(standin_build_dir, out)
    assert "up to date" not in proc.stdout
    assert "(1 written)" in proc.stdout
    assert f"redoing data/{name}: sha256 differs" in proc.stderr
    assert tree(out) == tree(whole)
    # Now it is: nothing read into a record, nothing written.
    assert "up to date" in _export(standin_build_dir, out).stdout


def test_a_killed_rerun_over_damaged_shards_never_certifies_them(
    standin_build_dir, whole, tmp_path
):
    """J1b: flip one shard, truncate another, kill the rerun inside the first shard it
    writes (export.json is then `replacing`): the next rerun redoes the flipped shard
    too, and keeps (by their carried records) the shards the killed run checked."""
    out, doc = _copy(whole, tmp_path)
    names = sorted(doc["shards"])
    flipped, cut = out / "data" / names[2], out / "data" / names[0]
    _flip(flipped)
    cut.write_bytes(cut.read_bytes()[: cut.stat().st_size // 2])
    proc = _export(standin_build_dir, out, check=False, env={export_hub.FAULT: "kill_in:0"})
    assert proc.returncode == -9, proc.stderr
    rec = json.loads((out / "export.json").read_text())
    assert rec["state"] == "replacing"
    one_error_line(run_cli("verify", str(out), check=False), "not finished", str(out))
    assert sorted(rec["shards"]) == sorted(set(names) - {names[0], names[2]})
    inodes = {n: (out / "data" / n).stat().st_ino for n in rec["shards"]}
    proc = _export(standin_build_dir, out)
    assert "(2 written)" in proc.stdout
    assert tree(out) == tree(whole)
    assert {n: (out / "data" / n).stat().st_ino for n in rec["shards"]} == inodes
    assert run_cli("verify", str(out)).returncode == 0


def test_a_stopped_run_that_carried_no_records_writes_its_shards_again(
    standin_build_dir, whole, tmp_path
):
    """export.json `replacing` with no shard records (a run of an older blurset killed):
    nothing vouches for the shards on disk, so none is hashed into the record."""
    out, doc = _copy(whole, tmp_path)
    names = sorted(doc["shards"])
    _flip(out / "data" / names[0])
    (out / "export.json").write_text(
        json.dumps(
            {
                "kind": "blurset export",
                "state": "replacing",
                "build": doc["build"],
                "scenes_dir": "data",
                "scenes": {},
                "owns": sorted([*(f"data/{n}" for n in names), "export.json"]),
            }
        )
    )
    proc = _export(standin_build_dir, out)
    assert f"({len(names)} written)" in proc.stdout
    assert tree(out) == tree(whole)


@pytest.fixture(scope="module")
def passes_build(tmp_path_factory, standin_blender) -> Path:
    """A build with a depth pass and masks (two settings)."""
    b = tmp_path_factory.mktemp("hub_passes") / "b"
    standin_build(b, standin_blender, "--passes", "depth,mask", "--settings-per-object", "1",
                  "--levels", "1")  # fmt: skip
    return b


@pytest.mark.parametrize("damage", ["meta", "focal", "c2w", "depth", "mask"])
def test_verify_reads_every_column(passes_build, tmp_path, damage):
    """A shard whose bytes export.json vouches for, but whose `meta` is not JSON (J1b's
    `69.50046947182:b9`), whose numbers are not finite, or whose depth EXR or mask does
    not decode, is named by its row and column."""
    out = tmp_path / "hub"
    run_cli("export", str(passes_build), "--out", str(out), "--for", "hub", "--levels",
            "sharp")  # fmt: skip
    assert run_cli("verify", str(out)).returncode == 0
    doc = json.loads((out / "export.json").read_text())
    name = sorted(doc["shards"])[0]

    def spoil(rows):
        r = rows[1]
        if damage == "meta":
            r["meta"] = r["meta"][:-1] + ', "phi_deg": 69.50046947182:b9}'
        elif damage == "focal":
            r["focal"] = math.nan
        elif damage == "c2w":
            r["c2w"][1][2] = math.inf
        elif damage == "depth":
            r["depth"] = r["depth"][: len(r["depth"]) // 2]
        else:
            r["mask"]["bytes"] = r["mask"]["bytes"][:60]

    _rewrite(out / "data" / name, spoil)
    _record_as_is(out, name)
    proc = run_cli("verify", str(out), check=False)
    assert proc.returncode == 1, proc.stderr
    setting = doc["shards"][name]["settings"][0]
    assert f"data/{name}: {setting} view 1 {damage}:" in proc.stdout, proc.stdout


@pytest.mark.parametrize("mb", ["1e300", "1e15", "1e18", "inf", "nan", "-1"])
def test_a_shard_size_no_record_can_hold_is_refused_up_front(standin_build_dir, tmp_path, mb):
    out = tmp_path / "out"
    proc = run_cli("export", str(standin_build_dir), "--for", "hub", "--out", str(out),
                   "--levels", "sharp", "--shard-size", mb, check=False)  # fmt: skip
    one_error_line(proc, "--shard-size")
    assert not out.exists()


def test_a_full_disk_names_the_shard(standin_build_dir, tmp_path, monkeypatch, capsys):
    """ENOSPC while a shard is written: one line naming the shard, its temp file gone."""
    out = tmp_path / "out"

    def full(self, b):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(export_hub._HashingFile, "write", full)
    argv = ["export", str(standin_build_dir), "--out", str(out), "--for", "hub", "--levels",
            "sharp"]  # fmt: skip
    assert cli.main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "No space left on device" in err[0], err
    assert f"{out / 'data' / 'sharp'}/" in err[0], err
    assert not list((out / "data").rglob(".*"))


def test_verify_still_passes_on_a_whole_export(whole, standin_build_dir, tmp_path):
    """A rerun with the build copied elsewhere keeps every shard (the records check out)."""
    b = copy_build(standin_build_dir, tmp_path / standin_build_dir.name)
    out, _ = _copy(whole, tmp_path)
    assert "up to date" in _export(b, out).stdout
    assert run_cli("verify", str(whole)).returncode == 0
