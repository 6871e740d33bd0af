"""Compiled pulley friction of one sample: the friction compensation (3.35), (3.43)-(3.44) and, for
the simulated plant, its inverse, the platform's forces as the winch force sensor sees them
(3.30)-(3.44), (3.36) (:func:`sensor_force_kernel`, :func:`friction_sensor_force`; the numpy
reference is :meth:`cdpr_control.model.friction.PulleyFriction.sensor_force`). Both Dahl steps loop over
the cables and share the direction step (:func:`_direction`), in this one file because numba's disk
cache keeps a kernel's callees and renews it only when the kernel's own file changes.

The functions of :mod:`cdpr_control.model.friction` that are written in the array subset numba compiles
(the swivelling pulley's tables: the numpy reference itself), compiled, and the Dahl step as a loop
over the cables (:func:`platform_force_kernel`), applied to a
:class:`cdpr_control.model.friction.PulleyFriction`'s state. The tables depend on the wrap
angle alone (the series' constants are fixed), and a robot holding or repeating a pose sees the same
β_np every period: the last tables are kept for the last series while β's bytes repeat (comparing
the bytes costs a fraction of the compiled call; bytes tell -0.0 from 0.0, so a kept table is
always the one the same input computes). The two stay separate compiled calls: a kernel here
calling them would keep a stale copy of their code in numba's disk cache after an edit of
friction.py (the cache follows the caller's file only).
"""
from __future__ import annotations

import functools

import numpy as np

from cdpr_control.kernels.jit import njit

from cdpr_control.model import friction as np_friction
from cdpr_control.model.memo import Memo
from cdpr_control.kernels.robot_data import vector

_tables = njit(np_friction.last_pulley_tables)

# rows of the Dahl state (friction.ROW_*) as literals: numba freezes a global into the cached code,
# which it renews when this file changes, not when friction.py does
_DIRECTION, _THETA_0, _F_0, _THETA, _F_D = 0, 1, 2, 3, 4
if (_DIRECTION, _THETA_0, _F_0, _THETA, _F_D) != (np_friction.ROW_DIRECTION, np_friction.ROW_THETA_0,
                                                   np_friction.ROW_F_0, np_friction.ROW_THETA, np_friction.ROW_F_D):
    raise ImportError("kernels.friction: the Dahl state rows differ from cdpr_control.model.friction.ROW_*")


@njit(error_model="numpy")
def _direction(state, i, thetadot_i, v_eps, alpha_table, gamma_table):
    """Cable i's direction of motion s and its pulley coefficients alpha, gamma (3.41); a direction
    change stores theta_0 and F_0 of the last sample (3.43). Advances ``state``."""
    direction = state[_DIRECTION, i]
    s = np.sign(thetadot_i) if abs(thetadot_i) > v_eps else direction
    if s != direction:
        state[_THETA_0, i] = state[_THETA, i]
        state[_F_0, i] = state[_F_D, i]
    state[_DIRECTION, i] = s
    if s > 0.0:
        return s, alpha_table[2, i], gamma_table[2, i]
    if s < 0.0:
        return s, alpha_table[0, i], gamma_table[0, i]
    return s, alpha_table[1, i], gamma_table[1, i]


@njit(error_model="numpy")
def platform_force_kernel(f_w, theta, thetadot, alpha_table, gamma_table, sigma, v_eps, state, f):
    """friction.platform_force_step (3.41)-(3.44) per cable, into f (m,); advances ``state``.

    The reference as whole-array expressions allocates a temporary per operation, several times the
    arithmetic on 8 numbers; this loop does the same operations in the same order on each element
    (numpy's scalar sign, maximum and exp, as numba compiles the reference's), so the same numbers,
    bit for bit (tests/kernels/test_kernel_wrappers_fast_paths.py). NaN as in the reference: a NaN direction selects
    the s = 0 row, np.maximum keeps a NaN F_c.
    """
    m = state.shape[1]
    if f_w.shape[0] != m or theta.shape[0] != m or thetadot.shape[0] != m or f.shape[0] != m:
        raise ValueError("f_w, theta and thetadot must have one value per cable")   # (no bounds checks)
    for i in range(m):
        s, alpha, gamma = _direction(state, i, thetadot[i], v_eps, alpha_table, gamma_table)
        F_c = np.maximum(s * ((alpha - 1.0) * f_w[i] + gamma * thetadot[i]), 1e-300)    # |F_f| (3.41)
        sF = s * F_c
        F_D = sF + (state[_F_0, i] - sF) * np.exp(-sigma[i] * np.abs(theta[i] - state[_THETA_0, i]) / F_c)  # (3.43)
        state[_THETA, i] = theta[i]
        state[_F_D, i] = F_D
        f[i] = f_w[i] + F_D

