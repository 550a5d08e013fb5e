"""Scale-out (issue 8, DESIGN §11) on real renders: a local build, a local pool, a real
local Ray instance and two concurrent `--shard` jobs give the same dataset; Objaverse
ids resolve through a cache laid out like the objaverse package's, offline, and download
from an HF_ENDPOINT mirror with retries when online."""

from __future__ import annotations

import gzip
import http.server
import json
import shutil
import subprocess
import sys
import threading
import types
from pathlib import Path

import pytest
from blurset.exceptions import InputError
from blurset.services import objaverse_cache
from blurset.services.demo import make_demo_objects
from blurset.services.objects import resolve_objects

from tests.conftest import run_cli

TINY = (
    "--views", "4", "--levels", "1", "--latents", "2", "--samples", "2",
    "--resolution", "32", "--settings-per-object", "2", "--threads", "1", "--quiet",
)  # fmt: skip


@pytest.fixture(scope="module")
def demo_glbs(tmp_path_factory) -> list[Path]:
    return make_demo_objects(tmp_path_factory.mktemp("demo"), seed=0)


def tree(out: Path) -> dict[str, object]:
    """Every file of a build, with what may differ between runs (timings, where the
    output lives, how it was run) left out."""
    files: dict[str, object] = {}
    for p in sorted(out.rglob("*")):
        if not p.is_file() or p.name in (".lock", "MANIFEST.sha256"):
            continue  # the manifest hashes meta.json timings; its own tests are elsewhere
        name = str(p.relative_to(out))
        data = p.read_bytes()
        if p.name == ".complete":
            files[name] = "marker"
        elif p.name == "meta.json":
            meta = json.loads(data)
            meta.pop("timings")
            files[name] = meta
        elif p.name == "dataset.json":
            ds = json.loads(data)
            for k in ("created", "seconds", "config"):
                ds.pop(k)
            files[name] = ds
        elif p.name == "failures.jsonl":
            recs = [json.loads(line) for line in data.decode().splitlines()]
            files[name] = [
                {k: v for k, v in r.items() if k not in ("seconds", "time")} for r in recs
            ]
        else:
            files[name] = data
    return files


@pytest.mark.blender
@pytest.mark.slow
def test_local_pool_ray_and_shards_build_the_same_dataset(demo_glbs, tmp_path):
    objs = tmp_path / "objs"
    objs.mkdir()
    for g in demo_glbs:
        shutil.copy(g, objs / g.name)
    (objs / "broken.glb").write_bytes(b"")  # fails the same way everywhere
    base = ("build", "--objects", str(objs), *TINY)

    run_cli(*base, "--out", str(tmp_path / "local"))
    run_cli(*base, "--out", str(tmp_path / "pool"), "--workers", "2")
    run_cli(*base, "--out", str(tmp_path / "ray"), "--executor", "ray")
    # Two array jobs at once into one output, as a Slurm array would run them.
    shards = [
        subprocess.Popen(
            [
                sys.executable,
                "-m",
                "blurset.cli",
                *base,
                "--out",
                str(tmp_path / "shards"),
                "--shard",
                f"{i}/2",
            ],
            stderr=subprocess.PIPE,
            text=True,
        )  # fmt: skip
        for i in range(2)
    ]
    for p in shards:
        _, err = p.communicate(timeout=600)
        assert p.returncode in (0, 1), err  # a shard holding only the broken file builds nothing
    # The shards split the objects: each built something, none built the same thing.
    ref = tree(tmp_path / "local")
    assert ref["failures.jsonl"] == [
        {"uid": "broken", "path": "broken.glb", "stage": "preflight",
         "reason": "empty file (0 bytes)", "attempts": 1}
    ]  # fmt: skip
    for other in ("pool", "ray", "shards"):
        got = tree(tmp_path / other)
        assert sorted(got) == sorted(ref), (other, set(got) ^ set(ref))
        for name in ref:
            assert got[name] == ref[name], (other, name)


