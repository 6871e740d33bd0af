"""Progress of long commands (bag reading, identification runs, analyses, the demo's program) on stderr.

On a terminal one line is rewritten in place (at most ten times a second); into a file or a pipe
(CI logs) a line is written per tenth of the work, so logs stay short. The ``cdpr`` command turns it
on (:func:`enable`); used as a library (tests, scripts) the code stays quiet unless asked.
"""
from __future__ import annotations

import sys
import time
from typing import Iterable, Iterator, TypeVar

T = TypeVar("T")
_enabled = False
MIN_INTERVAL = 0.1  # s between rewrites of a terminal line


def enable(on: bool = True) -> None:
    global _enabled
    _enabled = on


def enabled() -> bool:
    return _enabled


class Progress:
    """``update(fraction, detail)`` as the work goes, ``done()`` at the end."""

    def __init__(self, label: str, stream=None, force: bool = False):
        self.label = label
        self.stream = stream or sys.stderr
        self.active = force or _enabled
        self.tty = self.active and getattr(self.stream, "isatty", lambda: False)()
        self._decile = -1
        self._last = 0.0
        self._shown = False

    def update(self, fraction: float, detail: str = "") -> None:
        if not self.active:
            return
        fraction = min(max(float(fraction), 0.0), 1.0)
        text = f"{self.label}: {100 * fraction:5.1f} %" + (f"  {detail}" if detail else "")
        if self.tty:
            now = time.monotonic()
            if now - self._last >= MIN_INTERVAL or fraction >= 1.0:
                self._last = now
                self.stream.write("\r\x1b[K" + text)
                self.stream.flush()
                self._shown = True
            return
        decile = int(10 * fraction)
        if decile > self._decile:
            self._decile = decile
            self.stream.write(text + "\n")
            self.stream.flush()

    def done(self, detail: str = "") -> None:
        if not self.active:
            return
        if self.tty:
            self.update(1.0, detail)
            if self._shown:
                self.stream.write("\n")
                self.stream.flush()
        elif self._decile < 10:
            self.update(1.0, detail)

    def stop(self) -> None:
        """End the progress without claiming it complete (the work failed): a terminal's line is
        closed, so that the error that follows starts a line of its own."""
        if self.active and self.tty and self._shown:
            self.stream.write("\n")
            self.stream.flush()
            self._shown = False


def track(items: Iterable[T], total: int, label: str) -> Iterator[T]:
    """Yield ``items`` while showing how many of ``total`` have passed."""
    if not _enabled or total <= 0:
        yield from items
        return
    progress = Progress(label)
    step = max(1, total // 1000)  # a thousand updates at most: cheap next to the work per item
    count = 0
    for item in items:
        yield item
        count += 1
        if count % step == 0:
            progress.update(count / total)
    progress.done()
