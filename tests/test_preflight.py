"""The GLB pre-flight (DESIGN §10, issue 14 T1/U3, issue 18): whatever a file holds, its
check ends in a Report or a one-line PreflightError, never another exception, and a
build records that file's failure and goes on. No rendering here: every object of these
builds fails before Blender starts."""

from __future__ import annotations

import copy
import json
import shutil
from pathlib import Path

import pytest
from blurset.services import preflight
from blurset.services.demo import make_demo_objects
from blurset.services.preflight import PreflightError, glb_inspect
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tests.conftest import run_cli, shared


@pytest.fixture(scope="module")
def box(tmp_path_factory) -> Path:
    return make_demo_objects(tmp_path_factory.mktemp("demo"), seed=0)[0]


def variant(src: Path, dst: Path, edit) -> Path:
    doc, bin_chunk = glb_inspect.read_glb(str(src))
    edit(doc)
    glb_inspect.write_glb(str(dst), doc, bin_chunk)
    return dst


def first(doc: dict, key: str) -> dict:
    return doc[key][0]


# The wrongly typed fields that escaped the pre-flight as other exceptions (issue 14 T1).
MUTATIONS = {
    "asset_string": lambda d: d.__setitem__("asset", "2.0"),
    "byteLength_null": lambda d: first(d, "buffers").__setitem__("byteLength", None),
    "extensionsUsed_int": lambda d: d.__setitem__("extensionsUsed", 5),
    "primitives_dict": lambda d: first(d, "meshes").__setitem__("primitives", {}),
    "uri_int": lambda d: first(d, "images").__setitem__("uri", 5),
    "byteOffset_str": lambda d: first(d, "bufferViews").__setitem__("byteOffset", "x"),
    "mode_str": lambda d: first(d, "meshes")["primitives"][0].__setitem__("mode", "triangles"),
    "uri_nul": lambda d: first(d, "images").__setitem__("uri", "tex\u0000.png"),
    "count_str": lambda d: first(d, "accessors").__setitem__("count", "x"),
    "min_str": lambda d: first(d, "accessors").__setitem__("min", "x"),
    "materials_list_of_int": lambda d: d.__setitem__("materials", [1, 2]),
    "baseColorTexture_str": lambda d: (
        d.setdefault("materials", [{}])[0]
        .setdefault("pbrMetallicRoughness", {})
        .__setitem__("baseColorTexture", "x")
    ),
}


@pytest.mark.parametrize("name", sorted(MUTATIONS))
def test_wrongly_typed_fields_are_a_preflight_error(box, tmp_path, name):
    path = variant(box, tmp_path / f"{name}.glb", MUTATIONS[name])
    try:
        preflight.check(path)
    except PreflightError as e:
        assert str(e) and "\n" not in str(e)


# Values of every JSON type, to put where the glTF expects another.
JSON_VALUES = st.recursive(
    st.none()
    | st.booleans()
    | st.integers(-(2**70), 2**70)
    | st.floats(allow_nan=False)
    | st.text(max_size=8),
    lambda inner: (
        st.lists(inner, max_size=3) | st.dictionaries(st.text(max_size=6), inner, max_size=3)
    ),
    max_leaves=6,
)


def _paths(node, prefix=()):
    """Every (container path, key) of a JSON document."""
    if isinstance(node, dict):
        for k, v in node.items():
            yield prefix, k
            yield from _paths(v, (*prefix, k))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            yield prefix, i
            yield from _paths(v, (*prefix, i))


