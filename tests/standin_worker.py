"""A stand-in for the Blender worker, for the fast test layer: it speaks the worker's
protocol (blender_scripts/worker.py) and writes analytic linear EXRs instead of Cycles
renders, so the whole orchestration of `blurset build` (objects, locks, resume, splits,
failures, publish, export, verify) runs in seconds without bpy. The render tests keep
the real worker.

Started as a "Blender binary" (`blurset build --blender <wrapper>`, see
`tests/conftest.py::standin_blender`): it ignores Blender's own arguments and reads ours
after "--". A GLB's box comes from its POSITION accessors' min/max (glTF JSON), centred
and scaled so its largest side is 1, as the real worker normalizes. A render casts one
ray per pixel at that box: each face a colour of its own, shaded by a checker in face
coordinates (detail for the QA and for COLMAP-free checks), alpha 1 on the box and 0
elsewhere; a frame's sample count and seed do not change it. Regions and crops follow
the real worker's rules: pixels outside a region are 0, a crop writes only the region.

BLURSET_STANDIN_FAULT="hang:S" or "crash:S" makes the load of a GLB whose path
contains S hang or die (SIGKILL), as the real worker's fault injection does;
"hang_render:S" loads it, renders its QA and sharp views, and hangs at its first render
of a blur level (a setting half-written).

BLURSET_STANDIN_CUDA="sm_90" makes it report a GPU of that arch whose kernels Blender does
not ship ("cuda" in its ready reply, as the real worker on CUDA or OptiX), and at its
first render it does what the driver's compile leaves: a file in $CUDA_CACHE_PATH.
"""

from __future__ import annotations

import json
import math
import os
import signal
import struct
import sys
import time

import numpy as np


def _die_with_parent() -> None:
    """SIGKILL this process when its parent dies, as the real worker does: a killed build
    leaves no stand-in behind (PR_SET_PDEATHSIG)."""
    if not sys.platform.startswith("linux"):
        return
    import ctypes

    parent = os.getppid()
    ctypes.CDLL(None, use_errno=True).prctl(1, int(signal.SIGKILL), 0, 0, 0)
    if os.getppid() != parent:
        os._exit(1)


_die_with_parent()
# The protocol stream is the process's stdout; nothing else may print on it.
PROTO = os.fdopen(os.dup(1), "w", buffering=1, encoding="utf-8")
os.dup2(2, 1)
sys.stdout = sys.stderr

from blurset.image import Accumulator  # noqa: E402

FACE_COLOURS = np.array(
    [
        [0.8, 0.2, 0.1],
        [0.1, 0.6, 0.2],
        [0.2, 0.3, 0.8],
        [0.8, 0.7, 0.1],
        [0.6, 0.1, 0.6],
        [0.1, 0.7, 0.7],
    ],
    dtype=np.float32,
)


def send(msg: dict) -> None:
    PROTO.write(json.dumps(msg) + "\n")
    PROTO.flush()


def glb_box(path: str) -> tuple[np.ndarray, np.ndarray, int]:
    """(min, max) of the POSITION accessors of a GLB or glTF, and their vertex count."""
    with open(path, "rb") as f:
        data = f.read()
    if data[:4] == b"glTF":
        (length,) = struct.unpack_from("<I", data, 12)
        doc = json.loads(data[20 : 20 + length])
    else:
        doc = json.loads(data)
    lo, hi, n = np.full(3, np.inf), np.full(3, -np.inf), 0
    accessors = doc.get("accessors", [])
    for mesh in doc.get("meshes", []):
        for prim in mesh.get("primitives", []):
            a = accessors[prim["attributes"]["POSITION"]]
            lo = np.minimum(lo, a["min"])
            hi = np.maximum(hi, a["max"])
            n += int(a["count"])
    if n == 0:
        raise ValueError("no mesh in the file")
    return lo, hi, n


