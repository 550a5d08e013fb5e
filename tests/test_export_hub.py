"""`blurset export BUILD --for hub` (issue 50): Parquet shards that `datasets` loads, a
card whose configs the Hub reads, open_scene from shards, resume, verify.

The build is the stand-in worker's (no Blender): blur levels, a defocus level, every
pass, and a noise output of one gain, so every kind of config and column is made.
`datasets` runs offline, its cache in a temp folder."""

from __future__ import annotations

import dataclasses
import os
import shutil
from pathlib import Path

import numpy as np
import pytest
from blurset import data, layout
from blurset.commands.export import hub as export_hub
from blurset.data import open_scene
from blurset.services import hub_format

from tests.conftest import one_error_line, run_cli, standin_build, temp_home, tree

# Offline, and nothing written to the user's cache: set before `datasets` is imported.
os.environ["HF_DATASETS_OFFLINE"] = "1"
os.environ["HF_HUB_OFFLINE"] = "1"
temp_home("HF_HOME", "blurset-hf-")
os.environ.setdefault("HF_DATASETS_DISABLE_PROGRESS_BARS", "1")

pq = pytest.importorskip("pyarrow.parquet")
datasets = pytest.importorskip("datasets")

GAIN = 4
# Small shards: several per config and split, each holding whole settings.
SHARD_MB = "0.02"


@pytest.fixture(scope="module")
def hub_build(tmp_path_factory, standin_blender) -> tuple[Path, Path]:
    """A build with blur levels, a defocus level and passes, and its noise output."""
    root = tmp_path_factory.mktemp("hub")
    b, n = root / "b", root / "n"
    standin_build(
        b, standin_blender, "--passes", "depth,normal,mask", "--defocus", "1", "--views", "5"
    )
    run_cli("noise", str(b), "--out", str(n), "--gains", str(GAIN), "--levels", "blur_1",
            "--quiet")  # fmt: skip
    return b, n


@pytest.fixture(scope="module")
def hub(hub_build, tmp_path_factory) -> Path:
    b, n = hub_build
    out = tmp_path_factory.mktemp("hub_out") / "hub"
    run_cli("export", str(b), "--for", "hub", "--out", str(out), "--noise", str(n),
            "--shard-size", SHARD_MB)  # fmt: skip
    run_cli("card", str(b), "--hub", str(out))
    return out


def _doc(out: Path) -> dict:
    return hub_format.hub_doc(out) or {}


def _configs(doc: dict) -> list[str]:
    return list(dict.fromkeys(doc["scenes"][s] for s in [*doc["train"], *doc["test"]]))


def _raw(ds):
    """A split with every image column's bytes, not decoded."""
    for name, feature in ds.features.items():
        if isinstance(feature, datasets.Image):
            ds = ds.cast_column(name, datasets.Image(decode=False))
    return ds


