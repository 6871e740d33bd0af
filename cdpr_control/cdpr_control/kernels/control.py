"""Compiled PI arithmetic of :class:`cdpr_control.pi_control.PIController` (OSPC (3.16), CFC (3.19))."""
from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True, error_model="numpy")
def pi_update(e, K_p, T_i, dt, integrator, u_neg, u_pos):
    """One PI period as PIController.update: returns new arrays (integrator, saturated, output).

    u = clip(K_p e + I, -u_neg, u_pos); I integrates K_p dt / T_i e unless that pushes a saturated
    output further out, and is clamped to the output range (anti-windup).
    """
    n = e.shape[0]
    integ, saturated, output = np.empty(n), np.empty(n, dtype=np.bool_), np.empty(n)
    for i in range(n):
        lo, hi = -u_neg[i], u_pos[i]
        p = K_p[i] * e[i]
        candidate = integrator[i] + K_p[i] * dt / T_i[i] * e[i]
        u_free = p + candidate
        blocked = (u_free > hi and e[i] > 0.0) or (u_free < lo and e[i] < 0.0)
        v = integrator[i] if blocked else candidate
        v = lo if v < lo else (hi if v > hi else v)
        u = p + v
        integ[i] = v
        saturated[i] = u > hi or u < lo
        output[i] = lo if u < lo else (hi if u > hi else u)
    return integ, saturated, output
