"""Progress of a build: a bar of frames rendered with settings done and an ETA (tqdm) on a
terminal; on a log (stderr not a TTY) one plain line per setting instead, since a bar's
carriage returns would bury the `failed:` lines."""

from __future__ import annotations

import sys
import threading

from tqdm import tqdm


class Progress:
    def __init__(self, settings: int, *, frames_per_setting: int = 0, enabled: bool = True) -> None:
        self.settings_total = settings
        self.settings_done = 0
        self.failed = 0
        self.fps = frames_per_setting
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
            s = f"{self.settings_done}/{self.settings_total} settings"
            if self.failed:
                s += f", {self.failed} failed"
            self._bar.set_postfix_str(s, refresh=False)

    def frame_done(self, n: int = 1) -> None:
        if self._bar is not None:
            with self._lock:
                self._bar.update(n)

    def setting_done(self) -> None:
        with self._lock:
            self.settings_done += 1
            self._post()
            if self._lines:
                failed = f", {self.failed} failed" if self.failed else ""
                print(
                    f"{self.settings_done}/{self.settings_total} settings done{failed}",
                    file=sys.stderr,
                    flush=True,
                )

    def skip(self, settings: int) -> None:
        """Settings already complete (resumed) or finished elsewhere (Ray)."""
        if settings <= 0:
            return
        with self._lock:
            self.settings_done += settings
            if self._bar is not None:
                self._total = max(0, self._total - settings * self.fps)
                self._bar.total = self._total
                self._bar.refresh()
            self._post()

    def object_failed(self, settings_left: int) -> None:
        with self._lock:
            self.failed += 1
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