def check_export(b: Path, n: Path | None, hub: Path) -> None:
    """Every config of the export at `hub` (of the build `b`, and the noise output `n`)
    loads with `datasets` (parquet, offline): each image's bytes are the build's file
    (every size, every pass), each pose row is poses_bounds.npy's, the held-out rows of a
    degraded level hold the sharp image, the records are meta.json's, and every complete
    setting is there."""
    doc = _doc(hub)
    splits = layout.read_json(b / layout.SPLITS, layout.SPLITS)
    settings = layout.complete_settings(b)
    factors, passes = doc["factors"], doc.get("passes") or []
    for config in _configs(doc):
        files = {
            sp: [str(hub / "data" / k) for k, r in doc["shards"].items()
                 if r["config"] == config and r["split"] == sp]
            for sp in ("train", "test")
        }  # fmt: skip
        ds = datasets.load_dataset("parquet", data_files={k: v for k, v in files.items() if v})
        seen = set()
        for sp in ds:
            assert isinstance(ds[sp].features["image"], datasets.Image)
            for row in _raw(ds[sp]):
                s, v = row["setting"], row["view"]
                seen.add(s)
                assert (s in splits["test"]) == (sp == "test")
                level = row["level"]
                root = b if row["gain"] is None else n
                assert root is not None
                src = b / s / level if row["gain"] is None else root / s / level / f"gain_{GAIN}"
                name = Path(row["image"]["path"]).name
                assert row["image"]["path"] == (src / "images" / name).relative_to(root).as_posix()
                assert row["image"]["bytes"] == (src / "images" / name).read_bytes()
                for f in factors:
                    assert row[f"image_{f}"]["bytes"] == (src / f"images_{f}" / name).read_bytes()
                pb = np.load(src / layout.POSES_BOUNDS)
                assert row["poses_bounds"] == pb[v].tolist()
                assert (row["near"], row["far"]) == (pb[v, 15], pb[v, 16])
                assert row["held_out"] == (v in splits["test_views"][s])
                if row["held_out"] and level != "sharp" and row["gain"] is None:
                    # Deblur-NeRF's convention: a held-out view holds the sharp image.
                    sharp = b / s / "sharp" / "images" / name
                    assert row["image"]["bytes"] == sharp.read_bytes()
                if "depth" in passes:
                    depth = b / s / "sharp" / "depth" / layout.pass_file("depth", name)
                    assert row["depth"] == depth.read_bytes()
                if level.startswith("blur_") and not row["held_out"]:
                    meta = layout.read_json(b / s / layout.META, layout.META)
                    rec = meta["views"][v]["levels"][level.split("_")[1]]
                    assert row["w_l"] == rec["w_l"] and row["motion_px"] == rec["motion_px"]
                    assert row["mean_c2w"] == rec["mean_pose"]["c2w"]
                if level.startswith("defocus_"):
                    assert (row["coc_px"] is None) == row["held_out"]
        assert seen == {s.name for s in settings}


def test_every_config_loads_with_datasets_and_holds_the_builds_bytes_and_poses(hub, hub_build):
    b, n = hub_build
    doc = _doc(hub)
    configs = _configs(doc)
    assert configs == ["sharp", "blur_1", "blur_2", "defocus_1", f"blur_1_gain_{GAIN}"]
    assert doc["passes"] == ["depth", "normal", "mask"] and doc["factors"] == [4]
    check_export(b, n, hub)
    # The card's configs: load_dataset(DIR, config) and the Hub's viewer.
    assert datasets.get_dataset_config_names(str(hub)) == configs
    ds = datasets.load_dataset(str(hub), "blur_2")
    rows = sum(r["rows"] for r in doc["shards"].values() if r["config"] == "blur_2")
    assert ds["train"].num_rows + ds["test"].num_rows == rows
    assert ds["train"][0]["image"].size == (32, 32)  # decoded by the Image feature


def test_a_shard_holds_whole_settings_one_row_group_each(hub):
    doc = _doc(hub)
    assert len({k for k, r in doc["shards"].items() if r["config"] == "sharp"}) > 2
    where: dict[tuple[str, str], list[str]] = {}
    for name, rec in doc["shards"].items():
        f = pq.ParquetFile(hub / "data" / name)
        assert f.num_row_groups == len(rec["settings"])
        for g, s in enumerate(rec["settings"]):
            t = f.read_row_group(g, columns=["setting", "view"]).to_pydict()
            assert set(t["setting"]) == {s} and t["view"] == list(range(len(t["view"])))
            where.setdefault((rec["config"], s), []).append(name)
        # A shard over the size holds one setting only.
        if rec["bytes"] > float(SHARD_MB) * 1e6:
            assert len(rec["settings"]) == 1
    assert all(len(v) == 1 for v in where.values())


