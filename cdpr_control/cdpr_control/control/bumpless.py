"""Bumpless transfer between controller configurations (issue: switching modes live).

A controller output that is switched on (force control after IK-only, CFC or OSPC enabled live) is
blended in with a weight that ramps from 0 to 1 in ``transfer_time``, and out the same way; while
its weight is 0 the controller's integrator tracks (is held at zero), so nothing winds up while
the output is not applied. The command then moves by at most the blended change per period, far
below the drives' v_max limit that bounded the step before.
"""
from __future__ import annotations


class Blend:
    """A weight in [0, 1] moving towards 1 (active) or 0 (inactive) at 1 / transfer_time per second."""

    def __init__(self, transfer_time: float, dt: float, active: bool = True):
        if not (transfer_time >= 0.0 and dt > 0.0):
            raise ValueError(f"need transfer_time >= 0 s and dt > 0 s, got {transfer_time}, {dt}")
        self.dt = dt
        self.set_transfer_time(transfer_time)
        self.value = 1.0 if active else 0.0

    def set_transfer_time(self, transfer_time: float) -> None:
        if not transfer_time >= 0.0:
            raise ValueError(f"transfer_time must be >= 0 s, got {transfer_time}")
        self.transfer_time = transfer_time
        self.step = 1.0 if transfer_time == 0.0 else min(1.0, self.dt / transfer_time)

    def update(self, active: bool) -> float:
        target = 1.0 if active else 0.0
        self.value = min(self.value + self.step, target) if target > self.value else max(self.value - self.step, target)
        return self.value
