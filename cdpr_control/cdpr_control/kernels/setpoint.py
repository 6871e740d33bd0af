"""Compiled Smith predictor period of the force set-point (3.24)-(3.26), section 3.6.1.

:meth:`cdpr_control.control.wrench_setpoint.WrenchSetpoint.update` with a
:class:`cdpr_control.control.filters.LowPass` on the disturbance, as one loop over the six axes: the same
operations in the same order, so the same numbers (tests/kernels/test_kernels.py compares them).
"""
from __future__ import annotations

from cdpr_control.kernels.jit import njit


@njit(error_model="numpy")
def smith_step(buffer, index, w, w_dyn, y, alpha, w_dist_max, known, w_d):
    """Write w_dyn into the delay line ``buffer`` at ``index``; the disturbance w - w_dyn(t - T_d,w)
    (3.24) (the row after ``index``) through the PT1 state y (y += alpha (u - y)), saturated to
    ±w_dist_max about ``known`` (np.maximum/np.minimum: NaN propagates); w_d = w_dyn + w_dist (3.26)."""
    delayed = (index + 1) % buffer.shape[0]
    for j in range(w.shape[0]):
        buffer[index, j] = w_dyn[j]
    for j in range(w.shape[0]):
        y[j] += alpha * ((w[j] - buffer[delayed, j]) - y[j])
        excess = y[j] - known[j]
        if excess < -w_dist_max[j]:
            excess = -w_dist_max[j]
        if excess > w_dist_max[j]:
            excess = w_dist_max[j]
        w_d[j] = w_dyn[j] + (known[j] + excess)
