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
def _cfc_error(f_d, f, f_min, f_max, y, c):
    """The CFC period's feedback: y <- PT1 of f (3.20) in place -> (e = f_d - y (3.2), the widened
    saturation's sat_n, sat_p)."""
    m = f.shape[0]
    e, sat_n, sat_p = np.empty(m), np.empty(m), np.empty(m)
    for i in range(m):
        y[i] += c.alpha * (f[i] - y[i])                                # (3.20)
        e[i] = f_d[i] - y[i]                                           # (3.2)
    widened_saturation_kernel(y, f_min, f_max, c.F_sat_n, c.F_sat_p, c.widen_band, c.widen_factor, sat_n, sat_p)
    return e, sat_n, sat_p


@njit(error_model="numpy")
def _cfc_output(f_ff, l_t, dq_0, c, out):
    """The CFC period's output from the PI's u (out[1]): f_c,out = f_ff + u (3.22) into out[2] and
    Δq_CFC (3.23) into out[3], K_l the linear k_spec / l_t (2.15) or the secant (2.16)-(2.17)."""
    for i in range(f_ff.shape[0]):
        f_out = f_ff[i] + out[1, i]                                    # (3.22)
        if c.linear != 0.0:
            k = c.k_spec_nominal / l_t[i]                              # (2.15)
        else:
            k = k_spec(max(f_out, 0.0), c.k0, c.k1, c.k2) / l_t[i]    # (2.16)-(2.17)
        out[2, i] = f_out
        out[3, i] = f_out / k - dq_0[i]                                # (3.23)


@njit(error_model="numpy")
def cfc_period(f_d, f_ff, f, f_min, f_max, l_t, dq_0, y, integrator, K_p, T_i, constants, saturated, out):
    """One period of the cable force controller (3.19)-(3.23) in one call, the twin of
    control.cable_force_control.cfc_period (the PI and the widened saturation above).

    y: the PT1 state of (3.20), updated in place; constants: the CFC_CONSTANTS record; out (4, m): the new
    integrator, the PI output u, f_c,out = f_ff + u (3.22) and Δq_CFC (3.23) with K_l the linear
    k_spec / l_t (2.15) or the secant (2.16)-(2.17) at f_c,out.
    """
    c = constants[0]
    e, sat_n, sat_p = _cfc_error(f_d, f, f_min, f_max, y, c)
    pi_update(e, K_p, T_i, c.dt, integrator, sat_n, sat_p, out[0], saturated, out[1])   # (3.19)
    _cfc_output(f_ff, l_t, dq_0, c, out)


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


# a row of A^T left with less than this fraction of its norm by the rows before it (in the free
# cables' components) counts as dependent on them: the projector is then the pseudo-inverse's
_INDEPENDENT = 1e-6


@njit(error_model="numpy")
def nullspace_projector_kernel(AT, held, P):
    """P (m, m) of control.cable_force_control.nullspace_projector(AT, held): the orthogonal
    projector onto the nullspace of [A^T; E_held^T] (2.41), the internal forces with the held cables'
    components 0. With F the free cables: the rows of A^T in the components F orthonormalised (Gram-
    Schmidt, twice), Q with min(6, |F|) rows, P_FF = I - Q^T Q, the held rows and columns 0. The same
    projector as the reference's I - A (A^T A)^-1 A^T (its 6x6 solve, no cable held) and
    I - pinv(M) M (held cables), with the rounding error of an orthogonalisation (eps cond(A^T)), not of
    the normal equations (eps cond(A^T)^2): six or fewer independent free cables give P = 0 to rounding.
    Where a row keeps less than ``_INDEPENDENT`` of its norm (A^T near rank-deficient on the free
    cables) the pseudo-inverse's projector, as the reference."""
    m = AT.shape[1]
    n_free = 0
    for k in range(m):
        if not held[k]:
            n_free += 1
    Q, v = np.zeros((6, m)), np.empty(m)
    rank = 0
    for r in range(6):
        size = 0.0
        for k in range(m):
            v[k] = 0.0 if held[k] else AT[r, k]
            size += v[k] * v[k]
        size = np.sqrt(size)
        for _ in range(2):                                # classical Gram-Schmidt, twice
            for j in range(rank):
                s = 0.0
                for k in range(m):
                    s += Q[j, k] * v[k]
                for k in range(m):
                    v[k] -= s * Q[j, k]
        norm = 0.0
        for k in range(m):
            norm += v[k] * v[k]
        norm = np.sqrt(norm)
        if norm > _INDEPENDENT * size and rank < n_free:
            for k in range(m):
                Q[rank, k] = v[k] / norm
            rank += 1
    if rank == min(6, n_free):
        for i in range(m):
            for j in range(i + 1):
                if held[i] or held[j]:
                    P[i, j] = P[j, i] = 0.0
                    continue
                s = 0.0
                for r in range(rank):
                    s += Q[r, i] * Q[r, j]
                P[i, j] = P[j, i] = (1.0 if i == j else 0.0) - s
        return
    n_held = m - n_free                                   # rank-deficient: the reference's pseudo-inverse
    M = np.empty((6 + n_held, m))
    M[:6] = AT
    r = 6
    for k in range(m):
        if held[k]:
            M[r] = 0.0
            M[r, k] = 1.0
            r += 1
    P[:, :] = np.eye(m) - np.linalg.pinv(M) @ M


