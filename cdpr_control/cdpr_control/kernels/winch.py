"""Compiled winch side of the simulated plant: the drives (3.10)/(5.11) and the pulley friction
from the platform to the force sensor (3.30)-(3.44), once per physics step or control period.

:meth:`cdpr_control.drive_models.DriveModel.step` and
:meth:`cdpr_control.friction.PulleyFriction.sensor_force` are the numpy reference; the functions
here are the same arithmetic as loops over the m cables, in one compiled call each. As whole-array
expressions (even compiled by numba) they allocate a temporary per operation, which costs several
times the arithmetic on 8 numbers; the loops do the same operations in the same order on each
element, so the results are the same numbers as the reference compiled by numba (plain numpy's
vectorised exp may round the last bit differently). The model objects keep their state; the
wrappers pass it in.
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
    raise ImportError("kernels.winch: the Dahl state rows differ from cdpr_control.friction.ROW_*")


@numba.njit(cache=True, error_model="numpy")
def sensor_force_kernel(f, theta, thetadot, alpha_table, gamma_table, sigma, v_eps, state, tol, max_iterations,
                        sensor_gain, F_s):
    """friction.sensor_force_step followed by friction.sensor_from_winch_force, per cable.

    Arguments as sensor_force_step; sensor_gain = 1 - cos(beta_1) (3.36); writes the sensor forces
    F_s (m,) and advances ``state``. The fixed-point iteration runs on all cables together and stops
    on the largest change, as the reference does (the iteration count is shared). Maxima propagate
    NaN as numpy's max does (a NaN never satisfies the stopping test).
    """
    m = f.shape[0]
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
    m = dahl.state.shape[1]
    f, theta, thetadot = vector(f), vector(theta), vector(thetadot)
    if f.shape != (m,) or theta.shape != (m,) or thetadot.shape != (m,):     # the loops do not check bounds
        raise ValueError(f"f, theta, thetadot must have shape ({m},), got {f.shape}, {theta.shape}, {thetadot.shape}")
    F_s = np.empty(m)
    sensor_force_kernel(f, theta, thetadot, alpha, gamma, dahl.sigma, dahl.v_eps, dahl.state, tol, max_iterations,
                        _sensor_gain(model.beta_1), F_s)
    return F_s


@numba.njit(cache=True, error_model="numpy")
def drive_step_kernel(theta_d, Phi, G_new, G_old, x, buffer, head, delay, v_max, dt, thetadot, theta):
    """drive_models.drive_step per cable; also writes theta = x[0] (m,) at the end of the step.

    Phi x stays one BLAS product as in the reference: written out as sums it would save about
    0.2 us but round differently where BLAS fuses a multiply and an add (the second-order drive's
    theta in the last bit). The rest is elementwise. The speed limit applies to every cable once
    any cable exceeds it, as the reference's test on the largest step (NaN: no limit) does.
    """
    n, m = x.shape
    L = buffer.shape[0]
    for j in range(m):
        buffer[head, j] = theta_d[j]
    new = (head - delay) % L
    old = (head - delay - 1) % L
    x_new = Phi @ x
    step = np.empty(m)
    largest = 0.0
    for j in range(m):
        for i in range(n):
            x_new[i, j] = x_new[i, j] + G_new[i] * buffer[new, j] + G_old[i] * buffer[old, j]
        step[j] = x_new[0, j] - x[0, j]
        a = abs(step[j])
        if a > largest or a != a:
            largest = a
    limit = v_max * dt
    clip = largest > limit                                    # speed limit of the servo
    for j in range(m):
        if clip:
            s = step[j]
            if s < -limit:
                s = -limit
            if s > limit:
                s = limit
            step[j] = s
            x_new[0, j] = x[0, j] + s
            if n == 2:
                v = x_new[1, j]
                if v < -v_max:
                    v = -v_max
                if v > v_max:
                    v = v_max
                x_new[1, j] = v
        for i in range(n):
            x[i, j] = x_new[i, j]
        thetadot[j] = step[j] / dt
        theta[j] = x_new[0, j]
    return (head + 1) % L


def drive_step(model, theta_d) -> np.ndarray:
    """DriveModel.step of ``model`` compiled: advances the drives by dt with theta_d (m,) held and
    returns theta (m,) at the end of the step (a new array, also ``model.theta``)."""
    theta_d = vector(theta_d)
    if theta_d.shape != (model.m,):                           # the loops do not check bounds
        raise ValueError(f"theta_d must have shape ({model.m},), got {theta_d.shape}")
    theta = np.empty(model.m)
    model.head = drive_step_kernel(theta_d, model.Phi, model.G_new, model.G_old, model.x, model.buffer, model.head,
                                   model.delay_steps, model.v_max, model.dt, model.thetadot, theta)
    model.theta = theta
    return theta
