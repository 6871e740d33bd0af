"""Compiled platform wrench of one pose, (2.33): gravity minus the Newton-Euler w_dyn.

The same as :func:`cdpr_control.dynamics.platform_wrench` (numpy reference, batched) for one pose
with twist and acceleration given.
"""
from __future__ import annotations

import numba
import numpy as np

from .kinematics import rotation
from .robot_data import robot_data, vector


@numba.njit(cache=True, error_model="numpy")
def _cross(a, b, out):
    out[0] = a[1] * b[2] - a[2] * b[1]
    out[1] = a[2] * b[0] - a[0] * b[2]
    out[2] = a[0] * b[1] - a[1] * b[0]


@numba.njit(cache=True, error_model="numpy")
def platform_wrench_kernel(x, xdot, xddot, mass, cog, inertia, gravity, w):
    """w = w_gravity - w_dyn (6,): [m g; c x m g] - (M(x) xddot + [m w x (w x c); w x J_o w]),
    c = R c_p, J_o = R J_c R^T - m [c][c] (2.33), twist xdot = [r_dot; omega]; into w."""
    R = np.empty((3, 3))
    rotation(x[3], x[4], x[5], R)
    c, t1, t2 = np.empty(3), np.empty(3), np.empty(3)
    for j in range(3):
        c[j] = R[j, 0] * cog[0] + R[j, 1] * cog[1] + R[j, 2] * cog[2]
    RJ, J_o = np.empty((3, 3)), np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            RJ[i, j] = R[i, 0] * inertia[0, j] + R[i, 1] * inertia[1, j] + R[i, 2] * inertia[2, j]
    cc = c[0] * c[0] + c[1] * c[1] + c[2] * c[2]
    for i in range(3):
        for j in range(3):
            # [c][c] = c c^T - |c|^2 I
            CC = c[i] * c[j] - (cc if i == j else 0.0)
            J_o[i, j] = RJ[i, 0] * R[j, 0] + RJ[i, 1] * R[j, 1] + RJ[i, 2] * R[j, 2] - mass * CC
    omega, a, omega_dot = xdot[3:], xddot[:3], xddot[3:]
    fg = np.empty(3)
    for j in range(3):
        fg[j] = mass * gravity[j]
    _cross(c, fg, t1)                                  # moment of the weight about the origin
    for j in range(3):
        w[j], w[3 + j] = fg[j], t1[j]
    # force: m (a - c x omega_dot + omega x (omega x c))
    _cross(c, omega_dot, t1)
    _cross(omega, c, t2)
    f_dyn = np.empty(3)
    for j in range(3):
        f_dyn[j] = a[j] - t1[j]
    _cross(omega, t2, t1)
    for j in range(3):
        w[j] -= mass * (f_dyn[j] + t1[j])
    # torque: m c x a + J_o omega_dot + omega x (J_o omega)
    _cross(c, a, t1)
    Jw = np.empty(3)
    for j in range(3):
        Jw[j] = J_o[j, 0] * omega[0] + J_o[j, 1] * omega[1] + J_o[j, 2] * omega[2]
    _cross(omega, Jw, t2)
    for j in range(3):
        w[3 + j] -= mass * t1[j] + (J_o[j, 0] * omega_dot[0] + J_o[j, 1] * omega_dot[1]
                                    + J_o[j, 2] * omega_dot[2]) + t2[j]


def platform_wrench(robot, x, xdot, xddot) -> np.ndarray:
    """The w of (2.10) for one pose: gravity - w_dyn (2.33), compiled (dynamics.platform_wrench)."""
    d = robot_data(robot)
    w = np.empty(6)
    platform_wrench_kernel(vector(x), vector(xdot), vector(xddot), d.mass, d.cog, d.inertia, d.gravity, w)
    return w
