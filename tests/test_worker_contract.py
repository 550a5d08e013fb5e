"""The worker contract (issue 49): every line the builder sends a Blender worker and every
line a worker sends back fits schemas/worker/ (the core's dataset/wire.rs types), for the
real worker and for the stand-in the fast layer runs on; the shipped schemas are the
core's; every request line is made by the core (a render's frame spelled by it alone),
every reply typed by it and handed on as sent; the Python types of both are generated."""

from __future__ import annotations

import copy
import json
import subprocess
from pathlib import Path
from typing import Any

import jsonschema
import numpy as np
import pytest
from blurset.services import outputs, stubgen
from blurset.services import worker_client as wc
from blurset.services.demo import make_demo_objects

ROOT = Path(__file__).resolve().parents[1]
EYE = [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 3.0], [0.0, 0.0, 0.0, 1.0]]
# What the real worker (bpy 5.0.1, CPU) sent: ready, a refused load, a load, a frame on
# disk, the render done, its --probe line (the core's wire tests read the same file).
REAL_LINES = (ROOT / "rust" / "core" / "testdata" / "worker_lines.jsonl").read_text().splitlines()


def _validators() -> tuple[jsonschema.Draft202012Validator, jsonschema.Draft202012Validator]:
    s = outputs.worker_schemas()
    return (
        jsonschema.Draft202012Validator(s["worker/request.schema.json"]),
        jsonschema.Draft202012Validator(s["worker/reply.schema.json"]),
    )


def _traced(monkeypatch) -> tuple[list[dict], list[dict]]:
    """Every message a Worker sends and receives from now on, as it crossed the pipe (a
    copy: the client adds its own fields to a load reply afterwards)."""
    sent: list[dict] = []
    got: list[dict] = []
    send, receive = wc.Worker._send_line, wc.Worker._receive

    def _send_line(self: wc.Worker, line: str) -> None:
        sent.append(json.loads(line))
        send(self, line)

    def _receive(self: wc.Worker, **kw: Any) -> dict[str, Any]:
        msg = receive(self, **kw)
        got.append(copy.deepcopy(msg))
        return msg

    monkeypatch.setattr(wc.Worker, "_send_line", _send_line)
    monkeypatch.setattr(wc.Worker, "_receive", _receive)
    return sent, got


def _exercise(w: wc.Worker, work: Path) -> None:
    """Every kind of request and reply: ready, a refused load, a load, renders with every
    frame field and every request option."""
    bad = work / "not_a.glb"
    bad.write_bytes(b"not a GLB")
    with pytest.raises(wc.WorkerError):
        w.load(bad, work / "v.npy")
    w.load(make_demo_objects(work / "objs")[0], work / "v.npy")
    frames = [
        {"c2w": EYE, "seed": 1, "out": work / "a.exr", "region": [0, 0, 16, 16], "call": 0,
         "view": 0, "level": "sharp", "kind": {"type": "sharp"}, "phase": 0},
        {"c2w": EYE, "seed": 2, "out": work / "b.exr", "samples": 2, "sample_offset": 2,
         "sample_sequence": 4, "view": 0, "level": "blur_1", "half": 1},
        {"c2w": EYE, "seed": 3, "out": work / "c.exr", "motion": {"steps": 1, "keys": [EYE] * 3},
         "rolling_shutter": True},
        {"c2w": EYE, "seed": 4, "out": work / "d.exr",
         "dof": {"focus_distance": 3.0, "aperture_radius": 0.01}},
    ]  # fmt: skip
    w.render(frames, resolution=32, fov_deg=40.0, samples=1, crop=True)
    one = [{"c2w": EYE, "seed": 5, "out": work / "e.exr"}]
    w.render(one, resolution=32, fov_deg=40.0, samples=2, batch=False, exr_codec="ZIP",
             noise_threshold=0.1)  # fmt: skip
    w.render(one, resolution=32, fov_deg=40.0, samples=1, guides=True)
    w.render(one, resolution=32, fov_deg=40.0, samples=1, geometry=True)


def _check(sent: list[dict], got: list[dict], blender: str | None) -> None:
    request, reply = _validators()
    # close() writes the core's quit line directly: the contract has it too.
    for msg in [*sent, json.loads(wc.quit_line())]:
        errors = [e.message for e in request.iter_errors(msg)]
        assert not errors, (msg.get("cmd"), errors[:1])
    for msg in got:
        errors = [e.message for e in reply.iter_errors(msg)]
        assert not errors, (sorted(msg), errors[:1])
    cmds = [m["cmd"] for m in sent]
    assert cmds.count("load") == 2 and cmds.count("render") >= 5, cmds
    kinds = {
        next(k for k in ("ready", "frame", "done", "reason", "bbox_dims") if k in m) for m in got
    }
    assert kinds == {"ready", "frame", "done", "reason", "bbox_dims"}, kinds
    assert blender is None or "cuda" in got[0], "the stand-in's GPU ready line went untested"
    # The --probe line of the same worker.
    out = subprocess.run(wc.worker_command(blender, 1, probe=True), capture_output=True,
                         timeout=300, check=True).stdout.decode()  # fmt: skip
    probe = [json.loads(line) for line in out.splitlines() if line.startswith("{")]
    assert probe and not list(reply.iter_errors(probe[-1])), probe


