"""Drive a Blender worker process (blender_scripts/worker.py) over its JSON-lines protocol.

Each object renders in its own worker process with a per-reply timeout (DESIGN §10): a
crash, hang or bad GLB costs that object only. A Worker restarts its process lazily
after a crash or timeout, so one Worker can serve a whole queue of objects.

    with Worker(threads=2, timeout=300) as w:
        info = w.load(glb, vertices_out)           # WorkerError: the object failed
        w.render(frames, resolution=96, fov_deg=40.0, samples=8)

Every request line is made by the core and every reply line typed by it (dataset/wire.rs,
schemas/worker/): the types of both here are generated from its schemas (`_records.pyi`:
WorkerRequest, WorkerReply and their members).
"""

from __future__ import annotations

import json
import os
import queue
import shutil
import subprocess
import sys
import tempfile
import threading
import time
import weakref
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import IO, TYPE_CHECKING, Any, NoReturn, TypedDict

from blurset import _core
from blurset.exceptions import BlursetError
from blurset.services import kernels
from blurset.services.scripts import blender_script

if TYPE_CHECKING:
    from blurset import _records

WORKER_SCRIPT = blender_script("worker.py")
STDERR_TAIL_LINES = 6
# Lines of worker stdout held at most: a worker that floods its stdout blocks on the pipe
# instead of filling this process's memory, and its deadline still runs (issue 14 H3).
QUEUE_LINES = 256

_LIVE: weakref.WeakSet[Worker] = weakref.WeakSet()
_LIVE_LOCK = threading.Lock()


def kill_all() -> None:
    """Kill every live worker process of this process (a stop: Ctrl-C, SIGTERM)."""
    with _LIVE_LOCK:
        workers = list(_LIVE)
    for w in workers:
        w.kill()


def request_line(frames: Sequence[Mapping[str, Any]], **request: Any) -> str:
    """The render request of `frames` as the line the worker reads: the core types each
    frame as its Render (the plan's renders as they are; a caller's `c2w`, `seed` and
    `out`, NumPy numbers made plain), checks it and makes its EXR path absolute
    (dataset/wire.rs, the contract in schemas/worker/); ValueError naming what is wrong.
    `request`: resolution, fov_deg, samples and the render options."""
    return _core.render_request([{**_plain(f), "out": str(f["out"])} for f in frames], **request)


def load_line(
    glb: Path,
    vertices_out: Path,
    *,
    unlit: _records.Unlit = "lit",
    light_paths: _records.LightPaths = "auto",
) -> str:
    """The load request of `glb` as the line the worker reads (the core's: dataset/wire.rs),
    both paths resolved (the worker runs in a folder of its own); ValueError for an
    `unlit` or `light_paths` the contract lacks."""
    return _core.load_request(
        str(Path(glb).resolve()),
        str(Path(vertices_out).resolve()),
        unlit=unlit,
        light_paths=light_paths,
    )


def quit_line() -> str:
    """The line that asks the worker to exit (the core's)."""
    return _core.quit_request()


def typed_reply(msg: object) -> _records.WorkerReply:
    """A line the worker sent (parsed JSON), checked by the core against the contract's
    replies: the same object, every field as sent (a null kept), or ValueError naming the
    reply and the field that does not fit."""
    return _core.worker_reply(msg)


class WorkerError(BlursetError):
    """An object-level failure (bad GLB, render QA, crash); the message is one line.

    `transient` says whether the same work may succeed when tried again (a crash or a
    hang may be the machine's fault; a file Blender refuses is refused every time)."""

    transient = False


class WorkerCrash(WorkerError):
    """The worker process died (signal, exit, out of memory)."""

    transient = True


class WorkerTimeout(WorkerError):
    """The worker sent nothing for `timeout` seconds; its process was killed."""

    transient = True


class WorkerStopped(WorkerError):
    """The command is stopping (Ctrl-C, SIGTERM): no worker starts, none is retried."""


class ObjectTimeout(WorkerTimeout):
    """The object used up its whole budget (`--object-timeout`); retrying cannot help."""

    transient = False


