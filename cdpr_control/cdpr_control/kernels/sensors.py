"""Compiled sensor side of the simulated plant: the pulley friction from the platform to the winch
force sensor (3.30)-(3.44) and the sensor pulley (3.36), once per control period.

:meth:`cdpr_control.friction.PulleyFriction.sensor_force` is the numpy reference; the function here
is the same arithmetic as loops over the m cables, in one compiled call. As whole-array
expressions (even compiled by numba) it allocates a temporary per operation, which costs several
times the arithmetic on 8 numbers; the loops do the same operations in the same order on each
element, so the results are the same numbers as the reference compiled by numba (plain numpy's
vectorised exp may round the last bit differently). The model keeps its state; the wrapper passes
it in.
"""
from __future__ import annotations

import functools

import numba
import numpy as np

from .. import friction as np_friction
from .robot_data import vector

# rows of the Dahl state (friction.ROW_*) as literals: numba freezes a global into the cached code,
# which it renews when this file changes, not when friction.py does
_DIRECTION, _THETA_0, _F_0, _THETA, _F_D = 0, 1, 2, 3, 4
if (_DIRECTION, _THETA_0, _F_0, _THETA, _F_D) != (np_friction.ROW_DIRECTION, np_friction.ROW_THETA_0,
                                                   np_friction.ROW_F_0, np_friction.ROW_THETA, np_friction.ROW_F_D):
    raise ImportError("kernels.sensors: the Dahl state rows differ from cdpr_control.friction.ROW_*")


@numba.njit(cache=True, error_model="numpy")
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
        direction = state[_DIRECTION, i]
        s_i = np.sign(thetadot[i]) if abs(thetadot[i]) > v_eps else direction
        if s_i != direction:                                  # store theta_0, F_0 (3.43)
            state[_THETA_0, i] = state[_THETA, i]
            state[_F_0, i] = state[_F_D, i]
        state[_DIRECTION, i] = s_i
        if s_i > 0.0:
            alpha, gamma = alpha_table[2, i], gamma_table[2, i]
        elif s_i < 0.0:
            alpha, gamma = alpha_table[0, i], gamma_table[0, i]
        else:
            alpha, gamma = alpha_table[1, i], gamma_table[1, i]
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