@njit(error_model="numpy")
def internal_pi_kernel(e, K_p, T_i, dt, integrator, u_neg, u_pos, AT, integ, saturated, output):
    """One period of control.cable_force_control.internal_pi_update into the (new) arrays integ,
    saturated, output: the PI (3.19) whose increment is projected onto the internal forces (2.41)
    (P of :func:`nullspace_projector_kernel`), a part of I outside the nullspace decaying by
    min(1, dt/T_i) a period, the saturated cables pushed further out held and the increment
    projected again, the integrator scaled into the output range (see the reference)."""
    m = e.shape[0]
    P, Ph = np.empty((m, m)), np.empty((m, m))
    held, pushed = np.zeros(m, dtype=np.bool_), np.empty(m, dtype=np.bool_)
    nullspace_projector_kernel(AT, held, P)
    I, p, printed, step = np.empty(m), np.empty(m), np.empty(m), np.empty(m)
    for i in range(m):                                   # the part outside the nullspace decays
        s = 0.0
        for k in range(m):
            s += P[i, k] * integrator[k]
        I[i] = integrator[i] - min(1.0, dt / T_i[i]) * (integrator[i] - s)
    for i in range(m):
        p[i] = K_p[i] * e[i]
        printed[i] = K_p[i] * dt / T_i[i] * e[i]
    for i in range(m):
        s = 0.0
        for k in range(m):
            s += P[i, k] * printed[k]
        step[i] = s
    any_held = False
    for _ in range(m):                                   # conditional integration inside the projection
        same, anything = True, False
        for i in range(m):
            u_free = p[i] + I[i] + step[i]
            out = (u_free > u_pos[i] and step[i] > 0.0) or (u_free < -u_neg[i] and step[i] < 0.0)
            pushed[i] = out or (any_held and held[i])
            anything = anything or pushed[i]
            same = same and pushed[i] == held[i]
        if (any_held and same) or not (any_held or anything):
            break
        any_held = True
        held[:] = pushed
        nullspace_projector_kernel(AT, held, Ph)
        for i in range(m):
            s = 0.0
            for k in range(m):
                s += Ph[i, k] * printed[k]
            step[i] = s
    factor, outside = 1.0, False                         # clamping: one factor towards 0
    for i in range(m):
        c = I[i] + step[i]
        integ[i] = c
        if c > u_pos[i]:
            outside = True
            factor = min(factor, u_pos[i] / c)
        elif c < -u_neg[i]:
            outside = True
            factor = min(factor, -u_neg[i] / c)
    for i in range(m):
        if outside:
            integ[i] = integ[i] * factor
        u = p[i] + integ[i]
        lo, hi = -u_neg[i], u_pos[i]
        saturated[i] = u > hi or u < lo
        output[i] = lo if u < lo else (hi if u > hi else u)


@njit(error_model="numpy")
def cfc_internal_period(f_d, f_ff, f, f_min, f_max, l_t, dq_0, y, integrator, K_p, T_i, AT, constants, saturated,
                        out):
    """:func:`cfc_period` with the internal integral (:func:`internal_pi_kernel`, A^T = ``AT`` of
    x_d) in place of the PI (3.19): the twin of control.cable_force_control.cfc_internal_period."""
    c = constants[0]
    e, sat_n, sat_p = _cfc_error(f_d, f, f_min, f_max, y, c)
    internal_pi_kernel(e, K_p, T_i, c.dt, integrator, sat_n, sat_p, AT, out[0], saturated, out[1])   # (3.19)
    _cfc_output(f_ff, l_t, dq_0, c, out)