def test_shards_partition_by_object_whatever_the_listing_order(demo_glbs, tmp_path):
    from blurset.commands.builder import job_objects
    from blurset.services.config import make_config

    entries = [str(g) for g in demo_glbs]

    def shard(i: int, order: list[str]) -> list[str]:
        cfg = make_config({}, {"objects": order, "out": tmp_path / "o", "shard": f"{i}/2"})
        return [o.uid for o in job_objects(cfg)]

    a = [shard(i, entries) for i in range(2)]
    b = [shard(i, entries[::-1]) for i in range(2)]
    assert a == b
    assert sorted(a[0] + a[1]) == sorted(g.stem for g in demo_glbs) and not set(a[0]) & set(a[1])


# --------------------------------------------------------------------------- objaverse

UIDS = {
    "box": "0a1b2c3d4e5f60718293a4b5c6d7e8f9",
    "vase": "f9e8d7c6b5a4938271605f4e3d2c1b0a",
    "gone": "1234567890abcdef1234567890abcdef",
}


def make_cache(root: Path, demo_glbs: list[Path], *, with_gone: bool = False) -> Path:
    """A cache directory laid out like the objaverse package's (hf-objaverse-v1)."""
    v = root / "hf-objaverse-v1"
    paths = {u: f"glbs/000-{i:03d}/{u}.glb" for i, u in enumerate(UIDS.values())}
    (v / "glbs").mkdir(parents=True)
    with gzip.open(v / "object-paths.json.gz", "wt") as f:
        json.dump(paths, f)
    with gzip.open(v / "lvis-annotations.json.gz", "wt") as f:
        json.dump({"box": [UIDS["box"], UIDS["gone"]], "vase": [UIDS["vase"]]}, f)
    for name, glb in (("box", demo_glbs[0]), ("vase", demo_glbs[2])):
        dest = v / paths[UIDS[name]]
        dest.parent.mkdir(parents=True)
        shutil.copy(glb, dest)
    if with_gone:
        dest = v / paths[UIDS["gone"]]
        dest.parent.mkdir(parents=True)
        shutil.copy(demo_glbs[1], dest)
    return root


