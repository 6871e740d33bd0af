"""Centre of gravity of the platform (with its loads, (4.1)) from the circle run, thesis (4.2)-(4.3).

About the platform origin the cable wrench w = A^T f (2.10) balances weight and inertia (2.33); its
torque is, the rotational terms J omega_dot + omega x J omega left out (the platform barely turns on
the circle),

    tau = m_p c x (xddot - g),   c = R c_mp  (c_mp in the platform frame).

On the circle (4.2) this is the dynamic torque of (4.3) plus the static one of the weight: the first
harmonics of tau_x, tau_y carry c_z (amplitude m_p r_c thetadot_c^2 c_z), that of tau_z carries
c_x, c_y, and the means of tau_x, tau_y carry c_y, c_x (the static alternative of section 4.1.1).
tau is linear in c_mp, tau = Phi c_mp with Phi = -m_p [xddot - g] R; the mean and first harmonic
(DFT at the circle frequency, as (4.3)) of tau and of each column of Phi over the constant-velocity
window give 9 equations, solved by linear least squares. c_z rests on the harmonic torques alone
(a few 0.01 N m on the Mini), so it is the poorly observed one (the thesis: errors up to 255 mm).
"""
from __future__ import annotations

import numpy as np

from cdpr_control.model.kinematics import rotation_matrix, skew


def torque_regressor(x, xddot, m_p: float, gravity) -> np.ndarray:
    """Phi (N, 3, 3) with tau = Phi c_mp at poses x (N, 6) and accelerations xddot (N, 3)."""
    return -m_p * skew(xddot - np.asarray(gravity, dtype=float)) @ rotation_matrix(x[:, 3:])


def accelerations(t, x) -> np.ndarray:
    """xddot (N, 3) of the recorded positions x[:, :3] (central differences, twice)."""
    return np.gradient(np.gradient(x[:, :3], t, axis=0), t, axis=0)


def centre_of_gravity(t, x, xddot, tau, m_p: float, omega: float, gravity) -> np.ndarray:
    """c_mp (3,) [m, platform frame] from the torques tau (N, 3) = w[:, 3:] about the platform origin
    at poses x (N, 6) with accelerations xddot (N, 3), stamps t (N,) of the constant-velocity window;
    omega [rad/s] of the circle."""
    Phi = torque_regressor(x, xddot, m_p, gravity)
    B = np.column_stack([np.ones_like(t), np.cos(omega * t), np.sin(omega * t)])
    P = np.linalg.pinv(B)                              # (3, N): mean and first harmonic of a signal
    lhs = np.einsum("kn,nij->ikj", P, Phi).reshape(9, 3)   # rows: torque axis i, coefficient k
    rhs = (P @ tau).T.reshape(9)
    return np.linalg.lstsq(lhs, rhs, rcond=None)[0]
