"""The export targets are a registry (issue 49): each `--for` target is one module of
blurset.commands.export.targets, and everything else follows from it. The `--for` choices and help come
from the registry, every target is a name of the core's `ExportTarget` (which
export.json's `for` is read as) and has its docs page, export.py names no target, and a
target module export.py has never seen is exported with it unchanged."""

from __future__ import annotations

import ast
import hashlib
import json
import re
import sys
from pathlib import Path

import pytest
from blurset import cli
from blurset.commands.export import targets as exports
from blurset.commands.export.rules import OwnOutput, SceneFolders
from blurset.services import outputs

from tests.conftest import ROOT, run_cli, standin_build

pq = pytest.importorskip("pyarrow.parquet")

EXPORT_PY = ROOT / "python" / "blurset" / "commands" / "export" / "cli.py"
DOCS = ROOT / "docs"
# The page that explains exports: every target has its row there.
OVERVIEW = DOCS / "training" / "index.md"


def _export_parser():
    parser = cli.make_parser()
    sub = next(a for a in parser._actions if a.choices and "export" in a.choices)
    return sub.choices["export"]


def _for_action(parser):
    return next(a for a in parser._actions if "--for" in a.option_strings)


def test_every_target_is_found_and_is_its_modules_name() -> None:
    files = sorted(
        p.stem
        for p in (ROOT / "python" / "blurset" / "commands" / "export" / "targets").glob("*.py")
    )
    assert set(exports.targets()) == {f for f in files if f != "__init__"}
    assert exports.DEFAULT in exports.targets()
    for name, t in exports.targets().items():
        assert t.name == name
        assert isinstance(t.output, (SceneFolders, OwnOutput))


def test_the_for_choices_and_help_are_the_registrys() -> None:
    action = _for_action(_export_parser())
    assert sorted(action.choices) == sorted(exports.targets())
    assert action.default == exports.DEFAULT
    for t in exports.targets().values():
        assert f"{t.name}: {t.help}" in action.help
    # A target's own options are declared by it, and only it reads them.
    dests = {a.dest for a in _export_parser()._actions}
    for t in exports.targets().values():
        if isinstance(t.output, OwnOutput):
            assert set(t.output.options) <= dests


def test_every_target_is_a_name_of_the_records_enum() -> None:
    """export.json's `for` is the core's ExportTarget: the registry and the enum hold
    the same names (an unregistered name is a record no target writes; a target
    missing there, one whose export.json the core refuses)."""
    defs = outputs.record_schemas()["export.schema.json"]["$defs"]
    assert defs["ExportDoc"]["properties"]["for"] == {"$ref": "#/$defs/ExportTarget"}
    names = [alt["const"] for alt in defs["ExportTarget"]["oneOf"]]
    assert sorted(names) == sorted(exports.targets())


def test_every_target_has_its_docs_page_and_its_row() -> None:
    nav = (ROOT / "mkdocs.yml").read_text()
    overview = OVERVIEW.read_text()
    for t in exports.targets().values():
        page = DOCS / t.docs
        assert page.is_file(), (t.name, t.docs)
        assert re.search(rf"\b{re.escape(t.docs)}\b", nav), f"{t.docs} is not in mkdocs.yml"
        assert f"--for {t.name}" in page.read_text(), (t.name, t.docs)
        assert f"`--for {t.name}`" in overview, f"{t.name} has no row on {OVERVIEW.name}"


