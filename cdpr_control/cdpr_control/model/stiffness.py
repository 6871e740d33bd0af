"""Stiffness of the cable robot in operational space, thesis (2.18)-(2.22), and the platform
eigenfrequencies of section 4.3, (4.8).

dw = K_x dx (2.18) with dx = [dr; dtheta] a small translation and a small rotation about the base
axes (the twist coordinates of kinematics.py). Convert to Kardan coordinates with
K_x @ blockdiag(I, kardan_rate_matrix(phi)).

Sign convention: K_x = K_g + K_c with K_g = -(dA^T/dx) f (the thesis writes the minus sign in front
of the brace in (2.22)); so K_g is positive (semi-)definite for a tensed, stable configuration.
"""

from __future__ import annotations

import numpy as np

from cdpr_control.model.kinematics import InverseKinematics, skew, unit_vector_jacobian


def geometric_stiffness(ik: InverseKinematics, f) -> np.ndarray:
    """K_g = -(dA^T/dx) f (2.22) [(...,6,6)] in closed form, including the swivelling pulleys.

    With D_i = du_i/dp_i (kinematics.unit_vector_jacobian), S_i = [R b_i], U_i = [u_i], a cable
    column a_i = [u_i; R b_i x u_i] varies as
        d a_i = [[D, -D S], [S D, -S D S + U S]] [dr; dtheta],
    and K_g = -sum_i f_i d a_i / dx. It is not symmetric away from equilibrium of the moments.
    """
    f = np.asarray(f, dtype=float)
    D = unit_vector_jacobian(ik)
    S = skew(ik.Rb)
    DS = D @ S
    K = np.empty(np.broadcast_shapes(f.shape[:-1], ik.q.shape[:-1]) + (6, 6))
    K[..., :3, :3] = -np.einsum("...m,...mij->...ij", f, D)
    K[..., :3, 3:] = np.einsum("...m,...mij->...ij", f, DS)
    K[..., 3:, :3] = -np.einsum("...m,...mij->...ij", f, S @ D)
    K[..., 3:, 3:] = np.einsum("...m,...mij->...ij", f, S @ DS - skew(ik.u) @ S)
    return K


def cable_stiffness(ik: InverseKinematics, k_l) -> np.ndarray:
    """K_c = A^T K_l A (2.22) with K_l = diag(k_l) (..., m) the cable stiffness (2.20) [N/m]."""
    AT = ik.AT
    return (AT * np.asarray(k_l, dtype=float)[..., None, :]) @ np.swapaxes(AT, -1, -2)


def operational_stiffness(ik: InverseKinematics, f, k_l) -> np.ndarray:
    """K_x = K_g + K_c (2.22) for cable forces f and cable stiffness k_l (tangent_stiffness)."""
    return geometric_stiffness(ik, f) + cable_stiffness(ik, k_l)


def eigenfrequencies(K_x, M) -> np.ndarray:
    """Per-axis eigenfrequencies [Hz] (4.8): sqrt(K_x[j, j] / M[j, j]) / (2 pi).

    M is dynamics.mass_matrix: its translational diagonal is m_p, giving (4.8) exactly; the
    rotational entries use the platform's moments of inertia about the platform axes.
    """
    return np.sqrt(np.diagonal(K_x, axis1=-2, axis2=-1) / np.diagonal(M, axis1=-2, axis2=-1)) / (
        2.0 * np.pi
    )


def modal_frequencies(K_x, M) -> np.ndarray:
    """Coupled undamped eigenfrequencies [Hz] of M xddot + K_x x = 0, ascending.

    The symmetric part of K_x is used (the antisymmetric part of K_g does no work on small cycles).
    NaN where K_x has a negative eigenvalue (statically unstable pose).
    """
    K = 0.5 * (K_x + np.swapaxes(K_x, -1, -2))
    L = np.linalg.cholesky(M)
    Linv = np.linalg.inv(L)
    lam = np.linalg.eigvalsh(Linv @ K @ np.swapaxes(Linv, -1, -2))
    with np.errstate(invalid="ignore"):
        return np.sqrt(lam) / (2.0 * np.pi)
