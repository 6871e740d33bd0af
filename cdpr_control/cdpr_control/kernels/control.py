"""Compiled PI arithmetic of :class:`cdpr_control.control.pi_control.PIController` (OSPC (3.16), CFC (3.19)),
and one whole period of the cable force controller (3.19)-(3.23)."""
from __future__ import annotations

import numba
import numpy as np


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


@numba.njit(cache=True, error_model="numpy")
def cfc_period(f_d, f_ff, f, f_min, f_max, l_t, dq_0, y, integrator, K_p, T_i, c, saturated, out):
    """One period of the cable force controller (3.19)-(3.23) in one call, as
    CableForceController.update with CableForceControl's stiffness model (the PI and the widened
    saturation above; here, not in a module of its own, so that an edit of them recompiles it).

    y: the PT1 state of (3.20), updated in place; c = [alpha of the PT1, dt, F_sat,n, F_sat,p, widen
    band, widen factor, linear model (1/0), k_spec nominal, k0, k1, k2]; out (4, m): the new
    integrator, the PI output u, f_c,out = f_ff + u (3.22) and Δq_CFC (3.23) with K_l the linear
    k_spec / l_t (2.15) or the secant (2.16)-(2.17) at f_c,out.
    """
    m = f.shape[0]
    e, sat_n, sat_p = np.empty(m), np.empty(m), np.empty(m)
    for i in range(m):
        y[i] += c[0] * (f[i] - y[i])                                   # (3.20)
        e[i] = f_d[i] - y[i]                                           # (3.2)
    widened_saturation_kernel(y, f_min, f_max, c[2], c[3], c[4], c[5], sat_n, sat_p)
    pi_update(e, K_p, T_i, c[1], integrator, sat_n, sat_p, out[0], saturated, out[1])   # (3.19)
    for i in range(m):
        f_out = f_ff[i] + out[1, i]                                    # (3.22)
        if c[6] != 0.0:
            k = c[7] / l_t[i]                                          # (2.15)
        else:
            fp = max(f_out, 0.0)
            k = (c[8] + fp * (c[9] + c[10] * fp)) / l_t[i]             # (2.16)-(2.17)
        out[2, i] = f_out
        out[3, i] = f_out / k - dq_0[i]                                # (3.23)
