"""Compiled PI arithmetic of :class:`cdpr_control.pi_control.PIController` (OSPC (3.16), CFC (3.19))."""
from __future__ import annotations

import numba


@numba.njit(cache=True, error_model="numpy")
def pi_update(e, K_p, T_i, dt, integrator, u_neg, u_pos, integ, saturated, output):
    """One PI period as PIController.update into the (new) arrays integ, saturated, output.

    u = clip(K_p e + I, -u_neg, u_pos); I integrates K_p dt / T_i e unless that pushes a saturated
    output further out, and is clamped to the output range (anti-windup).
    """
    for i in range(e.shape[0]):
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


@numba.njit(cache=True, error_model="numpy")
def widened_saturation_kernel(f, f_min, f_max, F_sat_n, F_sat_p, band, factor, sat_n, sat_p):
    """sat_n, sat_p (m,) of cable_force_control.widened_saturation: F_sat,n and F_sat,p raised
    linearly up to ``factor`` times as f enters the band of width ``band`` at f_max and f_min."""
    gain = factor - 1.0
    for i in range(f.shape[0]):
        near_min = (f_min[i] + band - f[i]) / band
        near_min = 0.0 if near_min < 0.0 else (1.0 if near_min > 1.0 else near_min)
        near_max = (f[i] - (f_max[i] - band)) / band
        near_max = 0.0 if near_max < 0.0 else (1.0 if near_max > 1.0 else near_max)
        sat_n[i] = F_sat_n * (1.0 + gain * near_max)
        sat_p[i] = F_sat_p * (1.0 + gain * near_min)
