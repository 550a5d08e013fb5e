"""scripts/check_clients.py, the blurset side: it finds the build an export links into,
knows a sharp copy by its bytes, and judges what a client read (the client side needs
the clients' code and torch, and runs by hand: docs/training/index.md). Here the
client's reads are written as a client would make them, on a stand-in build."""

from __future__ import annotations

import importlib.util
import json
import sys
from pathlib import Path

import pytest

from tests.conftest import ROOT, run_cli, standin_build

SCRIPT = ROOT / "scripts" / "check_clients.py"


@pytest.fixture(scope="module")
def cc():
    spec = importlib.util.spec_from_file_location("check_clients", SCRIPT)
    mod = importlib.util.module_from_spec(spec)
    sys.modules["check_clients"] = mod
    spec.loader.exec_module(mod)
    return mod


@pytest.fixture(scope="module")
def geonerf_export(tmp_path_factory, standin_blender):
    tmp = tmp_path_factory.mktemp("cc")
    out = tmp / "b"
    standin_build(out, standin_blender, "--views", "17")
    run_cli("export", str(out), "--out", str(tmp / "g"), "--for", "geonerf")
    return out, tmp / "g"


def _result(root: Path, draw) -> dict:
    """What a GeoNeRF child reports: every test scene read, one target each."""
    scenes, draws = [], []
    for d in sorted((root / "geonerf" / "test").iterdir()):
        files = sorted(str(p) for p in (d / "images_4").iterdir())
        scenes.append({"dir": str(d), "images": 8, "poses": 8, "shape": [16, 16, 3],
                       "focal": 1.0, "held_out": [0]})  # fmt: skip
        target, sources = draw(files)
        draws.append({"dir": str(d), "target": target, "sources": sources, "target_index": 0})
    phase = {"name": "val", "draws": draws,
             "expect": {"targets_sharp": True, "sources_sharp": False}}  # fmt: skip
    return {"python": "py", "versions": [], "ran": ["x"], "scenes": scenes, "phases": [phase]}


def test_the_build_is_found_from_the_links_and_sharp_copies_are_told(cc, geonerf_export):
    build, root = geonerf_export
    doc = json.loads((root / "export.json").read_text())
    assert cc._find_build(root, doc) == build.resolve()
    # GeoNeRF with nb_views 6: the 6 nearest of the 7 degraded views, the target first.
    report, status = cc.analyse(
        "geonerf", root, doc, build, _result(root, lambda f: (f[0], f[1:7]))
    )
    assert status == 0 and "verdict: ok" in report, report
    assert "0 of them a sharp copy (expected none: ok)" in report
    n = sum(1 for k in doc["scenes"] if k.startswith("test/") and "__sharp" not in k)
    assert f"{n} targets, {n} of them sharp (expected {n}: ok)" in report
    # With nb_views 9 the target comes back among the sources: a sharp copy.
    report, status = cc.analyse(
        "geonerf", root, doc, build, _result(root, lambda f: (f[0], [*f[1:7], f[0]]))
    )
    assert status == 1 and "verdict: FAILED" in report, report
    assert f"{n * 7} sources, {n} of them a sharp copy" in report
    assert "the target itself is among the sources" in report


def test_a_client_given_the_wrong_export_or_failing_says_so(cc, geonerf_export, tmp_path, capsys):
    _, root = geonerf_export
    args = ["--checkout", str(tmp_path), "--python", sys.executable]
    assert cc.main(["ibrnet", str(root), *args]) == 2
    assert "reads an export --for llff" in capsys.readouterr().err
    # An empty checkout: the client's modules do not import, and the error is shown.
    assert cc.main(["geonerf", str(root), *args]) == 2
    assert "ModuleNotFoundError" in capsys.readouterr().out


def test_a_relative_python_and_checkout_are_the_ones_the_user_named(
    cc, geonerf_export, tmp_path, capsys, monkeypatch
):
    """The docs' form, `--python env/bin/python --checkout GeoNeRF` from the folder
    holding both: the child runs inside the checkout, where those relative paths would
    name nothing; the client's own code is reached (here an empty checkout, so its
    import fails and says so)."""
    _, root = geonerf_export
    (tmp_path / "env" / "bin").mkdir(parents=True)
    (tmp_path / "env" / "bin" / "python").symlink_to(sys.executable)
    (tmp_path / "GeoNeRF").mkdir()
    monkeypatch.chdir(tmp_path)
    args = ["--checkout", "GeoNeRF", "--python", "env/bin/python"]
    assert cc.main(["geonerf", str(root), *args]) == 2
    out = capsys.readouterr()
    assert "ModuleNotFoundError" in out.out, out


def test_json_never_replaces_a_file_it_did_not_write(cc, tmp_path, capsys):
    # Refused before anything runs (no export, checkout or Python is looked at): one line
    # naming --json and the file, its bytes unchanged; its own earlier report may go.
    mine = tmp_path / "meta.json"
    mine.write_text('{"build": "not a client report"}')
    before = mine.read_bytes()
    args = ["geonerf", str(tmp_path / "none"), "--checkout", str(tmp_path), "--python", "x"]
    assert cc.main([*args, "--json", str(mine)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--json" in err[0] and str(mine) in err[0], err
    assert mine.read_bytes() == before
    assert cc.main([*args, "--json", str(tmp_path)]) == 2  # a folder
    own = tmp_path / "read.json"
    own.write_text(
        json.dumps({"python": "py", "versions": [], "ran": [], "scenes": [], "phases": []})
    )
    capsys.readouterr()
    assert cc.main([*args, "--json", str(own)]) == 2  # past the claim: the export is absent
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert "export.json" in line and str(tmp_path / "none") in line, line