def _same(a, b, files: bool = True) -> None:
    """Two Scenes hold the same arrays (and the same file names, unless the second was
    read from decoded images, which carry none)."""
    for f in dataclasses.fields(a):
        x, y = getattr(a, f.name), getattr(b, f.name)
        if f.name.endswith("_files"):
            assert not files or [p.name for p in x] == [p.name for p in y]
        elif isinstance(x, np.ndarray):
            assert x.dtype == y.dtype and np.array_equal(x, y), f.name
        else:
            assert x == y, f.name


def test_list_scenes_of_shards_is_the_builds(hub, hub_build):
    b, _ = hub_build
    assert data.list_scenes(hub) == data.list_scenes(b)


@pytest.mark.parametrize("level", ["sharp", "blur_1", "blur_2", "defocus_1"])
def test_open_scene_from_shards_equals_the_folder(hub, hub_build, level):
    b, n = hub_build
    for s in layout.complete_settings(b)[:2]:
        for downsample in (1, 4):
            for pose in ("written", "mean") if level.startswith("blur") else ("written",):
                folder = open_scene(b, s.name, level, downsample=downsample, pose=pose)
                _same(folder, open_scene(hub, s.name, level, downsample=downsample, pose=pose))
                assert folder.depth is not None and folder.masks is not None
    s = layout.complete_settings(b)[-1].name
    if level == "blur_1":
        folder = open_scene(b, s, level, GAIN, noise=n)
        _same(folder, open_scene(hub, s, level, GAIN))


def test_open_scene_from_a_datasets_stream_equals_the_folder(hub, hub_build):
    b, _ = hub_build
    doc = _doc(hub)
    s = next(r["settings"][-1] for r in doc["shards"].values() if r["split"] == "train")
    rows = datasets.load_dataset(str(hub), "blur_2", split="train", streaming=True)
    sharp = datasets.load_dataset(str(hub), "sharp", split="train", streaming=True)
    # Streamed rows carry decoded images (PIL), the same pixels, no file names.
    _same(open_scene(b, s, "blur_2"), open_scene(rows, s, "blur_2", sharp_rows=sharp), False)
    raw = _raw(rows)  # undecoded: the PNG bytes and their paths
    _same(open_scene(b, s, "blur_2"), open_scene(raw, s, "blur_2", sharp_rows=_raw(sharp)))
    decoded = datasets.load_dataset(str(hub), "blur_2", split="train")  # PIL images
    plain = datasets.load_dataset(str(hub), "sharp", split="train")
    _same(
        open_scene(b, s, "blur_2"), open_scene(decoded, s, "blur_2", sharp_rows=plain), files=False
    )


def test_an_export_stopped_half_way_resumes_to_the_same_bytes(hub_build, tmp_path, monkeypatch):
    """A run stopped after some shards (and a dead run's temp file left behind) resumes:
    the finished shards are kept as they are, the rest written, and every byte is the
    uninterrupted export's."""
    b, n = hub_build
    whole, cut = tmp_path / "whole", tmp_path / "cut"
    args = ["--for", "hub", "--noise", str(n), "--shard-size", SHARD_MB]
    run_cli("export", str(b), "--out", str(whole), *args)
    from blurset import cli

    real, count = export_hub.write_shard, {"n": 0}

    def stop_after_three(*a, **k):
        if count["n"] == 3:
            raise KeyboardInterrupt
        count["n"] += 1
        return real(*a, **k)

    monkeypatch.setattr(export_hub, "write_shard", stop_after_three)
    parsed = cli.make_parser().parse_args(["export", str(b), "--out", str(cut), *args])
    with pytest.raises(KeyboardInterrupt):
        export_hub.run(parsed)
    monkeypatch.undo()
    kept = {p: p.stat().st_ino for p in (cut / "data").rglob("*.parquet")}
    assert len(kept) == 3
    # A killed process's temp file beside the shards.
    first = next(iter(kept))
    dead = first.with_name(f".{first.name}.tmp999999")
    dead.write_bytes(b"torn")
    run_cli("export", str(b), "--out", str(cut), *args)
    assert tree(cut) == tree(whole)
    assert all(p.stat().st_ino == ino for p, ino in kept.items())
    # A rerun changes nothing.
    before = {p: p.stat().st_mtime_ns for p in cut.rglob("*")}
    assert "up to date" in run_cli("export", str(b), "--out", str(cut), *args).stdout
    assert {p: p.stat().st_mtime_ns for p in cut.rglob("*")} == before


