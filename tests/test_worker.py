"""The Blender worker and its client: real bpy renders at tiny sizes (no mocks of bpy).

What a build relies on: the object is normalized (largest side 1, centred), frames are
scene-linear float RGBA EXR with a transparent background, each Cycles seed gives its own
noise and the same seed the same image, failures come back as one-line reasons, and a
hung or crashed worker costs one object, not the build.
"""

from __future__ import annotations

import importlib.util
import math
import os
import signal
import threading
from pathlib import Path

import numpy as np
import OpenEXR
import pytest
from blurset.exceptions import BlursetError
from blurset.services.demo import make_demo_objects
from blurset.services.worker_client import WORKER_SCRIPT, Worker, WorkerError, WorkerTimeout

from tests.conftest import shared, skip_or_fail_in_ci

pytestmark = pytest.mark.blender

FOV = 40.0

_spec = importlib.util.spec_from_file_location(
    "glb_inspect", WORKER_SCRIPT.parent / "glb_inspect.py"
)
glb_inspect = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(glb_inspect)


def look_at(phi_deg: float, theta_deg: float, dist: float) -> np.ndarray:
    """OpenGL camera-to-world (columns right, up, backwards, position) looking at 0, Z up."""
    p, t = math.radians(phi_deg), math.radians(theta_deg)
    pos = dist * np.array([math.sin(p) * math.cos(t), math.sin(p) * math.sin(t), math.cos(p)])
    back = pos / np.linalg.norm(pos)
    right = np.cross([0.0, 0.0, 1.0], back)
    right /= np.linalg.norm(right)
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = right, np.cross(back, right), back, pos
    return m


def fit_distance(bbox_dims) -> float:
    return 0.5 * float(np.linalg.norm(bbox_dims)) / math.sin(math.radians(FOV / 2)) * 1.05


def read_exr(path) -> np.ndarray:
    with OpenEXR.File(str(path)) as f:
        ch = f.channels()
        assert list(ch) == ["RGBA"], f"{path}: channels {list(ch)}"
        return np.asarray(ch["RGBA"].pixels)


def unpremultiplied(rgba: np.ndarray, min_alpha: float = 0.999) -> np.ndarray:
    """Colours of (nearly) opaque pixels."""
    m = rgba[..., 3] > min_alpha
    return rgba[m][:, :3] / rgba[m][:, 3:4]


@pytest.fixture(scope="module")
def worker():
    with Worker(threads=2, timeout=120) as w:
        yield w


@pytest.fixture(scope="module")
def demo_glbs(tmp_path_factory):
    return make_demo_objects(tmp_path_factory.mktemp("demo"), seed=0)


def test_demo_object_load_and_render(worker, demo_glbs, tmp_path):
    box = demo_glbs[0]
    info = worker.load(box, tmp_path / "v.npy")
    assert info["ok"] is True
    dims = np.array(info["bbox_dims"])
    assert abs(dims.max() - 1.0) < 1e-4
    np.testing.assert_allclose(dims, [1.0, 0.7, 0.5], atol=1e-4)  # the box's proportions
    assert info["n_triangles"] == 12 and info["unlit_fixed"] is False

    v = np.load(tmp_path / "v.npy")
    assert v.dtype == np.float32 and v.shape == (info["n_vertices"], 3)
    lo, hi = v.min(axis=0), v.max(axis=0)
    np.testing.assert_allclose((lo + hi) / 2, 0.0, atol=1e-4)
    assert abs((hi - lo).max() - 1.0) < 1e-4

    c2w = look_at(60.0, 30.0, fit_distance(dims))
    frames = [
        {"c2w": c2w, "seed": s, "out": tmp_path / f"f{k}.exr"} for k, s in enumerate((7, 7, 8))
    ]
    seen = []
    worker.render(frames, resolution=48, fov_deg=FOV, samples=4, on_frame=lambda *a: seen.append(a))
    # No region: whole images, so no origin.
    assert seen == [(k, str(f["out"]), None) for k, f in enumerate(frames)]
    a, b, c = (read_exr(f["out"]) for f in frames)
    assert a.dtype == np.float32 and a.shape == (48, 48, 4)
    assert np.all(np.isfinite(a))
    for corner in (a[0, 0], a[0, -1], a[-1, 0], a[-1, -1]):
        assert corner[3] == 0.0
    assert a[24, 24, 3] > 0.99
    assert a[..., :3].max() > 0.05  # lit and textured, not black
    assert np.array_equal(a, b), "same Cycles seed must give the identical image"
    assert not np.array_equal(a, c), "a different seed must give different noise"
    # Same camera: the noise differs, the picture does not.
    assert abs(float(a[..., 3].mean()) - float(c[..., 3].mean())) < 0.02
    # No temporary file left next to the frames.
    assert sorted(p.name for p in tmp_path.iterdir()) == ["f0.exr", "f1.exr", "f2.exr", "v.npy"]


