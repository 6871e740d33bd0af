"""Compiled friction compensation of one sample, (3.35) and (3.43)-(3.44).

The functions of :mod:`cdpr_control.friction` that are written in the array subset numba compiles
(the swivelling pulley's tables: the numpy reference itself), compiled, and the Dahl step as a loop
over the cables (:func:`platform_force_kernel`), applied to a
:class:`cdpr_control.friction.PulleyFriction`'s state. The tables depend on the wrap
angle alone (the series' constants are fixed), and a robot holding or repeating a pose sees the same
β_np every period: the last tables are kept for the last series while β's bytes repeat (comparing
the bytes costs a fraction of the compiled call; bytes tell -0.0 from 0.0, so a kept table is
always the one the same input computes). The two stay separate compiled calls: a kernel here
calling them would keep a stale copy of their code in numba's disk cache after an edit of
friction.py (the cache follows the caller's file only).
"""
from __future__ import annotations

import numba
import numpy as np

from .. import friction as np_friction
from .robot_data import vector

_tables = numba.njit(cache=True)(np_friction.last_pulley_tables)

# rows of the Dahl state (friction.ROW_*) as literals: numba freezes a global into the cached code,
# which it renews when this file changes, not when friction.py does
_DIRECTION, _THETA_0, _F_0, _THETA, _F_D = 0, 1, 2, 3, 4
if (_DIRECTION, _THETA_0, _F_0, _THETA, _F_D) != (np_friction.ROW_DIRECTION, np_friction.ROW_THETA_0,
                                                   np_friction.ROW_F_0, np_friction.ROW_THETA, np_friction.ROW_F_D):
    raise ImportError("kernels.friction: the Dahl state rows differ from cdpr_control.friction.ROW_*")


@numba.njit(cache=True, error_model="numpy")
def platform_force_kernel(f_w, theta, thetadot, alpha_table, gamma_table, sigma, v_eps, state, f):
    """friction.platform_force_step (3.41)-(3.44) per cable, into f (m,); advances ``state``.

    The reference as whole-array expressions allocates a temporary per operation, several times the
    arithmetic on 8 numbers; this loop does the same operations in the same order on each element
    (numpy's scalar sign, maximum and exp, as numba compiles the reference's), so the same numbers,
    bit for bit (tests/test_fast_paths_kwrap.py). NaN as in the reference: a NaN direction selects
    the s = 0 row, np.maximum keeps a NaN F_c.
    """
    m = state.shape[1]
    if f_w.shape[0] != m or theta.shape[0] != m or thetadot.shape[0] != m or f.shape[0] != m:
        raise ValueError("f_w, theta and thetadot must have one value per cable")   # (no bounds checks)
    for i in range(m):
        direction = state[_DIRECTION, i]
        s = np.sign(thetadot[i]) if np.abs(thetadot[i]) > v_eps else direction
        if s != direction:                                  # store theta_0, F_0 (3.43)
            state[_THETA_0, i] = state[_THETA, i]
            state[_F_0, i] = state[_F_D, i]
        state[_DIRECTION, i] = s
        if s > 0.0:
            alpha, gamma = alpha_table[2, i], gamma_table[2, i]
        elif s < 0.0:
            alpha, gamma = alpha_table[0, i], gamma_table[0, i]
        else:
            alpha, gamma = alpha_table[1, i], gamma_table[1, i]
        F_c = np.maximum(s * ((alpha - 1.0) * f_w[i] + gamma * thetadot[i]), 1e-300)    # |F_f| (3.41)
        sF = s * F_c
        F_D = sF + (state[_F_0, i] - sF) * np.exp(-sigma[i] * np.abs(theta[i] - state[_THETA_0, i]) / F_c)  # (3.43)
        state[_THETA, i] = theta[i]
        state[_F_D, i] = F_D
        f[i] = f_w[i] + F_D

_last_tables: tuple = (None, b"", (), None, None)    # (series, β bytes, β shape, alpha, gamma) of the last call


def _series_tables(series, beta_last) -> tuple[np.ndarray, np.ndarray]:
    """The compiled PulleySeries.tables of beta_last, computed again only when the series or β's
    bytes differ from the last call's (the step only reads them)."""
    global _last_tables
    beta = vector(beta_last)
    key = beta.tobytes()
    last_series, last_key, last_shape, alpha, gamma = _last_tables
    if last_series is series and last_key == key and last_shape == beta.shape:
        return alpha, gamma
    alpha_in, gamma_in = series.inner
    alpha, gamma = _tables(beta, series.mu, series.F_pv, series.has_last, alpha_in, gamma_in)
    _last_tables = (series, key, beta.shape, alpha, gamma)
    return alpha, gamma


def friction_platform_force(model, f_w, theta, thetadot, beta_last) -> np.ndarray:
    """PulleyFriction.platform_force of ``model`` from the winch forces f_w (3.40) (the sensor
    forces already converted), compiled; advances the model's Dahl state like the reference."""
    dahl = model.dahl
    alpha, gamma = _series_tables(model.series, beta_last)
    state = dahl.state
    f = np.empty(state.shape[1])
    platform_force_kernel(vector(f_w), vector(theta), vector(thetadot), alpha, gamma, dahl.sigma, dahl.v_eps, state, f)
    return f