class StandIn:
    def __init__(self) -> None:
        self.half: np.ndarray | None = None
        self.hang_blur = False
        self.compiled = False

    def load(self, cmd: dict) -> dict:
        glb = str(cmd["glb"])
        fault = os.environ.get("BLURSET_STANDIN_FAULT", "")
        kind, _, needle = fault.partition(":")
        self.hang_blur = kind == "hang_render" and bool(needle) and needle in glb
        if needle and needle in glb:
            if kind == "hang":
                while True:
                    time.sleep(3600)
            if kind == "crash":
                os.kill(os.getpid(), signal.SIGKILL)
        try:
            lo, hi, n = glb_box(glb)
        except (OSError, ValueError, KeyError, IndexError) as e:
            return {"ok": False, "reason": f"stand-in cannot read the model: {e}"}
        dims = hi - lo
        scale = 1.0 / float(dims.max())
        self.half = dims * scale / 2
        corners = np.array(
            [[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], dtype=np.float32
        ) * self.half.astype(np.float32)
        os.makedirs(os.path.dirname(cmd["vertices_out"]) or ".", exist_ok=True)
        np.save(cmd["vertices_out"], corners)
        return {
            "ok": True,
            "bbox_dims": (dims * scale).tolist(),
            "n_vertices": n,
            "n_triangles": max(1, n // 3),
            "scale": scale,
            "center": ((lo + hi) / 2).tolist(),
            "warnings": [],
            "unlit_fixed": False,
            # The real worker's report for an opaque, lit object (no transmission or
            # transparent bounces under auto).
            "light_paths": {
                "mode": cmd.get("light_paths", "auto"),
                "transmission": False,
                "transparency": False,
                "unlit_only": False,
                "bounces": {
                    "max_bounces": 6,
                    "diffuse_bounces": 2,
                    "glossy_bounces": 2,
                    "transmission_bounces": 0 if cmd.get("light_paths", "auto") == "auto" else 4,
                    "volume_bounces": 0,
                    "transparent_max_bounces": 0 if cmd.get("light_paths", "auto") == "auto" else 8,
                },
            },
            "device": {"backend": "CPU", "devices": ["stand-in"], "kernel": "analytic"},
            "seconds": 0.0,
        }

    def image(self, c2w: list[list[float]], res: int, fov_deg: float) -> np.ndarray:
        """RGBA (premultiplied, linear) of the box seen from the OpenGL camera `c2w`."""
        assert self.half is not None
        m = np.asarray(c2w, dtype=np.float64)
        t = math.tan(math.radians(fov_deg) / 2)
        px = (np.arange(res) + 0.5) / res * 2 - 1
        x, y = np.meshgrid(px * t, -px * t)
        d_cam = np.stack([x, y, -np.ones_like(x)], axis=-1)
        d = d_cam @ m[:3, :3].T
        o = m[:3, 3]
        with np.errstate(divide="ignore", invalid="ignore"):
            t0 = (-self.half - o) / d
            t1 = (self.half - o) / d
        tmin = np.nanmax(np.minimum(t0, t1), axis=-1)
        tmax = np.nanmin(np.maximum(t0, t1), axis=-1)
        hit = (tmax >= tmin) & (tmax > 0)
        p = o + d * tmin[..., None]
        rel = p / self.half
        axis = np.argmax(np.abs(rel), axis=-1)
        face = axis * 2 + (np.take_along_axis(rel, axis[..., None], -1)[..., 0] > 0)
        uv = np.floor((rel + 1) * 4).sum(axis=-1) % 2
        rgb = FACE_COLOURS[face] * (0.6 + 0.4 * uv[..., None]).astype(np.float32)
        out = np.zeros((res, res, 4), dtype=np.float32)
        out[hit, :3] = rgb[hit]
        out[hit, 3] = 1.0
        return out

    def geometry(self, c2w: list[list[float]], res: int, fov_deg: float) -> dict:
        """Depth (along the viewing axis; Cycles' 1e10 where nothing is hit) and world
        normal of the box at each pixel centre, as the channels of a multi-layer EXR
        holding Cycles' Depth and Normal passes (set_passes(geometry=True))."""
        assert self.half is not None
        m = np.asarray(c2w, dtype=np.float64)
        t = math.tan(math.radians(fov_deg) / 2)
        px = (np.arange(res) + 0.5) / res * 2 - 1
        x, y = np.meshgrid(px * t, -px * t)
        d = np.stack([x, y, -np.ones_like(x)], axis=-1) @ m[:3, :3].T
        o = m[:3, 3]
        with np.errstate(divide="ignore", invalid="ignore"):
            t0, t1 = (-self.half - o) / d, (self.half - o) / d
        tmin = np.nanmax(np.minimum(t0, t1), axis=-1)
        tmax = np.nanmin(np.maximum(t0, t1), axis=-1)
        hit = (tmax >= tmin) & (tmax > 0)
        rel = (o + d * tmin[..., None]) / self.half
        axis = np.argmax(np.abs(rel), axis=-1)
        normal = np.zeros((res, res, 3), dtype=np.float32)
        sign = np.sign(np.take_along_axis(rel, axis[..., None], -1)[..., 0])
        np.put_along_axis(normal, axis[..., None], sign[..., None].astype(np.float32), -1)
        normal[~hit] = 0.0
        # The camera ray's direction has z = -1 in the camera frame: its parameter at the
        # hit is the depth along the viewing axis.
        depth = np.where(hit, tmin, 1e10).astype(np.float32)
        alpha = hit.astype(np.float32)
        chans = {"ViewLayer.Depth.Z": depth, "ViewLayer.Combined.A": alpha}
        for k, c in enumerate("XYZ"):
            chans[f"ViewLayer.Normal.{c}"] = np.ascontiguousarray(normal[..., k])
        return chans

    def render(self, cmd: dict) -> dict:
        if self.half is None:
            return {"ok": False, "reason": "render before a successful load"}
        res, fov = int(cmd["resolution"]), float(cmd["fov_deg"])
        crop = bool(cmd.get("crop", False))
        frames = cmd["frames"]
        if self.hang_blur and any(str(f.get("level", "")).startswith("blur") for f in frames):
            while True:
                time.sleep(3600)
        arch = os.environ.get("BLURSET_STANDIN_CUDA")
        if arch and not self.compiled:
            # What the driver's JIT leaves in the cache the worker was given.
            cache = os.environ["CUDA_CACHE_PATH"]
            os.makedirs(cache, exist_ok=True)
            with open(os.path.join(cache, f"standin-{arch}.jit"), "a") as f:
                f.write(f"{os.getpid()}\n")
            self.compiled = True
        calls: set = set()
        for i, fr in enumerate(frames):
            t_start = time.perf_counter()
            if cmd.get("geometry"):
                import OpenEXR

                os.makedirs(os.path.dirname(fr["out"]) or ".", exist_ok=True)
                OpenEXR.File({}, self.geometry(fr["c2w"], res, fov)).write(fr["out"])
                calls.add((fr.get("view"), fr.get("level"), i))
                send({"frame": i, "out": fr["out"], "seconds": 0.0, "origin": None})
                continue
            img = self.image(fr["c2w"], res, fov)
            region = None if fr.get("motion") else fr.get("region")
            origin = None
            if region is not None:
                x0, y0, x1, y1 = (int(v) for v in region)
                inside = np.zeros_like(img)
                inside[y0:y1, x0:x1] = img[y0:y1, x0:x1]
                img = inside
                if crop:
                    img = img[y0:y1, x0:x1]
                    origin = [x0, y0]
            acc = Accumulator(img.shape[1], img.shape[0])
            acc.add(np.ascontiguousarray(img))
            os.makedirs(os.path.dirname(fr["out"]) or ".", exist_ok=True)
            acc.write_exr(fr["out"])
            calls.add(fr.get("call", (fr.get("view"), fr.get("level"), i)))
            send(
                {
                    "frame": i,
                    "out": fr["out"],
                    "seconds": time.perf_counter() - t_start,
                    "origin": origin,
                }
            )
        return {"ok": True, "done": len(frames), "jobs": len(calls)}


def main() -> int:
    argv = sys.argv[sys.argv.index("--") + 1 :] if "--" in sys.argv else sys.argv[1:]
    if "--probe" in argv:
        send({"ok": True, "devices": {"CPU": ["stand-in"]}, "blender": "stand-in"})
        return 0
    ready = {
        "ok": True,
        "ready": True,
        "blender": "stand-in",
        "blender_version": "stand-in",
        "device": {"backend": "CPU", "devices": ["stand-in"], "kernel": "analytic"},
        "pid": os.getpid(),
    }
    arch = os.environ.get("BLURSET_STANDIN_CUDA")
    if arch:
        ready["cuda"] = {"archs": [arch], "kernels": ["sm_86", "sm_89"], "driver": 13000}
    send(ready)
    worker = StandIn()
    for line in sys.stdin:
        line = line.strip()
        if not line:
            continue
        try:
            cmd = json.loads(line)
            name = cmd.get("cmd")
            if name == "quit":
                return 0
            if name == "load":
                reply = worker.load(cmd)
            elif name == "render":
                reply = worker.render(cmd)
            else:
                reply = {"ok": False, "reason": f"unknown command {name!r}"}
        except Exception as e:  # one line back, as the real worker does
            reply = {"ok": False, "reason": f"{type(e).__name__}: {e}"}
        send(reply)
    return 0


if __name__ == "__main__":
    sys.exit(main())
