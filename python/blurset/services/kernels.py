"""Cycles' GPU kernels: the compile a GPU may wait for before its first frame, and the
cache that keeps it (issue 47, DESIGN §11).

bpy ships Cycles' CUDA kernels compiled for some GPU architectures only (bpy 5.0.1:
sm_50 to sm_89 and sm_120). On any other NVIDIA GPU, an H100 or H200 (sm_90) among them,
the driver compiles Blender's PTX before the first frame, silently: 459 s on an H200
(one core; OptiX waits as long, it loads the same CUDA module). The driver keeps the
result in its CUDA cache, so the next worker starts at once, but only where that cache
is found again.

A worker reports its GPUs' archs and the archs Cycles ships (blender_scripts/worker.py,
"cuda" in its ready reply); here the driver judges them: it says before the first render
that the compile is coming, gives that render the time the compile takes, points the
cache at a folder that outlives the process (the user's cache folder unless
CUDA_CACHE_PATH is set) and large enough to hold it, and marks there, once a render has
come back, that this Blender's kernels for that arch and driver are compiled.
"""

from __future__ import annotations

import os
import sys
import threading
from collections.abc import Mapping
from pathlib import Path
from typing import Any

# Minutes the driver took on an H200 (459 s): what the notice promises, rounded.
COMPILE_MINUTES = 8
# Extra seconds a worker's replies may take while its kernels compile: well past the
# measured 459 s, for slower CPUs and several GPUs compiling at once.
COMPILE_ALLOWANCE_S = 3600.0
# The CUDA cache's size, bytes: the compiled kernels of one Blender are 32 MB, and the
# driver's default (256 MB or less on older drivers) evicts them among other programs'.
CACHE_MAXSIZE = 1 << 30

_SAID: set[str] = set()
_SAID_LOCK = threading.Lock()


def cache_root(env: Mapping[str, str]) -> Path:
    """blurset's folder in the user's cache ($XDG_CACHE_HOME, else ~/.cache)."""
    base = env.get("XDG_CACHE_HOME") or str(Path(env.get("HOME", "~")).expanduser() / ".cache")
    return Path(base) / "blurset"


def worker_env(env: Mapping[str, str]) -> dict[str, str]:
    """The environment a Blender worker starts with: `env`, plus the CUDA and OptiX
    cache folders and the CUDA cache's size where the user set none."""
    out = dict(env)
    root = cache_root(env)
    out.setdefault("CUDA_CACHE_PATH", str(root / "cuda"))
    out.setdefault("CUDA_CACHE_MAXSIZE", str(CACHE_MAXSIZE))
    out.setdefault("OPTIX_CACHE_PATH", str(root / "optix"))
    return out


def _marker(env: Mapping[str, str], blender: str, arch: str, driver: int) -> Path:
    # Beside the compiled kernels, so a cache shared between nodes carries it.
    return Path(env["CUDA_CACHE_PATH"]) / f"blurset-compiled-{blender}-{arch}-{driver}"


def to_compile(ready: Mapping[str, Any], env: Mapping[str, str]) -> list[str]:
    """The archs of a worker's GPUs (its ready reply) whose kernels Cycles does not ship
    and this cache has not been seen to hold: the first render waits for their compile."""
    cuda = ready.get("cuda")
    if not isinstance(cuda, Mapping) or "CUDA_CACHE_PATH" not in env:
        return []
    shipped = set(cuda.get("kernels") or [])
    blender = str(ready.get("blender_version", ready.get("blender", "?")))
    driver = int(cuda.get("driver", 0))
    return [
        str(a)
        for a in cuda.get("archs") or []
        if a not in shipped and not _marker(env, blender, str(a), driver).exists()
    ]


def notice(archs: list[str], env: Mapping[str, str]) -> str:
    """The line a build prints before a first render that waits for a compile."""
    return (
        f"compiling Cycles kernels for {', '.join(archs)}: once per machine, about "
        f"{COMPILE_MINUTES} min before the first frame (Blender ships none for this GPU; "
        f"kept in {env['CUDA_CACHE_PATH']}, CUDA_CACHE_PATH)"
    )


def announce(archs: list[str], env: Mapping[str, str]) -> None:
    """Print the notice on stderr, once per process and arch (several workers start
    together; each compiles, one line says so), and make the cache folder."""
    Path(env["CUDA_CACHE_PATH"]).mkdir(parents=True, exist_ok=True)
    with _SAID_LOCK:
        new = [a for a in archs if a not in _SAID]
        _SAID.update(new)
    if new:
        print(notice(new, env), file=sys.stderr, flush=True)


def mark_compiled(ready: Mapping[str, Any], archs: list[str], env: Mapping[str, str]) -> None:
    """Record that a render came back after the compile of `archs`: the cache holds them.
    A marker that cannot be written only costs a repeated notice."""
    cuda = ready.get("cuda") or {}
    blender = str(ready.get("blender_version", ready.get("blender", "?")))
    driver = int(cuda.get("driver", 0))
    for arch in archs:
        try:
            _marker(env, blender, arch, driver).touch()
        except OSError:
            pass


def environ() -> dict[str, str]:
    """This process's environment as a worker gets it."""
    return worker_env(os.environ)
