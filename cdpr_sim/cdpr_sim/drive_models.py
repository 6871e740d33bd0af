"""Position-controlled winch drives as discrete-time models, thesis sections 3.3.1 and 5.2.3.

A drive makes the cable length theta (the winch's unstretched cable length, as measured by the
motor encoder, (2.24)-(2.25)) follow the command theta_d through

* PT1 + dead time (3.10): G_a(s) = e^{-T_d s} / (1 + T_1 s)            (IPAnema 3), or
* second order (5.11):   G_a(s) = e^{-T_d s} / (1 + 2 zeta T_w s + (T_w s)^2)   (IPAnema 3 Mini).

The command is held constant over each step of length dt (zero-order hold, as a field bus delivers
it). The discretisation is exact for that input, including a dead time that is not a multiple of
dt: with T_d = (d + nu) dt, 0 <= nu < 1, the delayed input switches from theta_d[k-d-1] to
theta_d[k-d] at nu dt inside step k, so

    x[k+1] = Phi x[k] + e^{A (1-nu) dt} Gamma(nu dt) theta_d[k-d-1] + Gamma((1-nu) dt) theta_d[k-d]

with Phi = e^{A dt} and Gamma(tau) = int_0^tau e^{A s} ds B. The drive's speed limit v_max clips
the change of theta per step to v_max dt (and, for the second-order model, the velocity state to
+-v_max): a saturated servo, outside the linear models of the thesis.

All drives of a robot share one model; the state is vectorised over the m cables. The step,
:func:`drive_step`, is written in the array subset numba compiles: a caller needing speed (the
simulator, once per physics step) passes ``jit=cdpr_control.kernels.jit.njit``; this module imports only numpy/scipy.
"""
from __future__ import annotations

import math

import numpy as np
from scipy.linalg import expm

PT1_DEADTIME = "pt1_deadtime"
SECOND_ORDER = "second_order"


def _zoh_integral(A: np.ndarray, B: np.ndarray, tau: float) -> tuple[np.ndarray, np.ndarray]:
    """(e^{A tau}, int_0^tau e^{A s} ds B) from one matrix exponential of [[A, B], [0, 0]] tau."""
    n = A.shape[0]
    M = np.zeros((n + 1, n + 1))
    M[:n, :n] = A
    M[:n, n] = B
    E = expm(M * tau)
    return np.ascontiguousarray(E[:n, :n]), np.ascontiguousarray(E[:n, n])


def drive_step(theta_d, Phi, G_new, G_old, x, buffer, head, delay, v_max, dt, thetadot):
    """Advance the state x (n, m) of the drives by dt with the held command theta_d (m,).

    buffer (delay + 2, m): ring buffer of the commands, head: the slot for theta_d; the delayed
    inputs theta_d[k-d] and theta_d[k-d-1] enter through G_new and G_old. Writes x and the mean
    velocity thetadot (m,) in place; returns the next head.
    """
    L = buffer.shape[0]
    buffer[head] = theta_d
    u_new = buffer[(head - delay) % L]
    u_old = buffer[(head - delay - 1) % L]
    x_new = Phi @ x + G_new[:, None] * u_new + G_old[:, None] * u_old
    step = x_new[0] - x[0]
    limit = v_max * dt
    if np.abs(step).max() > limit:                 # speed limit of the servo
        step = np.minimum(np.maximum(step, -limit), limit)
        x_new[0] = x[0] + step
        if x.shape[0] == 2:
            x_new[1] = np.minimum(np.maximum(x_new[1], -v_max), v_max)
    x[:] = x_new
    thetadot[:] = step / dt
    return (head + 1) % L


