"""Bumpless transfer between controller configurations (issue: switching modes live).

A controller output that is switched on (force control after IK-only, CFC or OSPC enabled live) is
blended in with a weight that ramps from 0 to 1 in ``transfer_time``, and out the same way; while
its weight is 0 the controller's integrator tracks (is held at zero), so nothing winds up while
the output is not applied. The command then moves by at most the blended change per period, far
below the drives' v_max limit that bounded the step before.
"""
from __future__ import annotations

import numpy as np

# s: the start ramp's length. The drives take the controllers' command over from the lengths the
# plant holds at power-on in this time (the joint command ramps out the first period's gap, the model's
# error there). Long against the feedback filter (T_1,r 80 ms, table 3.1) and the platforms' lowest
# eigenfrequencies (2-5 Hz on the IPAnema 3), short against what a program waits for at start.
START_RAMP = 0.5
# s: the cable force controller's set-point rises from the forces measured at power-on to f_d at most
# at the cable's force range (f_max - f_min) in this time: a few periods at home (the Mini: 2.5 N in
# 0.07 s), half a second where the plant's power-on tension is far from f_d (a Mini border pose: 15 N).
START_FORCE_RANGE_TIME = 1.0


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


class StartRamp:
    """A share s rising from 0 to 1 as a cosine over ``duration`` (of periods of ``dt``), then 1.
    Smooth at both ends (no velocity step), its steepest slope π/2 per duration at the middle."""

    def __init__(self, duration: float, dt: float):
        if not (np.isfinite(duration) and duration >= 0.0 and dt > 0.0):
            raise ValueError(f"the start ramp needs a finite duration >= 0 s and dt > 0 s, got {duration}, {dt}")
        self.periods = int(round(duration / dt))
        self.k = 0

    @property
    def running(self) -> bool:
        return self.k < self.periods

    def share(self) -> float:
        """s of the next period (1.0 once the ramp has ended)."""
        self.k += 1
        if self.k >= self.periods:
            return 1.0
        return 0.5 - 0.5 * float(np.cos(np.pi * self.k / self.periods))
