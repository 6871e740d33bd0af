"""The start-up calibration of the elastic models: the pre-tension Δq_0 of (3.9) and (3.23).

The encoders are set at the home pose with the cables under tension (section 2.3.2): there they
read θ = IK{home} while the cables are stretched by the calibration forces. The forward kinematics
(3.7)-(3.9) and the cable force control (3.23) need that stretch, Δq_0 = dq(f_home) at the home
lengths. Two sources:

* the home calibration: the forces recorded when the encoders were set (``set_home``); right
  wherever the controller starts;
* the first ``window`` samples after start-up, averaged (the default): right when the controller
  starts at home where the encoders were set, and the average keeps one noisy force sample (the
  16-bit AD plus noise of section 3.7.1) out of a value that is then used for the whole run.

Until the window is full the running mean is used, so the stages have a Δq_0 from the first period.
"""
from __future__ import annotations

import numpy as np

from cdpr_control.model.kinematics import inverse_kinematics

DEFAULT_WINDOW = 100          # samples: 0.1 s at the 1 ms control period


class StartupCalibration:
    """The (f_0, θ_0) of the encoder calibration, from the home calibration or a start-up window."""

    def __init__(self, window: int = DEFAULT_WINDOW):
        if not (isinstance(window, (int, np.integer)) and window >= 1):
            raise ValueError(f"calibration window must be an integer >= 1 sample, got {window}")
        self.window = int(window)
        self.n = 0
        self.f_0: np.ndarray | None = None
        self.theta_0: np.ndarray | None = None
        self.from_home = False

    @property
    def done(self) -> bool:
        return self.from_home or self.n >= self.window

    def set_home(self, robot, f_home) -> None:
        """The home calibration: forces f_home (m,) [N] at the platform when θ was set to IK{home}."""
        f_home = np.asarray(f_home, dtype=float)
        if f_home.shape != (robot.m,) or not np.all(np.isfinite(f_home)) or np.any(f_home <= 0.0):
            raise ValueError(f"home calibration needs {robot.m} finite positive forces, got {f_home}")
        self.f_0, self.theta_0 = f_home.copy(), inverse_kinematics(robot, robot.home).q
        self.from_home = True

    def update(self, f, theta) -> bool:
        """Add one sample while the window is open; True when (f_0, θ_0) changed."""
        if self.done:
            return False
        f, theta = np.asarray(f, dtype=float), np.asarray(theta, dtype=float)
        self.n += 1
        if self.f_0 is None:
            self.f_0, self.theta_0 = f.copy(), theta.copy()
        else:
            self.f_0 += (f - self.f_0) / self.n
            self.theta_0 += (theta - self.theta_0) / self.n
        return True
