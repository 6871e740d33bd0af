"""Compiled friction compensation of one sample, (3.35) and (3.43)-(3.44).

The functions of :mod:`cdpr_control.friction` that are written in the array subset numba compiles
(the swivelling pulley's tables and the Dahl step: the numpy reference itself), compiled and
applied to a :class:`cdpr_control.friction.PulleyFriction`'s state. The tables depend on the wrap
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
_step = numba.njit(cache=True)(np_friction.platform_force_step)

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
    return _step(vector(f_w), vector(theta), vector(thetadot), alpha, gamma, dahl.sigma, dahl.v_eps, dahl.state)
