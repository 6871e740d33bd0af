"""Compiled friction compensation of one sample, (3.35) and (3.43)-(3.44).

The functions of :mod:`cdpr_control.friction` that are written in the array subset numba compiles
(the swivelling pulley's tables and the Dahl step: the numpy reference itself), compiled and
applied to a :class:`cdpr_control.friction.PulleyFriction`'s state. The controller sees a new wrap
angle every period, so the tables are recomputed each time (cheap compiled) instead of compared.
The two stay separate compiled calls: a kernel here calling them would keep a stale copy of their
code in numba's disk cache after an edit of friction.py (the cache follows the caller's file only).
"""
from __future__ import annotations

import numba
import numpy as np

from .. import friction as np_friction
from .robot_data import vector

_tables = numba.njit(cache=True)(np_friction.last_pulley_tables)
_step = numba.njit(cache=True)(np_friction.platform_force_step)


def friction_platform_force(model, f_w, theta, thetadot, beta_last) -> np.ndarray:
    """PulleyFriction.platform_force of ``model`` from the winch forces f_w (3.40) (the sensor
    forces already converted), compiled; advances the model's Dahl state like the reference."""
    series, dahl = model.series, model.dahl
    alpha_in, gamma_in = series.inner
    alpha, gamma = _tables(vector(beta_last), series.mu, series.F_pv, series.has_last, alpha_in, gamma_in)
    return _step(vector(f_w), vector(theta), vector(thetadot), alpha, gamma, dahl.sigma, dahl.v_eps, dahl.state)
