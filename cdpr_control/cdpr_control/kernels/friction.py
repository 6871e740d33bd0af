"""Compiled friction compensation of one sample, (3.35) and (3.43)-(3.44).

The functions of :mod:`cdpr_control.friction` that are written in the array subset numba compiles
(the swivelling pulley's tables and the Dahl step, the numpy reference itself), compiled and called
in one go on a :class:`cdpr_control.friction.PulleyFriction`'s state: the controller sees a new wrap
angle every period, so the tables are recomputed each time (cheap compiled) instead of compared.
"""
from __future__ import annotations

import numba
import numpy as np

from .. import friction as np_friction
from .robot_data import vector

_tables = numba.njit(cache=True)(np_friction.last_pulley_tables)
_step = numba.njit(cache=True)(np_friction.platform_force_step)


@numba.njit(cache=True)
def platform_force_kernel(f_w, theta, thetadot, beta_last, mu, F_pv, has_last, alpha_in, gamma_in, sigma, v_eps,
                          state, f):
    """f = f_w + F_D (3.44) into f (m,); advances the Dahl ``state`` (5, m) (friction.platform_force_step)."""
    alpha, gamma = _tables(beta_last, mu, F_pv, has_last, alpha_in, gamma_in)
    f[:] = _step(f_w, theta, thetadot, alpha, gamma, sigma, v_eps, state)


def friction_platform_force(model, f_w, theta, thetadot, beta_last) -> np.ndarray:
    """PulleyFriction.platform_force of ``model`` from the winch forces f_w (3.40) (the sensor
    forces already converted), compiled; advances the model's Dahl state like the reference."""
    series, dahl = model.series, model.dahl
    alpha_in, gamma_in = series.inner
    f = np.empty(series.m)
    platform_force_kernel(vector(f_w), vector(theta), vector(thetadot), vector(beta_last), series.mu, series.F_pv,
                          series.has_last, alpha_in, gamma_in, dahl.sigma, dahl.v_eps, dahl.state, f)
    return f