def test_camera_convention_is_opengl_c2w(worker, demo_glbs, tmp_path):
    """The matrix is assigned as is: a camera on +X looking at the origin sees the object
    centred; shifting the camera right (its +X column) moves the object left in the image."""
    info = worker.load(demo_glbs[1], tmp_path / "v.npy")
    d = fit_distance(info["bbox_dims"])
    c2w = look_at(90.0, 0.0, d)
    shifted = c2w.copy()
    shifted[:3, 3] += 0.3 * c2w[:3, 0]
    frames = [
        {"c2w": m, "seed": 0, "out": tmp_path / f"c{k}.exr"} for k, m in enumerate((c2w, shifted))
    ]
    worker.render(frames, resolution=48, fov_deg=FOV, samples=2)
    cols = []
    for f in frames:
        alpha = read_exr(f["out"])[..., 3]
        xs = np.arange(alpha.shape[1])
        cols.append(float((alpha.sum(axis=0) * xs).sum() / alpha.sum()))
    assert abs(cols[0] - 23.5) < 1.5  # centred
    assert cols[1] < cols[0] - 3  # object moved left


@pytest.mark.parametrize(
    "name",
    [
        "khronos_BoxTextured.glb",
        "khronos_2CylinderEngine.glb",
        "sketchfab_MapPin.glb",
        "WaterBottle_blender_reexport.glb",
        "sketchfab_MazdaRX7Stylised.glb",
        "edge_BoxTextured_draco.glb",
    ],
)
def test_shared_glb_loads_normalized_or_fails_clearly(worker, tmp_path, name):
    glb = shared("glb", name)
    try:
        info = worker.load(glb, tmp_path / "v.npy")
    except WorkerError as e:
        # Only the Draco file may fail, and only for want of a decoder.
        assert "draco" in name and "Draco" in str(e), str(e)
        return
    dims = np.array(info["bbox_dims"])
    assert abs(dims.max() - 1.0) < 1e-4
    v = np.load(tmp_path / "v.npy")
    np.testing.assert_allclose((v.min(0) + v.max(0)) / 2, 0.0, atol=1e-4)
    np.testing.assert_allclose(v.max(0) - v.min(0), dims, atol=1e-4)
    assert info["n_triangles"] > 0 and info["scale"] > 0 and len(info["center"]) == 3
    assert min(q.coverage for q in worker.object_qa) > 0.01


def test_draco_box_decodes_to_the_same_mesh(worker, tmp_path):
    draco, plain = (
        shared("glb", "edge_BoxTextured_draco.glb"),
        shared("glb", "khronos_BoxTextured.glb"),
    )
    try:
        info = worker.load(draco, tmp_path / "d.npy")
    except WorkerError as e:
        assert "Draco" in str(e) and "#2184" in str(e)
        skip_or_fail_in_ci(f"this bpy has no Draco decoder: {e}")
    assert any("Draco" in w for w in info["warnings"])
    worker.load(plain, tmp_path / "p.npy")
    d, p = np.load(tmp_path / "d.npy"), np.load(tmp_path / "p.npy")
    key = lambda a: a[np.lexsort(np.round(a, 4).T)]  # noqa: E731
    np.testing.assert_allclose(key(np.unique(d, axis=0)), key(np.unique(p, axis=0)), atol=1e-3)


def _rewrite(src: Path, dst: Path, edit) -> Path:
    doc, binary = glb_inspect.read_glb(str(src))
    edit(doc)
    glb_inspect.write_glb(str(dst), doc, binary)
    return dst