def _targets_named(source: str) -> list[str]:
    """Where a source names an export target: a string (other than a docstring) holding
    a target's name as a word, or a name made of it (`_geonerf_scenes`, `SCENES_DIR`
    keyed by them is caught by its strings)."""
    names = list(exports.targets())
    tree = ast.parse(source)
    docstrings = {
        id(n.body[0].value)
        for n in ast.walk(tree)
        if isinstance(n, (ast.Module, ast.FunctionDef, ast.ClassDef))
        and n.body
        and isinstance(n.body[0], ast.Expr)
        and isinstance(n.body[0].value, ast.Constant)
    }
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Constant) and isinstance(node.value, str):
            if id(node) in docstrings:
                continue
            found += [
                f"{n!r} in {node.value!r}" for n in names if re.search(rf"\b{n}\b", node.value)
            ]
        ident = (
            node.id if isinstance(node, ast.Name)
            else node.attr if isinstance(node, ast.Attribute)
            else node.name if isinstance(node, (ast.FunctionDef, ast.ClassDef))
            else None
        )  # fmt: skip
        if ident:
            found += [
                f"{n!r} in {ident}" for n in names if re.search(rf"(^|_){n}(_|$)", ident.lower())
            ]
    return found


def test_export_py_names_no_target() -> None:
    source = EXPORT_PY.read_text()
    assert _targets_named(source) == []
    # The check sees a branch on a target, a table keyed by one and a helper named for one.
    branch = source.replace(
        "def run(args) -> int:\n",
        'def run(args) -> int:\n    if args.target == "geonerf":\n        pass\n',
    )
    assert _targets_named(branch) == ["'geonerf' in 'geonerf'"]
    assert _targets_named('DIRS = {"llff": "nerf_llff_data"}\n') == ["'llff' in 'llff'"]
    assert _targets_named("def _hub_run(): pass\n") == ["'hub' in _hub_run"]


# A target export.py has never seen: scenes under flat/, the held-out views of a
# setting each a scene of their own, and only the level's poses and a note written.
THROWAWAY = """
from blurset.commands.export.rules import SceneFolders, Target


def split(s):
    return [(f"{s.scene}__v{v}", [v]) for v in s.held_out] if s.is_test else [(s.scene, None)]


def write(s):
    s.path.mkdir(parents=True)
    s.put(s.src / "poses_bounds.npy", "poses_bounds.npy")
    (s.path / "note.txt").write_text(s.name)


TARGET = Target(
    name="llff",
    help="a throwaway layout",
    docs="training/index.md",
    output=SceneFolders(folder="flat", write=write, hint=lambda doc, root: "throwaway hint",
                        split=split, passes=False),
)
"""


@pytest.fixture
def throwaway_registry(tmp_path, monkeypatch):
    """The registry with one module, the throwaway target, in place of the package's own.
    (It is named llff: export.json's `for` is read as ExportTarget, which a real new
    target joins by its name.)"""
    pkg = tmp_path / "pkg"
    pkg.mkdir()
    (pkg / "llff.py").write_text(THROWAWAY)
    monkeypatch.setattr(exports, "__path__", [str(pkg)])
    monkeypatch.delitem(sys.modules, "blurset.commands.export.targets.llff", raising=False)
    exports.targets.cache_clear()
    yield
    exports.targets.cache_clear()
    sys.modules.pop("blurset.commands.export.targets.llff", None)


def test_a_new_target_module_is_exported_with_by_export_py_unchanged(
    standin_build_dir, throwaway_registry, tmp_path, capsys
) -> None:
    before = EXPORT_PY.read_bytes()
    assert list(exports.targets()) == ["llff"]
    assert _for_action(_export_parser()).choices == ["llff"]
    out = tmp_path / "out"
    assert cli.main(["export", str(standin_build_dir), "--out", str(out)]) == 0
    assert EXPORT_PY.read_bytes() == before
    doc = json.loads((out / "export.json").read_text())
    splits = json.loads((standin_build_dir / "splits.json").read_text())
    assert doc["for"] == "llff" and doc["scenes_dir"] == "flat" and "passes" not in doc
    # The throwaway split rule made the scenes: held-out views of test settings apart.
    want_test = [
        f"{s}__{lvl}__v{v}"
        for s in splits["test"]
        for lvl in doc["levels"]
        for v in splits["test_views"][s]
    ]
    assert sorted(doc["test"]) == sorted(want_test) and want_test
    assert sorted(doc["train"]) == sorted(
        f"{s}__{lvl}" for s in splits["train"] for lvl in doc["levels"]
    )
    assert doc["views"] == {s: [int(s.rsplit("__v", 1)[1])] for s in want_test}
    # Its writer wrote each scene, and nothing else was.
    for scene in doc["scenes"]:
        d = out / "flat" / scene
        assert sorted(p.name for p in d.iterdir()) == ["note.txt", "poses_bounds.npy"]
        assert (d / "note.txt").read_text() == scene
    assert sorted(p.name for p in out.iterdir()) == ["export.json", "flat", "test.txt", "train.txt"]
    assert "throwaway hint" in capsys.readouterr().out


