"""Pulley friction between a winch-integrated force sensor and the platform, thesis section 3.7.2.

The cable runs from the drum over the sensor pulley P1 and the pulleys P2 .. P_np to the platform;
P_np is the swivelling pulley whose wrap angle beta_np comes from the inverse kinematics (2.6), the
pulleys in between have the fixed wrap angle beta_inner. Forces: F_s the sensor signal, F_1 = f_w
the cable force after P1 (3.36)-(3.40), F_np = f the force at the platform.

* Coulomb + viscous friction of the pulley series (3.30)-(3.35): with s = sgn(thetadot) and
  k_j = sqrt(2 (1 - cos beta_j)) (3.33), each pulley maps F_{j-1} to
  F_j = (F_{j-1} (2 + s mu k_j) + 2 F_pv thetadot) / (2 - s mu k_j), so the series is affine,
  F_np = alpha F_1 + gamma thetadot, and its macroscopic friction is F_f = F_np - F_1 (3.41).
* Dahl hysteresis (3.42) with alpha = 1, solved between direction changes (3.43):
  F_D = s F_c + (F_0 - s F_c) exp(-sigma |theta - theta_0| / F_c), F_c = |F_f|, where theta_0 and
  F_0 are the cable length and friction stored at the last direction change. (The thesis prints
  "F_0 + F_f sgn" in the bracket; only the minus sign solves (3.42) and gives F_D = F_0 at the
  direction change.) While the cable stands still the last direction is kept.
* The force at the platform (3.44): f = f_w + F_D.

Directions: thetadot > 0 pays the cable out; the platform then pulls the cable over the pulleys,
so f > f_w, and pulling in (thetadot < 0) shows a sensor force above the platform force.

:class:`PulleyFriction` holds the state and offers both directions, each advancing the Dahl state
by one sample: :meth:`PulleyFriction.platform_force` (sensor -> platform, the compensation and the
identification (3.45)) and :meth:`PulleyFriction.sensor_force` (platform -> sensor, the simulator),
its exact inverse. Everything is vectorised over the m cables; pure numpy.

The two per-sample steps, :func:`platform_force_step` and :func:`sensor_force_step`, are written in
the array subset that numba compiles and take the Dahl state as an explicit array, so a caller that
needs speed passes ``jit=cdpr_control.kernels.jit.njit`` to :class:`PulleyFriction` and runs this same code compiled;
this module itself imports nothing beyond numpy. The simulator runs :meth:`PulleyFriction.sensor_force`
as :func:`cdpr_control.kernels.friction_sensor_force` (the same operations as a loop over the
cables) while the kernels are enabled.
"""
from __future__ import annotations

import numpy as np


def wrap_factor(beta) -> np.ndarray:
    """k = sqrt(2 (1 - cos beta)) (3.33): normal force on a pulley per unit mean cable force."""
    return np.sqrt(2.0 * (1.0 - np.cos(beta)))


def pulley_force(F_prev, thetadot, mu, F_pv, beta, s=None) -> np.ndarray:
    """F_j of one pulley (3.35) from F_{j-1}; s defaults to sgn(thetadot)."""
    s = np.sign(thetadot) if s is None else s
    smk = s * mu * wrap_factor(beta)
    return (F_prev * (2.0 + smk) + 2.0 * F_pv * thetadot) / (2.0 - smk)


def winch_force_from_sensor(F_s, beta_1) -> np.ndarray:
    """f_w = F_1 from the sensor force of the sensor pulley P1 without friction, (3.36)-(3.40).

    Geometry: the sensor measures the load of P1 along the cable that leaves P1 towards the
    platform (force F_1); the cable from the drum (force F_0) wraps P1 by beta_1. The force balance
    along the sensor axis is (3.36), F_s = F_1 - F_0 cos(beta_1), and with F_0 = F_1 (no friction)
    F_1 = F_s / (1 - cos beta_1) at every wrap angle. The thesis summarises its two designs by
    (3.40), F_1 = F_s (1 + sin beta_1) / 2, which equals this only at beta_1 = 90 deg (IPAnema 3,
    (3.37): F_1 = F_s) and 180 deg (IPAnema 3 Mini, (3.39) without friction: F_s / 2); at other
    angles (3.40) is not a force balance (135 deg: 0.854 F_s against 0.586 F_s), so the code uses
    (3.36). A load cell in the pulley axle, measuring the resultant along the bisector, would be
    F_1 = F_s / (2 sin(beta_1 / 2)) instead: robots with that design need their own beta_1
    equivalent (sensor calibration), see docs/model.md.
    """
    return np.asarray(F_s, dtype=float) / (1.0 - np.cos(beta_1))