def test_meshopt_fails_up_front_naming_the_compression(worker, tmp_path):
    def edit(doc):
        doc["extensionsUsed"] = ["EXT_meshopt_compression"]
        doc["extensionsRequired"] = ["EXT_meshopt_compression"]

    glb = _rewrite(shared("glb", "khronos_BoxTextured.glb"), tmp_path / "meshopt.glb", edit)
    with pytest.raises(WorkerError, match="meshopt"):
        worker.load(glb, tmp_path / "v.npy")
    assert not (tmp_path / "v.npy").exists()


def test_mazda_unlit_renders_its_colours(worker, tmp_path):
    """Sketchfab unlit: black base colour, colour in emissiveFactor. Blender alone renders
    it black; the worker must show the car's colours (lit by our fixed lights)."""
    info = worker.load(shared("glb", "sketchfab_MazdaRX7Stylised.glb"), tmp_path / "v.npy")
    assert info["unlit_fixed"] is True
    assert min(q.luminance for q in worker.object_qa) > 0.1
    c2w = look_at(60.0, 200.0, fit_distance(info["bbox_dims"]))
    out = tmp_path / "mazda.exr"
    worker.render([{"c2w": c2w, "seed": 1, "out": out}], resolution=64, fov_deg=FOV, samples=8)
    rgb = unpremultiplied(read_exr(out))
    lum = rgb @ [0.2126, 0.7152, 0.0722]
    assert lum.mean() > 0.2, f"mean luminance {lum.mean()}"
    chroma = rgb.max(axis=1) - rgb.min(axis=1)
    assert (chroma > 0.1).sum() >= 5, "expected coloured (not only grey) pixels"


def test_exr_is_scene_linear(worker, tmp_path):
    """In emission mode an unlit surface's pixels equal its glTF colour exactly: the EXR
    holds scene-linear values, no view transform (sRGB would turn 0.0588 into 0.27)."""
    glb = shared("glb", "sketchfab_MazdaRX7Stylised.glb")
    info = worker.load(glb, tmp_path / "v.npy", unlit="emission")
    doc, _ = glb_inspect.read_glb(str(glb))
    targets = np.array([m["emissiveFactor"] for m in doc["materials"]])
    c2w = look_at(60.0, 30.0, fit_distance(info["bbox_dims"]))
    out = tmp_path / "m.exr"
    worker.render([{"c2w": c2w, "seed": 3, "out": out}], resolution=64, fov_deg=FOV, samples=4)
    rgb = unpremultiplied(read_exr(out))
    nearest = np.abs(rgb[:, None, :] - targets[None]).max(axis=2).min(axis=1)
    assert (nearest < 2e-3).mean() > 0.6, "most opaque pixels should equal an emissive colour"


def test_black_object_fails_render_qa(worker, tmp_path):
    def edit(doc):
        doc["extensionsUsed"] = ["KHR_materials_unlit"]
        for m in doc["materials"]:
            m["extensions"] = {"KHR_materials_unlit": {}}
            m["pbrMetallicRoughness"] = {"baseColorFactor": [0, 0, 0, 1]}
            m["emissiveFactor"] = [0, 0, 0]

    glb = _rewrite(shared("glb", "khronos_BoxTextured.glb"), tmp_path / "black.glb", edit)
    with pytest.raises(WorkerError, match="render QA: object renders black"):
        worker.load(glb, tmp_path / "v.npy", unlit="emission")


def test_invisible_object_fails_render_qa(worker, tmp_path):
    def edit(doc):
        for m in doc["materials"]:
            m["alphaMode"] = "BLEND"
            m["pbrMetallicRoughness"] = {"baseColorFactor": [1, 1, 1, 0]}

    glb = _rewrite(shared("glb", "khronos_BoxTextured.glb"), tmp_path / "ghost.glb", edit)
    with pytest.raises(WorkerError, match="render QA: object is invisible"):
        worker.load(glb, tmp_path / "v.npy")


