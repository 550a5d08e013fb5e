"""Issue 49: the build's tail is the core's (`dataset/build_tail.rs`): failures.jsonl,
splits.json and dataset.json over the complete settings' meta.json, with what the
builder wrote before (a failure record spelled as `json.dumps` spells it, the latest per
object or setting whose work is not complete; the counts of dataset.json). No renders:
a synthetic build and a failures.jsonl with every kind of record."""

from __future__ import annotations

import json

from blurset.commands.builder.dataset import append_failures, finalize
from blurset.services.config import make_config

from tests.conftest import write_synthetic_build

VIEWS, LEVELS = 4, (1, 2)


def test_the_core_writes_the_builds_tail(tmp_path, capsys) -> None:
    out = tmp_path / "b"
    # obj00000 … obj00002, four settings each (θ0 0, 90, 180, 270).
    write_synthetic_build(out, 12, views=VIEWS, levels=LEVELS, latents=2, templates=2)
    # A complete setting whose meta.json does not read: left out, named, redone later.
    (out / "obj00002_270" / "meta.json").write_text('{"uid": "obj00002", "vie')
    later = [
        # Its object is complete now: no failure any more.
        {"uid": "obj00001", "path": "o1.glb", "stage": "render", "reason": "crash",
         "seconds": 1.5, "attempts": 2, "time": "2026-01-02T03:04:05"},
        # The latest record of an object counts, spelled as Python spells it.
        {"uid": "θbj", "path": "θ.glb", "stage": "fetch", "reason": "old", "seconds": 0.0},
        {"uid": "θbj", "path": "θ.glb", "stage": "load", "reason": 'café "bad"\n',
         "seconds": 1e-05, "attempts": 1},
        # Left out by --licenses: a record, not a failure.
        {"uid": "lic", "path": "l.glb", "stage": "license", "reason": "CC-BY-NC-4.0"},
        # A setting's QA failure: kept while its setting is not complete (a setting
        # whose meta.json does not read is not complete).
        {"uid": "obj00002", "setting": "obj00002_270", "stage": "qa", "reason": "black"},
        {"uid": "obj00000", "setting": "obj00000_090", "stage": "qa", "reason": "black"},
    ]  # fmt: skip
    append_failures(out, later)
    with open(out / "failures.jsonl", "a") as f:
        f.write('{"uid": "torn", "sta')  # a record a kill cut short
    cfg = make_config({}, {"objects": ["x.glb"], "out": str(out), "views": VIEWS,
                           "levels": list(LEVELS), "settings_per_object": 4})  # fmt: skip

    summary = finalize(out, cfg, 12.34, vouched=[])

    assert "skipped obj00002_270: unreadable meta.json" in capsys.readouterr().err
    # synthetic's own ("broken"), then by uid: the latest of each, sorted keys.
    kept = [
        {"uid": "broken", "stage": "load", "reason": "synthetic failure"},
        later[3],
        later[4],
        later[2],
    ]
    expect = "".join(json.dumps(r, sort_keys=True) + "\n" for r in kept)
    assert (out / "failures.jsonl").read_text() == expect
    assert summary["failures"] == kept
    assert summary["settings_complete"] == 11

    doc = json.loads((out / "dataset.json").read_text())
    assert doc["counts"] == {
        "objects": 3,
        "objects_failed": 3,  # broken, obj00002, θbj: not lic, skipped by request
        "settings": 11,
        "settings_failed": 1,
        "images": 11 * VIEWS * (1 + len(LEVELS)),
    }
    settings = sorted(p.parent.name for p in out.glob("*/meta.json"))
    assert doc["settings"] == [s for s in settings if s != "obj00002_270"]
    assert doc["seconds"] == 12.3 and doc["levels"] == ["sharp", "blur_1", "blur_2"]
    assert doc["config"] == json.loads(json.dumps(cfg.record()))
    assert doc["versions"]["blender"] is None and doc["render_devices"] == []
    splits = json.loads((out / "splits.json").read_text())
    assert sorted(splits["train"] + splits["test"]) == doc["settings"]
    assert summary["test_settings"] == len(splits["test"]) > 0
