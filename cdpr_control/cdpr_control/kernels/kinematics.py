"""Compiled inverse kinematics of one pose with swivelling pulleys, (2.3)-(2.10).

The same equations, in the same order, as :func:`cdpr_control.kinematics.inverse_kinematics`
(the readable numpy reference, which also handles batches), written as one loop over the cables.
"""
from __future__ import annotations

import math

import numba
import numpy as np

from ..kinematics import InverseKinematics
from .robot_data import robot_data, vector


@numba.njit(cache=True)
def rotation(phi_x, phi_y, phi_z, R):
    """Fill R (3, 3) = Rx Ry Rz of the Kardan angles (kinematics.rotation_matrix)."""
    ca, cb, cc = math.cos(phi_x), math.cos(phi_y), math.cos(phi_z)
    sa, sb, sc = math.sin(phi_x), math.sin(phi_y), math.sin(phi_z)
    sa_sb, ca_sb = sa * sb, ca * sb
    R[0, 0], R[0, 1], R[0, 2] = cb * cc, -cb * sc, sb
    R[1, 0], R[1, 1], R[1, 2] = ca * sc + sa_sb * cc, ca * cc - sa_sb * sc, -sa * cb
    R[2, 0], R[2, 1], R[2, 2] = sa * sc - ca_sb * cc, sa * cc + ca_sb * sc, ca * cb


@numba.njit(cache=True, error_model="numpy")
def ik(x, a, b, R_A, r_p, pulleys):
    """(q, l, u, AT, c, beta, gamma, l_f, Rb, R, n, kappa) of pose x (6,), as InverseKinematics.

    Pulleys (2.3)-(2.9): b = R_A^T (r + R b_i - a_i), gamma = atan2(b_y, b_x), l_f (2.5),
    beta = atan2(b_xy - r_p, b_z) + atan2(r_p, l_f) (2.6), q = l_f + beta r_p (2.7), c_i (2.8);
    without pulleys q = |a_i - r - R b_i| (2.2). A^T columns [u_i; R b_i x u_i] (2.10).
    """
    m = a.shape[0]
    R = np.empty((3, 3))
    rotation(x[3], x[4], x[5], R)
    q, l, u, AT = np.empty(m), np.empty((m, 3)), np.empty((m, 3)), np.empty((6, m))
    c, beta, gamma, l_f = np.empty((m, 3)), np.zeros(m), np.zeros(m), np.empty(m)
    Rb, n, kappa = np.empty((m, 3)), np.zeros((m, 3)), np.zeros(m)
    p = np.empty(3)
    for i in range(m):
        for j in range(3):
            Rb[i, j] = R[j, 0] * b[i, 0] + R[j, 1] * b[i, 1] + R[j, 2] * b[i, 2]
            p[j] = Rb[i, j] + x[j]                                   # platform anchor B_i
        if pulleys:
            rp = r_p[i]
            d0, d1, d2 = p[0] - a[i, 0], p[1] - a[i, 1], p[2] - a[i, 2]
            bx = R_A[i, 0, 0] * d0 + R_A[i, 1, 0] * d1 + R_A[i, 2, 0] * d2    # B_i in K_A
            by = R_A[i, 0, 1] * d0 + R_A[i, 1, 1] * d1 + R_A[i, 2, 1] * d2
            bz = R_A[i, 0, 2] * d0 + R_A[i, 1, 2] * d1 + R_A[i, 2, 2] * d2
            b_xy = math.hypot(bx, by)
            g = math.atan2(by, bx)
            cos_g, sin_g = math.cos(g), math.sin(g)
            lf = math.sqrt(b_xy * (b_xy - 2.0 * rp) + bz * bz)           # (2.4)-(2.5)
            be = math.atan2(b_xy - rp, bz) + math.atan2(rp, lf)          # (2.6)
            q[i] = lf + be * rp                                          # (2.7)
            rho = rp - rp * math.cos(be)
            kappa[i] = rho / b_xy                       # not finite on the swivel axis
            rs = rp * math.sin(be)
            for j in range(3):
                X, Y, Z = R_A[i, j, 0], R_A[i, j, 1], R_A[i, j, 2]
                c[i, j] = a[i, j] + rho * (cos_g * X + sin_g * Y) + rs * Z    # (2.8)
                n[i, j] = cos_g * Y - sin_g * X
                l[i, j] = c[i, j] - p[j]                                 # (2.9)
            beta[i], gamma[i], l_f[i] = be, g, lf
        else:
            for j in range(3):
                c[i, j] = a[i, j]
                l[i, j] = a[i, j] - p[j]                                 # (2.1)
            lf = math.sqrt(l[i, 0] * l[i, 0] + l[i, 1] * l[i, 1] + l[i, 2] * l[i, 2])   # (2.2)
            q[i] = l_f[i] = lf
        for j in range(3):
            u[i, j] = AT[j, i] = l[i, j] / l_f[i]
        AT[3, i] = Rb[i, 1] * u[i, 2] - Rb[i, 2] * u[i, 1]                 # R b_i x u_i (2.10)
        AT[4, i] = Rb[i, 2] * u[i, 0] - Rb[i, 0] * u[i, 2]
        AT[5, i] = Rb[i, 0] * u[i, 1] - Rb[i, 1] * u[i, 0]
    return q, l, u, AT, c, beta, gamma, l_f, Rb, R, n, kappa


