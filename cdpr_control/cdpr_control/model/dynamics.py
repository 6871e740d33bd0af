"""Platform dynamics, thesis (2.33): the Newton-Euler inverse dynamics wrench w_dyn and the gravity
wrench, both about the platform origin and in the base frame.

Velocities are twists xdot = [r_dot; omega], accelerations xddot = [r_ddot; omega_dot] with omega
in the base frame (kinematics.twist_from_pose_rates converts Kardan rates).

Sign convention of (2.10): the cables satisfy A^T f = -w with w the wrench of everything else on the
platform. For a moving platform w = w_gravity + w_ext - w_dyn (platform_wrench).
"""

from __future__ import annotations

import numpy as np

from cdpr_control.model.kinematics import cross, rotation_matrix, skew


def _mass_properties(robot, R):
    """m_p, c_mp = R c, [c_mp] and the inertia about the platform origin J_c - m [c][c]."""
    p = robot.platform
    c = R @ p.center_of_gravity
    C = skew(c)
    J_o = R @ p.inertia @ np.swapaxes(R, -1, -2) - p.mass * C @ C
    return p.mass, c, C, J_o


def mass_matrix(robot, x) -> np.ndarray:
    """M(x) (..., 6, 6) of (2.33): [[m I, -m [c]], [m [c], J_c - m [c][c]]] in the base frame."""
    x = np.asarray(x, dtype=float)
    m, _, C, J_o = _mass_properties(robot, rotation_matrix(x[..., 3:]))
    M = np.empty(x.shape[:-1] + (6, 6))
    M[..., :3, :3] = m * np.eye(3)
    M[..., :3, 3:] = -m * C
    M[..., 3:, :3] = m * C
    M[..., 3:, 3:] = J_o
    return M


def dynamic_wrench(robot, x, xdot, xddot) -> np.ndarray:
    """w_dyn (..., 6) of (2.33): M(x) xddot + [m w x (w x c); w x (J_c - m [c][c]) w]."""
    x = np.asarray(x, dtype=float)
    xdot, xddot = np.asarray(xdot, dtype=float), np.asarray(xddot, dtype=float)
    m, c, C, J_o = _mass_properties(robot, rotation_matrix(x[..., 3:]))
    w, a, w_dot = xdot[..., 3:], xddot[..., :3], xddot[..., 3:]
    f = m * (a - cross(c, w_dot) + cross(w, cross(w, c)))
    tau = (
        m * cross(c, a)
        + np.einsum("...ij,...j->...i", J_o, w_dot)
        + cross(w, np.einsum("...ij,...j->...i", J_o, w))
    )
    return np.concatenate([f, tau], axis=-1)


def gravity_wrench(robot, x) -> np.ndarray:
    """Weight of the platform as a wrench (..., 6) about the platform origin: [m g; c_mp x m g]."""
    x = np.asarray(x, dtype=float)
    p = robot.platform
    c = rotation_matrix(x[..., 3:]) @ p.center_of_gravity
    f = np.broadcast_to(p.mass * robot.gravity, c.shape)
    return np.concatenate([f, cross(c, f)], axis=-1)


def platform_wrench(robot, x, xdot=None, xddot=None, w_ext=None) -> np.ndarray:
    """The w of (2.10), A^T f = -w: gravity + external wrench - w_dyn (2.33) [(..., 6)].

    A missing xdot or xddot counts as zero; static it is the gravity wrench (plus w_ext), the w_0
    of (2.37).
    """
    w = gravity_wrench(robot, x)
    if xdot is not None or xddot is not None:
        zero = np.zeros(np.shape(x))
        xdot = zero if xdot is None else xdot
        w = w - dynamic_wrench(robot, x, xdot, zero if xddot is None else xddot)
    if w_ext is not None:
        w = w + w_ext
    return w