@pytest.mark.blender
def test_the_real_worker_speaks_the_contract(tmp_path, monkeypatch) -> None:
    sent, got = _traced(monkeypatch)
    with wc.Worker(threads=1, timeout=300, workdir=tmp_path / "scratch") as w:
        _exercise(w, tmp_path)
    _check(sent, got, None)


def test_the_standin_worker_speaks_the_contract(tmp_path, monkeypatch, standin_blender) -> None:
    # As a GPU worker whose arch Blender ships no kernel for: "cuda" in its ready line.
    monkeypatch.setenv("BLURSET_STANDIN_CUDA", "sm_90")
    monkeypatch.setenv("CUDA_CACHE_PATH", str(tmp_path / "cuda-cache"))
    sent, got = _traced(monkeypatch)
    with wc.Worker(blender=str(standin_blender), threads=1, timeout=120,
                   workdir=tmp_path / "scratch") as w:  # fmt: skip
        _exercise(w, tmp_path)
    _check(sent, got, str(standin_blender))


def test_the_shipped_worker_schemas_are_the_cores() -> None:
    shipped = {
        f"worker/{p.name}": json.loads(p.read_text())
        for p in (ROOT / "schemas" / "worker").glob("*.schema.json")
    }
    assert shipped == outputs.worker_schemas(), "schemas/worker/ differs: run `make schemas`"


def test_a_message_outside_the_contract_is_refused() -> None:
    """The schemas bite: a misspelled field, a missing one, a 3×4 camera, an unknown command."""
    request, reply = _validators()
    frame = {"c2w": EYE, "seed": 1, "out": "/a.exr"}
    render = {"cmd": "render", "resolution": 8, "fov_deg": 40.0, "samples": 1, "frames": [frame]}
    assert not list(request.iter_errors(render))
    for bad in (
        {**render, "frames": [{**frame, "sampels": 2}]},
        {**render, "frames": [{"c2w": EYE, "out": "/a.exr"}]},
        {**render, "frames": [{**frame, "c2w": EYE[:3]}]},
        {**render, "cmd": "paint"},
    ):
        assert list(request.iter_errors(bad)), bad
    assert list(reply.iter_errors({"frame": 0, "out": "a", "seconds": 0.1}))  # no origin


def test_the_core_spells_a_frame_and_refuses_a_broken_one() -> None:
    """worker_client sends the request line the core makes of the renders: each frame the
    plan's Render as it is (the worker leaves its kind, phase and half), checked."""
    plan_render = {"view": 2, "level": "blur_1", "kind": {"type": "blur", "level": 1},
                   "phase": 1, "half": 0, "c2w": EYE, "seed": 9, "out": "/x/a.exr",
                   "samples": 4, "call": 7}  # fmt: skip

    def line(frames):
        return json.loads(wc.request_line(frames, resolution=8, fov_deg=40.0, samples=1))

    msg = line([plan_render])
    assert msg["cmd"] == "render" and msg["frames"] == [plan_render]
    request, _ = _validators()
    assert not list(request.iter_errors(msg))
    # A caller's NumPy camera, seed, region and samples go as plain numbers, its EXR
    # path absolute.
    mixed = {"c2w": np.asarray(EYE), "seed": np.int64(9), "out": Path("b.exr"),
             "region": np.array([0, 0, 8, 8]), "samples": np.int32(2)}  # fmt: skip
    item = line([mixed])["frames"][0]
    assert (item["seed"], item["region"], item["samples"]) == (9, [0, 0, 8, 8], 2)
    assert Path(item["out"]).is_absolute()
    with pytest.raises(ValueError, match="sample_sequence"):
        line([{**plan_render, "sample_offset": 4}])
    with pytest.raises(ValueError, match="keys"):
        line([{**plan_render, "motion": {"steps": 2, "keys": [EYE] * 3}}])
    with pytest.raises(ValueError, match="sampels"):
        line([{**plan_render, "sampels": 2}])


