"""First-order low-pass (PT1) filter, the G_r,c of (3.20), exactly discretised for a held input."""
from __future__ import annotations

import numpy as np


class LowPass:
    """y' = (u - y) / T, discretised as y += (1 - exp(-dt/T)) (u - y); T = 0 passes u through.

    The first sample initialises the state (no start-up transient from zero).
    """

    def __init__(self, T: float, dt: float):
        if not (T >= 0.0 and dt > 0.0):
            raise ValueError(f"need T >= 0 s and dt > 0 s, got T={T}, dt={dt}")
        self.dt = dt
        self.set_time_constant(T)
        self.y: np.ndarray | None = None

    def set_time_constant(self, T: float) -> None:
        if not T >= 0.0:
            raise ValueError(f"time constant must be >= 0 s, got {T}")
        self.T = T
        self.alpha = 1.0 if T == 0.0 else 1.0 - np.exp(-self.dt / T)

    def reset(self, y=None) -> None:
        self.y = None if y is None else np.array(y, dtype=float)

    def update(self, u) -> np.ndarray:
        if self.y is None:
            self.y = np.array(u, dtype=float)
        else:
            self.y += self.alpha * (np.asarray(u, dtype=float) - self.y)
        return self.y

    def update_floats(self, u: list[float]) -> list[float]:
        """:meth:`update` of a short vector given as Python floats, element by element: the same
        numbers (the same IEEE operations in the same order) without numpy's per-call cost, which
        on 1-3 values at 1 kHz is most of the time. The state stays an array."""
        y = self.y
        if y is None:
            out = [float(v) for v in u]
        else:
            alpha = float(self.alpha)
            out = [a + alpha * (b - a) for a, b in zip(y.tolist(), u)] if y.ndim else [
                float(y) + alpha * (float(u[0]) - float(y))]
        self.y = np.array(out) if y is None or y.ndim else np.array(out[0])
        return out
