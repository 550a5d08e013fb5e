"""Which Cycles device a build renders on (`--device`, `--gpus`; issue 16, DESIGN §11).

`auto` takes the best backend Cycles reports (OptiX > CUDA > HIP > oneAPI > Metal > CPU).
Only Blender knows which backends and devices exist, so when the choice can fail (a named
GPU backend, GPU indices, several workers to pin) the build asks a short-lived worker
(`worker.py --probe`) before it writes anything, and a missing backend or index is a
one-line error naming what exists. Otherwise each worker resolves `auto` itself and
reports what it used (meta.json `render.device`).
"""

from __future__ import annotations

import json
import subprocess
from collections.abc import Mapping

from blurset.exceptions import ConfigError

# The `--device` choices, and the Cycles backend each names; best GPU backend first.
DEVICES = ("auto", "cpu", "optix", "cuda", "hip", "oneapi", "metal")
GPU_BACKENDS = ("OPTIX", "CUDA", "HIP", "ONEAPI", "METAL")
NAMES = {"OPTIX": "OptiX", "CUDA": "CUDA", "HIP": "HIP", "ONEAPI": "oneAPI", "METAL": "Metal"}


def needs_probe(
    device: str, gpus: list[int] | None, workers: int, per_gpu: int | None = None
) -> bool:
    """Whether the choice can fail or needs the device count (to pin workers)."""
    return (
        device not in ("auto", "cpu")
        or gpus is not None
        or (device == "auto" and workers > 1)
        or per_gpu is not None
    )


def probe(blender: str | None, timeout: float = 300.0) -> dict[str, list[str]]:
    """{backend: [device names]} as Cycles reports it, from a short-lived worker (its
    probe line, checked by the core against the worker contract)."""
    from blurset.services.worker_client import typed_reply, worker_command

    cmd = worker_command(blender, 1, probe=True)
    try:
        proc = subprocess.run(cmd, capture_output=True, timeout=timeout, check=False)
    except (OSError, subprocess.TimeoutExpired) as e:
        raise ConfigError(f"--device: cannot ask Blender which devices exist: {e}") from None
    for line in proc.stdout.decode("utf-8", "replace").splitlines():
        line = line.strip()
        if line.startswith("{"):
            try:
                msg = json.loads(line)
            except ValueError:
                continue
            if not isinstance(msg, dict):
                continue
            try:
                reply = typed_reply(msg)
            except ValueError as e:
                raise ConfigError(f"--device: Blender's answer is no probe line: {e}") from None
            if "devices" in reply and reply["ok"]:
                return reply["devices"]
    tail = proc.stderr.decode("utf-8", "replace").strip().splitlines()[-1:]
    raise ConfigError(f"--device: Blender did not report its devices ({' '.join(tail)})")


def describe(available: dict[str, list[str]]) -> str:
    """`OptiX: 0 NVIDIA A100, 1 NVIDIA A100; CPU: AMD EPYC` — what exists, one line."""
    parts = []
    for backend, names in available.items():
        if backend == "CPU":
            parts.append(f"CPU: {', '.join(names)}")
        else:
            listed = ", ".join(f"{i} {n}" for i, n in enumerate(names))
            parts.append(f"{NAMES.get(backend, backend)}: {listed}")
    return "; ".join(parts)


def resolve(
    device: str, gpus: list[int] | None, available: dict[str, list[str]]
) -> tuple[str, list[int] | None]:
    """(Cycles backend, GPU indices or None for all) for `--device`/`--gpus` on a machine
    with `available` devices; ConfigError naming what exists when it cannot be."""
    if device not in DEVICES:
        raise ConfigError(f"--device: expected one of {', '.join(DEVICES)}, got {device!r}")
    here = describe(available)
    if device == "auto":
        backend = next((b for b in GPU_BACKENDS if available.get(b)), "CPU")
    else:
        backend = device.upper()
        if backend != "CPU" and not available.get(backend):
            raise ConfigError(
                f"--device {device}: no {NAMES[backend]} device here (Cycles: {here})"
            )
    if gpus is None:
        return backend, None
    if backend == "CPU":
        raise ConfigError(
            f"--gpus: rendering on the CPU, there is no GPU to choose (Cycles: {here})"
        )
    n = len(available[backend])
    bad = [g for g in gpus if g >= n]
    if bad:
        raise ConfigError(
            f"--gpus {bad[0]}: {NAMES[backend]} has devices 0..{n - 1} (Cycles: {here})"
        )
    return backend, gpus


