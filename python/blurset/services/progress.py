"""Progress of a build: a bar of frames rendered with settings done and an ETA (tqdm) on a
terminal; on a log (stderr not a TTY) one plain line per setting instead, and one a minute
at least while frames render, with the time elapsed and an ETA, since a bar's carriage
returns would bury the `failed:` lines."""

from __future__ import annotations

import sys
import threading
import time
from collections.abc import Callable

from tqdm import tqdm


def duration(seconds: float) -> str:
    """A short duration for a log line: 42s, 3m07s, 2h05m."""
    s = max(0, int(round(seconds)))
    if s < 60:
        return f"{s}s"
    if s < 3600:
        return f"{s // 60}m{s % 60:02d}s"
    return f"{s // 3600}h{s % 3600 // 60:02d}m"


# The longest a log goes without a line while frames render (seconds).
LOG_EVERY_S = 60.0


class Progress:
    """Settings done, and frames rendered (the work left is counted in frames, so an ETA
    moves within a setting too). Settings found complete (`skip`) and those of a failed
    object leave the work to do; the ETA is the time per frame rendered in this run times
    the frames left. `clock` is for tests (seconds, monotonic)."""

    def __init__(
        self,
        settings: int,
        *,
        frames_per_setting: int = 0,
        enabled: bool = True,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.settings_total = settings
        self.settings_done = 0
        self.settings_skipped = 0
        self.failed = 0
        self.skipped = 0  # objects --licenses leaves out: by request, not failures
        self.fps = frames_per_setting
        self.frames_total = settings * frames_per_setting
        self.frames_done = 0
        self._clock = clock
        self._t0 = self._said = clock()
        self._lock = threading.Lock()
        tty = sys.stderr.isatty()
        self._lines = enabled and not tty
        # The bar's total, kept here (tqdm types its total as optional).
        self._total = settings * frames_per_setting
        self._bar = (
            tqdm(
                total=self._total,
                unit="frame",
                dynamic_ncols=True,
                file=sys.stderr,
                smoothing=0.05,
            )
            if enabled and tty and settings * frames_per_setting > 0
            else None
        )
        self._post()

    def _post(self) -> None:
        if self._bar is not None:
            s = f"{self.settings_done}/{self.settings_total} settings{self._tally()}"
            self._bar.set_postfix_str(s, refresh=False)

    def _tally(self) -> str:
        """`, 1 failed, 2 skipped (licence)`: what did not render, and why."""
        s = f", {self.failed} failed" if self.failed else ""
        return s + (f", {self.skipped} skipped (licence)" if self.skipped else "")

    def timing(self) -> str:
        """`1m05s elapsed, ETA 3m10s` (ETA `-` before the first frame of this run)."""
        elapsed = self._clock() - self._t0
        left = max(0, self.frames_total - self.frames_done)
        if left == 0:
            eta = "0s"
        elif self.frames_done > 0:
            eta = duration(elapsed * left / self.frames_done)
        else:
            eta = "-"
        return f"{duration(elapsed)} elapsed, ETA {eta}"

    def frame_done(self, n: int = 1) -> None:
        with self._lock:
            self.frames_done += n
            if self._bar is not None:
                self._bar.update(n)
            # A log hears from a long setting too, not only when it ends (hours at 512 px).
            if self._lines and self._clock() - self._said >= LOG_EVERY_S:
                self._line(f"{self.frames_done}/{self.frames_total} frames, ")

    def setting_done(self) -> None:
        with self._lock:
            self.settings_done += 1
            self._post()
            if self._lines:
                self._line("")

    def _line(self, head: str) -> None:
        self._said = self._clock()
        done = f"{self.settings_done}/{self.settings_total} settings done{self._tally()}"
        print(f"{head}{done} ({self.timing()})", file=sys.stderr, flush=True)

    def skip(self, settings: int) -> None:
        """Settings already complete (resumed) or finished elsewhere (Ray)."""
        if settings <= 0:
            return
        with self._lock:
            self.settings_done += settings
            self.settings_skipped += settings
            self.frames_total = max(self.frames_done, self.frames_total - settings * self.fps)
            if self._bar is not None:
                self._total = max(0, self._total - settings * self.fps)
                self._bar.total = self._total
                self._bar.refresh()
            self._post()

    def object_failed(self, settings_left: int) -> None:
        self._drop(settings_left, skipped=False)

    def object_skipped(self, settings_left: int) -> None:
        """An object `--licenses` leaves out: its settings leave the work, not failed."""
        self._drop(settings_left, skipped=True)

    def _drop(self, settings_left: int, skipped: bool) -> None:
        with self._lock:
            if skipped:
                self.skipped += 1
            else:
                self.failed += 1
            if settings_left > 0:
                self.frames_total = max(
                    self.frames_done, self.frames_total - settings_left * self.fps
                )
            if self._bar is not None and settings_left > 0:
                self._total = max(int(self._bar.n), self._total - settings_left * self.fps)
                self._bar.total = self._total
            self._post()

    def write(self, msg: str) -> None:
        if self._bar is not None:
            self._bar.write(msg, file=sys.stderr)
        else:
            print(msg, file=sys.stderr, flush=True)

    def __enter__(self) -> Progress:
        return self

    def __exit__(self, *exc: object) -> None:
        if self._bar is not None:
            self._bar.close()
