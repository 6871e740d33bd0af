"""Wrench set-point generation with the Smith predictor of section 3.6.1.

The measured wrench w = -A^T f (2.11) contains the platform's inertia forces only after the
transfer delay T_d,w (3.25). The desired wrench anticipates them (3.26):

    w_d = w + (I - G_w(s)) w_dyn = w + w_dyn(t) - w_dyn(t - T_d,w) ,

where w_dyn is the inverse-dynamics wrench (2.33) of the desired motion. Written as
w_d = w_dyn + w_dist with the disturbance w_dist = w - w_dyn(t - T_d,w) of (3.24), the measured
part can be saturated (section 3.6.1): |w_dist| <= w_dist_max per axis limits how far model errors
and the platform's own oscillations reach the force set-point (w_dist_max = 0 gives the model
wrench (3.1), no limit the pure null-space control).

A low-pass filter against sensor noise and platform oscillation belongs on the disturbance
w_dist, not on the measured wrench w: filtering w before the delayed model wrench is subtracted
leaves w_d = w_dyn + LPF(w) - w_dyn(t - T_d,w), whose anticipation of the inertia forces lasts one
delay T_d,w and then falls back to the lag of the filter, the lag of Fig. 3.13 that (3.26) removes.
"""
from __future__ import annotations

import numpy as np

from cdpr_control import kernels
from cdpr_control.kernels.robot_data import vector
from cdpr_control.kernels.setpoint import smith_step


class WrenchSetpoint:
    """Discrete (3.26): a ring buffer delays w_dyn by round(T_d,w / dt) periods."""

    _zeros: np.ndarray | None = None          # w_known of update_filtered when there is none

    def __init__(self, T_d_w: float, dt: float, n: int = 6):
        if not dt > 0.0 or not T_d_w >= 0.0:
            raise ValueError(f"need dt > 0 s and T_d_w >= 0 s, got dt={dt}, T_d_w={T_d_w}")
        self.dt = dt
        self.n = n
        self.set_delay(T_d_w)

    def set_delay(self, T_d_w: float) -> None:
        """Change T_d,w; the buffer restarts filled with the latest w_dyn (no jump in w_d)."""
        self.T_d_w = T_d_w
        self.delay = int(round(T_d_w / self.dt))
        buffer = getattr(self, "_buffer", None)
        last = np.zeros(self.n) if buffer is None else buffer[self._index - 1]      # the row written last
        self._buffer = np.tile(last, (self.delay + 1, 1))
        self._index = 0

    def reset(self, w_dyn=None) -> None:
        """Fill the delay line with w_dyn (e.g. the static wrench at start-up)."""
        self._buffer[:] = 0.0 if w_dyn is None else np.asarray(w_dyn, dtype=float)

    def update(self, w, w_dyn, w_dist_max=None, dist_filter=None, w_known=None) -> np.ndarray:
        """One period: measured wrench w and model wrench w_dyn -> w_d (3.26), optionally with
        the disturbance w - w_dyn(t - T_d,w) filtered (``dist_filter``, a callable such as
        LowPass.update) and then saturated to ±w_dist_max (6,) about ``w_known``, a part of the
        disturbance that is known (an identified payload): it does not count against the limit,
        and it changes nothing else (adding it to w_dyn instead would count it twice while the
        filter catches up, a positive feedback through the payload estimate)."""
        w_dyn = np.asarray(w_dyn, dtype=float)
        self._buffer[self._index] = w_dyn
        self._index = (self._index + 1) % (self.delay + 1)
        delayed = self._buffer[self._index]        # written `delay` periods ago
        w_dist = np.asarray(w, dtype=float) - delayed                                 # (3.24)
        if dist_filter is not None:
            w_dist = dist_filter(w_dist)
        if w_dist_max is not None:
            known = 0.0 if w_known is None else np.asarray(w_known, dtype=float)
            w_dist = known + np.minimum(np.maximum(w_dist - known, -w_dist_max), w_dist_max)    # np.clip, faster
        return w_dyn + w_dist

    def update_filtered(self, w, w_dyn, w_dist_max, low_pass, w_known=None) -> np.ndarray:
        """:meth:`update` with the disturbance filtered by ``low_pass`` (a LowPass) and saturated to
        ±w_dist_max (6,): the law :func:`smith_period` (compiled: kernels.setpoint.smith_step, ~1 us
        against ~6 us of numpy calls, the same numbers) once the filter has started."""
        if low_pass.y is None:                          # (its first sample initialises the filter)
            return self.update(w, w_dyn, w_dist_max, low_pass.update, w_known)
        return smith_period(self, w, w_dyn, w_dist_max, low_pass, w_known)

    def _compiled_period(self, w, w_dyn, w_dist_max, low_pass, w_known) -> np.ndarray:
        if self._zeros is None:
            self._zeros = np.zeros(self.n)
        w_d = np.empty(self.n)
        smith_step(self._buffer, self._index, vector(w), vector(w_dyn), low_pass.y, low_pass.alpha,
                   vector(w_dist_max), self._zeros if w_known is None else vector(w_known), w_d)
        self._index = (self._index + 1) % (self.delay + 1)
        return w_d


def _smith_period(predictor: WrenchSetpoint, w, w_dyn, w_dist_max, low_pass, w_known=None) -> np.ndarray:
    """One period of the Smith predictor (3.24)-(3.26) with the disturbance low-passed and saturated."""
    return predictor.update(w, w_dyn, w_dist_max, low_pass.update, w_known)


smith_period = kernels.law("smith_period", _smith_period, WrenchSetpoint._compiled_period)
