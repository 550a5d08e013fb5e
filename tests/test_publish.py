"""Publishable builds (issue 19) and `blurset verify` (issue 14 D6): attribution and
licences in meta.json, the `--licenses` filter, no builder paths in any output, the
dataset card, MANIFEST.sha256 against GNU sha256sum, and verify on damaged copies.

The builds are real renders of the shared Sketchfab and Khronos GLBs, tiny sizes."""

from __future__ import annotations

import gzip
import hashlib
import json
import re
import shutil
import struct
import subprocess
from pathlib import Path

import pytest
import yaml
from blurset.exceptions import ConfigError
from blurset.plan import BuildConfig
from blurset.services import attribution, publish
from blurset.services.demo import make_demo_objects

from tests.conftest import run_cli, shared

TINY = (
    "--views", "4", "--levels", "1,2", "--latents", "2", "--samples", "2",
    "--resolution", "32", "--settings-per-object", "1", "--quiet",
)  # fmt: skip
NAMES = ("sketchfab_MapPin", "sketchfab_MazdaRX7Stylised", "khronos_BoxTextured")


def without_extras(glb: Path, dst: Path) -> None:
    """A copy of a GLB whose glTF `asset` has no `extras` (the JSON chunk rewritten,
    padded with spaces to 4 bytes as the GLB format asks)."""
    data = glb.read_bytes()
    (n,) = struct.unpack_from("<I", data, 12)
    tree = json.loads(data[20 : 20 + n])
    tree.get("asset", {}).pop("extras", None)
    js = json.dumps(tree).encode()
    js += b" " * (-len(js) % 4)
    rest = data[20 + n :]
    body = struct.pack("<I", len(js)) + b"JSON" + js + rest
    dst.write_bytes(data[:8] + struct.pack("<I", 12 + len(body)) + body)


def glbs() -> list[Path]:
    return [shared("glb", f"{n}.glb") for n in NAMES]


@pytest.fixture(scope="module")
def published(tmp_path_factory) -> Path:
    """A build of the two Sketchfab GLBs and a Khronos one (no asset.extras), with linear
    EXRs and previews, then its statistics, a contact sheet and a noise output."""
    out = tmp_path_factory.mktemp("pub") / "build"
    run_cli("build", "--objects", *map(str, glbs()), "--out", str(out), *TINY,
            "--keep-linear", "--previews")  # fmt: skip
    run_cli("stats", str(out), "--quiet")
    run_cli("preview", str(out))
    run_cli("noise", str(out), "--out", str(out.parent / "noisy"), "--gains", "1", "4",
            "--levels", "blur_2", "--quiet")  # fmt: skip
    return out


def metas(build: Path) -> dict[str, dict]:
    return {
        json.loads((d / "meta.json").read_text())["uid"]: json.loads((d / "meta.json").read_text())
        for d in build.iterdir()
        if (d / ".complete").is_file()
    }


def sha256sum_check(root: Path) -> subprocess.CompletedProcess:
    return subprocess.run(
        ["sha256sum", "-c", "--quiet", "MANIFEST.sha256"],
        cwd=root,
        capture_output=True,
        text=True,
    )


# -- attribution ------------------------------------------------------------------------


@pytest.mark.blender
def test_meta_json_attributes_every_object(published):
    objs = {uid: m["object"] for uid, m in metas(published).items()}
    assert sorted(objs) == sorted(NAMES)
    pin, mazda, box = (objs[n] for n in NAMES)
    assert pin["author"] == "Ilyas.King" and pin["title"] == "Map Pin"
    assert mazda["author"] == "SheldonJ99" and mazda["title"] == "Mazda RX7 Stylised"
    for o, slug in ((pin, "map-pin-"), (mazda, "mazda-rx7-stylised-")):
        assert o["license"] == "CC-BY-4.0"
        assert o["license_text"] == "CC-BY-4.0 (http://creativecommons.org/licenses/by/4.0/)"
        assert o["source_url"].startswith(f"https://sketchfab.com/3d-models/{slug}")
    # A file that names nobody says so; nothing is guessed from where it came from.
    for key in ("title", "author", "license", "license_text", "source_url"):
        assert box[key] == "unknown", (key, box)
    for name, glb in zip(NAMES, glbs(), strict=True):
        assert objs[name]["path"] == glb.name
        assert objs[name]["sha256"] == hashlib.sha256(glb.read_bytes()).hexdigest()
        assert "source" not in objs[name]


