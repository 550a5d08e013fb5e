"""blurset Blender worker: one process renders one object at a time, driven over JSON lines.

Start with the venv's bpy:   python blender_scripts/worker.py --threads N [--workdir D]
                                [--device CPU|OPTIX|CUDA|HIP|ONEAPI|METAL] [--gpus 0,2]
or a Blender binary:        blender -b --factory-startup --disable-autoexec \
                                --python-exit-code 1 -P blender_scripts/worker.py -- --threads N
`--probe` prints {"ok":true,"devices":{backend: [device names]},"blender":version} and exits:
the build asks it which devices exist before it writes anything.
`--device`/`--gpus` pick the Cycles backend and its devices (indices into that backend's
list; default all); every object's scene renders on them.

--workdir D keeps the worker's scratch files (rewritten GLBs, QA renders) under D, so a
killed build leaves them where the next run cleans up, not in /tmp.

stdin: one JSON command per line. Replies: one JSON object per line on the process's
original stdout, which this script takes over privately at start-up; fd 1 then points at
stderr so Blender's C-level prints ("Fra:", "Saved:") cannot corrupt the protocol.
The contract is typed once, in the core (rust/core/src/dataset/wire.rs): its schemas are
schemas/worker/request.schema.json and reply.schema.json, and tests/test_worker_contract.py
checks every line this worker and the tests' stand-in exchange against them. Below, the
same in short.

  {"cmd":"load","glb":P,"vertices_out":NPY[,"unlit":"lit"|"emission"]
   [,"light_paths":"auto"|"fixed"]}
      -> {"ok":true,"bbox_dims":[..],"n_vertices":N,"n_triangles":T,"scale":s,
          "center":[..],"warnings":[..],"unlit_fixed":b,"light_paths":{..},
          "device":{"backend":..,"devices":[..],"kernel":..}, ...} | {"ok":false,"reason":..}
  {"cmd":"render","resolution":R,"fov_deg":F,"samples":S[,"exr_codec":"NONE"|"ZIP"|...]
   [,"noise_threshold":T][,"batch":true][,"crop":true][,"guides":true][,"geometry":true],
   "frames":[{"c2w":[[4x4 row-major]],"seed":I,"out":EXR[,"samples":S_i]
              [,"sample_offset":O,"sample_sequence":Q]
              [,"motion":{"steps":n,"keys":[c2w, ...]}][,"region":[x0,y0,x1,y1]]
              [,"dof":{"focus_distance":s,"aperture_radius":R}][,"rolling_shutter":true]
              [,"call":C][,"view":V,"level":L]}, ...]}
      -> {"frame":i,"out":EXR,"seconds":t,"origin":[x0,y0]|null} per frame, then
         {"ok":true,"done":n,"jobs":j}
      A frame's "samples" overrides S; with "sample_offset" it renders the samples
      [O, O + S_i) of a Q-sample sequence (Cycles sample subsets). A frame with "motion" is
      one Cycles motion blur render along its 2^n + 1 keys (blender_scene.render_motion_blur),
      with "rolling_shutter": true through Cycles' rolling shutter (rows top to bottom).
      A frame with "dof" renders through a thin lens focused at s with an aperture of
      radius R (blender_scene.set_dof); without it, the pinhole camera.
      "noise_threshold" turns Cycles adaptive sampling on for this command (off without).
      "guides" writes every EXR of this command as a multi-layer EXR with Cycles'
      denoising guide passes (albedo, normal) beside the combined RGBA (off without).
      "geometry" writes every EXR of this command as a multi-layer EXR with the Depth and
      Normal data passes of the surface each pixel's centre sees (one sample per pixel at
      its centre: send "samples":1; blender_scene.set_passes).
      "region" (the core's plan/region.rs) restricts Cycles to the pixels that can see
      the object; the pixels are those of a whole render. With "crop", a frame rendered
      in a region writes only that region's pixels (those of the whole render, bit for
      bit), and its reply's "origin" says where they sit (null: a whole image). Runs of frames of one render
      "call" (without it: of one "view" and "level") and without "motion" render as one
      animation job each, in their regions together (blender_scene.render_job), unless
      "batch" is false or the object is animated; "jobs" counts the render operator calls.
  {"cmd":"quit"} -> exit 0

At start-up the worker announces itself with
{"ok":true,"ready":true,"blender":version,"blender_version":version,"pid":pid,
 "device":{..}[,"cuda":{"archs":["sm_90",..],"kernels":["sm_89",..]}]}: "cuda" (CUDA and
OptiX only) gives the compute capabilities of the GPUs it sees and the archs Cycles ships
kernels for, so the driver can say when the first frame will wait for a compile.

Fault injection, for the reliability tests only (a real hang or crash of this process,
nothing simulated downstream): BLURSET_WORKER_FAULT="hang:S" makes the load of a GLB
whose path contains S never return; "crash:S" kills the process with SIGKILL there;
"crash_once:S:FLAG" does so only while the file FLAG does not exist (and creates it),
a transient failure that a retry survives.
"""

