"""The simulated robot at power-on: platform at rest under a QP force distribution, encoders set.

Thesis section 2.3.2: the cables are tensed at the home pose to a distribution between the minimum
and maximum feasible force, and the absolute encoders are set so that they read the IK cable length
there. Here the distribution is the QP (3.27)-(3.28) of cdpr_control.force_distribution with the
reference force f_ref = f_min + level (f_max - f_min) (the tension level of SetTensionLevel).
"""
from __future__ import annotations

import numpy as np

from cdpr_control.model.dynamics import gravity_wrench
from cdpr_control.force_distribution.qp import quadratic_program
from cdpr_control.model.friction import sensor_from_winch_force, winch_force_from_sensor
from cdpr_control.model.kinematics import inverse_kinematics

from cdpr_sim.simulator import SimConfig, home_calibration_offset, plant_of, pretension_lengths


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


def startup_state(robot, x0, level: float, calibrate_home: bool, config: SimConfig = SimConfig()):
    """(x0, theta0, encoder_offset) of a platform at rest at x0 under the QP forces of ``level``.

    robot: the nominal robot file; the state is the one of the plant of ``config`` (pass the
    simulator's config). theta0 are the plant's unstretched cable lengths (Simulator convention);
    encoder_offset makes the encoders read the nominal IK{home} at home under the plant's QP forces
    there (section 2.3.2: the encoders are set on the real robot against the model's cable
    lengths; None with calibrate_home False). With the nominal plant the offset is the elongation
    dq(f) at home (:func:`home_calibration_offset`).
    """
    x0 = np.asarray(x0, dtype=float)
    true = plant_of(robot, config).robot
    theta0 = pretension_lengths(true, x0, startup_forces(true, x0, level))
    if not calibrate_home:
        return x0, theta0, None
    if true is robot:
        return x0, theta0, home_calibration_offset(robot, startup_forces(robot, robot.home, level))
    theta_home = pretension_lengths(true, robot.home, startup_forces(true, robot.home, level))
    return x0, theta0, inverse_kinematics(robot, robot.home).q - theta_home


def calibration_forces(sim, level: float) -> np.ndarray:
    """The platform forces (m,) the controller recorded when the encoders were set at home
    (section 2.3.2): the plant's QP forces of ``level`` at home as its sensors read them (true
    sensor line, the robot file's calibration, no noise: an average) and as the friction-free
    sensor pulley (3.36) turns them into platform forces at rest. For
    ``ControlLoop.set_home_calibration``."""
    true = startup_forces(sim.robot, sim.nominal.home, level)
    beta_1 = sim.nominal.sensor.beta_1
    reading = sim.sensor.line(sensor_from_winch_force(true, sim.robot.sensor.beta_1))
    return winch_force_from_sensor(reading, beta_1)