def test_an_export_killed_inside_a_shard_resumes_to_the_same_bytes(hub_build, tmp_path):
    """SIGKILL inside a shard (after its first setting is in its temp file): the shards
    before it are whole and in place, the torn one only under its temp name, and the
    rerun leaves exactly the uninterrupted export."""
    b, n = hub_build
    whole, cut = tmp_path / "whole", tmp_path / "cut"
    args = ["--for", "hub", "--noise", str(n), "--shard-size", SHARD_MB]
    run_cli("export", str(b), "--out", str(whole), *args)
    proc = run_cli("export", str(b), "--out", str(cut), *args, check=False,
                   env={export_hub.FAULT: "kill_in:4"})  # fmt: skip
    assert proc.returncode == -9, proc.stderr
    done = sorted((cut / "data").rglob("*.parquet"))
    torn = [p for p in (cut / "data").rglob(".*.tmp*")]
    assert len(done) == 4 and len(torn) == 1
    assert all(p.read_bytes() == (whole / p.relative_to(cut)).read_bytes() for p in done)
    run_cli("export", str(b), "--out", str(cut), *args)
    assert tree(cut) == tree(whole)


def test_a_rerun_after_the_build_changed_rewrites_only_what_changed(hub_build, tmp_path):
    b0, _ = hub_build
    b = tmp_path / "b"
    shutil.copytree(b0, b)
    out = tmp_path / "hub"
    run_cli("export", str(b), "--for", "hub", "--out", str(out), "--levels", "sharp,blur_1",
            "--shard-size", SHARD_MB)  # fmt: skip
    doc = _doc(out)
    s = layout.complete_settings(b)[0].name
    png = b / s / "blur_1" / "images" / "001.png"
    png.write_bytes(png.read_bytes())  # same bytes, a new mtime: the manifest keys it
    other = layout.complete_settings(b)[-1].name
    p = b / other / "blur_1" / "images" / "001.png"
    before = {k: (out / "data" / k).stat().st_ino for k in doc["shards"]}
    # Another image in the file (the manifest is rewritten as a rerun of the build would).
    from blurset.services import publish

    shutil.copyfile(b / other / "blur_1" / "images" / "002.png", p)
    publish.write_manifest(b)
    run_cli("export", str(b), "--for", "hub", "--out", str(out), "--levels", "sharp,blur_1",
            "--shard-size", SHARD_MB)  # fmt: skip
    changed = {k for k in doc["shards"] if (out / "data" / k).stat().st_ino != before[k]}
    assert changed == {
        k for k, r in doc["shards"].items() if r["config"] == "blur_1" and other in r["settings"]
    }
    assert open_scene(out, other, "blur_1").images[1].tobytes() == (
        open_scene(b, other, "blur_1").images[1].tobytes()
    )


def test_bad_input_gets_one_line_and_writes_nothing(hub_build, tmp_path):
    b0, _ = hub_build
    out = tmp_path / "out"
    proc = run_cli("export", str(b0), "--for", "hub", "--out", str(out), "--shard-size", "0",
                   check=False)  # fmt: skip
    one_error_line(proc, "--shard-size")
    proc = run_cli("export", str(b0), "--for", "hub", "--out", str(b0 / "hub"), check=False)
    one_error_line(proc, "--out")
    assert not (b0 / "hub").exists()
    # A build that is not whole: a setting being rebuilt, and one damaged.
    b = tmp_path / "b"
    shutil.copytree(b0, b)
    s = layout.complete_settings(b)[0]
    (s / "blur_1" / "images" / "002.png").unlink()
    proc = run_cli("export", str(b), "--for", "hub", "--out", str(out), check=False)
    one_error_line(proc, s.name)
    (s / layout.MARKER).unlink()
    proc = run_cli("export", str(b), "--for", "hub", "--out", str(out), check=False)
    one_error_line(proc, "not finished")
    proc = run_cli("export", str(b0), "--out", str(out), "--shard-size", "10", check=False)
    one_error_line(proc, "--shard-size", "--for hub")
    assert not out.exists()


