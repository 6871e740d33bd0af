"""Compiled model core of one pose: inverse kinematics, platform wrench, elastic forward kinematics.

* the inverse kinematics with swivelling pulleys (2.3)-(2.10): the same equations, in the same
  order, as :func:`cdpr_control.model.kinematics.inverse_kinematics` (the readable numpy reference, which
  also handles batches), written as one loop over the cables;
* the platform wrench (2.33), gravity minus the Newton-Euler w_dyn, as
  :func:`cdpr_control.model.dynamics.platform_wrench`;
* the numeric core of :meth:`cdpr_control.model.forward_kinematics.ForwardKinematics.elastic`
  (pulleys='frozen'): the cable state q_hat, K_l of (3.7)/(2.15), and the Levenberg-Marquardt
  iterations of ``ForwardKinematics._solve`` on the frozen-pulley residual ``_frozen_residual``,
  step for step (same damping schedule, same stopping rules); the 6 x 6 normal equations are solved
  by a Cholesky factorisation, as LAPACK's dposv there.

One file on purpose: numba's disk cache of a function is renewed when its own source file changes,
not when a compiled function it calls from another file does, so the kernels that share helpers
(:func:`rotation`) live together.
"""
from __future__ import annotations

import math

import numpy as np

from cdpr_control.kernels.jit import njit

from cdpr_control.model.kinematics import InverseKinematics
from cdpr_control.kernels.robot_data import robot_data, vector

# termination codes of elastic_frozen, in the order of forward_kinematics._TERMINATIONS
CONVERGED, MAX_ITERATIONS, STALLED, NON_FINITE = 0, 1, 2, 3
_LAMBDA_START, _LAMBDA_MIN, _LAMBDA_MAX, _LAMBDA_CONVERGED = 1e-6, 1e-12, 1e12, 1e-2
_EPS = float(np.finfo(np.float64).eps)

@njit
def rotation(phi_x, phi_y, phi_z, R):
    """Fill R (3, 3) = Rx Ry Rz of the Kardan angles (kinematics.rotation_matrix)."""
    ca, cb, cc = math.cos(phi_x), math.cos(phi_y), math.cos(phi_z)
    sa, sb, sc = math.sin(phi_x), math.sin(phi_y), math.sin(phi_z)
    sa_sb, ca_sb = sa * sb, ca * sb
    R[0, 0], R[0, 1], R[0, 2] = cb * cc, -cb * sc, sb
    R[1, 0], R[1, 1], R[1, 2] = ca * sc + sa_sb * cc, ca * cc - sa_sb * sc, -sa * cb
    R[2, 0], R[2, 1], R[2, 2] = sa * sc - ca_sb * cc, sa * cc + ca_sb * sc, ca * cb


@njit(error_model="numpy")
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


@njit(error_model="numpy")
def ik_packed(x, a, b, R_A, r_p, pulleys, out):
    """:func:`ik` into one array out (23 + 3, m): rows q, beta, gamma, l_f, kappa, A^T (6), l^T, c^T,
    Rb^T, n^T (3 each), then R in the first three columns of the last three rows (needs m >= 3)."""
    q, l, u, AT, c, beta, gamma, l_f, Rb, R, n, kappa = ik(x, a, b, R_A, r_p, pulleys)
    out[_Q], out[_BETA], out[_GAMMA], out[_L_F], out[_KAPPA] = q, beta, gamma, l_f, kappa
    out[_AT:_AT + 6] = AT
    out[_L:_L + 3], out[_C:_C + 3], out[_RB:_RB + 3], out[_N:_N + 3] = l.T, c.T, Rb.T, n.T
    out[_ROWS:] = 0.0
    out[_ROWS:, :3] = R


@njit(error_model="numpy")
def cable_lengths_kernel(x, a, b, R_A, r_p, pulleys, q):
    """q (m,) of :func:`ik` into q."""
    q[:] = ik(x, a, b, R_A, r_p, pulleys)[0]