def worker_command(
    blender: str | None,
    threads: int,
    workdir: Path | None = None,
    device: str = "CPU",
    gpus: list[int] | None = None,
    probe: bool = False,
) -> list[str]:
    """The argv that starts a worker: the venv's bpy, or a user's Blender binary.
    `device` is a Cycles backend (CPU, OPTIX, CUDA, HIP, ONEAPI, METAL), `gpus` indices
    into its device list; `probe` makes it report the devices and exit."""
    ours = ["--threads", str(threads), "--device", device]
    if gpus is not None:
        ours += ["--gpus", ",".join(str(g) for g in gpus)]
    if workdir is not None:
        ours += ["--workdir", str(workdir)]
    if probe:
        ours.append("--probe")
    script = str(WORKER_SCRIPT)
    if blender is None:
        return [sys.executable, script, *ours]
    # GLBs are untrusted: --disable-autoexec keeps Python in .blend data from running.
    return [
        blender,
        "-b",
        "--factory-startup",
        "--disable-autoexec",
        "--python-exit-code",
        "1",
        "-P",
        script,
        "--",
        *ours,
    ]


class RenderOptions(TypedDict):
    """What every render of one setting shares (`Worker.render`'s keywords)."""

    resolution: int
    fov_deg: float
    crop: bool
    guides: bool


