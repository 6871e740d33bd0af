"""Forward kinematics by Levenberg-Marquardt, thesis sections 2.1.4 and 3.2.

Three formulations of the pose x = [r; phi] (Kardan angles) from joint-space measurements:

* joint space, rigid cables: min |IK(x) - theta|^2 (2.34)-(2.35);
* operational space: min |W (A^T f_hat(x) + w)|^2 with f_hat from the elongation IK(x) - theta
  (2.36)-(2.38), i.e. the pose where the elastic cables balance the wrench w (A^T f = -w, (2.10));
* elastic joint space: min |K_l (IK(x) - q_hat)|^2 (3.8)-(3.9) with q_hat = theta + dq(f) - dq_0
  from the measured forces (3.7); with pulleys='frozen' the leave points c_i and wrap angles beta
  are computed once at the start pose x_d (section 3.2) and the iterations use the pulley-free
  model.

A :class:`ForwardKinematics` object holds the robot and preallocated buffers; each solve returns an
:class:`FKResult` saying whether it converged and why it stopped. A solve never returns a pose
silently: ``converged`` is False unless the Gauss-Newton step fell below ``xtol``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.linalg.lapack import dposv

from cdpr_control.model import cable
from cdpr_control import kernels
from cdpr_control.model.dynamics import gravity_wrench
from cdpr_control.model.kinematics import inverse_kinematics, kardan_rate_matrix, rotation_matrix, skew
from cdpr_control.model.stiffness import operational_stiffness

CONVERGED = "step"  # the (nearly undamped) LM step fell below xtol
MAX_ITERATIONS = "max_iterations"  # iteration budget used up
STALLED = "stalled"  # damping grew past its limit without reducing the cost
NON_FINITE = "non_finite"  # the model gave NaN/inf at the start pose (e.g. beyond cable range)
# by the termination codes of cdpr_control.kernels.model.elastic_frozen
_TERMINATIONS = (CONVERGED, MAX_ITERATIONS, STALLED, NON_FINITE)

# Marquardt damping, relative to diag(J^T J): warm starts are nearly Gauss-Newton
_LAMBDA_START = 1e-6
_LAMBDA_MIN = 1e-12
_LAMBDA_MAX = 1e12
_LAMBDA_CONVERGED = 1e-2  # below this damping a small step means convergence (else check GN step)
_EPS = float(np.finfo(float).eps)  # unit roundoff, of the elastic residual's rounding error


@dataclass(frozen=True)
class FKResult:
    """Outcome of one forward kinematics solve.

    x (6,) pose estimate; converged; termination (CONVERGED, MAX_ITERATIONS, STALLED, NON_FINITE);
    iterations (LM iterations, each one linear solve); residual_norm |Psi(x)| of the objective
    in its own unit (m, N or N/Nm-weighted).
    """

    x: np.ndarray
    converged: bool
    termination: str
    iterations: int
    residual_norm: float


def _rotation_derivatives(phi_x, phi_y, S):
    """Fill S (9, 3) = [[h_1]; [h_2]; [h_3]], so that dR/dphi_k = [h_k] R with h_k = column k of
    kardan_rate_matrix. Scalar math into a buffer whose constant entries are set already
    (zeros, S[1, 2] = -1, S[2, 1] = 1): for one pose cheaper than numpy calls."""
    ca, sa = math.cos(phi_x), math.sin(phi_x)
    cb, sb = math.cos(phi_y), math.sin(phi_y)
    hx, hy, hz = sb, -sa * cb, ca * cb
    S[3, 1], S[3, 2], S[4, 0], S[5, 0] = -sa, ca, sa, -ca
    S[6, 1], S[6, 2], S[7, 0], S[7, 2], S[8, 0], S[8, 1] = -hz, hy, hz, -hx, -hy, hx


def _gauss_newton_step_norm(JT, res) -> float:
    """|dx| of the undamped step: a heavily damped step is small without being converged."""
    _, dx, info = dposv(np.dot(JT, JT.T), np.dot(JT, res))
    return math.sqrt(np.dot(dx, dx)) if info == 0 else math.inf


def _within_rounding(increase, gain, res, rounding) -> bool:
    """Whether a step's cost increase and its predicted gain g^T dx (g = J^T Psi) are both within
    the rounding error of comparing two costs, 4 sum |Psi_i| rounding_i (rounding (m,): of each
    Psi_i): the comparison cannot tell, so the step is taken as the linear model predicts."""
    noise = 4.0 * np.dot(np.abs(res), rounding)        # d|Psi|^2 = 2 Psi dPsi, two costs compared
    return increase <= noise and gain <= noise


class ForwardKinematics:
    """Levenberg-Marquardt forward kinematics for one robot (single poses).

    xtol [m, rad]: convergence when the Gauss-Newton step is below it. max_iterations: LM
    iterations (linear solves) per call. Holds scratch buffers: use one object per thread.
    """

    def __init__(self, robot, *, xtol: float = 1e-10, max_iterations: int = 100):
        self.robot = robot
        self.xtol = xtol
        self.max_iterations = max_iterations
        self._bT = np.ascontiguousarray(robot.b.T)  # (3, m)
        self._S = np.zeros((9, 3))  # buffer of _rotation_derivatives
        self._S[1, 2], self._S[2, 1] = -1.0, 1.0
        self._b_norm = np.linalg.norm(robot.b, axis=1)
        self._lever = float(np.mean(self._b_norm))

    # --- public solves ------------------------------------------------------------------------

    def joint_space(self, theta, x0) -> FKResult:
        """Rigid-cable FK (2.34)-(2.35): min_x |IK(x) - theta|^2, started at x0 (e.g. x_d).

        Uses the robot's pulley model (robot.swivelling_pulleys) in every iteration.
        """
        theta = np.asarray(theta, dtype=float)
        robot = self.robot

        def residual(x):
            ik = inverse_kinematics(robot, x)
            return ik.q - theta, self._jacobian_T(ik.AT, x, 1.0)

        return self._solve(residual, x0)

    def operational_space(self, theta, x0, w=None, weights=None) -> FKResult:
        """Operational-space FK (2.36)-(2.38): min_x |W (A^T f_hat + w)|^2.

        f_hat = cable.force_from_elongation(IK(x) - theta, l_t) (2.17), l_t = IK(x) + l_0 (2.14);
        w is the wrench of (2.10) acting on the platform (default: its weight at x, the w_0 of
        (2.37); the thesis writes A^T f - w_0 with w_0 the load the cables carry).
        weights: diagonal of W (6,), default [1, 1, 1, 1/rho] with rho the mean platform radius
        (a torque of rho N m weighs as much as 1 N).
        """
        robot = self.robot
        theta = np.asarray(theta, dtype=float)
        w_fixed = None if w is None else np.asarray(w, dtype=float)
        if weights is None:
            weights = np.r_[np.ones(3), np.full(3, 1.0 / self._lever)]
        W = np.asarray(weights, dtype=float)

        def residual(x):
            ik = inverse_kinematics(robot, x)
            l_t = cable.total_free_length(robot, ik.q)
            f = cable.force_from_elongation(robot, ik.q - theta, l_t)
            k_l = cable.tangent_stiffness(robot, f, l_t)
            # d(A^T f)/dx = -K_x; the Kardan angles enter through H.
            J = -operational_stiffness(ik, f, k_l)
            if w_fixed is None:
                w = gravity_wrench(robot, x)
                # the weight's moment c x m g turns with the platform: d/dtheta = [m g][c]
                J[3:, 3:] += skew(w[:3]) @ skew(ik.R @ robot.platform.center_of_gravity)
            else:
                w = w_fixed
            J[:, 3:] = J[:, 3:] @ kardan_rate_matrix(x[3:])
            return W * (ik.AT @ f + w), (W[:, None] * J).T

        return self._solve(residual, x0)

    def elastic(self, theta, f, x_d, dq0=None, pulleys: str = "frozen", ik_d=None) -> FKResult:
        """FK with non-linear elastic cables (3.7)-(3.9), warm-started at the desired pose x_d.

        theta (m,): winch cable lengths (encoders); f (m,): measured cable forces; dq0 (m,):
        elongation at controller start-up (default 0). The elongation dq of (3.7) uses
        l_t = q_hat + l_0 (2.14), solved in closed form
        (cable.elongation_from_force_and_winch_length), then q_hat = theta + dq - dq0 and
        K_l = diag(k_spec(f) / l_t) (2.15).

        pulleys='frozen' (section 3.2): c_i and beta_i from the pulley IK at x_d, then
        IK(x) = |c_i - r - R b_i| + beta_i r_p; exact only when x = x_d, the error is second order
        in |x - x_d|. ik_d: the IK of x_d when the caller has it already, as
        :func:`cdpr_control.kernels.setpoint_ik` (ControlLoop's, shared by the period's stages) or
        an :class:`~cdpr_control.model.kinematics.InverseKinematics`, saving the one pulley IK of 'frozen'.
        pulleys='full': the pulley IK in every iteration (exact, several times slower).
        Robots without swivelling pulleys use their fixed anchors either way.
        """
        robot = self.robot
        x_d = np.asarray(x_d, dtype=float)
        theta = np.asarray(theta, dtype=float)
        if dq0 is not None:
            theta = theta - dq0
        if pulleys == "frozen":
            return elastic_frozen(self, theta, f, x_d, ik_d)
        return self._elastic_numpy(theta, f, x_d, ik_d, pulleys)

    def _elastic_numpy(self, theta, f, x_d, ik_d, pulleys: str) -> FKResult:
        """:meth:`elastic` on numpy: the pulley IK in each iteration ('full') or frozen at x_d."""
        robot = self.robot
        dq = cable.elongation_from_force_and_winch_length(robot, f, theta)
        q_hat = theta + dq
        k_l = cable.stiffness(robot, f, cable.total_free_length(robot, q_hat))
        if pulleys not in ("frozen", "full"):
            raise ValueError(f"pulleys must be 'frozen' or 'full', got {pulleys!r}")
        if ik_d is None:
            ik_d = inverse_kinematics(robot, x_d)
        rounding = self._residual_rounding(k_l, ik_d.c, x_d)
        if pulleys == "full":

            def residual(x):
                ik = inverse_kinematics(robot, x)
                return k_l * (ik.q - q_hat), self._jacobian_T(ik.AT, x, k_l)

            return self._solve(residual, x_d, rounding=rounding)
        residual = self._frozen_residual(
            np.ascontiguousarray(ik_d.c.T), q_hat - ik_d.beta * robot.r_p, k_l
        )
        # at x_d the frozen model is the pulley IK itself: its first residual comes for free
        first = (k_l * (ik_d.q - q_hat), self._jacobian_T(ik_d.AT, x_d, k_l))
        return self._solve(residual, x_d, first, rounding)

    # --- internals ----------------------------------------------------------------------------

    def _elastic_frozen_compiled(self, theta, f, x_d, ik_d) -> FKResult:
        """elastic(pulleys='frozen') as one compiled call (cdpr_control.kernels), same numbers."""
        robot = self.robot
        d = kernels.robot_data(robot)
        v, x = kernels.vector, np.empty(6)
        x_d = v(x_d)
        if ik_d is None:      # the four fields the kernel takes (C-contiguous rows), without building the others
            q, AT, cT, beta = kernels.setpoint_ik(robot, x_d)
        elif type(ik_d) is kernels.SetpointIK:
            q, AT, cT, beta = ik_d
        else:
            q, AT, cT, beta = v(ik_d.q), v(ik_d.AT), v(ik_d.c.T), v(ik_d.beta)
        code, iterations, norm = kernels.elastic_frozen(
            x_d, q, AT, cT, beta, d.b, d.r_p, v(theta), v(f), d.l_0,
            d.k0, d.k1, d.k2, self.xtol, self.max_iterations, x)
        return FKResult(x, code == 0, _TERMINATIONS[code], iterations, norm)

    def _residual_rounding(self, k_l, c, x_d):
        """(m,) rounding error of the elastic residual Psi_i = k_l,i (|c_i - r - R b_i| - q_free_i)
        at x_d: eps k_l,i (|c_i| + |b_i| + |r_d|), a few ulp of the lengths it subtracts."""
        return _EPS * k_l * (np.linalg.norm(c, axis=1) + self._b_norm + math.sqrt(np.dot(x_d[:3], x_d[:3])))

    def _jacobian_T(self, AT, x, k_l):
        """(dPsi/dx)^T (6, m) of Psi = k_l (IK(x) - .): dq/dx = -A blockdiag(I, H(phi))."""
        JT = -AT * k_l
        JT[3:] = kardan_rate_matrix(x[3:]).T @ JT[3:]
        return JT

    def _frozen_residual(self, cT, q_free, k_l):
        """Residual k_l (|c_i - r - R b_i| - q_free) and its Jacobian (transposed) for fixed
        anchors cT (3, m).

        dq_i/dr = -u_i, dq_i/dphi_k = -u_i . ([h_k] R b_i) (h_k: column k of kardan_rate_matrix).
        """
        bT, S = self._bT, self._S
        m = bT.shape[1]
        add, dot, multiply = np.add.reduce, np.dot, np.multiply

        def residual(x):
            _rotation_derivatives(x[3], x[4], S)
            Rb = dot(rotation_matrix(x[3:]), bT)
            l = cT - Rb
            l -= x[:3, None]
            L = np.sqrt(add(l * l, 0))
            JT = np.empty((6, m))
            multiply(l, -k_l / L, out=JT[:3])  # -k_l u
            add(dot(S, Rb).reshape(3, 3, m) * JT[:3], 1, out=JT[3:])
            return k_l * (L - q_free), JT

        return residual

    def _solve(self, residual, x0, first=None, rounding=None) -> FKResult:
        """Levenberg-Marquardt with Marquardt scaling; stops on a small nearly-undamped step.

        residual(x) -> (Psi, dPsi/dx transposed); first: its value at x0 if already known.
        rounding (m,): the rounding error of each Psi_i; with it a step is also taken when its
        cost increase and predicted gain are both below what comparing two costs can resolve
        (:func:`_within_rounding`): with a large least-squares residual (forces and lengths no pose
        explains exactly) a Gauss-Newton step just above xtol in a weakly determined direction
        gains less than the cost's rounding error, and rejecting it stalled the solve there.
        """
        x = np.array(x0, dtype=float)
        res, JT = residual(x) if first is None else first
        cost = float(np.dot(res, res))
        if not math.isfinite(cost) or not math.isfinite(JT.sum()):
            return FKResult(x, False, NON_FINITE, 0, math.sqrt(cost) if cost >= 0 else math.nan)
        lam = _LAMBDA_START
        xtol = self.xtol
        for it in range(1, self.max_iterations + 1):
            A = np.dot(JT, JT.T)
            A.flat[::7] *= 1.0 + lam  # Marquardt: A + lam diag(A)
            g = np.dot(JT, res)
            _, dx, info = dposv(A, g, overwrite_a=1)
            if info != 0:
                lam *= 10.0
                if lam > _LAMBDA_MAX:
                    return FKResult(x, False, STALLED, it, math.sqrt(cost))
                continue
            if math.sqrt(np.dot(dx, dx)) <= xtol and (
                lam <= _LAMBDA_CONVERGED or _gauss_newton_step_norm(JT, res) <= xtol
            ):
                return FKResult(x, True, CONVERGED, it, math.sqrt(cost))
            x_new = x - dx
            res_new, JT_new = residual(x_new)
            cost_new = float(np.dot(res_new, res_new))
            if cost_new <= cost or (rounding is not None
                                    and _within_rounding(cost_new - cost, np.dot(g, dx), res, rounding)):
                x, res, JT, cost = x_new, res_new, JT_new, cost_new
                lam = max(lam * 0.1, _LAMBDA_MIN)
            else:
                lam *= 10.0
                if lam > _LAMBDA_MAX:
                    return FKResult(x, False, STALLED, it, math.sqrt(cost))
        return FKResult(x, False, MAX_ITERATIONS, self.max_iterations, math.sqrt(cost))


def _elastic_frozen_numpy(fk: ForwardKinematics, theta, f, x_d, ik_d) -> FKResult:
    return fk._elastic_numpy(theta, f, x_d, ik_d, "frozen")


# the elastic FK with frozen pulleys (3.7)-(3.9), section 3.2 (the compiled flavour: the method itself,
# a call frame less in every period than a function wrapping it)
elastic_frozen = kernels.law("elastic_frozen", _elastic_frozen_numpy, ForwardKinematics._elastic_frozen_compiled)
