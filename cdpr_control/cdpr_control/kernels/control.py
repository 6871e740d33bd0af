"""Compiled PI arithmetic of :class:`cdpr_control.control.pi_control.PIController` (OSPC (3.16), CFC (3.19)),
and one whole period of the cable force controller (3.19)-(3.23)."""
from __future__ import annotations

import numpy as np

from cdpr_control.kernels.jit import njit
from cdpr_control.kernels.model import k_spec


# The constants of one CFC period (:func:`cfc_period`), by name: the PT1 feedback filter's alpha
# (3.20), the period dt, the widened saturation (F_sat,n, F_sat,p, band, factor) and the stiffness
# model of (3.23): ``linear`` 1.0 for k_spec nominal / l_t (2.15), 0.0 for the secant of
# k_spec = k0 + k1 f + k2 f^2 (2.16)-(2.17). A record array of one element: numba reads its fields by
# name at the cost of an array argument (a NamedTuple of eleven floats costs 2 us more a call).
CFC_CONSTANTS = np.dtype([(name, np.float64) for name in (
    "alpha", "dt", "F_sat_n", "F_sat_p", "widen_band", "widen_factor", "linear", "k_spec_nominal", "k0", "k1", "k2")])


def cfc_constants(**values: float) -> np.ndarray:
    """The (1,) record of :data:`CFC_CONSTANTS` with ``values`` (every field by name)."""
    missing = set(CFC_CONSTANTS.names) - set(values)
    if missing:
        raise TypeError(f"cfc_constants needs {sorted(missing)}")
    return np.array([tuple(float(values[name]) for name in CFC_CONSTANTS.names)], dtype=CFC_CONSTANTS)


@njit(error_model="numpy")
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


@njit(error_model="numpy")
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


@njit(error_model="numpy")
def cfc_period(f_d, f_ff, f, f_min, f_max, l_t, dq_0, y, integrator, K_p, T_i, constants, saturated, out):
    """One period of the cable force controller (3.19)-(3.23) in one call, the twin of
    control.cable_force_control.cfc_period (the PI and the widened saturation above).

    y: the PT1 state of (3.20), updated in place; constants: the CFC_CONSTANTS record; out (4, m): the new
    integrator, the PI output u, f_c,out = f_ff + u (3.22) and Δq_CFC (3.23) with K_l the linear
    k_spec / l_t (2.15) or the secant (2.16)-(2.17) at f_c,out.
    """
    m = f.shape[0]
    c = constants[0]
    e, sat_n, sat_p = np.empty(m), np.empty(m), np.empty(m)
    for i in range(m):
        y[i] += c.alpha * (f[i] - y[i])                                # (3.20)
        e[i] = f_d[i] - y[i]                                           # (3.2)
    widened_saturation_kernel(y, f_min, f_max, c.F_sat_n, c.F_sat_p, c.widen_band, c.widen_factor, sat_n, sat_p)
    pi_update(e, K_p, T_i, c.dt, integrator, sat_n, sat_p, out[0], saturated, out[1])   # (3.19)
    for i in range(m):
        f_out = f_ff[i] + out[1, i]                                    # (3.22)
        if c.linear != 0.0:
            k = c.k_spec_nominal / l_t[i]                              # (2.15)
        else:
            k = k_spec(max(f_out, 0.0), c.k0, c.k1, c.k2) / l_t[i]    # (2.16)-(2.17)
        out[2, i] = f_out
        out[3, i] = f_out / k - dq_0[i]                                # (3.23)


@njit(error_model="numpy")
def force_watch_period(f, f_d, has_f_d, bounds, state, alpha, inv_dt, out):
    """One period of the force watch's per-cable counters and rates, the twin of
    control.safety.force_watch_period (see there for the arguments) -> whether f is finite."""
    m = f.shape[0]
    for i in range(m):
        if not np.isfinite(f[i]):
            return False
    clean, longest, i_longest, worst, i_worst = True, -1.0, 0, -np.inf, 0
    for i in range(m):
        fi = f[i]
        outside = fi < bounds[0, i] or fi > bounds[1, i]
        state[0, i] = state[0, i] + 1.0 if outside else 0.0
        r = state[1, i] + alpha * ((fi - state[3, i]) * inv_dt - state[1, i])
        state[1, i] = r
        if not has_f_d:
            away = abs(r)
        elif fi > f_d[i]:
            away = r
        elif fi < f_d[i]:
            away = -r
        else:
            away = 0.0
        state[2, i] = away
        state[3, i] = fi
        clean = clean and not outside and abs(r) < 0.5 * bounds[2, i]
        if state[0, i] > longest:
            longest, i_longest = state[0, i], i
        excess = away / bounds[2, i]
        if excess > worst:
            worst, i_worst = excess, i
    out[0], out[1], out[2], out[3], out[4] = clean, longest, i_longest, worst, i_worst
    return True