def test_bad_inputs_give_clear_errors_and_the_worker_survives(worker, tmp_path):
    pid = worker.info["pid"]
    missing = tmp_path / "nope.glb"
    with pytest.raises(WorkerError, match=r"model file not found: .*nope\.glb"):
        worker.load(missing, tmp_path / "v.npy")
    text = tmp_path / "text.glb"
    text.write_text("hello")
    with pytest.raises(WorkerError, match="not a binary glTF"):
        worker.load(text, tmp_path / "v.npy")
    # A render after a failed load has no object to render.
    with pytest.raises(WorkerError, match="render before a successful load"):
        worker.render(
            [{"c2w": np.eye(4), "seed": 0, "out": tmp_path / "x.exr"}],
            resolution=16,
            fov_deg=FOV,
            samples=1,
        )
    assert isinstance(WorkerError("x"), BlursetError)
    assert worker.alive and worker.info["pid"] == pid


def test_bad_render_arguments_are_reported(worker, demo_glbs, tmp_path):
    worker.load(demo_glbs[0], tmp_path / "v.npy")
    with pytest.raises(WorkerError, match="c2w must be a finite 4x4"):
        worker.render(
            [{"c2w": np.full((4, 4), np.nan), "seed": 0, "out": tmp_path / "x.exr"}],
            resolution=16,
            fov_deg=FOV,
            samples=1,
        )
    with pytest.raises(WorkerError, match="fov_deg"):
        worker.render(
            [{"c2w": np.eye(4), "seed": 0, "out": tmp_path / "x.exr"}],
            resolution=16,
            fov_deg=0.0,
            samples=1,
        )
    assert not (tmp_path / "x.exr").exists()


def _pid_gone(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return True
    return False


def test_timeout_kills_the_worker_and_the_next_object_gets_a_new_one(demo_glbs, tmp_path):
    with Worker(threads=1, timeout=120, log_path=tmp_path / "w.log") as w:
        w.load(demo_glbs[0], tmp_path / "v.npy")
        pid = w.info["pid"]
        w.timeout = 0.5
        c2w = look_at(60.0, 30.0, 2.5)
        with pytest.raises(WorkerTimeout, match="did not reply within 0.5 s"):
            w.render(
                [{"c2w": c2w, "seed": 0, "out": tmp_path / "slow.exr"}],
                resolution=96,
                fov_deg=FOV,
                samples=100_000,
            )
        assert not w.alive and _pid_gone(pid)
        w.timeout = 120
        info = w.load(demo_glbs[1], tmp_path / "v.npy")
        assert info["ok"] and w.info["pid"] != pid


def test_crash_raises_worker_error_with_stderr_tail(demo_glbs, tmp_path):
    log = tmp_path / "w.log"
    with Worker(threads=1, timeout=120, log_path=log) as w:
        w.load(demo_glbs[0], tmp_path / "v.npy")
        pid = w.info["pid"]
        killer = threading.Timer(1.0, os.kill, (pid, signal.SIGKILL))
        killer.start()
        try:
            with pytest.raises(WorkerError, match=r"exited with code -9; last stderr: .+") as e:
                w.render(
                    [{"c2w": look_at(60.0, 30.0, 2.5), "seed": 0, "out": tmp_path / "x.exr"}],
                    resolution=96,
                    fov_deg=FOV,
                    samples=100_000,
                )
        finally:
            killer.cancel()
        assert "\n" not in str(e.value)
        assert not isinstance(e.value, WorkerTimeout)
    assert log.stat().st_size > 0  # the caller's log is kept


def test_missing_blender_binary_is_a_clear_error(tmp_path):
    with pytest.raises(WorkerError, match="cannot start Blender worker .*no-such-blender"):
        Worker(blender=str(tmp_path / "no-such-blender"))


def test_failing_on_frame_callback_does_not_desync_the_protocol(worker, demo_glbs, tmp_path):
    info = worker.load(demo_glbs[0], tmp_path / "v.npy")
    c2w = look_at(60.0, 30.0, fit_distance(info["bbox_dims"]))
    frames = [{"c2w": c2w, "seed": k, "out": tmp_path / f"f{k}.exr"} for k in range(3)]

    def boom(i, out, origin):
        raise RuntimeError("callback failed")

    with pytest.raises(RuntimeError, match="callback failed"):
        worker.render(frames, resolution=16, fov_deg=FOV, samples=1, on_frame=boom)
    # The next command gets its own reply, not a stale frame message.
    again = worker.load(demo_glbs[2], tmp_path / "v2.npy")
    assert again["ok"] and again["n_triangles"] > 12
