"""Compiled elastic forward kinematics with frozen pulleys, (3.7)-(3.9) and section 3.2.

The numeric core of :meth:`cdpr_control.forward_kinematics.ForwardKinematics.elastic`
(pulleys='frozen'): the cable state q_hat, K_l of (3.7)/(2.15), and the Levenberg-Marquardt
iterations of ``ForwardKinematics._solve`` on the frozen-pulley residual ``_frozen_residual``,
step for step (same damping schedule, same stopping rules). The 6 x 6 normal equations are solved
by a Cholesky factorisation, as LAPACK's dposv there.
"""
from __future__ import annotations

import math

import numba
import numpy as np

from .kinematics import rotation

# termination codes, in the order of forward_kinematics.TERMINATIONS
CONVERGED, MAX_ITERATIONS, STALLED, NON_FINITE = 0, 1, 2, 3
_LAMBDA_START, _LAMBDA_MIN, _LAMBDA_MAX, _LAMBDA_CONVERGED = 1e-6, 1e-12, 1e12, 1e-2


@numba.njit(cache=True, error_model="numpy")
def elastic_cable_state(theta, f, l_0, k0, k1, k2):
    """(q_hat, k_l) (m,): q_hat = theta + dq with dq = f (theta + l_0) / (k_spec - f) (3.7) and
    the secant stiffness k_l = k_spec(f) / (q_hat + l_0) (2.14)-(2.16) (cdpr_control.cable)."""
    m = theta.shape[0]
    q_hat, k_l = np.empty(m), np.empty(m)
    for i in range(m):
        fp = max(f[i], 0.0)
        k_spec = k0 + fp * (k1 + k2 * fp)
        q_hat[i] = theta[i] + f[i] * (theta[i] + l_0[i]) / (k_spec - f[i])
        k_l[i] = k_spec / (q_hat[i] + l_0[i])
    return q_hat, k_l


@numba.njit(cache=True, error_model="numpy")
def secant_stiffness(f, l_t, k0, k1, k2, k):
    """k = k_spec(f) / l_t (2.15)-(2.16) (m,), k_spec = k0 + f (k1 + k2 f) with f <= 0 giving k0
    (cable.stiffness)."""
    for i in range(f.shape[0]):
        fp = max(f[i], 0.0)
        k[i] = (k0 + fp * (k1 + k2 * fp)) / l_t[i]


@numba.njit(cache=True, error_model="numpy")
def _frozen_residual(x, cT, b, q_free, k_l, res, JT, R, S, Rb):
    """Psi = k_l (|c_i - r - R b_i| - q_free) into res (m,) and (dPsi/dx)^T into JT (6, m); returns
    |Psi|^2. dq_i/dr = -u_i, dq_i/dphi_k = -u_i . ([h_k] R b_i), h_k column k of H(phi)."""
    rotation(x[3], x[4], x[5], R)
    ca, sa = math.cos(x[3]), math.sin(x[3])
    cb, sb = math.cos(x[4]), math.sin(x[4])
    hx, hy, hz = sb, -sa * cb, ca * cb
    # S (3, 3, 3): [h_k] for k = 0, 1, 2 (h_0 = e_x, h_1 = (0, ca, sa), h_2 = (hx, hy, hz))
    S[:] = 0.0
    S[0, 1, 2], S[0, 2, 1] = -1.0, 1.0
    S[1, 0, 1], S[1, 0, 2], S[1, 1, 0], S[1, 2, 0] = -sa, ca, sa, -ca
    S[2, 0, 1], S[2, 0, 2], S[2, 1, 0], S[2, 1, 2], S[2, 2, 0], S[2, 2, 1] = -hz, hy, hz, -hx, -hy, hx
    cost = 0.0
    for i in range(cT.shape[1]):
        for j in range(3):
            Rb[j] = R[j, 0] * b[i, 0] + R[j, 1] * b[i, 1] + R[j, 2] * b[i, 2]
        l0, l1, l2 = cT[0, i] - Rb[0] - x[0], cT[1, i] - Rb[1] - x[1], cT[2, i] - Rb[2] - x[2]
        L = math.sqrt(l0 * l0 + l1 * l1 + l2 * l2)
        s = -k_l[i] / L
        JT[0, i], JT[1, i], JT[2, i] = l0 * s, l1 * s, l2 * s                  # -k_l u
        for k in range(3):
            acc = 0.0
            for j in range(3):
                acc += (S[k, j, 0] * Rb[0] + S[k, j, 1] * Rb[1] + S[k, j, 2] * Rb[2]) * JT[j, i]
            JT[3 + k, i] = acc
        res[i] = k_l[i] * (L - q_free[i])
        cost += res[i] * res[i]
    return cost


@numba.njit(cache=True, error_model="numpy")
def _cholesky_solve(A, g, dx, L):
    """dx = A^-1 g for symmetric A (6, 6); False where A is not positive definite (dposv's info)."""
    n = A.shape[0]
    for j in range(n):
        d = A[j, j]
        for k in range(j):
            d -= L[j, k] * L[j, k]
        if not d > 0.0:
            return False
        L[j, j] = math.sqrt(d)
        for i in range(j + 1, n):
            s = A[i, j]
            for k in range(j):
                s -= L[i, k] * L[j, k]
            L[i, j] = s / L[j, j]
    for i in range(n):                       # L y = g
        s = g[i]
        for k in range(i):
            s -= L[i, k] * dx[k]
        dx[i] = s / L[i, i]
    for i in range(n - 1, -1, -1):           # L^T dx = y
        s = dx[i]
        for k in range(i + 1, n):
            s -= L[k, i] * dx[k]
        dx[i] = s / L[i, i]
    return True