@pytest.mark.blender
def test_no_builder_path_in_any_output(published):
    inputs = str(glbs()[0].parent.resolve())
    home = str(Path.home())
    needles = {s.encode() for s in (inputs, home, str(published.resolve()))}
    noisy = published.parent / "noisy"
    checked = 0
    for root in (published, noisy):
        for p in root.rglob("*"):
            if not p.is_file():
                continue
            data = p.read_bytes()
            hits = [n.decode() for n in needles if n in data]
            assert not hits, (p, hits)
            checked += 1
    assert checked > 100
    # The absolute paths are kept, but only on this machine, outside the build.
    log = publish.local_paths_file(published)
    assert not log.is_relative_to(published.resolve())
    local = [json.loads(x) for x in log.read_text().splitlines()]
    assert {r["path"] for r in local} == {str(g.resolve()) for g in glbs()}
    assert not (published / ".local").exists()


@pytest.mark.blender
def test_licenses_filter_skips_before_rendering(tmp_path):
    out = tmp_path / "cc0"
    proc = run_cli("build", "--objects", *map(str, glbs()), "--out", str(out), *TINY,
                   "--licenses", "cc0-1.0", check=False)  # fmt: skip
    assert proc.returncode == 1, proc.stderr  # nothing was allowed, nothing built
    recs = [json.loads(x) for x in (out / "failures.jsonl").read_text().splitlines()]
    assert sorted(r["uid"] for r in recs) == sorted(NAMES)
    assert all(r["stage"] == "license" for r in recs), recs
    by = {r["uid"]: r for r in recs}
    assert "licence CC-BY-4.0" in by["sketchfab_MapPin"]["reason"]
    assert "licence unknown" in by["khronos_BoxTextured"]["reason"]
    assert "cc0" in by["khronos_BoxTextured"]["reason"].lower()
    # Skipped before Blender: no setting, no scratch, nothing rendered.
    assert sorted(p.name for p in out.iterdir() if not p.name.startswith(".")) == [
        "MANIFEST.sha256", "dataset.json", "failures.jsonl", "splits.json",
    ]  # fmt: skip
    assert not list(out.glob(".work-*"))
    # Skipped by request is not failed: dataset.json counts none.
    assert json.loads((out / "dataset.json").read_text())["counts"]["objects_failed"] == 0


@pytest.mark.blender
def test_licenses_from_the_objaverse_annotations(tmp_path):
    """Objaverse objects are attributed from the annotations the objaverse package caches
    beside the GLBs (read offline), and filtered by them."""
    glb_a, glb_b = make_demo_objects(tmp_path / "demo", seed=0)[:2]
    v = tmp_path / "cache" / "hf-objaverse-v1"
    uids = {"a" * 32: glb_a, "b" * 32: glb_b}
    paths = {u: f"glbs/000-007/{u}.glb" for u in uids}
    for u, g in uids.items():
        (v / paths[u]).parent.mkdir(parents=True, exist_ok=True)
        # The demo objects carry blurset's own licence in asset.extras, which would win
        # over the annotation: these stand for objaverse models that carry none.
        without_extras(g, v / paths[u])
    with gzip.open(v / "object-paths.json.gz", "wt") as f:
        json.dump(paths, f)
    (v / "metadata").mkdir()
    ann = {
        u: {
            "uid": u,
            "name": f"Thing {u[0]}",
            "viewerUrl": f"https://sketchfab.com/3d-models/{u}",
            "user": {
                "displayName": f"Maker {u[0]}",
                "profileUrl": f"https://sketchfab.com/m{u[0]}",
            },
            "license": lic,
        }
        for u, lic in zip(uids, ("by", "by-nc"), strict=True)
    }
    with gzip.open(v / "metadata" / "000-007.json.gz", "wt") as f:
        json.dump(ann, f)
    out = tmp_path / "out"
    run_cli("build", "--objects", *(f"objaverse:{u}" for u in uids), "--out", str(out), *TINY,
            "--objaverse-dir", str(tmp_path / "cache"), "--objaverse-offline",
            "--licenses", "cc-by-4.0")  # fmt: skip
    (meta,) = metas(out).values()
    o = meta["object"]
    assert o["path"] == f"objaverse:{'a' * 32}" and o["license"] == "CC-BY-4.0"
    assert (o["title"], o["author"], o["author_url"]) == (
        "Thing a", "Maker a", "https://sketchfab.com/ma",
    )  # fmt: skip
    assert o["source_url"] == f"https://sketchfab.com/3d-models/{'a' * 32}"
    (rec,) = [json.loads(x) for x in (out / "failures.jsonl").read_text().splitlines()]
    assert rec["uid"] == "b" * 32 and rec["stage"] == "license"
    assert "CC-BY-NC-4.0" in rec["reason"]
    assert str(tmp_path) not in (out / "failures.jsonl").read_text()