def worker_slots(
    backend: str, gpus: list[int] | None, n_gpus: int, workers: int, per_gpu: int | None = None
) -> list:
    """The GPU indices of each local worker: one worker renders on all chosen GPUs;
    with several workers, worker i is pinned to one device (round robin). CPU: None.
    `per_gpu` (--workers-per-gpu): that many workers pinned to each chosen GPU, which
    overlap one another's fixed cost of a render call (scene sync, film readback)."""
    chosen = gpus if gpus is not None else list(range(n_gpus))
    if per_gpu is not None and backend != "CPU":
        workers = per_gpu * len(chosen)
    elif backend == "CPU" or workers <= 1:
        return [gpus] * max(1, workers)
    return [[chosen[i % len(chosen)]] for i in range(workers)]


Device = tuple[str, "list[int] | None"]  # (Cycles backend or AUTO, GPU indices or None)


def plan_local(cfg) -> list[Device]:
    """The device of each local worker of a build (`cfg`: a BuildConfig), checked before
    the build writes anything: one (backend, GPU indices) per worker slot."""
    per_gpu = cfg.workers_per_gpu
    if not needs_probe(cfg.device, cfg.gpus, cfg.workers, per_gpu):
        backend = "CPU" if cfg.device == "cpu" else "AUTO"
        return [(backend, None)] * max(1, cfg.workers)
    available = probe(cfg.blender)
    backend, gpus = resolve(cfg.device, cfg.gpus, available)
    if backend == "CPU":
        refuse_sharing_no_gpu(per_gpu, f"Cycles: {describe(available)}")
    n = len(available.get(backend, []))
    return [(backend, g) for g in worker_slots(backend, gpus, n, cfg.workers, per_gpu)]


def refuse_sharing_no_gpu(
    per_gpu: int | None, where: str, hint: str = "the CPU takes --workers"
) -> None:
    """--workers-per-gpu shares GPUs among workers: a build that renders on the CPU has
    none to share. One rule for the local executor and Ray (`where`: what the machine
    or cluster has), refused before the build writes anything."""
    if per_gpu is not None:
        raise ConfigError(
            f"--workers-per-gpu {per_gpu}: rendering on the CPU, there is no GPU to share "
            f"({where}); {hint}"
        )


def check_ray(cfg, cluster: Mapping[str, float]) -> None:
    """A Ray build's devices, checked against the cluster's resources before the build
    writes anything: a cluster without GPUs renders on the CPU (tasks reserve no GPU,
    ray_gpus_per_task), so --workers-per-gpu is refused as on a machine without one."""
    gpus = cluster.get("GPU", 0)
    if cfg.device == "cpu" or not gpus > 0:
        refuse_sharing_no_gpu(
            cfg.workers_per_gpu,
            f"Ray cluster: {cluster.get('CPU', 0):g} CPUs, {gpus:g} GPUs",
            "Ray runs one task per object on its CPUs without it",
        )


def for_ray(cfg) -> Device:
    """A Ray task's device: Ray hands each task its GPUs (CUDA_VISIBLE_DEVICES), so the
    worker takes every device it sees; `auto` is resolved by the worker on its node."""
    return ("AUTO" if cfg.device == "auto" else cfg.device.upper(), None)


def ray_gpus_per_task(cfg, cluster_gpus: float) -> float:
    """GPUs a Ray task reserves: --gpus-per-task, else 1 (1/N under --workers-per-gpu
    N) when the build renders on GPUs (a GPU backend, or auto on a cluster that has
    GPUs), else 0."""
    if cfg.gpus_per_task is not None:
        return float(cfg.gpus_per_task)
    share = 1.0 / cfg.workers_per_gpu if cfg.workers_per_gpu else 1.0
    if cfg.device == "cpu":
        return 0.0
    if cfg.device == "auto":
        return share if cluster_gpus > 0 else 0.0
    return share