def sensor_from_winch_force(f_w, beta_1) -> np.ndarray:
    """F_s = f_w (1 - cos beta_1), the inverse of :func:`winch_force_from_sensor`."""
    return np.asarray(f_w, dtype=float) * (1.0 - np.cos(beta_1))


class PulleySeries:
    """The pulleys P2 .. P_np of every cable as the affine map F_np = alpha F_1 + gamma thetadot.

    mu, F_pv (m,): Coulomb coefficient (3.31) and viscous parameter [N s/m] per cable (the same
    for every pulley of a cable, as identified in table 3.4); n_pulleys (m,): pulleys from the
    sensor to the platform including P1 and the swivelling P_np; beta_inner [rad]: wrap angle of
    P2 .. P_np-1. A cable with n_pulleys = 1 has no pulley after the sensor and no friction.
    """

    def __init__(self, mu, F_pv, n_pulleys, beta_inner: float):
        self.mu = np.array(mu, dtype=float)
        self.F_pv = np.array(F_pv, dtype=float)
        n_p = np.asarray(n_pulleys, dtype=int)
        self.m = self.mu.shape[0]
        self.has_last = n_p >= 2
        # the fixed inner pulleys as an affine map per direction s = -1, 0, +1 (row s + 1)
        n_inner = np.maximum(n_p - 2, 0)
        self._alpha_in = np.empty((3, self.m))
        self._gamma_in = np.empty((3, self.m))
        for row, s in enumerate((-1.0, 0.0, 1.0)):
            smk = s * self.mu * wrap_factor(beta_inner)
            a = (2.0 + smk) / (2.0 - smk)
            b = 2.0 * self.F_pv / (2.0 - smk)
            alpha, gamma = np.ones(self.m), np.zeros(self.m)
            for j in range(int(n_inner.max(initial=0))):
                inner = j < n_inner
                alpha, gamma = np.where(inner, a * alpha, alpha), np.where(inner, a * gamma + b, gamma)
            self._alpha_in[row], self._gamma_in[row] = alpha, gamma
        self._cols = np.arange(self.m)
        self._beta_key = None
        self._beta_seen = None

    @property
    def inner(self) -> tuple[np.ndarray, np.ndarray]:
        """alpha, gamma (3, m) of the inner pulleys P2 .. P_np-1 alone, rows s = -1, 0, 1."""
        return self._alpha_in, self._gamma_in

    def tables(self, beta_last) -> tuple[np.ndarray, np.ndarray]:
        """alpha, gamma (3, m) for s = -1, 0, 1 (rows); recomputed only when beta_last changes."""
        if beta_last is not self._beta_seen and (self._beta_key is None or not (self._beta_key == beta_last).all()):
            self._alpha, self._gamma = last_pulley_tables(_floats(beta_last), self.mu, self.F_pv, self.has_last,
                                                          self._alpha_in, self._gamma_in)
            self._beta_key = np.array(beta_last, dtype=float)
        # the same read-only array again (the simulator's frozen wrap angles): no comparison needed
        self._beta_seen = beta_last if isinstance(beta_last, np.ndarray) and not beta_last.flags.writeable else None
        return self._alpha, self._gamma

    def gains(self, s, beta_last) -> tuple[np.ndarray, np.ndarray]:
        """(alpha, gamma) (m,) of F_np = alpha F_1 + gamma thetadot for directions s (m,) in {-1, 0, 1}."""
        alpha, gamma = self.tables(beta_last)
        row = (np.asarray(s) + 1).astype(np.intp)
        return alpha[row, self._cols], gamma[row, self._cols]

    def platform_force(self, F_1, thetadot, beta_last, s=None) -> np.ndarray:
        """F_np from F_1 through (3.35) for every pulley; s defaults to sgn(thetadot)."""
        s = np.sign(thetadot) if s is None else s
        alpha, gamma = self.gains(s, beta_last)
        return alpha * F_1 + gamma * thetadot

    def winch_force(self, F_np, thetadot, beta_last, s=None) -> np.ndarray:
        """F_1 from F_np, the exact inverse of :meth:`platform_force`."""
        s = np.sign(thetadot) if s is None else s
        alpha, gamma = self.gains(s, beta_last)
        return (F_np - gamma * thetadot) / alpha