@settings(
    max_examples=300, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(data=st.data())
def test_any_mutated_field_gives_a_report_or_a_preflight_error(box, tmp_path, data):
    doc, bin_chunk = glb_inspect.read_glb(str(box))
    for _ in range(data.draw(st.integers(1, 3))):
        places = list(_paths(doc))
        if not places:
            break
        prefix, key = data.draw(st.sampled_from(places))
        parent = doc
        for k in prefix:
            parent = parent[k]
        parent[key] = data.draw(JSON_VALUES)
    path = tmp_path / "mutated.glb"
    glb_inspect.write_glb(str(path), copy.deepcopy(doc), bin_chunk)
    try:
        report = preflight.check(path)
    except PreflightError as e:
        assert str(e) and "\n" not in str(e)
    else:
        assert report.triangles > 0


def test_uris_outside_the_models_folder_are_refused(box, tmp_path):
    (tmp_path / "m").mkdir()
    (tmp_path / "secret.png").write_bytes(b"\x89PNG\r\n\x1a\n" + b"\0" * 16)
    cases = {
        "absolute": "/etc/hostname",
        "parent": "../secret.png",
        "url": "file:///etc/hostname",
        "encoded_parent": "%2E%2E/secret.png",
    }
    for name, uri in cases.items():
        path = variant(
            box,
            tmp_path / "m" / f"{name}.glb",
            lambda d, uri=uri: first(d, "images").__setitem__("uri", uri),
        )
        with pytest.raises(PreflightError, match="model's folder|relative path"):
            preflight.check(path)


def test_budgets_refuse_big_meshes_and_textures(box):
    report = preflight.check(box)
    n = report.triangles
    assert n >= 12 and report.texture_pixels >= 512 * 512
    with pytest.raises(PreflightError, match=rf"{n} triangles \(budget --max-triangles {n - 1}\)"):
        preflight.check(box, preflight.Budget(max_triangles=n - 1))
    with pytest.raises(PreflightError, match=r"--max-texture-pixels 1000\)"):
        preflight.check(box, preflight.Budget(max_texture_pixels=1000))
    assert preflight.check(box, preflight.Budget(report.triangles, report.texture_pixels)) == report


def test_latin1_json_chunk_is_named(tmp_path):
    glb = shared("glb", "khronos_BoxTextured.glb")
    doc, bin_chunk = glb_inspect.read_glb(str(glb))
    doc["asset"]["copyright"] = "caf\u00e9"
    raw = json.dumps(doc, ensure_ascii=False).encode("latin-1")
    raw += b" " * (-len(raw) % 4)
    body = len(raw).to_bytes(4, "little") + (0x4E4F534A).to_bytes(4, "little") + raw
    bin_ = bin_chunk + b"\0" * (-len(bin_chunk) % 4)
    body += len(bin_).to_bytes(4, "little") + (0x004E4942).to_bytes(4, "little") + bin_
    path = tmp_path / "latin1.glb"
    path.write_bytes(
        b"glTF" + (2).to_bytes(4, "little") + (12 + len(body)).to_bytes(4, "little") + body
    )
    with pytest.raises(PreflightError, match=r"not UTF-8 \(glTF requires UTF-8"):
        preflight.check(path)


def test_a_build_records_each_bad_file_and_goes_on(box, tmp_path):
    """Every object here fails its pre-flight, so nothing renders: each one is a record in
    failures.jsonl naming its file, and the build ends with its summary, not a traceback."""
    objs = tmp_path / "objs"
    objs.mkdir()
    for name in ("asset_string", "primitives_dict", "byteOffset_str", "mode_str", "uri_nul"):
        variant(box, objs / f"{name}.glb", MUTATIONS[name])
    shutil.copy(box, objs / "too_big.glb")
    out = tmp_path / "out"
    proc = run_cli(
        "build", "--objects", str(objs), "--out", str(out), "--views", "2", "--levels", "none",
        "--resolution", "16", "--max-triangles", "1", "--quiet", check=False,
    )  # fmt: skip
    # Nothing was built: exit 1 with the summary line, never 2 (bad input) or 70 (a bug).
    assert proc.returncode == 1, proc.stderr
    assert "6 of 6 objects failed" in proc.stderr, proc.stderr
    recs = [json.loads(line) for line in (out / "failures.jsonl").read_text().splitlines()]
    by_uid = {r["uid"]: r for r in recs}
    assert set(by_uid) == {p.stem for p in objs.iterdir()}
    for uid, r in by_uid.items():
        assert r["stage"] == "preflight" and r["path"].endswith(f"{uid}.glb"), r
    assert "--max-triangles 1)" in by_uid["too_big"]["reason"]
    assert "malformed glTF JSON" in by_uid["byteOffset_str"]["reason"]