class DriveModel:
    """m identical position-controlled drives; :meth:`step` advances them by dt under theta_d.

    Build with :meth:`pt1_deadtime`, :meth:`second_order` or :meth:`from_robot`. After a step,
    ``theta`` (m,) is the cable length at the end of the step and ``thetadot`` (m,) the mean cable
    velocity over the step, (theta[k+1] - theta[k]) / dt, as a drive differentiating its encoder
    reports it. jit: compiler for :func:`drive_step` (e.g. cdpr_control.kernels.jit.njit), None runs it as numpy.
    """

    def __init__(self, kind: str, A: np.ndarray, B: np.ndarray, T_d: float, dt: float, m: int,
                 v_max: float = math.inf, params: dict | None = None, jit=None):
        if not dt > 0.0:
            raise ValueError(f"dt must be > 0 s, got {dt}")
        if not T_d >= 0.0:
            raise ValueError(f"dead time T_d must be >= 0 s, got {T_d}")
        if not v_max > 0.0:
            raise ValueError(f"v_max must be > 0 m/s, got {v_max}")
        self.kind = kind
        self.params = dict(params or {})
        self.T_d = float(T_d)
        self.dt = float(dt)
        self.m = int(m)
        self.v_max = float(v_max)
        ratio = T_d / dt
        d = int(math.floor(ratio + 1e-9))
        nu = max(ratio - d, 0.0)
        if nu < 1e-9:
            nu = 0.0
        self.delay_steps, self.delay_fraction = d, nu
        if A.shape[0] == 0:           # pure dead time (PT1 with T_1 = 0): theta = theta_d[k-d] at the step end
            self._Phi, self._G_new, self._G_old = np.zeros((1, 1)), np.ones(1), np.zeros(1)
        else:
            self._Phi, _ = _zoh_integral(A, B, dt)
            Phi_late, self._G_new = _zoh_integral(A, B, (1.0 - nu) * dt)
            _, G_early = _zoh_integral(A, B, nu * dt)
            self._G_old = Phi_late @ G_early
        self._buffer = np.zeros((d + 2, self.m))   # ring buffer of the last d + 2 commands
        self._head = 0
        self._x = np.zeros((self._Phi.shape[0], self.m))    # state, row 0 is theta
        self._step = drive_step if jit is None else jit(drive_step)
        self.theta = np.zeros(self.m)
        self.thetadot = np.zeros(self.m)

    # --- constructors ----------------------------------------------------------------------

    @classmethod
    def pt1_deadtime(cls, T_1: float, T_d: float, dt: float, m: int, v_max: float = math.inf, jit=None):
        """G_a(s) = e^{-T_d s} / (1 + T_1 s) (3.10); T_1 = 0 is a pure dead time."""
        if not T_1 >= 0.0:
            raise ValueError(f"T_1 must be >= 0 s, got {T_1}")
        if T_1 == 0.0:
            A, B = np.zeros((0, 0)), np.zeros(0)
        else:
            A, B = np.array([[-1.0 / T_1]]), np.array([1.0 / T_1])
        return cls(PT1_DEADTIME, A, B, T_d, dt, m, v_max, {"T_1": float(T_1)}, jit)

    @classmethod
    def second_order(cls, T_w: float, zeta: float, T_d: float, dt: float, m: int,
                     v_max: float = math.inf, jit=None):
        """G_a(s) = e^{-T_d s} / (1 + 2 zeta T_w s + (T_w s)^2) (5.11), state [theta, thetadot]."""
        if not (T_w > 0.0 and zeta > 0.0):
            raise ValueError(f"second-order drives need T_w > 0 s and zeta > 0, got {T_w}, {zeta}")
        A = np.array([[0.0, 1.0], [-1.0 / T_w**2, -2.0 * zeta / T_w]])
        B = np.array([0.0, 1.0 / T_w**2])
        return cls(SECOND_ORDER, A, B, T_d, dt, m, v_max, {"T_w": float(T_w), "zeta": float(zeta)}, jit)

    @classmethod
    def from_robot(cls, robot, dt: float, jit=None) -> "DriveModel":
        """The drive model of the robot file (robot.drive.model) for m = robot.m drives."""
        d = robot.drive
        if d.model == PT1_DEADTIME:
            return cls.pt1_deadtime(d.T_1, d.T_d, dt, robot.m, d.v_max, jit)
        return cls.second_order(d.T_w, d.zeta, d.T_d, dt, robot.m, d.v_max, jit)

    # --- running ---------------------------------------------------------------------------

    def reset(self, theta) -> None:
        """Standstill at theta (m,): the state and every buffered command equal theta."""
        theta = np.broadcast_to(np.asarray(theta, dtype=float), (self.m,))
        self._buffer[:] = theta
        self._x[:] = 0.0
        self._x[0] = theta
        self._head = 0
        self.theta = theta.copy()
        self.thetadot = np.zeros(self.m)

    def step(self, theta_d) -> np.ndarray:
        """Advance one dt with theta_d (m,) held; returns theta (m,) at the end of the step."""
        self._head = self._step(np.asarray(theta_d, dtype=float), self._Phi, self._G_new, self._G_old, self._x,
                                self._buffer, self._head, self.delay_steps, self.v_max, self.dt, self.thetadot)
        self.theta = self._x[0].copy()
        return self.theta

    def step_arguments(self) -> tuple:
        """The arguments of :func:`drive_step` after theta_d, for a caller that runs the step inside
        its own compiled code (the simulator's period): it then hands the returned head and the new
        theta over to :meth:`stepped`."""
        return (self._Phi, self._G_new, self._G_old, self._x, self._buffer, self._head, self.delay_steps, self.v_max,
                self.dt, self.thetadot)

    def stepped(self, head: int, theta: np.ndarray) -> None:
        """Take over the result of a :func:`drive_step` run on :meth:`step_arguments`: the next head
        and theta (m,), a new array (a copy of the state's first row, as :meth:`step` makes)."""
        self._head = head
        self.theta = theta

    # --- continuous model ------------------------------------------------------------------

    def transfer_function(self, s) -> np.ndarray:
        """G_a(s) of the continuous model (3.10) or (5.11) at complex frequencies s."""
        s = np.asarray(s, dtype=complex)
        if self.kind == PT1_DEADTIME:
            G = 1.0 / (1.0 + self.params["T_1"] * s)
        else:
            T_w, zeta = self.params["T_w"], self.params["zeta"]
            G = 1.0 / (1.0 + 2.0 * zeta * T_w * s + (T_w * s) ** 2)
        return G * np.exp(-self.T_d * s)
