"""JSON Schemas of the records blurset writes (schemas/, generated from the core's serde
types by `make schemas`): the shipped files are the generated ones, and every record of
real outputs validates against them (a stand-in build, its noise output, statistics,
exports, a scene's noise; the demo build's in the render tests)."""

from __future__ import annotations

import json
from pathlib import Path

import jsonschema
import pytest
from blurset.services import outputs

from tests.conftest import ROOT, copy_build, run_cli, shared, standin_build

SCHEMAS = ROOT / "schemas"


def validators() -> dict[str, jsonschema.Draft202012Validator]:
    out = {}
    for name in sorted(p.name for p in SCHEMAS.glob("*.schema.json")):
        schema = json.loads((SCHEMAS / name).read_text())
        jsonschema.Draft202012Validator.check_schema(schema)
        out[name.replace(".schema.json", ".json")] = jsonschema.Draft202012Validator(schema)
    return out


def check_tree(root: Path, seen: dict[str, int]) -> None:
    """Validate every record under `root` (by file name) against its schema."""
    v = validators()
    for p in sorted(root.rglob("*.json")):
        if p.name in v and not p.name.startswith("."):
            errors = sorted(v[p.name].iter_errors(json.loads(p.read_text())), key=str)
            assert not errors, (p, [e.message for e in errors[:3]])
            seen[p.name] = seen.get(p.name, 0) + 1


def test_the_stubs_typed_dicts_are_the_cores():
    """blurset/_records.pyi (the types of the dicts crossing the FFI) is what the core's
    serde types make today (`make schemas` writes it), and _core.pyi uses them."""
    from blurset.services import stubgen

    assert stubgen.STUB.read_text() == stubgen.render(), "run `make schemas`"
    text = stubgen.STUB.read_text()
    for name in ("Render", "SettingPlan", "LevelPlan", "DatasetDoc", "NoiseDoc", "BuildStats"):
        assert f"class {name}(TypedDict)" in text, name
    core_stub = (stubgen.STUB.parent / "_core.pyi").read_text()
    assert "-> list[rec.Render]" in core_stub and "def record(self) -> rec.NoiseDoc" in core_stub
    # Nothing the core hands back is an untyped dict: each has its generated type.
    assert "dict[str, Any]" not in core_stub
    for name in ("HalfNoise", "Render", "Failure"):
        assert f"rec.{name}" in core_stub, name


def test_the_shipped_schemas_are_the_cores():
    generated = outputs.record_schemas()
    shipped = {p.name: json.loads(p.read_text()) for p in SCHEMAS.glob("*.schema.json")}
    assert shipped == generated, "schemas/ differs from the core's types: run `make schemas`"


def test_every_record_of_real_outputs_fits_its_schema(standin_build_dir, standin_blender, tmp_path):
    b = copy_build(standin_build_dir, tmp_path / "b")
    run_cli("stats", str(b), "--quiet")
    run_cli("noise", str(b), "--out", str(tmp_path / "n"), "--gains", "1", "--levels", "blur_1",
            "--quiet")  # fmt: skip
    run_cli("export", str(b), "--out", str(tmp_path / "e"))
    run_cli("export", str(b), "--out", str(tmp_path / "en"), "--noise", str(tmp_path / "n"))
    g = tmp_path / "g"
    standin_build(g, standin_blender, "--views", "17")
    run_cli("export", str(g), "--out", str(tmp_path / "eg"), "--for", "geonerf")
    run_cli("noise", str(shared("llff", "fern")), "--factor", "8", "--gains", "1",
            "--out", str(tmp_path / "fern"))  # fmt: skip
    seen: dict[str, int] = {}
    for root in ("b", "n", "e", "en", "g", "eg", "fern"):
        check_tree(tmp_path / root, seen)
    assert set(seen) == {p.replace(".schema.json", ".json") for p in outputs.record_schemas()}
    assert seen["meta.json"] >= 6 and seen["noise.json"] >= 6


def test_a_schema_refuses_what_the_core_would_not_write(standin_build_dir):
    v = validators()
    splits = json.loads((standin_build_dir / "splits.json").read_text())
    splits["train"] = 5
    assert list(v["splits.json"].iter_errors(splits))
    meta = json.loads(next(standin_build_dir.glob("*/meta.json")).read_text())
    meta["views"][0]["w_u"] = "large"
    assert list(v["meta.json"].iter_errors(meta))
    with pytest.raises(ValueError, match="noise_scene.json does not fit its schema"):
        outputs.write_record(standin_build_dir.parent / "x" / "noise_scene.json", {"kind": "x"})


@pytest.mark.blender
def test_the_records_of_a_real_demo_build_fit_their_schemas(linear_build):
    seen: dict[str, int] = {}
    check_tree(linear_build, seen)
    assert {"meta.json", "splits.json", "dataset.json"} <= set(seen)