# -- the card ---------------------------------------------------------------------------


@pytest.mark.blender
def test_card_header_attribution_and_counts(published, tmp_path):
    card = tmp_path / "card" / "README.md"
    run_cli("card", str(published), "--out", str(card))
    text = card.read_text()
    m = re.match(r"^---\n(.*?)\n---\n", text, re.S)
    assert m, text[:200]
    head = yaml.safe_load(m.group(1))
    # Two CC-BY-4.0 objects and an unknown one: mixed, so `other` with the list.
    assert head["license"] == "other"
    assert "cc-by-4.0 (2 objects)" in head["license_details"]
    assert "unknown (1 object)" in head["license_details"]
    assert set(head["task_categories"]) == {"image-to-3d", "image-to-image"}
    assert head["size_categories"] == ["n<1K"] and head["pretty_name"]
    # The gains of the noise output found beside the build.
    assert "## Noise variants (`noisy/`)" in text and "| 4 |" in text
    # Every object in the attribution table, with its author, licence and link.
    table = text.split("## Licensing and attribution", 1)[1]
    rows = {r.split("|")[1].strip(): r for r in table.splitlines() if r.startswith("| ")}
    for name in NAMES:
        assert name in rows, name
    assert "[Ilyas.King](https://sketchfab.com/Ilyas.King)" in rows["sketchfab_MapPin"]
    assert "CC-BY-4.0" in rows["sketchfab_MazdaRX7Stylised"]
    assert rows["khronos_BoxTextured"].count("unknown") == 4
    # The counts are dataset.json's.
    counts = json.loads((published / "dataset.json").read_text())["counts"]
    body = text.split("## Contents", 1)[1]
    header, _, values = body.strip().splitlines()[:3]
    got = dict(zip(
        [c.strip() for c in header.strip("|").split("|")],
        [c.strip() for c in values.strip("|").split("|")],
        strict=True,
    ))  # fmt: skip
    for key in ("objects", "settings", "images"):
        assert int(got[key]) == counts[key], (key, got, counts)
    assert int(got["objects failed"]) == counts["objects_failed"]
    for needle in (str(Path.home()), str(glbs()[0].parent), str(published)):
        assert needle not in text


@pytest.mark.blender
def test_a_card_inside_the_build_keeps_its_manifest_whole(published, tmp_path):
    build = tmp_path / "build"
    shutil.copytree(published, build)
    run_cli("card", str(build), "--previews")
    text = (build / "README.md").read_text()
    assert "![contact sheet](contact_sheet.png)" in text
    assert "(sketchfab_MapPin_000/preview.png)" in text
    assert "README.md" in (build / "MANIFEST.sha256").read_text()
    assert sha256sum_check(build).returncode == 0
    assert run_cli("verify", str(build)).returncode == 0


# -- manifest and verify ----------------------------------------------------------------


