"""What `--objects` takes (issue 14 D4/U3, issue 18): models (.glb, and .gltf with its
external files), folders, list files; ids that depend on the set of files alone; and a
separate-file .gltf that builds with its textures."""

from __future__ import annotations

import hashlib
import json
import os
import shutil
from pathlib import Path

import numpy as np
import pytest
import trimesh
from blurset.exceptions import InputError
from blurset.services.demo import make_demo_objects
from blurset.services.objects import resolve_objects
from PIL import Image

from tests.conftest import run_cli


@pytest.fixture(scope="module")
def glbs(tmp_path_factory) -> list[Path]:
    return make_demo_objects(tmp_path_factory.mktemp("demo"), seed=0)


def write_gltf(glb: Path, folder: Path, name: str) -> Path:
    """A separate-file .gltf of `glb` (trimesh's export: .gltf + .bin buffers) whose
    texture is also a separate file, with a space in its name (a %20 in the uri), as
    DamagedHelmet ships."""
    folder.mkdir(parents=True, exist_ok=True)
    files = trimesh.exchange.gltf.export_gltf(trimesh.load(glb))
    doc = json.loads(files.pop("model.gltf"))
    for fname, data in files.items():
        (folder / fname).write_bytes(data)
    for img in doc["images"]:
        view = doc["bufferViews"][img.pop("bufferView")]
        buf = (folder / doc["buffers"][view["buffer"]]["uri"]).read_bytes()
        off = view.get("byteOffset", 0)
        (folder / "tex file.png").write_bytes(buf[off : off + view["byteLength"]])
        img["uri"] = "tex%20file.png"
    path = folder / f"{name}.gltf"
    path.write_text(json.dumps(doc))
    return path


def uids(entries: list[str]) -> dict[str, str]:
    return {s.path.name: s.uid for s in resolve_objects(entries, warn=lambda m: None)}


def test_clashing_names_get_ids_from_the_set_not_the_order(glbs, tmp_path):
    a, b = tmp_path / "with_space.glb", tmp_path / "with space.glb"
    shutil.copy(glbs[0], a)
    shutil.copy(glbs[1], b)
    forward = resolve_objects([str(a), str(b)])
    backward = resolve_objects([str(b), str(a)])
    assert {s.path: s.uid for s in forward} == {s.path: s.uid for s in backward}
    ids = [s.uid for s in forward]
    assert len(set(ids)) == 2 and all(i.startswith("with_space_") for i in ids), ids
    # One of them alone keeps the plain id: an id depends on the whole set.
    assert [s.uid for s in resolve_objects([str(a)])] == ["with_space"]


def test_list_files_bom_folders_and_at_lists(glbs, tmp_path):
    models = tmp_path / "models"
    (models / "sub").mkdir(parents=True)
    shutil.copy(glbs[0], models / "box.glb")
    shutil.copy(glbs[1], models / "sub" / "cyl.glb")
    lst = tmp_path / "objects.txt"
    lst.write_bytes("\ufeffmodels/box.glb\n# a comment\n".encode())
    assert uids([str(lst)]) == {"box.glb": "box"}
    lst.write_text("models\n")  # a folder in a list: every model under it
    assert uids([str(lst)]) == {"box.glb": "box", "cyl.glb": "cyl"}
    odd = tmp_path / "objects.cfg"
    odd.write_text(f"{models / 'box.glb'}\n")
    assert uids([f"@{odd}"]) == {"box.glb": "box"}
    with pytest.raises(InputError, match=r"not a \.glb/\.gltf model .*@FILE"):
        resolve_objects([str(odd)])


def test_unknown_files_and_dangling_links_are_named(glbs, tmp_path):
    obj = tmp_path / "model.obj"
    obj.write_text("mtllib model.mtl\nv 0 0 0\n")
    with pytest.raises(InputError, match=r"'.*model\.obj' is not a \.glb/\.gltf model"):
        resolve_objects([str(obj)])
    folder = tmp_path / "f"
    folder.mkdir()
    shutil.copy(glbs[0], folder / "box.glb")
    os.symlink(tmp_path / "gone.glb", folder / "dangling.glb")
    said: list[str] = []
    specs = resolve_objects([str(folder)], warn=said.append)
    assert [s.uid for s in specs] == ["box"]
    assert len(said) == 1 and "dangling symlink" in said[0] and "dangling.glb" in said[0]
    lst = tmp_path / "l.txt"
    lst.write_text("f/dangling.glb\n")
    with pytest.raises(InputError, match=r"line 1: dangling symlink"):
        resolve_objects([str(lst)])


def test_folders_take_gltf_and_subfolders(glbs, tmp_path):
    write_gltf(glbs[0], tmp_path / "m" / "helmet", "helmet")
    shutil.copy(glbs[1], tmp_path / "m" / "cyl.glb")
    got = uids([str(tmp_path / "m")])
    assert got == {"helmet.gltf": "helmet", "cyl.glb": "cyl"}


@pytest.mark.blender
def test_separate_file_gltf_renders_with_its_texture(glbs, tmp_path):
    """The same object as .glb and as .gltf + .bin + PNG, under the same id (same seeds,
    same views): the two builds' images match, so the texture was loaded."""
    (tmp_path / "glb").mkdir()
    shutil.copy(glbs[0], tmp_path / "glb" / "thing.glb")
    write_gltf(glbs[0], tmp_path / "gltf", "thing")
    args = ("--views", "2", "--levels", "none", "--resolution", "48", "--samples", "16",
            "--settings-per-object", "1", "--quiet")  # fmt: skip
    for kind in ("glb", "gltf"):
        run_cli(
            "build",
            "--objects",
            str(tmp_path / kind),
            "--out",
            str(tmp_path / f"out_{kind}"),
            *args,
        )
    for view in ("0.png", "1.png"):
        a, b = (
            np.asarray(
                Image.open(
                    next(
                        (tmp_path / f"out_{k}" / "thing_000" / "sharp" / "images").glob(f"*{view}")
                    )
                ),
                dtype=np.float64,
            )
            for k in ("glb", "gltf")
        )
        assert np.abs(a - b).mean() < 1.0, np.abs(a - b).mean()
        # The object is textured: many distinct colours, not a flat grey.
        assert len(np.unique(a.reshape(-1, a.shape[-1]), axis=0)) > 200


@pytest.mark.blender
def test_a_setting_of_another_file_with_the_same_id_is_redone(glbs, tmp_path):
    """D4: a complete setting whose meta.json names another file is never reused."""
    for k, d in enumerate(("a", "b")):
        (tmp_path / d).mkdir()
        shutil.copy(glbs[k], tmp_path / d / "same.glb")
    out = tmp_path / "out"
    args = ("--views", "2", "--levels", "none", "--resolution", "16", "--samples", "2",
            "--settings-per-object", "1", "--quiet")  # fmt: skip
    run_cli("build", "--objects", str(tmp_path / "a"), "--out", str(out), *args)
    first = sorted((out / "same_000" / "sharp" / "images").iterdir())[0].read_bytes()
    run_cli("build", "--objects", str(tmp_path / "b"), "--out", str(out), *args)
    meta = json.loads((out / "same_000" / "meta.json").read_text())
    # Same relative path, other bytes (issue 19: meta.json names no absolute path).
    b_sha = hashlib.sha256((tmp_path / "b" / "same.glb").read_bytes()).hexdigest()
    assert meta["object"]["path"] == "same.glb" and meta["object"]["sha256"] == b_sha
    second = sorted((out / "same_000" / "sharp" / "images").iterdir())[0].read_bytes()
    assert first != second