# -- noisy scenes: no noise-free image where a client trains (issue 72 item 4) -------------


def _sha(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def _trained_on(target: str, out: Path, doc: dict) -> dict[str, list[str]]:
    """Per noisy scene (hub: config and setting), the digests of every image its client
    trains on or draws as a source: all but the views its loader evaluates on."""
    scenes = out / doc["scenes_dir"]
    seen: dict[str, list[str]] = {}
    if target == "hub":
        for shard in sorted((out / "data").rglob("*.parquet")):
            for row in pq.read_table(shard).to_pylist():
                if row["gain"] is not None and not row["held_out"]:
                    cells = [row[k] for k in row if k == "image" or re.fullmatch(r"image_\d+", k)]
                    key = f"{shard.parent.name}/{row['setting']}"
                    seen.setdefault(key, []).extend(_sha(c["bytes"]) for c in cells)
        return seen
    for scene in doc["scenes"]:
        d = scenes / scene
        dirs = sorted(p for p in d.iterdir() if re.fullmatch(r"images(_\d+)?", p.name))
        names = [p.name for p in sorted(dirs[0].glob("*.png"))]
        if target == "geonerf":
            # A train scene: every view a target and a source; a test scene: image 0 is
            # its evaluated target, the others its sources.
            held = set() if scene.startswith("train/") else {names[0]}
        elif target == "nerfstudio":
            train = json.loads((d / "transforms.json").read_text())["train_filenames"]
            held = set(names) - {Path(f).name for f in train}
        else:  # llff: the loader holds every llffhold-th view out
            held = set(names[:: doc["llffhold"]])
        seen[scene] = [
            _sha(p.read_bytes()) for sub in dirs for p in sub.glob("*.png") if p.name not in held
        ]
    return seen


@pytest.mark.parametrize("build_args", [(), ("--blurry-test-views",)], ids=["sharp", "blurry"])
def test_a_noisy_export_holds_no_noise_free_image_a_client_trains_on(
    standin_blender, tmp_path, build_args
) -> None:
    """Every target's noisy scenes (sharp level included, and with held-out views the
    build rendered blurry), read as its client reads them: no image it trains on or
    draws as a source is byte-equal to an image of the build. A noise output keeps its
    held-out views noise-free, as targets: GeoNeRF trains on every view of a train
    scene, so its train scenes leave them out."""
    b, noise = tmp_path / "b", tmp_path / "n"
    standin_build(b, standin_blender, "--views", "17", *build_args)
    run_cli("noise", str(b), "--out", str(noise), "--gains", "4", "--quiet")
    clean = {_sha(p.read_bytes()) for p in b.rglob("*.png")}
    levels = json.loads((b / "dataset.json").read_text())["levels"]
    assert "sharp" in levels and len(levels) > 1
    for target in exports.targets():
        assert target in ("llff", "geonerf", "nerfstudio", "hub"), f"{target}: add its reader"
        out = tmp_path / target
        run_cli("export", str(b), "--noise", str(noise), "--for", target, "--out", str(out))
        seen = _trained_on(target, out, json.loads((out / "export.json").read_text()))
        for lvl in levels:
            assert any(f"{lvl}__gain_4" in k or f"{lvl}_gain_4/" in k for k in seen), (target, lvl)
        bad = {k: sum(h in clean for h in v) for k, v in seen.items()}
        bad = {k: n for k, n in bad.items() if n}
        assert not bad, f"--for {target}: noise-free images a client trains on: {bad}"
        assert all(seen.values()), target