@pytest.mark.blender
def test_manifest_passes_sha256sum_and_a_changed_byte_is_named(published, tmp_path):
    # Statistics and the contact sheet were written after the build: still whole.
    proc = sha256sum_check(published)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    listed = [x.split("  ", 1)[1] for x in (published / "MANIFEST.sha256").read_text().splitlines()]
    assert listed == sorted(listed, key=str.encode)
    assert "dataset.json" in listed and "stats/stats.json" in listed
    assert "contact_sheet.png" in listed
    assert not any(n.startswith(".") or "/." in n for n in listed)
    assert len(listed) == len(set(listed)) == len(publish.manifest_files(published))
    ok = run_cli("verify", str(published))
    assert "is whole" in ok.stderr and "files match MANIFEST.sha256" in ok.stderr

    build = tmp_path / "build"
    shutil.copytree(published, build)
    png = build / "sketchfab_MapPin_000" / "blur_1" / "images" / "002.png"
    data = bytearray(png.read_bytes())
    data[len(data) // 2] ^= 0x01
    png.write_bytes(bytes(data))
    proc = sha256sum_check(build)
    assert proc.returncode != 0 and "blur_1/images/002.png: FAILED" in proc.stdout
    proc = run_cli("verify", str(build), check=False)
    assert proc.returncode == 1
    bad = [x for x in proc.stdout.splitlines() if "002.png" in x]
    assert any("checksum mismatch" in x for x in bad), proc.stdout
    assert all(x.startswith(f"{build}/sketchfab_MapPin_000/blur_1/images/002.png: ") for x in bad)
    assert all("002.png" in x for x in proc.stdout.splitlines()), proc.stdout


@pytest.mark.blender
def test_verify_finds_damage_without_a_manifest(published, tmp_path):
    """Decoding and meta.json alone (no MANIFEST.sha256) catch a truncated image, a
    deleted poses_bounds.npy and a deleted level folder, each named once."""
    build = tmp_path / "build"
    shutil.copytree(published, build)
    (build / "MANIFEST.sha256").unlink()
    # A finished build always has its manifest: without it, that is the one problem.
    proc = run_cli("verify", str(build), check=False)
    assert proc.returncode == 1 and proc.stdout.strip().splitlines() == [
        f"{build}/MANIFEST.sha256: missing (every finished run writes it)"
    ], proc.stdout
    cut = build / "sketchfab_MazdaRX7Stylised_000" / "sharp" / "images" / "001.png"
    cut.write_bytes(cut.read_bytes()[: cut.stat().st_size // 2])
    (build / "sketchfab_MapPin_000" / "blur_2" / "poses_bounds.npy").unlink()
    shutil.rmtree(build / "khronos_BoxTextured_000" / "blur_1")
    exr = build / "khronos_BoxTextured_000" / "sharp" / "linear" / "003.exr"
    exr.write_bytes(exr.read_bytes()[:100])
    proc = run_cli("verify", str(build), check=False)
    assert proc.returncode == 1
    found = dict(line.split(": ", 1) for line in proc.stdout.splitlines())
    found.pop(f"{build}/MANIFEST.sha256")
    assert sorted(found) == sorted(
        f"{build}/{rel}"
        for rel in (
            "khronos_BoxTextured_000/blur_1",
            "khronos_BoxTextured_000/sharp/linear/003.exr",
            "sketchfab_MapPin_000/blur_2/poses_bounds.npy",
            "sketchfab_MazdaRX7Stylised_000/sharp/images/001.png",
        )
    ), proc.stdout
    assert found[f"{build}/khronos_BoxTextured_000/blur_1"] == "level folder missing"
    assert found[f"{build}/sketchfab_MapPin_000/blur_2/poses_bounds.npy"] == "missing"
    # The cut PNG is the cheap check's (the rerun's rule: no end chunk); only decoding
    # sees inside the EXR.
    png = f"{build}/sketchfab_MazdaRX7Stylised_000/sharp/images/001.png"
    assert found[png] == "truncated (no PNG end chunk)", found
    exr = f"{build}/khronos_BoxTextured_000/sharp/linear/003.exr"
    assert found[exr].startswith("does not decode"), found
    assert "5 problem(s)" in proc.stderr  # the four, and the missing manifest
    # The cheap check (headers, PNG end chunks, files, pose rows, and the EXRs decoded,
    # the rerun's rule since issue 48) catches the cut PNG and the cut EXR too; it
    # decodes no PNG.
    cheap = run_cli("verify", "--no-decode", str(build), check=False)
    assert cheap.returncode == 1
    found = dict(line.split(": ", 1) for line in cheap.stdout.splitlines())
    assert found.pop(f"{build}/MANIFEST.sha256").startswith("missing"), cheap.stdout
    assert found[png] == "truncated (no PNG end chunk)", cheap.stdout
    assert found[exr].startswith("does not decode"), cheap.stdout
    assert len(found) == 4 and f"{build}/khronos_BoxTextured_000/blur_1" in found


@pytest.mark.blender
def test_verify_compares_counts_and_meta(published, tmp_path):
    build = tmp_path / "build"
    shutil.copytree(published, build)
    (build / "MANIFEST.sha256").unlink()
    ds = json.loads((build / "dataset.json").read_text())
    ds["counts"]["images"] += 1
    (build / "dataset.json").write_text(json.dumps(ds))
    (build / "sketchfab_MapPin_000" / "sharp" / "images" / "004.png").write_bytes(b"x")
    (build / "khronos_BoxTextured_000" / "meta.json").write_text("[]")
    # An images_4/ file of the wrong size (a full-size image where a 1/4 copy belongs).
    mazda = build / "sketchfab_MazdaRX7Stylised_000" / "blur_1"
    shutil.copyfile(mazda / "images" / "002.png", mazda / "images_4" / "002.png")
    proc = run_cli("verify", str(build), check=False)
    assert proc.returncode == 1
    out = proc.stdout
    # A whole image of the wrong size is a damaged setting (issue 34): named with its size.
    assert f"{mazda}/images_4/002.png: 32x32 px, not 8x8" in out, out
    assert f"{build}/dataset.json: counts.images is {ds['counts']['images']}" in out
    assert f"{build}/sketchfab_MapPin_000/sharp/images/004.png: not a file of this" in out
    assert f"{build}/khronos_BoxTextured_000/meta.json: unreadable (" in out


@pytest.mark.blender
def test_noise_output_has_a_manifest_and_verifies(published, tmp_path):
    noisy = tmp_path / "noisy"
    shutil.copytree(published.parent / "noisy", noisy)
    assert sha256sum_check(noisy).returncode == 0
    doc = json.loads((noisy / "noise_dataset.json").read_text())
    assert doc["build"] == "build"
    ok = run_cli("verify", str(noisy))
    assert "is whole: 6 complete units" in ok.stderr
    gone = noisy / "sketchfab_MapPin_000" / "blur_2" / "gain_4" / "images" / "000.png"
    gone.unlink()
    proc = run_cli("verify", str(noisy), check=False)
    assert proc.returncode == 1
    rel = f"{noisy}/sketchfab_MapPin_000/blur_2/gain_4/images/000.png"
    assert f"{rel}: missing" in proc.stdout
    assert f"{rel}: missing (MANIFEST.sha256)" in proc.stdout
    # The noise drawn at 1/4 size (images_4/, linear_4/) is checked file by file too.
    small = noisy / "sketchfab_MapPin_000" / "blur_2" / "gain_1" / "linear_4" / "001.exr"
    small.unlink()
    proc = run_cli("verify", str(noisy), check=False)
    assert f"{small}: missing" in proc.stdout, proc.stdout


# -- without rendering ------------------------------------------------------------------


def test_licence_texts_map_to_spdx_ids():
    cases = {
        "CC-BY-4.0 (http://creativecommons.org/licenses/by/4.0/)": "CC-BY-4.0",
        "CC-BY-NC-SA-4.0 (http://creativecommons.org/licenses/by-nc-sa/4.0/)": "CC-BY-NC-SA-4.0",
        "CC0-1.0 (http://creativecommons.org/publicdomain/zero/1.0/)": "CC0-1.0",
        "Attribution (https://creativecommons.org/licenses/by-sa/3.0/)": "CC-BY-SA-3.0",
        "by-nd": "CC-BY-ND-4.0",  # an Objaverse annotation's code
        "cc0": "CC0-1.0",
        "SKETCHFAB-Standard (https://sketchfab.com/licenses)": "other",
        "free-st": "other",
        "MIT (https://opensource.org/licenses/MIT)": "MIT",  # blurset's demo objects
        "": "unknown",
        None: "unknown",
    }
    for text, want in cases.items():
        assert attribution.spdx(text) == want, text


def test_asset_extras_and_nothing_guessed():
    a = attribution.attribution(
        attribution.from_asset(
            {
                "version": "2.0",
                "copyright": "2017 (c) Khronos",
                "extras": {"author": "Someone (https://sketchfab.com/someone)", "title": "  T "},
            }
        )
    )
    assert a["author"] == "Someone" and a["author_url"] == "https://sketchfab.com/someone"
    assert a["title"] == "T" and a["copyright"] == "2017 (c) Khronos"
    # A copyright line is not a licence.
    assert a["license"] == "unknown" and a["license_text"] == "unknown"
    assert attribution.attribution(attribution.from_asset({"extras": "junk"}))["author"] == (
        "unknown"
    )


def test_licenses_filter():
    assert attribution.allowed("CC-BY-4.0", ["CC-BY-4.0"])
    assert not attribution.allowed("unknown", ["CC-BY-4.0"])
    assert attribution.allowed("unknown", None)


def test_licenses_in_a_toml_config(tmp_path):
    from blurset.services.config import load_toml, make_config

    toml = tmp_path / "b.toml"
    toml.write_text('objects = ["x.glb"]\nout = "o"\nlicenses = ["cc-by-4.0", "cc0-1.0"]\n')
    cfg = make_config(load_toml(toml), {})
    assert cfg.licenses == ["CC-BY-4.0", "CC0-1.0"]
    toml.write_text('objects = ["x.glb"]\nout = "o"\nlicenses = "cc-by-nc"\n')
    with pytest.raises(ConfigError, match="licenses"):
        make_config(load_toml(toml), {}, config_path=toml)


def test_manifest_format_is_gnu_sha256sum(tmp_path):
    root = tmp_path / "tree"
    for rel, data in {
        "dataset.json": b"{}",
        "a/b/c.png": b"\x89PNG",
        "with space.txt": b"s",
        "back\\slash": b"b",
        "new\nline": b"n",
        ".lock": b"",
        "s_000/.complete": b"x",
        "s_090.partial/meta.json": b"{}",
        ".local/paths.jsonl": b"/home/x",
    }.items():
        (root / rel).parent.mkdir(parents=True, exist_ok=True)
        (root / rel).write_bytes(data)
    assert publish.write_manifest(root) == 5
    proc = sha256sum_check(root)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert publish.check_manifest(root) == []
    (root / "a" / "b" / "c.png").write_bytes(b"\x89PNg")
    (root / "extra.txt").write_text("late")
    assert publish.check_manifest(root) == [
        ("a/b/c.png", "mismatch", "checksum mismatch"),
        ("extra.txt", "unlisted", "not in MANIFEST.sha256"),
    ]
    bad = tmp_path / "bad"
    bad.mkdir()
    (bad / "MANIFEST.sha256").write_text("not a checksum line\n")
    with pytest.raises(Exception, match="line 1"):
        publish.check_manifest(bad)


def test_the_config_record_has_no_paths():
    cfg = BuildConfig(
        out="/home/u/builds/run1",
        objects=["/home/u/models", "@/home/u/list.txt", "objaverse:lvis=chair", "a.glb"],
        objaverse_dir="/home/u/.objaverse",
        blender="/opt/blender/blender",
    )
    rec = cfg.record()
    assert (rec["out"], rec["objects"], rec["objaverse_dir"], rec["blender"]) == (
        "run1",
        ["models", "@list.txt", "objaverse:lvis=chair", "a.glb"],
        ".objaverse",
        "blender",
    )
    assert "/home/u" not in json.dumps(rec) and "/opt" not in json.dumps(rec)


def test_licenses_shape_outputs_so_a_rerun_must_match(tmp_path):
    """--licenses decides which objects a build holds: a rerun into OUT with another
    filter is refused (naming it) unless --allow-mixed, like any output-shaping option."""
    from blurset.commands.builder.dataset import RUN_OPTIONS, check_same_options

    assert "licenses" not in RUN_OPTIONS
    out = tmp_path / "out"
    out.mkdir()
    check_same_options(out, BuildConfig(out=str(out), demo=True, licenses="cc-by-4.0"))
    check_same_options(out, BuildConfig(out=str(out), demo=True, licenses=["CC-BY-4.0"]))
    with pytest.raises(ConfigError, match="--licenses"):
        check_same_options(out, BuildConfig(out=str(out), demo=True, licenses="cc0-1.0"))
    with pytest.raises(ConfigError, match="--licenses"):
        check_same_options(out, BuildConfig(out=str(out), demo=True))
    mixed = BuildConfig(out=str(out), demo=True, licenses="cc0-1.0", allow_mixed=True)
    check_same_options(out, mixed)