@njit(error_model="numpy")
def joint_command_kernel(x, a, b, R_A, r_p, pulleys, dq_cfc, theta_d, step, delta):
    """The rate-limited step of JointCommand.update into delta (m,): the target θ = q(x) - Δq_CFC
    ((2.7), (5.10)) less θ_d, limited to ±step; False (delta not set) when the target is not finite."""
    q = ik(x, a, b, R_A, r_p, pulleys)[0]
    for i in range(q.shape[0]):
        if not np.isfinite(q[i] - dq_cfc[i]):
            return False
    for i in range(q.shape[0]):
        delta[i] = min(max((q[i] - dq_cfc[i]) - theta_d[i], -step), step)
    return True


@njit(error_model="numpy")
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


def joint_command_step(robot, x, dq_cfc, theta_d, step: float) -> np.ndarray | None:
    """:func:`joint_command_kernel` of pose x (6,): the change of θ_d (m,), None for a target that is not finite."""
    d = robot_data(robot)
    delta = np.empty(d.a.shape[0])
    dq_cfc, theta_d = vector(dq_cfc), vector(theta_d)
    if dq_cfc.shape != delta.shape or theta_d.shape != delta.shape:   # (broadcast, or raise, as numpy would)
        dq_cfc, theta_d = (vector(np.broadcast_to(v, delta.shape)) for v in (dq_cfc, theta_d))
    finite = joint_command_kernel(vector(x), d.a, d.b, d.R_A, d.r_p, d.pulleys, dq_cfc, theta_d, float(step), delta)
    return delta if finite else None


def measured_wrench(robot, x, f) -> np.ndarray:
    """w = -A^T(x) f (2.11) of the cable forces f (m,) at pose x (6,), compiled."""
    d = robot_data(robot)
    w = np.empty(6)
    measured_wrench_kernel(vector(x), vector(f), d.a, d.b, d.R_A, d.r_p, d.pulleys, w)
    return w


# --- platform wrench (2.33) ----------------------------------------------------------------------

@njit(error_model="numpy")
def _cross(a, b, out):
    out[0] = a[1] * b[2] - a[2] * b[1]
    out[1] = a[2] * b[0] - a[0] * b[2]
    out[2] = a[0] * b[1] - a[1] * b[0]


@njit(error_model="numpy")
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


# --- elastic forward kinematics (3.7)-(3.9) -----------------------------------------------------

@njit(error_model="numpy")
def k_spec(f, k0, k1, k2):
    """k_spec = k0 + k1 f + k2 f^2 (2.16) of one force f >= 0 (model.cable.k_spec compiled)."""
    return k0 + f * (k1 + k2 * f)


@njit(error_model="numpy")
def elastic_cable_state(theta, f, l_0, k0, k1, k2):
    """(q_hat, k_l) (m,): q_hat = theta + dq with dq = f (theta + l_0) / (k_spec - f) (3.7) and
    the secant stiffness k_l = k_spec(f) / (q_hat + l_0) (2.14)-(2.16) (cdpr_control.model.cable)."""
    m = theta.shape[0]
    q_hat, k_l = np.empty(m), np.empty(m)
    for i in range(m):
        k = k_spec(max(f[i], 0.0), k0, k1, k2)
        q_hat[i] = theta[i] + f[i] * (theta[i] + l_0[i]) / (k - f[i])
        k_l[i] = k / (q_hat[i] + l_0[i])
    return q_hat, k_l


@njit(error_model="numpy")
def secant_stiffness(f, l_t, k0, k1, k2, k):
    """k = k_spec(f) / l_t (2.15)-(2.16) (m,), k_spec = k0 + f (k1 + k2 f) with f <= 0 giving k0
    (cable.stiffness)."""
    for i in range(f.shape[0]):
        k[i] = k_spec(max(f[i], 0.0), k0, k1, k2) / l_t[i]


@njit(error_model="numpy")
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


@njit(error_model="numpy")
def cholesky_solve(A, g, dx, L):
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


@njit(error_model="numpy")
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


@njit(error_model="numpy")
def _within_rounding(increase, gain, res, rounding):
    """Whether a step's cost increase and predicted gain g^T dx are both within 4 sum |Psi_i|
    rounding_i, the rounding error of comparing two costs (forward_kinematics._within_rounding)."""
    noise = 0.0
    for i in range(res.shape[0]):
        noise += abs(res[i]) * rounding[i]
    return increase <= 4.0 * noise and gain <= 4.0 * noise