from __future__ import annotations

import os
import sys


def _take_over_stdout():
    """A private text stream on the original stdout; fd 1 and sys.stdout go to stderr."""
    sys.stdout.flush()
    proto = os.fdopen(os.dup(1), "w", buffering=1, encoding="utf-8")
    os.dup2(2, 1)
    sys.stdout = sys.stderr
    return proto


def _die_with_parent() -> None:
    """Ask Linux to SIGKILL this process when the process that started it dies, so a
    killed build (SIGKILL, a crash) never leaves Blender rendering on under PID 1."""
    if not sys.platform.startswith("linux"):
        return
    try:
        import ctypes
        import signal as _signal

        parent = os.getppid()
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(1, int(_signal.SIGKILL), 0, 0, 0)  # PR_SET_PDEATHSIG
        if os.getppid() != parent:  # the parent died before prctl took effect
            os._exit(1)
    except (OSError, AttributeError):
        pass


_die_with_parent()
PROTO = _take_over_stdout()
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

import json  # noqa: E402
import shutil  # noqa: E402
import signal  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
import traceback  # noqa: E402

import blender_scene  # noqa: E402
import bpy  # noqa: E402
import numpy as np  # noqa: E402


def send(msg: dict) -> None:
    PROTO.write(json.dumps(msg) + "\n")
    PROTO.flush()


def one_line(e: BaseException) -> str:
    text = " ".join(str(e).split()) or type(e).__name__
    return f"{type(e).__name__}: {text}"[:500]


def parse_args(argv: list[str]) -> dict:
    """--threads, --workdir, --device, --gpus, --probe from our part of argv (after "--"
    under a Blender binary)."""
    args = argv[argv.index("--") + 1 :] if "--" in argv else argv[1:]
    out: dict = {"threads": 0, "workdir": None, "device": "CPU", "gpus": None, "probe": False}
    for i, a in enumerate(args):
        key, _, val = a.partition("=")
        if not val and i + 1 < len(args):
            val = args[i + 1]
        if key == "--threads":
            out["threads"] = int(val)
        elif key == "--workdir":
            out["workdir"] = val
        elif key == "--device":
            out["device"] = val.upper()
        elif key == "--gpus":
            out["gpus"] = [int(x) for x in val.split(",") if x.strip()]
        elif key == "--probe":
            out["probe"] = True
    return out


def inject_fault(glb: str) -> None:
    """See the module docstring: a real hang or crash, for the reliability tests."""
    spec = os.environ.get("BLURSET_WORKER_FAULT", "")
    kind, _, rest = spec.partition(":")
    needle, _, flag = rest.partition(":")
    if not needle or needle not in glb:
        return
    if kind == "hang":
        while True:
            time.sleep(3600)
    if kind == "crash" or (kind == "crash_once" and flag and not os.path.exists(flag)):
        if flag:
            open(flag, "w").close()
        os.kill(os.getpid(), signal.SIGKILL)


def _call_of(frame: dict):
    """Which render call a frame belongs to: its plan's "call" (the core's
    plan/region.rs splits an image's frames into calls), else its image."""
    if frame.get("call") is not None:
        return ("call", frame["call"])
    return frame.get("view"), frame.get("level")


def save_npy_atomic(path: str, arr: np.ndarray) -> None:
    os.makedirs(os.path.dirname(os.path.abspath(path)) or ".", exist_ok=True)
    tmp = f"{path}.part"
    with open(tmp, "wb") as f:
        np.save(f, arr)
    os.replace(tmp, path)


