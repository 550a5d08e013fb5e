"""Stopping a command: Ctrl-C, SIGTERM and SIGHUP all mean "stop now, keep what is
complete". The main thread gets KeyboardInterrupt; `STOP` tells every other thread
(local workers, progress) to give up at its next step instead of retrying or recording
a failure; the Blender worker processes are killed by the build (and die with their
parent anyway: see blender_scripts/worker.py)."""

from __future__ import annotations

import signal
import threading

STOP = threading.Event()
# Set when a core call is left running in its thread (a stop during it): the process
# must then end with os._exit, since finalizing Python under a thread that is inside
# the core aborts the process.
_ABANDONED = threading.Event()


def must_exit_now() -> bool:
    return _ABANDONED.is_set()


def _handler(signum: int, frame: object) -> None:
    STOP.set()
    raise KeyboardInterrupt(signal.Signals(signum).name)


def install() -> None:
    """Route SIGINT, SIGTERM and SIGHUP to KeyboardInterrupt (call from the main thread)."""
    STOP.clear()
    for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
        signal.signal(sig, _handler)


def exit_code(e: BaseException) -> int:
    """128 + the signal number (130 for Ctrl-C), as shells report a signal's death."""
    name = e.args[0] if e.args and isinstance(e.args[0], str) else "SIGINT"
    try:
        return 128 + int(signal.Signals[name])
    except KeyError:
        return 130


def interruptible(fn, *args, **kwargs):
    """Run a long call into the core (which holds no GIL and cannot see signals) in a
    thread, and wait for it here, where a signal lands at once: Ctrl-C or SIGTERM then
    stops the command promptly (the call's thread dies with the process) instead of
    after the call. Its result or exception is passed on."""
    import threading

    box: dict = {}

    def run() -> None:
        try:
            box["value"] = fn(*args, **kwargs)
        except BaseException as e:  # handed to the waiting thread
            box["error"] = e

    t = threading.Thread(target=run, daemon=True, name="blurset-core-call")
    t.start()
    try:
        while t.is_alive():
            t.join(0.1)
    except BaseException:
        _ABANDONED.set()
        raise
    if "error" in box:
        raise box["error"]
    return box.get("value")


def remove_tree(path) -> None:
    """rmtree that wins against a core call still writing into the tree (a stop)."""
    import shutil
    import time

    for _ in range(50):
        shutil.rmtree(path, ignore_errors=True)
        if not path.exists():
            return
        time.sleep(0.05)


def fault_index(var: str) -> int | None:
    """The K of a test's fault injection `VAR=kill_in:K` (SIGKILL inside the K-th unit of
    work, so a test of resume kills at a known point instead of racing the run); None
    when unset. Anything else is refused by name (ASCII digits only: str.isdigit() takes
    "²", which int() refuses)."""
    import os

    from blurset.exceptions import ConfigError

    spec = os.environ.get(var, "")
    kind, _, k = spec.partition(":")
    if kind != "kill_in" or not (k.isascii() and k.isdigit()):
        if spec:
            raise ConfigError(f"{var}={spec!r}: expected kill_in:K")
        return None
    return int(k)