@pytest.mark.blender
def test_objaverse_ids_from_the_cache_offline(demo_glbs, tmp_path):
    cache = make_cache(tmp_path / "cache", demo_glbs)
    listing = tmp_path / "uids.txt"
    listing.write_text(f"# vases\nobjaverse:{UIDS['vase']}\n")
    out = tmp_path / "out"
    proc = run_cli(
        "build", "--objects", "objaverse:lvis=box", str(listing), "--out", str(out), *TINY,
        "--objaverse-dir", str(cache), "--objaverse-offline", check=False,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    built = sorted(d.name for d in out.iterdir() if (d / ".complete").exists())
    assert built == sorted(f"{UIDS[n]}_{t:03d}" for n in ("box", "vase") for t in (0, 180))
    assert f"1 of 3 objects are not in the cache {cache / 'hf-objaverse-v1'}" in proc.stderr
    assert UIDS["gone"] in proc.stderr
    (rec,) = [json.loads(line) for line in (out / "failures.jsonl").read_text().splitlines()]
    assert rec["uid"] == UIDS["gone"] and rec["stage"] == "fetch"
    assert "not in the objaverse cache" in rec["reason"] and "offline" in rec["reason"]
    meta = json.loads((out / f"{UIDS['vase']}_000" / "meta.json").read_text())
    assert meta["uid"] == UIDS["vase"] and meta["object"]["path"] == f"objaverse:{UIDS['vase']}"


def test_objaverse_selection_rules(demo_glbs, tmp_path):
    c = objaverse_cache.Cache(make_cache(tmp_path / "cache", demo_glbs), offline=True)
    every = resolve_objects(["objaverse:all"], cache=c)
    assert sorted(o.uid for o in every) == sorted(UIDS.values())
    assert all(o.source == "objaverse" for o in every)
    one = resolve_objects(["objaverse:all"], cache=c, objaverse_count=1, seed=5)
    assert len(one) == 1
    assert one == resolve_objects(["objaverse:lvis=box+vase"], cache=c, objaverse_count=1, seed=5)
    picks = {
        resolve_objects(["objaverse:all"], cache=c, objaverse_count=1, seed=s)[0].uid
        for s in range(12)
    }
    assert len(picks) > 1  # the seed chooses
    two = resolve_objects(["objaverse:all"], cache=c, objaverse_count=2, seed=5)
    assert one[0] in two  # a bigger count keeps the smaller subset
    with pytest.raises(InputError, match="no LVIS category 'vse' .*did you mean vase"):
        resolve_objects(["objaverse:lvis=vse"], cache=c)
    with pytest.raises(InputError, match="is not an objaverse uid"):
        resolve_objects(["objaverse:../../etc/passwd"], cache=c)
    with pytest.raises(InputError, match="not in the Objaverse 1.0 index"):
        resolve_objects(["objaverse:ffffffffffffffffffffffffffffffff"], cache=c)
    # No index and offline: cached files are still found, by uid.
    (c.versioned / "object-paths.json.gz").unlink()
    bare = objaverse_cache.Cache(c.root, offline=True)
    (vase,) = resolve_objects([f"objaverse:{UIDS['vase']}"], cache=bare)
    assert vase.path.is_file()
    with pytest.raises(InputError, match="--objaverse-offline forbids downloading"):
        resolve_objects(["objaverse:all"], cache=bare)


class _Mirror(http.server.SimpleHTTPRequestHandler):
    """A Hugging Face mirror serving a directory; the first request of each file fails
    with 503, so only a downloader that retries gets anything."""

    seen: set[str] = set()

    def do_GET(self):  # noqa: N802 (http.server's name)
        if self.path not in self.seen:
            self.seen.add(self.path)
            self.send_error(503, "busy")
            return
        super().do_GET()

    def log_message(self, *args):
        pass


def test_objaverse_download_from_a_mirror_with_retries(demo_glbs, tmp_path, monkeypatch):
    remote = make_cache(tmp_path / "remote", demo_glbs, with_gone=True) / "hf-objaverse-v1"
    repo = tmp_path / "www" / "datasets" / "allenai" / "objaverse" / "resolve" / "main"
    shutil.copytree(remote, repo)
    handler = lambda *a, **k: _Mirror(*a, directory=str(tmp_path / "www"), **k)  # noqa: E731
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    try:
        monkeypatch.setenv("HF_ENDPOINT", f"http://127.0.0.1:{server.server_port}")
        # The backoff is asked for, not waited out: the test waits on the mirror alone.
        slept: list[float] = []
        monkeypatch.setattr(objaverse_cache, "time", types.SimpleNamespace(sleep=slept.append))
        local = objaverse_cache.Cache(tmp_path / "empty-cache")  # online, nothing cached
        (spec,) = resolve_objects([f"objaverse:{UIDS['gone']}"], cache=local)
        assert not spec.path.exists()
        got = local.ensure(spec.uid, spec.path)
        assert got.read_bytes() == demo_glbs[1].read_bytes()
        assert got == local.versioned / "glbs" / "000-002" / f"{UIDS['gone']}.glb"
        assert not [p for p in got.parent.iterdir() if p.name != got.name]  # no temp left
        # The index and the GLB: each answered 503 once, retried after the first step.
        assert slept == [2.0, 2.0]
        with pytest.raises(objaverse_cache.FetchError, match="HTTP 404"):
            local.ensure("x", local.versioned / "glbs" / "000-009" / "x.glb")
        assert slept == [2.0] * 3  # x.glb: a 503, one retry, a 404 that is not retried
    finally:
        server.shutdown()