# (series, alpha, gamma) of the last call's series, β bytes and shape (the series kept in the value:
# its id cannot be taken by another series while the memo holds it)
_tables_memo = Memo()


def _series_tables(series, beta_last) -> tuple[np.ndarray, np.ndarray]:
    """The compiled PulleySeries.tables of beta_last, computed again only when the series or β's
    bytes differ from the last call's (the step only reads them)."""
    beta = vector(beta_last)
    _, alpha, gamma = _tables_memo((id(series), beta.tobytes(), beta.shape), _compute_tables, series, beta)
    return alpha, gamma


def _compute_tables(series, beta) -> tuple:
    alpha_in, gamma_in = series.inner
    return (series, *_tables(beta, series.mu, series.F_pv, series.has_last, alpha_in, gamma_in))


def friction_platform_force(model, f_w, theta, thetadot, beta_last) -> np.ndarray:
    """PulleyFriction.platform_force of ``model`` from the winch forces f_w (3.40) (the sensor
    forces already converted), compiled; advances the model's Dahl state like the reference."""
    dahl = model.dahl
    alpha, gamma = _series_tables(model.series, beta_last)
    state = dahl.state
    f = np.empty(state.shape[1])
    platform_force_kernel(vector(f_w), vector(theta), vector(thetadot), alpha, gamma, dahl.sigma, dahl.v_eps, state, f)
    return f


# -- the simulator's side: the platform's forces as the winch force sensors see them --------------------

@njit(error_model="numpy")
def sensor_force_kernel(f, theta, thetadot, alpha_table, gamma_table, sigma, v_eps, state, tol, max_iterations,
                        sensor_gain, F_s):
    """friction.sensor_force_step followed by friction.sensor_from_winch_force, per cable.

    Arguments as sensor_force_step; sensor_gain = 1 - cos(beta_1) (3.36); writes the sensor forces
    F_s (m,) and advances ``state``. The fixed-point iteration runs on all cables together and stops
    on the largest change, as the reference does (the iteration count is shared). Maxima propagate
    NaN as numpy's max does (a NaN never satisfies the stopping test).
    """
    m = state.shape[1]
    if f.shape[0] != m or theta.shape[0] != m or thetadot.shape[0] != m:     # the loops do not check bounds
        raise ValueError("f, theta and thetadot must have one value per cable")
    c1, c0, neg_decay, s, f_w = np.empty(m), np.empty(m), np.empty(m), np.empty(m), np.empty(m)
    f_max = 0.0
    for i in range(m):
        s_i, alpha, gamma = _direction(state, i, thetadot[i], v_eps, alpha_table, gamma_table)
        s[i] = s_i
        c1[i] = s_i * (alpha - 1.0)                           # s F_f = c1 f_w + c0 (3.41)
        c0[i] = s_i * gamma * thetadot[i]
        neg_decay[i] = -sigma[i] * abs(theta[i] - state[_THETA_0, i])
        f_w[i] = f[i] - state[_F_D, i]
        a_f = abs(f[i])
        if a_f > f_max or a_f != a_f:
            f_max = a_f
    scale = tol * (f_max + 1.0)
    for _ in range(max_iterations):
        change = 0.0
        for i in range(m):
            F_c = c1[i] * f_w[i] + c0[i]
            if F_c < 1e-300:                                  # np.maximum(F_c, 1e-300), NaN kept
                F_c = 1e-300
            E = np.exp(neg_decay[i] / F_c)
            a = s[i] - s[i] * E
            new = (f[i] - a * c0[i] - state[_F_0, i] * E) / (1.0 + a * c1[i])     # (3.43)
            d = abs(new - f_w[i])
            if d > change or d != d:
                change = d
            f_w[i] = new
        if change <= scale:
            break
    for i in range(m):
        state[_THETA, i] = theta[i]
        state[_F_D, i] = f[i] - f_w[i]
        F_s[i] = f_w[i] * sensor_gain


@functools.lru_cache(maxsize=None)
def _sensor_gain(beta_1: float) -> float:
    """1 - cos(beta_1) of friction.sensor_from_winch_force, with numpy's cos (the same number)."""
    return float(1.0 - np.cos(beta_1))


def friction_sensor_force(model, f, theta, thetadot, beta_last, tol: float = 1e-12,
                          max_iterations: int = 50) -> np.ndarray:
    """PulleyFriction.sensor_force of ``model`` compiled: the sensor forces F_s (m,) that the forces
    at the platform f (m,) show (3.44), (3.36); advances the model's Dahl state like the reference."""
    alpha, gamma = model.series.tables(beta_last)
    dahl = model.dahl
    F_s = np.empty(dahl.state.shape[1])
    sensor_force_kernel(vector(f), vector(theta), vector(thetadot), alpha, gamma, dahl.sigma, dahl.v_eps, dahl.state,
                        tol, max_iterations, _sensor_gain(model.beta_1), F_s)
    return F_s