def test_verify_checks_every_shard(hub, tmp_path):
    assert run_cli("verify", str(hub)).returncode == 0
    bad = tmp_path / "hub"
    shutil.copytree(hub, bad)
    doc = _doc(bad)
    names = sorted(doc["shards"])
    # A flipped byte, a missing shard, a file no export wrote.
    p = bad / "data" / names[0]
    data = bytearray(p.read_bytes())
    data[len(data) // 2] ^= 0xFF
    p.write_bytes(bytes(data))
    (bad / "data" / names[1]).unlink()
    (bad / "data" / "sharp" / "note.parquet").write_bytes(b"x")
    proc = run_cli("verify", str(bad), check=False)
    assert proc.returncode == 1
    out = proc.stdout
    assert f"data/{names[0]}: sha256 differs" in out
    assert f"data/{names[1]}: missing" in out
    assert "data/sharp/note.parquet: not a shard" in out


def test_verify_decodes_every_image_of_a_shard(hub_build, tmp_path, monkeypatch):
    """A shard whose bytes export.json vouches for but whose image is damaged (written so
    by a bad build) is named by the row."""
    b, _ = hub_build
    out = tmp_path / "hub"
    s = layout.complete_settings(b)[0].name
    run_cli("export", str(b), "--for", "hub", "--out", str(out), "--levels", "sharp")
    # Truncate one image inside its shard, then record the new bytes as the export would.
    import json

    doc = json.loads((out / "export.json").read_text())
    name = next(k for k, r in doc["shards"].items() if s in r["settings"])
    t = pq.read_table(out / "data" / name)
    rows = t.to_pylist()
    rows[0]["image"]["bytes"] = rows[0]["image"]["bytes"][:40]
    import pyarrow as pa

    views = len([r for r in rows if r["setting"] == rows[0]["setting"]])
    pq.write_table(
        pa.Table.from_pylist(rows, schema=t.schema), out / "data" / name, row_group_size=views
    )
    import hashlib

    rec = doc["shards"][name]
    rec["bytes"] = (out / "data" / name).stat().st_size
    rec["sha256"] = hashlib.sha256((out / "data" / name).read_bytes()).hexdigest()
    (out / "export.json").write_text(json.dumps(doc))
    proc = run_cli("verify", str(out), check=False)
    assert proc.returncode == 1
    assert f"data/{name}: {rows[0]['setting']} view 0 image: does not decode" in proc.stdout


def test_the_card_names_every_config_and_its_counts(hub):
    text = (hub / "README.md").read_text()
    doc = _doc(hub)
    for c in _configs(doc):
        assert f'- config_name: "{c}"' in text
        assert f'path: "data/{c}/train-*.parquet"' in text
    total = sum(r["rows"] for r in doc["shards"].values())
    import re

    assert sum(int(x) for x in re.findall(r"num_examples: (\d+)", text)) == total
    assert "load_dataset(" in text and "## Licensing and attribution" in text


def test_a_card_written_into_a_hub_export_is_its_card(hub, hub_build, tmp_path):
    b, _ = hub_build
    other = tmp_path / "hub"
    shutil.copytree(hub, other)
    (other / "README.md").unlink()
    run_cli("card", str(b), "--out", str(other / "README.md"))
    assert (other / "README.md").read_text() == (hub / "README.md").read_text()


def test_a_hub_card_describes_the_noise_its_upload_holds_and_no_other(hub, hub_build, tmp_path):
    """A noise output beside the build is described by the build's card, but the card of
    a hub export that holds no noise says nothing of it (the upload does not hold it)."""
    b, n = hub_build
    section = f"## Noise variants (`{n.name}/`)"
    assert section in (hub / "README.md").read_text()  # exported with --noise
    run_cli("card", str(b), "--out", str(tmp_path / "c.md"))
    assert section in (tmp_path / "c.md").read_text()  # found beside the build
    clean = tmp_path / "clean"
    run_cli("export", str(b), "--for", "hub", "--out", str(clean), "--levels", "sharp")
    run_cli("card", str(b), "--hub", str(clean))
    text = (clean / "README.md").read_text()
    assert "## Noise variants" not in text and "σ_read" not in text


def test_an_llff_export_and_a_hub_export_replace_each_other_whole(hub_build, tmp_path):
    """The same --out from one target to the other (--overwrite): the old entries go,
    and the folders they leave empty with them."""
    b, _ = hub_build
    out = tmp_path / "x"
    (tmp_path / "x").mkdir()
    (out / "notes.txt").write_text("mine")
    run_cli("export", str(b), "--for", "hub", "--out", str(out), "--levels", "sharp")
    run_cli("export", str(b), "--out", str(out), "--levels", "sharp", "--overwrite")
    assert sorted(p.name for p in out.iterdir()) == [
        "export.json", "nerf_llff_data", "notes.txt", "test.txt", "train.txt"
    ]  # fmt: skip
    run_cli("export", str(b), "--for", "hub", "--out", str(out), "--levels", "sharp",
            "--overwrite")  # fmt: skip
    assert sorted(p.name for p in out.iterdir()) == [
        "README.md",
        "data",
        "export.json",
        "notes.txt",
    ]
    assert (out / "notes.txt").read_text() == "mine"
    assert run_cli("verify", str(out)).returncode == 0


def test_a_real_demo_build_exports_whole(demo_build, tmp_path):
    """The demo build rendered by Blender: every config loads with `datasets` and holds
    the build's bytes and poses, open_scene reads the same arrays, verify passes."""
    out = tmp_path / "hub"
    run_cli("export", str(demo_build), "--for", "hub", "--out", str(out))
    check_export(demo_build, None, out)
    s = layout.complete_settings(demo_build)[0].name
    for level in layout.setting_levels(demo_build / s):
        _same(open_scene(demo_build, s, level), open_scene(out, s, level))
    assert run_cli("verify", str(out)).returncode == 0


def test_a_targeted_builds_rows_carry_each_images_samples_and_psnr(standin_blender, tmp_path):
    """Under --target-psnr every image renders its own samples to its own estimate: each
    row carries its image's record (meta.json `views[].images[level]`)."""
    b, out = tmp_path / "b", tmp_path / "hub"
    run_cli("build", "--demo", "--views", "4", "--levels", "1", "--latents", "2",
            "--resolution", "32", "--settings-per-object", "1", "--target-psnr", "30",
            "--quiet", "--blender", str(standin_blender), "--out", str(b))  # fmt: skip
    run_cli("export", str(b), "--for", "hub", "--out", str(out))
    splits = layout.read_json(b / layout.SPLITS, layout.SPLITS)
    n = 0
    for p in sorted((out / "data").rglob("*.parquet")):
        for row in pq.read_table(p, columns=["setting", "level", "view", "held_out",
                                             "samples", "render_psnr_db"]).to_pylist():  # fmt: skip
            meta = layout.read_json(b / row["setting"] / layout.META, layout.META)
            # A held-out view of a blur level holds the sharp image: its record.
            level = "sharp" if row["held_out"] and splits["test_view_images"] == "sharp" else None
            im = meta["views"][row["view"]]["images"][level or row["level"]]
            assert (row["samples"], row["render_psnr_db"]) == (im["samples"], im["render_psnr_db"])
            n += 1
    assert n > 0
