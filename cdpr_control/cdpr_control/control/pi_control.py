"""Vectorised discrete PI controller with output saturation and anti-windup.

The one PI implementation of the project, used per DOF by the OSPC (3.16) and per cable by the
CFC (3.19). Continuous form ``u = K_p (e + 1/T_i ∫ e dt)``, discretised with the forward Euler rule
on the integrator. Anti-windup by conditional integration plus clamping: while the output is
saturated the integrator does not integrate an error that drives the output further into the
limit, and it is clamped so that ``K_p e + I`` cannot hide behind the saturation.
"""
from __future__ import annotations

import numpy as np

from cdpr_control import kernels


class PIController:
    """PI per channel: ``u = clip(K_p e + I, -u_neg, u_pos)``, ``I += K_p dt / T_i e``.

    All gains and limits are arrays of one value per channel (scalars broadcast). ``T_i = inf``
    disables the integral part. State: ``integrator`` (in output units) and ``saturated``.
    ``hold``: the integrator keeps its value (the output is K_p e + I, clipped): for a controller
    whose output is not applied (bumpless transfer, :mod:`cdpr_control.control.bumpless`).
    """

    def __init__(self, n: int, K_p, T_i, u_neg, u_pos, dt: float):
        if not dt > 0.0:
            raise ValueError(f"dt must be > 0 s, got {dt}")
        self.n = n
        self.dt = float(dt)
        self.set_gains(K_p, T_i)
        self.set_limits(u_neg, u_pos)
        self.integrator = np.zeros(n)
        self.saturated = np.zeros(n, dtype=bool)
        self.output = np.zeros(n)
        self.hold = False
        kernels.warm_up()                    # the compiled PI loaded now, not in the first period

    def set_gains(self, K_p, T_i) -> None:
        K_p = np.broadcast_to(np.asarray(K_p, dtype=float), (self.n,)).copy()
        T_i = np.broadcast_to(np.asarray(T_i, dtype=float), (self.n,)).copy()
        if np.any(K_p < 0.0) or np.any(T_i <= 0.0):
            raise ValueError("PI gains need K_p >= 0 and T_i > 0")
        self.K_p, self.T_i = K_p, T_i

    def set_limits(self, u_neg, u_pos) -> None:
        """Saturation ``-u_neg <= u <= u_pos`` (both given as non-negative magnitudes)."""
        u_neg = np.broadcast_to(np.asarray(u_neg, dtype=float), (self.n,)).copy()
        u_pos = np.broadcast_to(np.asarray(u_pos, dtype=float), (self.n,)).copy()
        if np.any(u_neg < 0.0) or np.any(u_pos < 0.0):
            raise ValueError("saturation limits are magnitudes and must be >= 0")
        self.u_neg, self.u_pos = u_neg, u_pos

    def reset(self, integrator=0.0) -> None:
        self.integrator = np.broadcast_to(np.asarray(integrator, dtype=float), (self.n,)).copy()
        self.saturated[:] = False
        self.output[:] = 0.0

    def update(self, e: np.ndarray, u_neg=None, u_pos=None) -> np.ndarray:
        """One control period for the error ``e``; optional per-call limits (e.g. widened ones)."""
        if self.hold:
            lo = -(self.u_neg if u_neg is None else u_neg)
            hi = self.u_pos if u_pos is None else u_pos
            u = self.K_p * np.asarray(e, dtype=float) + self.integrator
            self.saturated = (u > hi) | (u < lo)
            self.output = np.clip(u, lo, hi)
            return self.output
        self.integrator, self.saturated, self.output = pi_update(
            np.asarray(e, dtype=float), self.K_p, self.T_i, self.dt, self.integrator,
            self.u_neg if u_neg is None else u_neg, self.u_pos if u_pos is None else u_pos)
        return self.output


def _pi_update(e, K_p, T_i, dt, integrator, u_neg, u_pos):
    """One PI period (3.16)/(3.19) -> new arrays (integrator, saturated, output):
    ``u = clip(K_p e + I, -u_neg, u_pos)``; I integrates ``K_p dt / T_i e`` unless that pushes a
    saturated output further out, and is clamped to the output range (anti-windup)."""
    lo, hi = -u_neg, u_pos
    p = K_p * e
    candidate = integrator + K_p * dt / T_i * e
    u_free = p + candidate
    # integrate only when that does not push an already saturated output further out
    blocked = ((u_free > hi) & (e > 0.0)) | ((u_free < lo) & (e < 0.0))
    # the integral part alone may never exceed the output range
    integrator = np.clip(np.where(blocked, integrator, candidate), lo, hi)
    u = p + integrator
    return integrator, (u > hi) | (u < lo), np.clip(u, lo, hi)


pi_update = kernels.law("pi_update", _pi_update, kernels.compiled_pi_update)