def last_pulley_tables(beta_last, mu, F_pv, has_last, alpha_in, gamma_in):
    """alpha, gamma (3, m) of PulleySeries.tables: the inner pulleys' maps alpha_in, gamma_in (3, m)
    followed by the swivelling pulley P_np (3.35) of wrap angle beta_last (m,), for s = -1, 0, 1.
    In the array subset numba compiles (cdpr_control.kernels runs it compiled)."""
    k = np.sqrt(2.0 * (1.0 - np.cos(beta_last)))         # wrap_factor (3.33), inlined for numba
    smk = np.array([-1.0, 0.0, 1.0]).reshape(3, 1) * (mu * k)
    a = np.where(has_last, (2.0 + smk) / (2.0 - smk), 1.0)
    b = np.where(has_last, 2.0 * F_pv / (2.0 - smk), 0.0)
    return a * alpha_in, a * gamma_in + b


# rows of the Dahl state (5, m)
ROW_DIRECTION = 0   # last direction of motion s (0 before the first motion)
ROW_THETA_0 = 1     # cable length at the last direction change (3.43)
ROW_F_0 = 2         # friction F_D at the last direction change (3.43)
ROW_THETA = 3       # cable length of the last sample
ROW_F_D = 4         # friction F_D of the last sample


def platform_force_step(f_w, theta, thetadot, alpha_table, gamma_table, sigma, v_eps, state):
    """One sample of f = f_w + F_D (3.44) from the winch forces f_w (3.40); advances ``state``.

    theta, thetadot (m,); alpha_table, gamma_table (3, m): PulleySeries.tables; sigma (m,) [N/m];
    v_eps [m/s]: |thetadot| up to it keeps the last direction; state (5, m): ROW_* above.
    """
    direction = state[ROW_DIRECTION]
    s = np.where(np.abs(thetadot) > v_eps, np.sign(thetadot), direction)
    changed = s != direction                                  # store theta_0, F_0 (3.43)
    state[ROW_THETA_0] = np.where(changed, state[ROW_THETA], state[ROW_THETA_0])
    state[ROW_F_0] = np.where(changed, state[ROW_F_D], state[ROW_F_0])
    state[ROW_DIRECTION] = s
    alpha = np.where(s > 0.0, alpha_table[2], np.where(s < 0.0, alpha_table[0], alpha_table[1]))
    gamma = np.where(s > 0.0, gamma_table[2], np.where(s < 0.0, gamma_table[0], gamma_table[1]))
    F_c = np.maximum(s * ((alpha - 1.0) * f_w + gamma * thetadot), 1e-300)      # |F_f| (3.41)
    sF = s * F_c
    F_D = sF + (state[ROW_F_0] - sF) * np.exp(-sigma * np.abs(theta - state[ROW_THETA_0]) / F_c)   # (3.43)
    state[ROW_THETA] = theta
    state[ROW_F_D] = F_D
    return f_w + F_D


def sensor_force_step(f, theta, thetadot, alpha_table, gamma_table, sigma, v_eps, state, tol, max_iterations):
    """One sample of the inverse: f_w (m,) with f_w + F_D(f_w) = f; advances ``state``.

    Arguments as :func:`platform_force_step`. For a fixed Dahl factor
    E = exp(-sigma |theta - theta_0| / F_c) the equation is linear in f_w (F_c = s F_f is affine in
    f_w, (3.41)), so the iteration alternates E from f_w and f_w from E, starting at f - F_D of the
    last sample. Sliding (E ~ 0) it is exact at once; near a reversal it contracts by about
    |alpha - 1| / e. It stops when f_w changes by less than tol (|f| + 1 N).
    """
    direction = state[ROW_DIRECTION]
    s = np.where(np.abs(thetadot) > v_eps, np.sign(thetadot), direction)
    changed = s != direction                                  # store theta_0, F_0 (3.43)
    state[ROW_THETA_0] = np.where(changed, state[ROW_THETA], state[ROW_THETA_0])
    state[ROW_F_0] = np.where(changed, state[ROW_F_D], state[ROW_F_0])
    state[ROW_DIRECTION] = s
    alpha = np.where(s > 0.0, alpha_table[2], np.where(s < 0.0, alpha_table[0], alpha_table[1]))
    gamma = np.where(s > 0.0, gamma_table[2], np.where(s < 0.0, gamma_table[0], gamma_table[1]))
    c1 = s * (alpha - 1.0)                                    # s F_f = c1 f_w + c0 (3.41)
    c0 = s * gamma * thetadot
    neg_decay = -sigma * np.abs(theta - state[ROW_THETA_0])
    F_0 = state[ROW_F_0]
    f_w = f - state[ROW_F_D]
    scale = tol * (np.abs(f).max() + 1.0)
    for _ in range(max_iterations):
        E = np.exp(neg_decay / np.maximum(c1 * f_w + c0, 1e-300))
        a = s - s * E
        f_w_new = (f - a * c0 - F_0 * E) / (1.0 + a * c1)     # f_w + a (c1 f_w + c0) + F_0 E = f (3.43)
        done = np.abs(f_w_new - f_w).max() <= scale
        f_w = f_w_new
        if done:
            break
    state[ROW_THETA] = theta
    state[ROW_F_D] = f - f_w
    return f_w