@numba.njit(cache=True, error_model="numpy")
def _normal_equations(JT, res, lam, A, g):
    """A = J^T J (1 + lam on the diagonal, Marquardt), g = J^T Psi."""
    for r in range(6):
        acc = 0.0
        for i in range(JT.shape[1]):
            acc += JT[r, i] * res[i]
        g[r] = acc
        for s in range(r + 1):
            acc = 0.0
            for i in range(JT.shape[1]):
                acc += JT[r, i] * JT[s, i]
            A[r, s] = A[s, r] = acc
        A[r, r] *= 1.0 + lam


@numba.njit(cache=True, error_model="numpy")
def elastic_frozen(x_d, q_d, AT_d, cT, beta, b, r_p, theta, f, l_0, k0, k1, k2, xtol, max_iterations, x_out):
    """Levenberg-Marquardt on Psi = K_l (IK_frozen(x) - q_hat) (3.8)-(3.9) from x_d, with q_hat
    and K_l from the winch lengths theta and forces f (m,) (:func:`elastic_cable_state`).

    q_d (m,), AT_d (6, m), cT (3, m), beta (m,): the pulley IK at x_d (cT the leave points c_i as
    columns); the frozen model is IK(x) = |c_i - r - R b_i| + beta_i r_p, which at x_d is the
    pulley IK itself, so the first residual comes from q_d and A^T_d. The pose goes to x_out (6,);
    returns (termination code, iterations, |Psi|).
    """
    code, iterations, norm, x = _elastic_frozen(x_d, q_d, AT_d, cT, beta, b, r_p, theta, f, l_0, k0, k1, k2, xtol,
                                                max_iterations)
    x_out[:] = x
    return code, iterations, norm


@numba.njit(cache=True, error_model="numpy")
def _elastic_frozen(x_d, q_d, AT_d, cT, beta, b, r_p, theta, f, l_0, k0, k1, k2, xtol, max_iterations):
    m = cT.shape[1]
    q_hat, k_l = elastic_cable_state(theta, f, l_0, k0, k1, k2)
    x = x_d.copy()
    res, JT = np.empty(m), np.empty((6, m))
    res_new, JT_new, q_free = np.empty(m), np.empty((6, m)), np.empty(m)
    ca, sa = math.cos(x[3]), math.sin(x[3])
    cb, sb = math.cos(x[4]), math.sin(x[4])
    cost = 0.0
    for i in range(m):
        q_free[i] = q_hat[i] - beta[i] * r_p[i]
        res[i] = k_l[i] * (q_d[i] - q_hat[i])
        cost += res[i] * res[i]
        for k in range(6):
            JT[k, i] = -AT_d[k, i] * k_l[i]            # dq/dx = -A blockdiag(I, H(phi))
        t0, t1, t2 = JT[3, i], JT[4, i], JT[5, i]
        JT[3, i] = t0
        JT[4, i] = ca * t1 + sa * t2
        JT[5, i] = sb * t0 + -sa * cb * t1 + ca * cb * t2
    R, S, Rb = np.empty((3, 3)), np.empty((3, 3, 3)), np.empty(3)
    A, L, g, dx, x_new = np.empty((6, 6)), np.zeros((6, 6)), np.empty(6), np.empty(6), np.empty(6)
    if not (math.isfinite(cost) and math.isfinite(JT.sum())):
        return NON_FINITE, 0, math.sqrt(cost) if cost >= 0.0 else math.nan, x
    lam = _LAMBDA_START
    for it in range(1, max_iterations + 1):
        _normal_equations(JT, res, lam, A, g)
        if not _cholesky_solve(A, g, dx, L):
            lam *= 10.0
            if lam > _LAMBDA_MAX:
                return STALLED, it, math.sqrt(cost), x
            continue
        if math.sqrt(dx[0] ** 2 + dx[1] ** 2 + dx[2] ** 2 + dx[3] ** 2 + dx[4] ** 2 + dx[5] ** 2) <= xtol:
            if lam <= _LAMBDA_CONVERGED:
                return CONVERGED, it, math.sqrt(cost), x
            _normal_equations(JT, res, 0.0, A, g)           # the undamped (Gauss-Newton) step
            if _cholesky_solve(A, g, x_new, L) and math.sqrt(
                    x_new[0] ** 2 + x_new[1] ** 2 + x_new[2] ** 2 + x_new[3] ** 2 + x_new[4] ** 2
                    + x_new[5] ** 2) <= xtol:
                return CONVERGED, it, math.sqrt(cost), x
        for k in range(6):
            x_new[k] = x[k] - dx[k]
        cost_new = _frozen_residual(x_new, cT, b, q_free, k_l, res_new, JT_new, R, S, Rb)
        if cost_new <= cost:
            x, x_new = x_new, x
            res, res_new = res_new, res
            JT, JT_new = JT_new, JT
            cost = cost_new
            lam = max(lam * 0.1, _LAMBDA_MIN)
        else:
            lam *= 10.0
            if lam > _LAMBDA_MAX:
                return STALLED, it, math.sqrt(cost), x
    return MAX_ITERATIONS, max_iterations, math.sqrt(cost), x
