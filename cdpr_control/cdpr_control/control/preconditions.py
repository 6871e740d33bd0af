"""Stability preconditions of the force control, thesis sections 3.1.3 and 4.3.

A cable force control without operational-space position control (OSPC) is stable only where the
geometric stiffness K_g (2.22) is positive definite (section 3.1.3); whether it is depends on the
pose and on the force distribution (section 4.3: "one has to check the positive definiteness of
K_g for every pose and cable force distribution"). The OSPC closes the position loop and removes
the condition. :func:`check_force_control` states the reason a configuration is refused; the
control loop refuses it (ValueError) and the ``ospc`` node refuses to be disabled with it.
"""
from __future__ import annotations

import numpy as np

from cdpr_control.model.dynamics import gravity_wrench
from cdpr_control.model.kinematics import inverse_kinematics
from cdpr_control.model.stiffness import geometric_stiffness


def geometric_stiffness_margin(robot, x, f) -> float:
    """Smallest eigenvalue of the symmetric part of K_g(x, f) (2.22) [N/m or N m/rad]."""
    K_g = geometric_stiffness(inverse_kinematics(robot, x), np.asarray(f, dtype=float))
    return float(np.linalg.eigvalsh(0.5 * (K_g + K_g.T))[0])


def check_force_control(robot, x, f, ospc_enabled: bool) -> str | None:
    """None when force control is admissible at pose x with forces f, else the reason."""
    if ospc_enabled:
        return None
    lam = geometric_stiffness_margin(robot, x, f)
    if lam > 0.0:
        return None
    return (f"cable force control without OSPC needs a positive definite geometric stiffness K_g "
            f"(section 3.1.3); at x = {np.round(np.asarray(x, dtype=float), 3).tolist()} its symmetric part has "
            f"the eigenvalue {lam:.3g} <= 0: enable the OSPC")


def planned_home_forces(robot, force_params=None) -> np.ndarray:
    """The forces the distribution (3.27) plans at home for ``force_params`` (a ForceSetpointParams;
    None: its defaults, minimal tension with the robot file's limits)."""
    from cdpr_control.force_distribution import ForceDistributor
    from cdpr_control.control.force_setpoint import ForceSetpointParams

    p = force_params or ForceSetpointParams()
    c = robot.cable
    f_min = c.f_min if p.f_min is None else np.asarray(p.f_min, dtype=float)
    f_max = c.f_max if p.f_max is None else np.asarray(p.f_max, dtype=float)
    d = ForceDistributor(robot.m, f_min, f_max, method=p.method, backend=p.backend)
    d.set_reference(f_min + p.tension_level * (f_max - f_min))
    return d.solve(inverse_kinematics(robot, robot.home).AT, gravity_wrench(robot, robot.home), 1e-3).f