class DahlFriction:
    """State of the Dahl model (3.42)-(3.43) for m cables: ``state`` (5, m) with the ROW_* rows.

    Views (m,): ``last_direction``, ``theta_0``, ``F_0``, ``theta``, ``F_D``; ``sigma`` (m,) [N/m];
    ``v_eps`` [m/s]: speeds up to it count as standstill (the last direction is kept).
    """

    def __init__(self, sigma, theta, v_eps: float = 0.0):
        self.sigma = np.array(sigma, dtype=float)
        self.v_eps = float(v_eps)
        self.state = np.zeros((5,) + self.sigma.shape)
        self.reset(theta)

    def reset(self, theta) -> None:
        """No stored friction, standing still at theta."""
        self.state[:] = 0.0
        self.state[ROW_THETA_0] = theta
        self.state[ROW_THETA] = theta

    last_direction = property(lambda self: self.state[ROW_DIRECTION])
    theta_0 = property(lambda self: self.state[ROW_THETA_0])
    F_0 = property(lambda self: self.state[ROW_F_0])
    theta = property(lambda self: self.state[ROW_THETA])
    F_D = property(lambda self: self.state[ROW_F_D])


class PulleyFriction:
    """Force at the platform <-> sensor force for m cables: (3.30)-(3.44) with Dahl state.

    mu, sigma [N/m], F_pv [N s/m] (m,): friction parameters (table 3.4); n_pulleys (m,);
    beta_inner, beta_1 [rad]: wrap angles of the inner pulleys and of the sensor pulley;
    theta (m,): cable lengths to start from; v_eps [m/s]: standstill band of the Dahl model;
    jit: compiler for the per-sample steps (e.g. cdpr_control.kernels.jit.njit); None runs them as numpy.
    """

    def __init__(self, mu, sigma, F_pv, n_pulleys, beta_inner: float, beta_1: float, theta,
                 v_eps: float = 0.0, jit=None):
        self.series = PulleySeries(mu, F_pv, n_pulleys, beta_inner)
        self.dahl = DahlFriction(sigma, theta, v_eps)
        self.beta_1 = float(beta_1)
        self._platform_step = platform_force_step if jit is None else jit(platform_force_step)
        self._sensor_step = sensor_force_step if jit is None else jit(sensor_force_step)

    @classmethod
    def from_robot(cls, robot, theta, v_eps: float = 0.0, jit=None) -> "PulleyFriction":
        fr = robot.friction
        return cls(fr.mu, fr.sigma, fr.F_pv, fr.n_pulleys, fr.beta_inner, robot.sensor.beta_1,
                   theta, v_eps, jit)

    def reset(self, theta) -> None:
        self.dahl.reset(theta)

    def platform_force(self, F_s, theta, thetadot, beta_last) -> np.ndarray:
        """f = f_w + F_D (3.44) from the sensor forces F_s (m,); advances the Dahl state.

        theta, thetadot (m,): cable lengths and velocities driving the friction (the thesis uses
        the commanded theta_d, thetadot_d, section 3.7.3); beta_last (m,): wrap angle of the
        swivelling pulley from the inverse kinematics (2.6).
        """
        return self.platform_force_of_winch(winch_force_from_sensor(F_s, self.beta_1), theta, thetadot, beta_last)

    def platform_force_of_winch(self, f_w, theta, thetadot, beta_last) -> np.ndarray:
        """:meth:`platform_force` from the winch forces f_w (3.40) (the sensor forces converted)."""
        alpha, gamma = self.series.tables(beta_last)
        d = self.dahl
        return self._platform_step(f_w, _floats(theta), _floats(thetadot), alpha, gamma, d.sigma, d.v_eps, d.state)

    def sensor_force(self, f, theta, thetadot, beta_last, tol: float = 1e-12,
                     max_iterations: int = 50) -> np.ndarray:
        """F_s from the forces at the platform f (m,): the inverse of :meth:`platform_force`.

        Solves f_w + F_D(f_w) = f to tol (|f| + 1 N), see :func:`sensor_force_step`.
        """
        alpha, gamma = self.series.tables(beta_last)
        d = self.dahl
        f_w = self._sensor_step(_floats(f), _floats(theta), _floats(thetadot), alpha, gamma, d.sigma, d.v_eps,
                                d.state, tol, max_iterations)
        return sensor_from_winch_force(f_w, self.beta_1)


def _floats(x) -> np.ndarray:
    return np.asarray(x, dtype=float)
