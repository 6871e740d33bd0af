"""Pulley-friction compensation stage, thesis section 3.7.3: f = f_w + F_D (3.44) per period.

Wraps the friction model of :mod:`cdpr_control.model.friction` with what the control loop needs: the
choice of the cable motion that drives it (encoder θ, θ̇ or the commanded θ_d, θ̇_d) and the time
shift of the Dahl output (50 ms in the thesis, where the commanded motion runs ahead of the cable).
"""
from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np

from cdpr_control import kernels
from cdpr_control.model.friction import PulleyFriction


@dataclass
class FrictionCompensationParams:
    enabled: bool = True
    time_shift: float = 0.0      # s, delay of the Dahl output (thesis: 0.05 with commanded motion)
    mu: np.ndarray | None = None      # (m,) -, None: robot file
    sigma: np.ndarray | None = None   # (m,) N/m
    F_pv: np.ndarray | None = None    # (m,) N s/m

    def resolved(self, robot) -> "FrictionCompensationParams":
        fr = robot.friction
        out = FrictionCompensationParams(
            self.enabled, self.time_shift,
            *(np.asarray(fr_value if v is None else v, dtype=float)
              for v, fr_value in ((self.mu, fr.mu), (self.sigma, fr.sigma), (self.F_pv, fr.F_pv))))
        m = robot.m
        for name in ("mu", "sigma", "F_pv"):
            value = getattr(out, name)
            if value.shape != (m,) or not np.all(np.isfinite(value)):
                raise ValueError(f"{name} needs {m} finite values, got {value.tolist()}")
        if np.any(out.mu < 0) or np.any(out.F_pv < 0) or np.any(out.sigma <= 0):
            raise ValueError("friction needs mu >= 0, F_pv >= 0 and sigma > 0")
        if not out.time_shift >= 0.0:
            raise ValueError(f"time_shift must be >= 0 s, got {out.time_shift}")
        return out


class FrictionCompensation:
    def __init__(self, robot, dt: float, params: FrictionCompensationParams | None = None):
        self.robot = robot
        self.dt = dt
        self.set_params(params or FrictionCompensationParams())
        kernels.warm_up(robot)               # the compiled friction loaded now, not in the first period

    def set_params(self, params: FrictionCompensationParams) -> None:
        self.params = params.resolved(self.robot)
        self.shift = int(round(self.params.time_shift / self.dt))
        self.model: PulleyFriction | None = None          # rebuilt at the next sample
        self.delayed: deque = deque(maxlen=self.shift + 1)
        self.sensor_gain = 1.0 - np.cos(self.robot.sensor.beta_1)    # F_s / f_w of winch_force_from_sensor (3.40)

    def update(self, F_s, theta, thetadot, beta) -> np.ndarray:
        """Sensor forces F_s (m,), cable motion θ, θ̇ driving the friction, swivel-pulley wrap angle
        β_np (m,) from the IK (2.6) -> cable forces at the platform f (m,)."""
        f_w = np.asarray(F_s, dtype=float) / self.sensor_gain                  # (3.40), as winch_force_from_sensor
        if not self.params.enabled:
            return f_w
        if self.model is None:
            fr, p = self.robot.friction, self.params
            self.model = PulleyFriction(p.mu, p.sigma, p.F_pv, fr.n_pulleys, fr.beta_inner,
                                        self.robot.sensor.beta_1, theta)
        F_D = platform_force(self.model, f_w, theta, thetadot, beta) - f_w     # (3.43)
        self.delayed.append(F_D)
        return f_w + self.delayed[0]                                           # (3.44), shifted


def _platform_force(model: PulleyFriction, f_w, theta, thetadot, beta) -> np.ndarray:
    """f = f_w + F_D (3.44) of the winch forces f_w through ``model``; advances its Dahl state."""
    return model.platform_force_of_winch(f_w, theta, thetadot, beta)


platform_force = kernels.law("friction_platform_force", _platform_force, kernels.friction_platform_force)