class Worker:
    def __init__(self, threads: int, workdir: str | None, device: str, gpus: list[int] | None):
        self.threads = threads
        self.device = (device, gpus)
        self.loaded = False
        self.animated = False
        if workdir:
            os.makedirs(workdir, exist_ok=True)
        self.workdir = tempfile.mkdtemp(prefix="blurset-worker-", dir=workdir)

    def load(self, cmd: dict) -> dict:
        self.loaded = False
        glb = str(cmd["glb"])
        vertices_out = str(cmd["vertices_out"])
        unlit = str(cmd.get("unlit", "lit"))
        t0 = time.perf_counter()
        inject_fault(glb)
        try:
            warnings, unlit_fixed, doc = blender_scene.import_glb(glb, self.workdir, unlit)
            info = blender_scene.normalize(warnings)
            blender_scene.setup_scene(self.threads)
            # Preferences are reset with the factory scene: the device goes on every load.
            device = blender_scene.use_device(*self.device)
            light_paths = blender_scene.set_light_paths(doc, str(cmd.get("light_paths", "auto")))
        except blender_scene.LoadError as e:
            return {"ok": False, "reason": str(e)}
        save_npy_atomic(vertices_out, info.pop("vertices"))
        self.animated = blender_scene.scene_is_animated()
        self.loaded = True
        return {
            "ok": True,
            **info,
            "warnings": warnings,
            "unlit_fixed": unlit_fixed,
            "light_paths": light_paths,
            "device": device,
            "seconds": time.perf_counter() - t0,
        }

    def render(self, cmd: dict) -> dict:
        if not self.loaded:
            return {"ok": False, "reason": "render before a successful load"}
        frames = cmd["frames"]
        res, fov, samples = int(cmd["resolution"]), float(cmd["fov_deg"]), int(cmd["samples"])
        if "exr_codec" in cmd:
            blender_scene.set_exr_codec(str(cmd["exr_codec"]))
        blender_scene.set_noise_threshold(cmd.get("noise_threshold"))
        blender_scene.set_passes(bool(cmd.get("guides", False)), bool(cmd.get("geometry", False)))
        batch = bool(cmd.get("batch", True)) and not self.animated
        crop = bool(cmd.get("crop", False))
        jobs = 0
        i = 0
        while i < len(frames):
            fr = frames[i]
            motion = fr.get("motion")
            if batch and not motion:
                # One job per render call: its frames share one region.
                j = i
                while (
                    j < len(frames)
                    and not frames[j].get("motion")
                    and _call_of(frames[j]) == _call_of(fr)
                ):
                    j += 1

                def sent(k: int, out: str, secs: float, origin, base: int = i) -> None:
                    send({"frame": base + k, "out": out, "seconds": secs, "origin": origin})

                blender_scene.render_job(frames[i:j], res, fov, samples, sent, crop)
                jobs += 1
                i = j
                continue
            blender_scene.apply_frame(fr, res, fov, samples)
            origin = blender_scene.set_region(None if motion else fr.get("region"), res, crop)
            if motion:
                secs = blender_scene.render_motion_blur(
                    motion["keys"],
                    int(motion["steps"]),
                    str(fr["out"]),
                    int(fr["seed"]),
                    rolling=bool(fr.get("rolling_shutter", False)),
                )
            else:
                secs = blender_scene.render_frame(str(fr["out"]), int(fr["seed"]))
            send({"frame": i, "out": str(fr["out"]), "seconds": secs, "origin": origin})
            jobs += 1
            i += 1
        return {"ok": True, "done": len(frames), "jobs": jobs}

    def close(self) -> None:
        shutil.rmtree(self.workdir, ignore_errors=True)


def main() -> int:
    args = parse_args(sys.argv)
    version = bpy.app.version_string
    if args["probe"]:
        send({"ok": True, "devices": blender_scene.list_devices(), "blender": version})
        return 0
    worker = Worker(args["threads"], args["workdir"], args["device"], args["gpus"])
    try:
        # The device is checked here, before any object: a bad one fails the start.
        device = blender_scene.use_device(args["device"], args["gpus"])
    except ValueError as e:
        send({"ok": False, "reason": one_line(e)})
        worker.close()
        return 2
    ready = {
        "ok": True,
        "ready": True,
        "blender": version,
        "blender_version": version,
        "device": device,
        "pid": os.getpid(),
    }
    if device["backend"] in ("CUDA", "OPTIX"):
        # Whether the first frame waits for the driver to compile kernels: the driver
        # says so before it sends the first render (blurset.services.kernels).
        ready["cuda"] = blender_scene.cuda_kernels()
    send(ready)
    try:
        for line in sys.stdin:
            line = line.strip()
            if not line:
                continue
            try:
                cmd = json.loads(line)
                name = cmd.get("cmd") if isinstance(cmd, dict) else None
                if name == "quit":
                    return 0
                if name == "load":
                    reply = worker.load(cmd)
                elif name == "render":
                    reply = worker.render(cmd)
                else:
                    reply = {"ok": False, "reason": f"unknown command {name!r}"}
            except Exception as e:
                traceback.print_exc()
                reply = {"ok": False, "reason": one_line(e)}
            send(reply)
    finally:
        worker.close()
    return 0


if __name__ == "__main__":
    code = main()
    PROTO.close()
    sys.exit(code)
