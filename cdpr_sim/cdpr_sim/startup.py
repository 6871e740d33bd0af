"""The simulated robot at power-on: platform at rest under a QP force distribution, encoders set.

Thesis section 2.3.2: the cables are tensed at the home pose to a distribution between the minimum
and maximum feasible force, and the absolute encoders are set so that they read the IK cable length
there. Here the distribution is the QP (3.27)-(3.28) of cdpr_control.force_distribution with the
reference force f_ref = f_min + level (f_max - f_min) (the tension level of SetTensionLevel).
"""
from __future__ import annotations

import numpy as np

from cdpr_control.dynamics import gravity_wrench
from cdpr_control.force_distribution.qp import quadratic_program
from cdpr_control.kinematics import inverse_kinematics

from .simulator import home_calibration_offset, pretension_lengths


def startup_forces(robot, x, level: float) -> np.ndarray:
    """QP cable forces (m,) holding the platform's weight at pose x for tension level [0..1].

    Raises ValueError when no feasible distribution exists at x.
    """
    if not 0.0 <= level <= 1.0:
        raise ValueError(f"tension level must be in [0, 1], got {level}")
    c = robot.cable
    AT = inverse_kinematics(robot, x).AT
    result = quadratic_program(AT, gravity_wrench(robot, x), c.f_min, c.f_max, c.f_min + level * (c.f_max - c.f_min))
    if not result.feasible:
        raise ValueError(f"no feasible cable force distribution at x = {np.round(x, 4).tolist()}")
    return result.f


def startup_state(robot, x0, level: float, calibrate_home: bool):
    """(x0, theta0, encoder_offset) of a platform at rest at x0 under the QP forces of ``level``.

    theta0 are the unstretched cable lengths (Simulator convention); encoder_offset makes the
    encoders read IK{home} at home under the QP forces there (None with calibrate_home False).
    """
    x0 = np.asarray(x0, dtype=float)
    theta0 = pretension_lengths(robot, x0, startup_forces(robot, x0, level))
    offset = home_calibration_offset(robot, startup_forces(robot, robot.home, level)) if calibrate_home else None
    return x0, theta0, offset
