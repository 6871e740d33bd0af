"""External wrench pulses on the platform: a hand pushing it (thesis section 5.2), an impact.

A pulse is a peak wrench [force; torque] (base frame, torque about the application point) at a
point fixed in the platform, scaled over time by a shape (the SHAPE_* constants of
cdpr_msgs/srv/ApplyWrench):

    step        1 from the start, for ``duration`` (0: until replaced)
    rectangle   1 for ``duration``
    ramp        t / duration, then 1 (until replaced)
    half_sine   sin(pi t / duration) for ``duration``
    sine        sin(2 pi frequency t) for ``duration`` (0: until replaced)
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from cdpr_control.model.kinematics import cross

SHAPES = ("step", "rectangle", "ramp", "half_sine", "sine")


@dataclass(frozen=True)
class WrenchPulse:
    wrench: tuple                       # (6,) peak [N, N m], base frame
    point: tuple = (0.0, 0.0, 0.0)      # application point in the platform frame [m]
    shape: str = "step"
    duration: float = 0.0               # s
    frequency: float = 0.0              # Hz, sine only
    t_start: float = 0.0                # s, simulation time of the start

    def __post_init__(self):
        w, p = np.asarray(self.wrench, dtype=float), np.asarray(self.point, dtype=float)
        if w.shape != (6,) or not np.all(np.isfinite(w)):
            raise ValueError(f"wrench must be 6 finite numbers, got {self.wrench!r}")
        if p.shape != (3,) or not np.all(np.isfinite(p)):
            raise ValueError(f"point must be 3 finite numbers, got {self.point!r}")
        if self.shape not in SHAPES:
            raise ValueError(f"shape must be one of {', '.join(SHAPES)}, got {self.shape!r}")
        if not (math.isfinite(self.duration) and self.duration >= 0.0):
            raise ValueError(f"duration must be >= 0 s, got {self.duration}")
        if self.shape in ("rectangle", "half_sine") and self.duration == 0.0:
            raise ValueError(f"a {self.shape} pulse needs a duration > 0 s")
        if self.shape == "sine" and not (math.isfinite(self.frequency) and self.frequency > 0.0):
            raise ValueError(f"a sine pulse needs a frequency > 0 Hz, got {self.frequency}")

    def scale(self, t: float) -> float:
        """Shape factor at simulation time t (0 before the start and after the end)."""
        tau = t - self.t_start
        if tau < 0.0:
            return 0.0
        T = self.duration
        if self.shape == "ramp":
            return min(tau / T, 1.0) if T > 0.0 else 1.0
        if T > 0.0 and tau >= T:
            return 0.0
        if self.shape == "half_sine":
            return math.sin(math.pi * tau / T)
        if self.shape == "sine":
            return math.sin(2.0 * math.pi * self.frequency * tau)
        return 1.0

    def finished(self, t: float) -> bool:
        return self.shape != "ramp" and self.duration > 0.0 and t - self.t_start >= self.duration

    def wrench_about_origin(self, t: float, R) -> np.ndarray:
        """The pulse at time t as a wrench about the platform origin (platform rotation R), base frame."""
        s = self.scale(t)
        if s == 0.0:
            return np.zeros(6)
        w = s * np.asarray(self.wrench, dtype=float)
        arm = R @ np.asarray(self.point, dtype=float)
        w[3:] += cross(arm, w[:3])
        return w