@njit(error_model="numpy")
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


@njit(error_model="numpy")
def _elastic_frozen(x_d, q_d, AT_d, cT, beta, b, r_p, theta, f, l_0, k0, k1, k2, xtol, max_iterations):
    m = cT.shape[1]
    q_hat, k_l = elastic_cable_state(theta, f, l_0, k0, k1, k2)
    x = x_d.copy()
    res, JT = np.empty(m), np.empty((6, m))
    res_new, JT_new, q_free, rounding = np.empty(m), np.empty((6, m)), np.empty(m), np.empty(m)
    ca, sa = math.cos(x[3]), math.sin(x[3])
    cb, sb = math.cos(x[4]), math.sin(x[4])
    r_d = math.sqrt(x_d[0] ** 2 + x_d[1] ** 2 + x_d[2] ** 2)
    cost = 0.0
    for i in range(m):
        q_free[i] = q_hat[i] - beta[i] * r_p[i]
        # the rounding error of Psi_i (ForwardKinematics._residual_rounding)
        rounding[i] = _EPS * k_l[i] * (math.sqrt(cT[0, i] ** 2 + cT[1, i] ** 2 + cT[2, i] ** 2)
                                       + math.sqrt(b[i, 0] ** 2 + b[i, 1] ** 2 + b[i, 2] ** 2) + r_d)
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
        if not cholesky_solve(A, g, dx, L):
            lam *= 10.0
            if lam > _LAMBDA_MAX:
                return STALLED, it, math.sqrt(cost), x
            continue
        if math.sqrt(dx[0] ** 2 + dx[1] ** 2 + dx[2] ** 2 + dx[3] ** 2 + dx[4] ** 2 + dx[5] ** 2) <= xtol:
            if lam <= _LAMBDA_CONVERGED:
                return CONVERGED, it, math.sqrt(cost), x
            _normal_equations(JT, res, 0.0, A, g)           # the undamped (Gauss-Newton) step
            if cholesky_solve(A, g, x_new, L) and math.sqrt(
                    x_new[0] ** 2 + x_new[1] ** 2 + x_new[2] ** 2 + x_new[3] ** 2 + x_new[4] ** 2
                    + x_new[5] ** 2) <= xtol:
                return CONVERGED, it, math.sqrt(cost), x
        for k in range(6):
            x_new[k] = x[k] - dx[k]
        cost_new = _frozen_residual(x_new, cT, b, q_free, k_l, res_new, JT_new, R, S, Rb)
        if cost_new <= cost or _within_rounding(cost_new - cost, g[0] * dx[0] + g[1] * dx[1] + g[2] * dx[2]
                                                + g[3] * dx[3] + g[4] * dx[4] + g[5] * dx[5], res, rounding):
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


# The joint command's whole period (5.10) in one call: JointCommand.update with one offset sum, as
# one call instead of the offset pose, joint_command_step and three numpy operations on 8 numbers
# (call overhead at 1 kHz): the same operations in the same order (x_d + offset, the step of
# joint_command_kernel, θ̇_d = Δθ / dt, θ_d + Δθ), so the same numbers, bit for bit
# (tests/kernels/test_force_distribution_joint_command_fast_paths.py). Here, beside joint_command_kernel, because numba's disk cache
# keeps the callees of a kernel and renews it only when the kernel's own file changes.
@njit(error_model="numpy")
def joint_command_period(x_d, offset, a, b, R_A, r_p, pulleys, dq_cfc, theta_d, step, dt, theta_next, velocity):
    """θ_d of the next period into theta_next (m,) and θ̇_d into velocity (m,): the target
    q(x_d + offset) - Δq_CFC ((2.7), (5.10)) approached by at most ±step; False (outputs not set)
    when the target is not finite."""
    x = np.empty(6)
    for k in range(6):
        x[k] = x_d[k] + offset[k]
    delta = np.empty(theta_d.shape[0])
    if not joint_command_kernel(x, a, b, R_A, r_p, pulleys, dq_cfc, theta_d, step, delta):
        return False
    for i in range(delta.shape[0]):
        velocity[i] = delta[i] / dt
        theta_next[i] = theta_d[i] + delta[i]
    return True
