"""blurset Blender worker: one process renders one object at a time, driven over JSON lines.

Start with the venv's bpy:   python blender_scripts/worker.py --threads N [--workdir D]
or a Blender binary:        blender -b --factory-startup --disable-autoexec \
                                --python-exit-code 1 -P blender_scripts/worker.py -- --threads N

--workdir D keeps the worker's scratch files (rewritten GLBs, QA renders) under D, so a
killed build leaves them where the next run cleans up, not in /tmp.

stdin: one JSON command per line. Replies: one JSON object per line on the process's
original stdout, which this script takes over privately at start-up; fd 1 then points at
stderr so Blender's C-level prints ("Fra:", "Saved:") cannot corrupt the protocol.

  {"cmd":"load","glb":P,"vertices_out":NPY[,"unlit":"lit"|"emission"]}
      -> {"ok":true,"bbox_dims":[..],"n_vertices":N,"n_triangles":T,"scale":s,
          "center":[..],"warnings":[..],"unlit_fixed":b, ...} | {"ok":false,"reason":..}
  {"cmd":"render","resolution":R,"fov_deg":F,"samples":S[,"exr_codec":"NONE"|"ZIP"|...],
   "frames":[{"c2w":[[4x4 row-major]],"seed":I,"out":EXR[,"samples":S_i]
              [,"motion":{"steps":n,"keys":[c2w, ...]}]}, ...]}
      -> {"frame":i,"out":EXR,"seconds":t} per frame, then {"ok":true,"done":n}
      A frame's "samples" overrides S; a frame with "motion" is one Cycles motion blur
      render along its 2^n + 1 keys (blender_scene.render_motion_blur).
  {"cmd":"quit"} -> exit 0

At start-up the worker announces itself with
{"ok":true,"ready":true,"blender":version,"blender_version":version,"pid":pid}.

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


def parse_args(argv: list[str]) -> tuple[int, str | None]:
    """(--threads, --workdir) from our part of argv (after "--" under a Blender binary)."""
    args = argv[argv.index("--") + 1 :] if "--" in argv else argv[1:]
    threads, workdir = 0, None
    for i, a in enumerate(args):
        if a == "--threads" and i + 1 < len(args):
            threads = int(args[i + 1])
        elif a.startswith("--threads="):
            threads = int(a.split("=", 1)[1])
        elif a == "--workdir" and i + 1 < len(args):
            workdir = args[i + 1]
    return threads, workdir


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


def save_npy_atomic(path: str, arr: np.ndarray) -> None:
    os.makedirs(os.path.dirname(os.path.abspath(path)) or ".", exist_ok=True)
    tmp = f"{path}.part"
    with open(tmp, "wb") as f:
        np.save(f, arr)
    os.replace(tmp, path)


class Worker:
    def __init__(self, threads: int, workdir: str | None):
        self.threads = threads
        self.loaded = False
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
            warnings, unlit_fixed = blender_scene.import_glb(glb, self.workdir, unlit)
            info = blender_scene.normalize(warnings)
            blender_scene.setup_scene(self.threads)
        except blender_scene.LoadError as e:
            return {"ok": False, "reason": str(e)}
        save_npy_atomic(vertices_out, info.pop("vertices"))
        self.loaded = True
        return {
            "ok": True,
            **info,
            "warnings": warnings,
            "unlit_fixed": unlit_fixed,
            "seconds": time.perf_counter() - t0,
        }

    def render(self, cmd: dict) -> dict:
        if not self.loaded:
            return {"ok": False, "reason": "render before a successful load"}
        frames = cmd["frames"]
        res, fov, samples = int(cmd["resolution"]), float(cmd["fov_deg"]), int(cmd["samples"])
        if "exr_codec" in cmd:
            blender_scene.set_exr_codec(str(cmd["exr_codec"]))
        for i, fr in enumerate(frames):
            blender_scene.set_camera(fr["c2w"], res, fov, int(fr.get("samples", samples)))
            motion = fr.get("motion")
            if motion:
                secs = blender_scene.render_motion_blur(
                    motion["keys"], int(motion["steps"]), str(fr["out"]), int(fr["seed"])
                )
            else:
                secs = blender_scene.render_frame(str(fr["out"]), int(fr["seed"]))
            send({"frame": i, "out": str(fr["out"]), "seconds": secs})
        return {"ok": True, "done": len(frames)}

    def close(self) -> None:
        shutil.rmtree(self.workdir, ignore_errors=True)


def main() -> int:
    worker = Worker(*parse_args(sys.argv))
    version = bpy.app.version_string
    send(
        {
            "ok": True,
            "ready": True,
            "blender": version,
            "blender_version": version,
            "pid": os.getpid(),
        }
    )
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