# rows of the packed result of ik_packed (one array: every returned array costs ~0.5 us to box)
_Q, _BETA, _GAMMA, _L_F, _KAPPA, _AT, _L, _C, _RB, _N, _ROWS = 0, 1, 2, 3, 4, 5, 11, 14, 17, 20, 23


@numba.njit(cache=True, error_model="numpy")
def ik_packed(x, a, b, R_A, r_p, pulleys, out):
    """:func:`ik` into one array out (23 + 3, m): rows q, beta, gamma, l_f, kappa, A^T (6), l^T, c^T,
    Rb^T, n^T (3 each), then R in the first three columns of the last three rows (needs m >= 3)."""
    q, l, u, AT, c, beta, gamma, l_f, Rb, R, n, kappa = ik(x, a, b, R_A, r_p, pulleys)
    out[_Q], out[_BETA], out[_GAMMA], out[_L_F], out[_KAPPA] = q, beta, gamma, l_f, kappa
    out[_AT:_AT + 6] = AT
    out[_L:_L + 3], out[_C:_C + 3], out[_RB:_RB + 3], out[_N:_N + 3] = l.T, c.T, Rb.T, n.T
    out[_ROWS:] = 0.0
    out[_ROWS:, :3] = R


@numba.njit(cache=True, error_model="numpy")
def cable_lengths_kernel(x, a, b, R_A, r_p, pulleys, q):
    """q (m,) of :func:`ik` into q."""
    q[:] = ik(x, a, b, R_A, r_p, pulleys)[0]


@numba.njit(cache=True, error_model="numpy")
def measured_wrench_kernel(x, f, a, b, R_A, r_p, pulleys, w):
    """w = -A^T(x) f (2.11) into w (6,)."""
    AT = ik(x, a, b, R_A, r_p, pulleys)[3]
    for k in range(6):
        w[k] = 0.0
        for i in range(f.shape[0]):
            w[k] -= AT[k, i] * f[i]


def inverse_kinematics(robot, x) -> InverseKinematics:
    """Inverse kinematics of one pose x (6,) with the robot's pulley model, compiled.

    The fields are views of one array (u of A^T, as in the reference); shapes as the reference's.
    """
    d = robot_data(robot)
    if d.a.shape[0] < 3:                     # R does not fit the packed layout
        return InverseKinematics._make(ik(vector(x), d.a, d.b, d.R_A, d.r_p, d.pulleys))
    P = np.empty((_ROWS + 3, d.a.shape[0]))
    ik_packed(vector(x), d.a, d.b, d.R_A, d.r_p, d.pulleys, P)
    AT = P[_AT:_AT + 6]
    return InverseKinematics(P[_Q], P[_L:_L + 3].T, AT[:3].T, AT, P[_C:_C + 3].T, P[_BETA], P[_GAMMA],
                             P[_L_F], P[_RB:_RB + 3].T, P[_ROWS:, :3], P[_N:_N + 3].T, P[_KAPPA])


def cable_lengths(robot, x) -> np.ndarray:
    """q (m,) of the inverse kinematics (2.7) of one pose x (6,), compiled."""
    d = robot_data(robot)
    q = np.empty(d.a.shape[0])
    cable_lengths_kernel(vector(x), d.a, d.b, d.R_A, d.r_p, d.pulleys, q)
    return q


def measured_wrench(robot, x, f) -> np.ndarray:
    """w = -A^T(x) f (2.11) of the cable forces f (m,) at pose x (6,), compiled."""
    d = robot_data(robot)
    w = np.empty(6)
    measured_wrench_kernel(vector(x), vector(f), d.a, d.b, d.R_A, d.r_p, d.pulleys, w)
    return w