class Worker:
    """One Blender worker process. Not thread-safe: one caller at a time."""

    def __init__(
        self,
        *,
        blender: str | None = None,
        threads: int = 0,
        timeout: float = 300.0,
        log_path: Path | None = None,
        workdir: Path | None = None,
        deadline: float | None = None,
        device: str = "CPU",
        gpus: list[int] | None = None,
    ) -> None:
        """`timeout`: seconds without a reply before the worker counts as hung.
        `deadline`: a time.monotonic() instant after which the object's budget is spent
        (ObjectTimeout). `workdir`: where the worker keeps its scratch files. `device`,
        `gpus`: the Cycles backend and device indices it renders on (blurset.services.devices)."""
        if not WORKER_SCRIPT.is_file():
            raise WorkerError(f"worker script not found: {WORKER_SCRIPT}")
        if timeout <= 0:
            raise ValueError(f"timeout must be > 0 seconds, got {timeout}")
        self.blender = blender
        self.threads = int(threads)
        self.timeout = float(timeout)
        self.deadline = deadline
        # Without a workdir the scratch is ours, so close() removes it even when the
        # worker was killed and never cleaned up after itself.
        self._own_scratch = workdir is None
        self.workdir = (
            Path(tempfile.mkdtemp(prefix="blurset-worker-")) if workdir is None else workdir
        )
        self.device = device
        self.gpus = gpus
        self._own_log = log_path is None
        if log_path is None:
            fd, name = tempfile.mkstemp(prefix="blurset-worker-", suffix=".log")
            os.close(fd)
            log_path = Path(name)
        self.log_path = Path(log_path)
        # The worker's ready line (Blender version, device, CUDA archs), set by _start.
        self.info: _records.Ready
        # The core's QA measures of the views of the object loaded last (Worker.load).
        self.object_qa: list[_core.FrameQa] = []
        # Archs whose kernels the driver compiles before this worker's first frame.
        self._compiling: list[str] = []
        self._env = kernels.environ()
        self._proc: subprocess.Popen[bytes] | None = None
        self._log: IO[bytes] | None = None
        self._lines: queue.Queue[bytes | None] = queue.Queue()
        try:
            self._start()
        except BaseException:
            self.close()  # a worker that never started leaves no log or scratch behind
            raise

    @classmethod
    def in_folder(cls, work: Path, **kw: Any) -> Worker:
        """A worker that keeps its log (worker.log) and scratch files in `work`: what a
        build's object and a tradeoff run leave for the user to read when it fails."""
        return cls(log_path=work / "worker.log", workdir=work / "scratch", **kw)

    # -- process management ---------------------------------------------------------

    def _start(self) -> None:
        from blurset.services.stop import STOP

        if STOP.is_set():
            raise WorkerStopped("stopping: no new Blender worker")
        self.log_path.parent.mkdir(parents=True, exist_ok=True)
        self._log = open(self.log_path, "ab")  # noqa: SIM115 - lives as long as the process
        try:
            self._proc = subprocess.Popen(
                worker_command(self.blender, self.threads, self.workdir, self.device, self.gpus),
                stdin=subprocess.PIPE,
                stdout=subprocess.PIPE,
                stderr=self._log,
                env=self._env,
            )
        except OSError as e:
            self._log.close()
            self._log = None
            raise WorkerError(
                f"cannot start Blender worker {self.blender or sys.executable}: {e}"
            ) from None
        with _LIVE_LOCK:
            _LIVE.add(self)
        self._lines = queue.Queue(maxsize=QUEUE_LINES)
        threading.Thread(target=_pump, args=(self._proc.stdout, self._lines), daemon=True).start()
        ready = self._receive(startup=True)
        if "ready" not in ready or not ready["ok"]:
            reason = ready["reason"] if "reason" in ready else "its first line is no ready line"
            self._discard()
            raise WorkerError(f"Blender worker: {reason}")
        self.info = ready
        self._compiling = kernels.to_compile(self.info, self._env)
        if self._compiling:
            kernels.announce(self._compiling, self._env)

    @property
    def alive(self) -> bool:
        return self._proc is not None and self._proc.poll() is None

    def _ensure_started(self) -> None:
        if not self.alive:
            self._discard()
            self._start()

    def kill(self) -> None:
        """Kill the process now (from any thread); the caller's next read fails."""
        proc = self._proc
        if proc is not None and proc.poll() is None:
            try:
                proc.kill()
            except OSError:
                pass

    def _discard(self) -> None:
        """Kill the process (if any) and forget it."""
        if self._proc is not None:
            if self._proc.poll() is None:
                self._proc.kill()
            self._proc.wait()
            for f in (self._proc.stdin, self._proc.stdout):
                if f is not None:
                    f.close()
            self._proc = None
        if self._log is not None:
            self._log.close()
            self._log = None

    def stderr_tail(self, n: int = STDERR_TAIL_LINES) -> list[str]:
        try:
            with open(self.log_path, "rb") as f:
                f.seek(0, os.SEEK_END)
                f.seek(max(0, f.tell() - 16384))
                text = f.read().decode("utf-8", "replace")
        except OSError:
            return []
        return [ln.strip() for ln in text.splitlines() if ln.strip()][-n:]

    # -- protocol -----------------------------------------------------------------------

    def _send_line(self, line: str) -> None:
        self._ensure_started()
        assert self._proc is not None and self._proc.stdin is not None
        try:
            self._proc.stdin.write((line + "\n").encode("utf-8"))
            self._proc.stdin.flush()
        except (BrokenPipeError, OSError):
            self._crashed()

    def _crashed(self) -> NoReturn:
        code = self._proc.wait() if self._proc is not None else None
        tail = " | ".join(self.stderr_tail())
        self._discard()
        raise WorkerCrash(f"Blender worker exited with code {code}; last stderr: {tail}")

    @property
    def reply_wait(self) -> float:
        """Seconds a reply may take: `timeout`, and while the driver compiles this
        worker's kernels (before its first frame) the time that takes too."""
        return self.timeout + (kernels.COMPILE_ALLOWANCE_S if self._compiling else 0.0)

    def _receive(self, *, startup: bool = False) -> _records.WorkerReply:
        wait = self.reply_wait
        reply_by = time.monotonic() + wait
        deadline = min(reply_by, self.deadline) if self.deadline is not None else reply_by
        while True:
            left = deadline - time.monotonic()
            try:
                if left <= 0:  # checked per line: a flood of noise cannot outrun it
                    raise queue.Empty
                raw = self._lines.get(timeout=left)
            except queue.Empty:
                self._discard()
                if deadline < reply_by:
                    raise ObjectTimeout(
                        "object exceeded its time budget (--object-timeout); killed its worker"
                    ) from None
                what = "start up" if startup else "reply"
                raise WorkerTimeout(
                    f"Blender worker did not {what} within {wait:g} s; killed it"
                ) from None
            if raw is None:
                from blurset.services.stop import STOP

                if STOP.is_set():
                    self._discard()
                    raise WorkerStopped("stopping: the Blender worker was killed")
                self._crashed()
            line = raw.decode("utf-8", "replace").strip()
            # A Blender binary prints its banner on stdout before the worker script takes
            # the stream over; anything that is not a JSON object is such noise.
            if not line.startswith("{"):
                continue
            try:
                msg = json.loads(line)
            except ValueError:
                continue
            if isinstance(msg, dict):
                try:  # the core types it: the line as sent, or the field that is wrong
                    return typed_reply(msg)
                except ValueError as e:
                    self._discard()  # out of step with the contract: nothing it says counts
                    raise WorkerError(f"Blender worker: {e}") from None

    def _receive_in_sync(self) -> _records.WorkerReply:
        """_receive, but an interrupt (Ctrl-C) mid-command kills the worker: replies still
        on their way would otherwise be read as the answers to the next command."""
        try:
            return self._receive()
        except WorkerError:
            raise
        except BaseException:
            self._discard()
            raise

    # -- commands -----------------------------------------------------------------------

    def load(
        self,
        glb: Path,
        vertices_out: Path,
        *,
        unlit: _records.Unlit = "lit",
        light_paths: _records.LightPaths = "auto",
    ) -> _records.Loaded:
        """Import and normalize one GLB (light-path bounces from its materials, or fixed),
        then render its QA views and judge them (their measures: `object_qa`); the
        worker's reply as it sent it (see blender_scripts/worker.py).

        Raises WorkerError with a one-line reason when the object cannot be rendered
        (missing file, unsupported compression, no mesh, invisible, renders black, ...).
        """
        self.object_qa = []
        try:
            line = load_line(glb, vertices_out, unlit=unlit, light_paths=light_paths)
        except ValueError as e:  # refused before the worker sees it, as it would refuse
            raise WorkerError(f"load failed: {e} ({glb})") from None
        self._send_line(line)
        reply = self._receive_in_sync()
        if "bbox_dims" not in reply or not reply["ok"]:
            raise WorkerError(f"{reply['reason'] if 'reason' in reply else 'load failed'} ({glb})")
        qa = self._object_qa(reply["bbox_dims"])
        failure = _core.object_qa_verdict(qa)
        if failure:
            raise WorkerError(f"{failure} ({glb})")
        self.object_qa = qa
        return reply

    def _object_qa(self, bbox_dims: list[float]) -> list[_core.FrameQa]:
        """Render the core's QA views of the loaded object (tiny, few samples) and measure
        each with the core's frame QA: the worker renders, blurset-core judges."""
        if self.workdir is not None:
            self.workdir.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryDirectory(prefix="blurset-qa-", dir=self.workdir) as d:
            cameras = _core.object_qa_cameras(bbox_dims)
            outs = [Path(d) / f"qa_{k}.exr" for k in range(len(cameras))]
            frames: list[dict[str, Any]] = [
                {"c2w": c2w, "seed": k, "out": out}
                for k, (c2w, out) in enumerate(zip(cameras, outs, strict=True))
            ]
            self.render(
                frames,
                resolution=_core.OBJECT_QA_RESOLUTION,
                fov_deg=_core.OBJECT_QA_FOV_DEG,
                samples=_core.OBJECT_QA_SAMPLES,
            )
            return [_core.frame_qa_exr(out) for out in outs]

    def render(
        self,
        frames: Sequence[Mapping[str, Any]],
        *,
        resolution: int,
        fov_deg: float,
        samples: int | None = None,
        on_frame: Callable[[int, str, tuple[int, int] | None], None] | None = None,
        exr_codec: str | None = None,
        noise_threshold: float | None = None,
        batch: bool = True,
        crop: bool = False,
        guides: bool = False,
        geometry: bool = False,
    ) -> _records.Rendered:
        """Render frames ({"c2w": 4x4 row-major, "seed": int, "out": EXR path}) in order.

        `samples` is the count of every frame that carries none; without it, each frame
        must carry its own. A frame may carry its own "samples", a sample block ("sample_offset",
        "sample_sequence": Cycles sample subsets), and "motion": {"steps": n, "keys":
        [c2w …]} to be one Cycles motion blur render along 2^n + 1 camera keys, a
        "region" [x0, y0, x1, y1) of pixels that can see the object (the plan's; the rest
        of the image is transparent 0, as in a whole render), and its render "call" (or
        its "view" and "level"): consecutive frames of one call render as one job.
        `on_frame(i, out, origin)` runs as soon as frame i is on disk; the timeout applies
        per frame. `crop` writes a frame rendered in a region as that region's pixels
        only; `origin` is then its (x0, y0) in the image (Accumulator.add_exr takes it),
        None for an EXR of the whole image.
        `exr_codec` sets the codec of the EXRs the worker writes (its default: NONE).
        `noise_threshold` turns on Cycles adaptive sampling. `batch` False renders every
        frame with its own render call instead of one animation job per run of frames.
        `guides` writes multi-layer EXRs with Cycles' denoising albedo and normal passes
        (an Accumulator made with guides=True reads them). `geometry` writes multi-layer
        EXRs with the Depth and Normal data passes at each pixel's centre (send samples
        1; _core.write_geometry reads them).
        Returns the worker's final reply ({"done": n, "jobs": render calls}).
        """
        if samples is None:
            bare = [i for i, f in enumerate(frames) if f.get("samples") is None]
            if bare:
                raise ValueError(f"render: frame {bare[0]} carries no samples and the call none")
            # The protocol's call-level count, which every frame's own overrides.
            samples = int(frames[0]["samples"]) if frames else 1
        try:
            line = request_line(
                frames,
                resolution=resolution,
                fov_deg=fov_deg,
                samples=samples,
                exr_codec=exr_codec,
                noise_threshold=noise_threshold,
                batch=batch,
                crop=crop,
                guides=guides,
                geometry=geometry,
            )
        except ValueError as e:  # refused before the worker sees it, as it would refuse
            raise WorkerError(f"render failed: {e}") from None
        self._send_line(line)
        return self._await_render(len(frames), on_frame)

    def _await_render(
        self, n: int, on_frame: Callable[[int, str, tuple[int, int] | None], None] | None
    ) -> _records.Rendered:
        """The replies of one render request: each frame on disk to `on_frame`, then the
        final reply, which must count all `n` frames."""
        while True:
            msg = self._receive_in_sync()
            if "frame" in msg:
                if self._compiling:  # a frame came back: the cache holds the kernels
                    kernels.mark_compiled(self.info, self._compiling, self._env)
                    self._compiling = []
                if on_frame is not None:
                    try:
                        origin = msg["origin"]
                        at = None if origin is None else (origin[0], origin[1])
                        on_frame(msg["frame"], msg["out"], at)
                    except BaseException:
                        self._discard()  # it is still rendering: its replies would desync
                        raise
                continue
            if "done" not in msg or not msg["ok"]:
                reason = msg["reason"] if "reason" in msg else f"answered with {sorted(msg)}"
                raise WorkerError(f"render failed: {reason}")
            if msg["done"] != n:
                raise WorkerError(f"render: worker reported {msg['done']} of {n} frames")
            return msg

    def close(self) -> None:
        """Ask the worker to quit; kill it if it does not within a few seconds."""
        if self._proc is not None and self._proc.poll() is None:
            try:
                assert self._proc.stdin is not None
                self._proc.stdin.write((quit_line() + "\n").encode("utf-8"))
                self._proc.stdin.flush()
                self._proc.wait(timeout=10)
            except (OSError, subprocess.TimeoutExpired):
                pass
        self._discard()
        if self._own_log:
            try:
                self.log_path.unlink()
            except OSError:
                pass
        if self._own_scratch:
            shutil.rmtree(self.workdir, ignore_errors=True)

    def __enter__(self) -> Worker:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __del__(self) -> None:
        if getattr(self, "_proc", None) is not None:
            self._discard()


def _plain(v: Any) -> Any:
    """`v` with NumPy's arrays and scalars (a caller's camera, region or counts) as plain
    Python lists and numbers, which the core's typed reading takes."""
    if hasattr(v, "tolist"):  # an ndarray or a NumPy scalar (whose tolist is its item)
        return v.tolist()
    if isinstance(v, Mapping):
        return {k: _plain(x) for k, x in v.items()}
    if isinstance(v, list | tuple):
        return [_plain(x) for x in v]
    return v


def _pump(stream: IO[bytes] | None, out: queue.Queue[bytes | None]) -> None:
    """Move the worker's protocol lines onto a bounded queue, so reads can time out and
    a flood waits in the pipe; gives up once the stream is closed (worker discarded)."""

    def put(item: bytes | None) -> bool:
        while True:
            try:
                out.put(item, timeout=0.5)
                return True
            except queue.Full:
                if stream is None or stream.closed:
                    return False

    if stream is not None:
        try:
            for line in iter(stream.readline, b""):
                if not put(line):
                    return
        except (OSError, ValueError):
            pass
    put(None)
