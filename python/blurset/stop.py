"""Stopping a command: Ctrl-C, SIGTERM and SIGHUP all mean "stop now, keep what is
complete". The main thread gets KeyboardInterrupt; `STOP` tells every other thread
(local workers, progress) to give up at its next step instead of retrying or recording
a failure; the Blender worker processes are killed by the build (and die with their
parent anyway: see blender_scripts/worker.py)."""

from __future__ import annotations

import signal
import threading

STOP = threading.Event()


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
