"""Where the object units run: in this process (one at a time, or a thread pool of
workers, each driving its own Blender process) or as Ray tasks (DESIGN §11)."""

from __future__ import annotations

import concurrent.futures as cf
import contextlib
import os
import queue
from collections.abc import Callable, Iterator

from blurset.commands.builder.unit import ObjectResult, build_object
from blurset.exceptions import BlursetError
from blurset.services import devices
from blurset.services.config import BuildConfig
from blurset.services.devices import Device
from blurset.services.objects import ObjectSpec
from blurset.services.progress import Progress
from blurset.services.stop import STOP
from blurset.services.worker_client import kill_all

OnResult = Callable[[ObjectResult], None]


def run_local(
    objs: list[ObjectSpec],
    cfg: BuildConfig,
    progress: Progress,
    on_result: OnResult,
    slots: list[Device] | None = None,
) -> None:
    """`slots`: the device of each worker (blurset.services.devices.plan_local); an object takes
    a free slot, so with GPUs worker i stays pinned to its device."""
    slots = slots or [("AUTO", None)] * cfg.workers
    if len(slots) == 1:
        for o in objs:
            on_result(build_object(o, cfg, progress, slots[0]))
        return
    free: queue.Queue[Device] = queue.Queue()
    for s in slots:
        free.put(s)

    def unit(o: ObjectSpec) -> ObjectResult:
        slot = free.get()
        try:
            return build_object(o, cfg, progress, slot)
        finally:
            free.put(slot)

    pool = cf.ThreadPoolExecutor(len(slots))
    try:
        for fut in cf.as_completed([pool.submit(unit, o) for o in objs]):
            on_result(fut.result())
    except BaseException:
        # Ctrl-C / SIGTERM (or a bug): queued objects never start, running ones lose
        # their Blender process now and end without a failure record (STOP is set);
        # what is complete stays.
        STOP.set()
        pool.shutdown(wait=False, cancel_futures=True)
        kill_all()
        pool.shutdown(wait=True)
        raise
    pool.shutdown(wait=True)


@contextlib.contextmanager
def ray_cluster(cfg: BuildConfig) -> Iterator[None]:
    """For a Ray build, the cluster joined (or a local one started) for the whole build
    and its devices checked (devices.check_ray) before the build writes anything; the
    local executor: nothing."""
    if cfg.executor != "ray":
        yield
        return
    try:
        import ray
    except ImportError:
        raise BlursetError(
            "--executor ray: the ray package is not installed (pip install 'blurset[ray]')"
        ) from None
    started = not ray.is_initialized()
    if started:
        try:
            ray.init(
                address=cfg.ray_address or os.environ.get("RAY_ADDRESS"),
                log_to_driver=False,
                include_dashboard=False,
            )
        except (ConnectionError, RuntimeError, ValueError) as e:
            raise BlursetError(f"--ray-address {cfg.ray_address}: {_first_line(e)}") from None
    try:
        devices.check_ray(cfg, ray.cluster_resources())
        yield
    finally:
        if started:
            ray.shutdown()


def run_ray(
    objs: list[ObjectSpec], cfg: BuildConfig, progress: Progress, on_result: OnResult
) -> None:
    """One Ray task per object, on the cluster ray_cluster joined. A task is idempotent
    (complete settings are skipped, partial ones redone), so Ray may retry it after a
    lost worker or node."""
    import ray

    pending: list = []
    try:
        gpus = devices.ray_gpus_per_task(cfg, ray.cluster_resources().get("GPU", 0))
        remote = ray.remote(num_cpus=max(1, cfg.threads), num_gpus=gpus, max_retries=2)(_ray_unit)
        pending = [remote.remote(o, cfg) for o in objs]
        while pending:
            done, pending = ray.wait(pending, num_returns=1)
            res = ray.get(done[0])
            progress.skip(len(res.settings) - res.new_settings)
            progress.frame_done(res.new_settings * progress.fps)
            for _ in range(res.new_settings):
                progress.setting_done()
            on_result(res)
    except BaseException:
        # A stop: cancel what is queued or running (force kills the task's process, and
        # its Blender worker dies with it); complete settings stay on the shared path.
        for ref in pending:
            try:
                ray.cancel(ref, force=True)
            except Exception:  # noqa: BLE001 - best effort while stopping
                pass
        raise


def _first_line(e: BaseException) -> str:
    return (str(e).strip().splitlines() or [type(e).__name__])[0]


def _ray_unit(obj: ObjectSpec, cfg: BuildConfig) -> ObjectResult:
    return build_object(obj, cfg, Progress(0, enabled=False), devices.for_ray(cfg))