def test_the_core_makes_the_load_and_quit_lines(tmp_path) -> None:
    request, _ = _validators()
    glb, verts = tmp_path / "a.glb", tmp_path / "v.npy"
    msg = json.loads(wc.load_line(glb, verts, unlit="emission", light_paths="fixed"))
    assert msg == {"cmd": "load", "glb": str(glb), "vertices_out": str(verts),
                   "unlit": "emission", "light_paths": "fixed"}  # fmt: skip
    assert not list(request.iter_errors(msg))
    with pytest.raises(ValueError, match="light_paths"):
        wc.load_line(glb, verts, unlit="lit", light_paths="sometimes")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="unlit"):
        wc.load_line(glb, verts, unlit="glow", light_paths="auto")  # type: ignore[arg-type]
    assert json.loads(wc.quit_line()) == {"cmd": "quit"}
    # worker_client builds no envelope of its own: every line comes from the core.
    source = (ROOT / "python" / "blurset" / "services" / "worker_client.py").read_text()
    assert "json.dumps" not in source and '"cmd"' not in source


def test_a_load_the_contract_lacks_fails_before_the_worker_sees_it(tmp_path, standin_blender):
    sent: list[str] = []
    with wc.Worker(blender=str(standin_blender), threads=1, timeout=60) as w:
        send = w._send_line
        w._send_line = sent.append  # type: ignore[method-assign]
        with pytest.raises(wc.WorkerError, match="light_paths"):
            w.load(tmp_path / "a.glb", tmp_path / "v.npy", light_paths="sometimes")  # type: ignore[arg-type]
        w._send_line = send  # type: ignore[method-assign]
        assert not sent and w.alive


def test_a_reply_is_typed_by_the_core_and_handed_on_as_sent() -> None:
    """Every line of the real worker passes the core's reply types and comes back the same
    object, every field and its order kept; a null the contract allows stays a null (the
    typed value would drop it); a null, a wrong type or an extra field it does not allow
    is a ValueError naming the reply and the field."""
    _, reply = _validators()
    assert len(REAL_LINES) == 6
    for line in REAL_LINES:
        msg = json.loads(line)
        got = wc.typed_reply(msg)
        assert got is msg and json.dumps(got) == json.dumps(json.loads(line))
        assert not list(reply.iter_errors(msg))
    ready = {**json.loads(REAL_LINES[0]), "cuda": None}
    got = wc.typed_reply(copy.deepcopy(ready))
    assert got == ready and "cuda" in got and got["cuda"] is None
    assert not list(reply.iter_errors(ready))
    gpu = {**ready, "device": {"backend": "OPTIX", "devices": ["NVIDIA H100"], "kernel": "OPTIX"},
           "cuda": {"archs": ["sm_90"], "kernels": ["sm_86", "sm_89"], "driver": 13000}}  # fmt: skip
    assert wc.typed_reply(copy.deepcopy(gpu)) == gpu
    loaded = json.loads(REAL_LINES[2])
    for bad, field in (
        ({**ready, "device": {**ready["device"], "kernel": None}}, "device.kernel"),
        ({**loaded, "n_vertices": -1}, "n_vertices"),
        ({**loaded, "bbox": [1, 1, 1]}, "bbox"),
        ({"frame": 0, "out": "a.exr", "seconds": 0.1}, "origin"),
        ({"ok": True, "hello": 1}, "hello"),
    ):
        with pytest.raises(ValueError, match=field):
            wc.typed_reply(bad)
        assert list(reply.iter_errors(bad)), bad  # the schema refuses it too


def test_a_worker_line_outside_the_contract_fails_the_worker(tmp_path) -> None:
    """A worker whose ready line the contract lacks (an old worker.py, a changed Blender)
    fails at start-up with the core's reason, its process gone."""
    blender = tmp_path / "blender"
    line = json.dumps({**json.loads(REAL_LINES[0]), "gpu_memory": 80})
    blender.write_text(f"#!/bin/sh\necho 'Blender 5.0.1 banner'\necho '{line}'\nexec sleep 60\n")
    blender.chmod(0o755)
    with pytest.raises(wc.WorkerError, match="gpu_memory"):
        wc.Worker(blender=str(blender), threads=1, timeout=30)


def test_the_requests_and_replies_have_generated_types() -> None:
    """_records.pyi types every request and reply from the contract's schemas (no
    hand-written TypedDict for them), each closed (`@final`: mypy narrows a reply by
    its key), and worker_client returns them."""
    text = stubgen.STUB.read_text()
    replies = ["Ready", "Loaded", "FrameDone", "Rendered", "Refused", "Probe"]
    assert f"WorkerReply = {' | '.join(replies)}" in text
    assert "WorkerRequest = WorkerRequestOf0 | WorkerRequestOf1 | WorkerRequestOf2" in text
    for name in replies:
        assert f"@final\nclass {name}(TypedDict):" in text, name
    source = (ROOT / "python" / "blurset" / "services" / "worker_client.py").read_text()
    assert "TypedDict, total=False" not in source and "_records.Loaded, " not in source
    for typed in ("-> _records.Loaded:", "-> _records.Rendered:", "-> _records.WorkerReply:",
                  "self.info: _records.Ready"):  # fmt: skip
        assert typed in source, typed
