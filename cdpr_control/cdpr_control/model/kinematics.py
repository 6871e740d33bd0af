"""Kinematics of the cable robot, thesis section 2.1.1.

Kardan rotation R = Rx Ry Rz, the swivelling-pulley kinematics (2.3)-(2.9), the inverse kinematics
(2.2)/(2.7), the structure matrix A^T (2.10), its time derivative and the velocity and acceleration
maps (2.12)/(2.13).

Every function takes one pose x of shape (6,) or a batch of shape (..., 6) and returns arrays with
the same leading dimensions: q (..., m), u (..., m, 3), AT (..., 6, m).

Platform velocities are twists xdot = [r_dot; omega] with omega the angular velocity in the base
frame (the thesis' phi_dot of (2.12) and (2.33)); :func:`twist_from_pose_rates` converts Kardan
angle rates. The moment rows of A^T use the platform vector in the base frame, R b_i x u_i.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np


def rotation_matrix(phi) -> np.ndarray:
    """R = Rx(phi_x) Ry(phi_y) Rz(phi_z) of Kardan angles phi (..., 3) [rad], section 2.1.1."""
    phi = np.asarray(phi, dtype=float)
    if phi.shape == (3,):  # one pose: scalar math is several times cheaper than numpy calls
        ca, cb, cc = math.cos(phi[0]), math.cos(phi[1]), math.cos(phi[2])
        sa, sb, sc = math.sin(phi[0]), math.sin(phi[1]), math.sin(phi[2])
    else:
        c, s = np.cos(phi), np.sin(phi)
        ca, cb, cc = c[..., 0], c[..., 1], c[..., 2]
        sa, sb, sc = s[..., 0], s[..., 1], s[..., 2]
    sa_sb, ca_sb = sa * sb, ca * sb
    entries = (
        cb * cc,
        -cb * sc,
        sb,
        ca * sc + sa_sb * cc,
        ca * cc - sa_sb * sc,
        -sa * cb,
        sa * sc - ca_sb * cc,
        sa * cc + ca_sb * sc,
        ca * cb,
    )
    if phi.shape == (3,):
        return np.array(entries).reshape(3, 3)
    return np.stack(entries, axis=-1).reshape(phi.shape[:-1] + (3, 3))


def kardan_rate_matrix(phi) -> np.ndarray:
    """H(phi) (..., 3, 3) with omega = H phi_dot for R = Rx Ry Rz (omega in the base frame)."""
    phi = np.asarray(phi, dtype=float)
    if phi.shape == (3,):
        ca, cb, sa, sb = math.cos(phi[0]), math.cos(phi[1]), math.sin(phi[0]), math.sin(phi[1])
        return np.array([[1.0, 0.0, sb], [0.0, ca, -sa * cb], [0.0, sa, ca * cb]])
    ca, cb = np.cos(phi[..., 0]), np.cos(phi[..., 1])
    sa, sb = np.sin(phi[..., 0]), np.sin(phi[..., 1])
    H = np.zeros(phi.shape[:-1] + (3, 3))
    H[..., 0, 0] = 1.0
    H[..., 1, 1] = ca
    H[..., 2, 1] = sa
    H[..., 0, 2] = sb
    H[..., 1, 2] = -sa * cb
    H[..., 2, 2] = ca * cb
    return H


def twist_from_pose_rates(x, dx, ddx=None):
    """Twist xdot = [r_dot; omega] and its derivative from pose rates dx, ddx (Kardan rates).

    omega = H(phi) phi_dot and omega_dot = H phi_ddot + H_dot phi_dot. Returns (xdot, xddot); xddot
    is None when ddx is None.
    """
    x, dx = np.asarray(x, dtype=float), np.asarray(dx, dtype=float)
    if x.shape == (6,) and dx.shape == (6,):
        return _twist_from_pose_rates_one(x, dx, ddx)
    H = kardan_rate_matrix(x[..., 3:])
    xdot = np.concatenate([dx[..., :3], np.einsum("...ij,...j->...i", H, dx[..., 3:])], axis=-1)
    if ddx is None:
        return xdot, None
    ddx = np.asarray(ddx, dtype=float)
    a, b = x[..., 3], x[..., 4]
    da, db = dx[..., 3], dx[..., 4]
    H_dot = np.zeros_like(H)
    H_dot[..., 1, 1] = -np.sin(a) * da
    H_dot[..., 2, 1] = np.cos(a) * da
    H_dot[..., 0, 2] = np.cos(b) * db
    H_dot[..., 1, 2] = -np.cos(a) * np.cos(b) * da + np.sin(a) * np.sin(b) * db
    H_dot[..., 2, 2] = -np.sin(a) * np.cos(b) * da - np.cos(a) * np.sin(b) * db
    omega_dot = np.einsum("...ij,...j->...i", H, ddx[..., 3:]) + np.einsum(
        "...ij,...j->...i", H_dot, dx[..., 3:]
    )
    return xdot, np.concatenate([ddx[..., :3], omega_dot], axis=-1)


def _twist_from_pose_rates_one(x, dx, ddx):
    """twist_from_pose_rates of one pose in scalar math (the interpreter runs it every period)."""
    a, b = float(x[3]), float(x[4])
    ca, cb, sa, sb = math.cos(a), math.cos(b), math.sin(a), math.sin(b)
    da, db, dc = (float(v) for v in dx[3:])
    omega = (da + sb * dc, ca * db - sa * cb * dc, sa * db + ca * cb * dc)   # H(phi) phi_dot
    xdot = np.array([dx[0], dx[1], dx[2], *omega])
    if ddx is None:
        return xdot, None
    ddx = np.asarray(ddx, dtype=float)
    dda, ddb, ddc = (float(v) for v in ddx[3:])
    omega_dot = (dda + sb * ddc + cb * db * dc,                                # H phi_ddot + H_dot phi_dot
                 ca * ddb - sa * cb * ddc - sa * da * db + (-ca * cb * da + sa * sb * db) * dc,
                 sa * ddb + ca * cb * ddc + ca * da * db + (-sa * cb * da - ca * sb * db) * dc)
    return xdot, np.array([ddx[0], ddx[1], ddx[2], *omega_dot])


def skew(v) -> np.ndarray:
    """[v] (..., 3, 3) with [v] a = v x a."""
    v = np.asarray(v, dtype=float)
    S = np.zeros(v.shape + (3,))
    S[..., 0, 1], S[..., 0, 2] = -v[..., 2], v[..., 1]
    S[..., 1, 0], S[..., 1, 2] = v[..., 2], -v[..., 0]
    S[..., 2, 0], S[..., 2, 1] = -v[..., 1], v[..., 0]
    return S


def cross(a, b) -> np.ndarray:
    """a x b over the last axis (np.cross is ~10x slower on small arrays); two 3-vectors in plain
    Python floats, the same arithmetic (the simulator calls it several times a period)."""
    if np.ndim(a) == 1 and np.ndim(b) == 1:
        (a0, a1, a2), (b0, b1, b2) = a, b
        return np.array([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0])
    c = np.empty(np.broadcast_shapes(np.shape(a), np.shape(b)))
    c[..., 0] = a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1]
    c[..., 1] = a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2]
    c[..., 2] = a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]
    return c


class InverseKinematics(NamedTuple):
    """Inverse kinematics of one pose (shapes below) or a batch (extra leading dimensions).

    q (m,) cable length between leave point and platform incl. the wrap beta r_p, (2.2)/(2.7);
    l (m,3) cable vector from the platform point B_i to the pulley leave point C_i, (2.1)/(2.9);
    u (m,3) unit cable vectors; AT (6,m) structure matrix (2.10); c (m,3) leave points C_i (2.8)
    (= a_i without pulleys); beta (m,) wrap angle (2.6); gamma (m,) pulley swivel angle;
    l_f (m,) free cable length (2.5) (= q without pulleys); Rb (m,3) platform vectors in the base
    frame; R (3,3) platform rotation; n (m,3) normals of the pulley planes R_A R_z(gamma) e_y;
    kappa (m,) swivel lever ratio r_p (1 - cos beta) / b_xy (0 without pulleys), see
    :func:`unit_vector_jacobian`.
    """

    q: np.ndarray
    l: np.ndarray
    u: np.ndarray
    AT: np.ndarray
    c: np.ndarray
    beta: np.ndarray
    gamma: np.ndarray
    l_f: np.ndarray
    Rb: np.ndarray
    R: np.ndarray
    n: np.ndarray
    kappa: np.ndarray


_PULLEY_FRAMES: dict[bytes, tuple] = {}


def _pulley_cache(robot):
    """(R_A, to_pulley, X, Y, Z): R_A (m, 3, 3), to_pulley[i, j, k] = R_A[k, j, i] (R_A^T per cable
    for vectors along axis -2) and the pulley axes as (3, m) arrays. Cached per pulley geometry, so
    robots that differ only in payload (Robot.with_payload) share one entry."""
    key = robot.pulley_orientation.tobytes()
    entry = _PULLEY_FRAMES.get(key)
    if entry is None:
        R_A = rotation_matrix(robot.pulley_orientation)
        entry = [R_A, np.ascontiguousarray(R_A.transpose(2, 1, 0))]
        entry += [np.ascontiguousarray(R_A[:, :, k].T) for k in range(3)]
        for arr in entry:
            arr.setflags(write=False)
        entry = _PULLEY_FRAMES[key] = tuple(entry)
    return entry


def pulley_frames(robot) -> np.ndarray:
    """R_A (m, 3, 3) of the pulley frames K_A (2.3) from robot.pulley_orientation; cached."""
    return _pulley_cache(robot)[0]


_NEXT, _PREV = np.array([1, 2, 0]), np.array([2, 0, 1])


def _cross_T(a, b, out):
    """out[..., :, k] = a[..., :, k] x b[..., :, k] for vectors stored along axis -2."""
    return np.subtract(
        a.take(_NEXT, -2) * b.take(_PREV, -2), a.take(_PREV, -2) * b.take(_NEXT, -2), out=out
    )


def inverse_kinematics(robot, x, pulleys: bool | None = None) -> InverseKinematics:
    """Inverse kinematics of pose(s) x (..., 6), with swivelling pulleys (2.3)-(2.9) or not (2.1).

    pulleys=None follows robot.swivelling_pulleys. Without pulleys the cable runs from the fixed
    point a_i, beta = gamma = 0 and q = |l|.

    With pulleys, the platform point B_i in the pulley frame K_A is b = R_A^T (r + R b_i - a_i);
    gamma = atan2(b_y, b_x), d (2.4), l_f (2.5), beta (2.6), q = l_f + beta r_p (2.7), c_i (2.8).
    (2.6) is evaluated as beta = atan2(b_xy - r_p, b_z) + atan2(r_p, l_f): identical for
    b_xy >= r_p, better conditioned, and still right when B_i swings past the pulley axis.
    On the swivel axis (b_xy = 0) the swivel angle is undefined: gamma = 0 and kappa is not finite.
    Inside the pulley circle (d < r_p) there is no tangent and q is NaN.
    """
    x = np.asarray(x, dtype=float)
    R = rotation_matrix(x[..., 3:])
    RbT = R @ robot.b.T  # (..., 3, m): R b_i
    pT = RbT + x[..., :3, np.newaxis]  # platform anchors B_i
    use_pulleys = robot.swivelling_pulleys if pulleys is None else pulleys
    shape = RbT.shape
    if use_pulleys:
        _, to_pulley, X, Y, Z = _pulley_cache(robot)
        r_p = robot.r_p
        bA = (to_pulley * (pT - robot.a.T)[..., None, :, :]).sum(axis=-2)  # B_i in K_A
        bx, by, bz = bA[..., 0, :], bA[..., 1, :], bA[..., 2, :]
        b_xy = np.hypot(bx, by)
        gamma = np.arctan2(by, bx)
        cos_g, sin_g = np.cos(gamma)[..., None, :], np.sin(gamma)[..., None, :]
        with np.errstate(invalid="ignore", divide="ignore"):
            l_f = np.sqrt(b_xy * (b_xy - 2.0 * r_p) + bz * bz)  # (2.4)-(2.5)
            beta = np.arctan2(b_xy - r_p, bz) + np.arctan2(r_p, l_f)  # (2.6)
            q = l_f + beta * r_p  # (2.7)
            rho = r_p - r_p * np.cos(beta)  # distance of C_i from the swivel axis
            kappa = rho / b_xy
        # (2.8) with R_A R_z(gamma) e_x = cos_g X + sin_g Y, the pulley plane's radial axis
        cT = (
            robot.a.T
            + rho[..., None, :] * (cos_g * X + sin_g * Y)
            + (r_p * np.sin(beta))[..., None, :] * Z
        )
        nT = cos_g * Y - sin_g * X  # R_A R_z(gamma) e_y
        lT = cT - pT  # (2.9)
    else:
        lT = robot.a.T - pT  # (2.1)
        l_f = q = np.sqrt(np.einsum("...im,...im->...m", lT, lT))  # (2.2)
        cT = np.broadcast_to(robot.a.T, shape)
        beta = gamma = kappa = np.zeros_like(q)
        nT = np.zeros(shape)
    uT = lT / l_f[..., None, :]
    AT = np.empty(shape[:-2] + (6, shape[-1]))
    AT[..., :3, :] = uT
    _cross_T(RbT, uT, AT[..., 3:, :])
    return InverseKinematics(
        q, _T(lT), _T(AT[..., :3, :]), AT, _T(cT), beta, gamma, l_f, _T(RbT), R, _T(nT), kappa
    )


def cable_lengths(robot, x) -> np.ndarray:
    """q (m,) of one pose x (6,), (2.7)."""
    return inverse_kinematics(robot, x).q


def measured_wrench(robot, x, f) -> np.ndarray:
    """w = -A^T(x) f (2.11): the wrench that the cable forces f (m,) balance at pose x (6,)."""
    return -inverse_kinematics(robot, x).AT @ f


def _T(a):
    return np.swapaxes(a, -1, -2)


def unit_vector_jacobian(ik: InverseKinematics) -> np.ndarray:
    """du_i/dp_i (..., m, 3, 3): derivative of the unit cable vector w.r.t. the platform point B_i.

    For a fixed anchor du = -(I - u u^T) dp / l. With a swivelling pulley, the leave point C_i
    slides along u when B_i moves in the pulley plane (no effect on u), and the pulley plane turns
    by dgamma = (n . dp) / b_xy about the swivel axis, carrying C_i by rho dgamma along n. Hence
    du/dp = -(I - u u^T - kappa n n^T) / l_f with kappa = rho / b_xy.
    """
    u, n = ik.u, ik.n
    P = (
        np.eye(3)
        - u[..., :, None] * u[..., None, :]
        - ik.kappa[..., None, None] * (n[..., :, None] * n[..., None, :])
    )
    return -P / ik.l_f[..., None, None]


def structure_matrix_derivative(ik: InverseKinematics, xdot) -> np.ndarray:
    """dA^T/dt (..., 6, m) for the twist xdot = [r_dot; omega] (..., 6), used in (2.13).

    Columns [u_dot; (omega x R b_i) x u_i + R b_i x u_dot], u_dot = du/dp (r_dot + omega x R b_i).
    """
    xdot = np.asarray(xdot, dtype=float)
    v, w = xdot[..., None, :3], xdot[..., None, 3:]
    w_x_Rb = cross(w, ik.Rb)
    u_dot = np.einsum("...ij,...j->...i", unit_vector_jacobian(ik), v + w_x_Rb)
    m_dot = cross(w_x_Rb, ik.u) + cross(ik.Rb, u_dot)
    return np.concatenate([np.swapaxes(u_dot, -1, -2), np.swapaxes(m_dot, -1, -2)], axis=-2)


def cable_velocities(ik: InverseKinematics, xdot) -> np.ndarray:
    """q_dot = -A xdot (2.12) for the twist xdot = [r_dot; omega]."""
    return -np.einsum("...ji,...j->...i", ik.AT, np.asarray(xdot, dtype=float))


def cable_accelerations(ik: InverseKinematics, xdot, xddot) -> np.ndarray:
    """q_ddot = -A xddot - A_dot xdot (2.13) for the twist xdot and its derivative xddot."""
    ATdot = structure_matrix_derivative(ik, xdot)
    return -np.einsum("...ji,...j->...i", ik.AT, np.asarray(xddot, dtype=float)) - np.einsum(
        "...ji,...j->...i", ATdot, np.asarray(xdot, dtype=float)
    )
