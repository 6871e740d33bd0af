"""Operational-space position control (OSPC), thesis sections 3.4.1 and 3.5.1.

One PI controller per DOF (3.16) on the pose error e_x = x_d - x (3.5), output x_OSPC limited by a
saturation with anti-windup. x is the elastic forward kinematics estimate; the output is added to
the set-point before the inverse kinematics (Fig. 3.4).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from cdpr_control.control.pi_control import PIController

AXES = ("x", "y", "z", "a", "b", "c")


@dataclass
class OSPCParams:
    """Per-DOF gains and output limits [m, m, m, rad, rad, rad].

    Table 3.1 gives only the z axis (K_p = 0.07, T_i = 0.18 s); the other axes use the same values
    (ASSUMPTION: conservative, since z has the lowest dynamics, section 3.3.2).
    """

    K_p: np.ndarray = field(default_factory=lambda: np.full(6, 0.07))
    T_i: np.ndarray = field(default_factory=lambda: np.full(6, 0.18))
    x_sat: np.ndarray = field(default_factory=lambda: np.array([0.02, 0.02, 0.02, 0.02, 0.02, 0.02]))

    def validate(self) -> None:
        for name in ("K_p", "T_i", "x_sat"):
            value = np.asarray(getattr(self, name), dtype=float)
            if value.shape != (6,) or not np.all(np.isfinite(value)):
                raise ValueError(f"OSPC {name} needs 6 finite values, got {value}")
        if np.any(np.asarray(self.K_p) < 0) or np.any(np.asarray(self.T_i) <= 0) or np.any(np.asarray(self.x_sat) < 0):
            raise ValueError("OSPC needs K_p >= 0, T_i > 0 and x_sat >= 0")


class OperationalSpacePositionController:
    """x_OSPC = PI(x_d - x) per DOF (3.16), saturated to ±x_sat with anti-windup."""

    def __init__(self, params: OSPCParams, dt: float):
        params.validate()
        self.params = params
        self.pi = PIController(6, params.K_p, params.T_i, params.x_sat, params.x_sat, dt)

    def set_params(self, params: OSPCParams) -> None:
        params.validate()
        self.params = params
        self.pi.set_gains(params.K_p, params.T_i)
        self.pi.set_limits(params.x_sat, params.x_sat)

    def reset(self) -> None:
        self.pi.reset()

    def update(self, x_d, x) -> np.ndarray:
        """One period: desired and estimated pose -> x_OSPC [m, rad]."""
        e_x = np.asarray(x_d, dtype=float) - np.asarray(x, dtype=float)   # (3.5)
        return self.pi.update(e_x)
