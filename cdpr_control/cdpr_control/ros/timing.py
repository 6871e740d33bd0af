"""Timing of a free-running loop: samples of a duration with their percentiles, for /diagnostics.

A node records one sample per period (e.g. the lateness of the simulator's step against its
wall-clock schedule, or the latency from publishing ``winch/state`` to receiving the
``winch/command`` that answers it) and reports p50/p99/max of the last report window; the whole
run stays available (up to ``keep`` samples) for benchmarks.
"""
from __future__ import annotations

from collections import deque

import numpy as np


class DurationStats:
    def __init__(self, name: str, keep: int = 3_600_000):
        self.name = name
        self.window: list[float] = []
        self.run: deque = deque(maxlen=keep)

    def add(self, seconds: float) -> None:
        self.window.append(seconds)
        self.run.append(seconds)

    @staticmethod
    def summary(samples) -> dict:
        """{p50_us, p99_us, max_us, count} of duration samples [s]."""
        if not len(samples):
            return {"p50_us": None, "p99_us": None, "max_us": None, "count": 0}
        x = np.asarray(samples, dtype=float) * 1e6
        p50, p99 = np.percentile(x, [50.0, 99.0])
        return {"p50_us": float(p50), "p99_us": float(p99), "max_us": float(x.max()), "count": int(x.size)}

    def report(self) -> dict:
        """Key-value pairs of the window since the last report (then a new window starts)."""
        s = self.summary(self.window)
        self.window = []
        return {f"{self.name}_{k}": ("" if v is None else (f"{v:.0f}" if k != "count" else v)) for k, v in s.items()}
