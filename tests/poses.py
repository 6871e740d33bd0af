"""Poses and what the sensors read at them, for the tests: random platform poses (positions in the
robot's workspace box) and the encoder lengths of the simulator's calibration convention."""
import numpy as np

from cdpr_control.model import cable
from cdpr_control.model.kinematics import inverse_kinematics


def random_poses(robot, n, rng, angle=0.2):
    """n poses: positions uniform in robot.workspace_min..max, Kardan angles uniform in ±angle rad."""
    r = rng.uniform(robot.workspace_min, robot.workspace_max, (n, 3))
    return np.hstack([r, rng.uniform(-angle, angle, (n, 3))])


def encoder_lengths(robot, x, f_x, f_home):
    """θ the encoders read at pose x under forces f_x when they were set to IK{home} under f_home
    (the simulator's convention with the nominal plant)."""
    q_home = inverse_kinematics(robot, robot.home).q
    offset = cable.elongation_from_force(robot, f_home, cable.total_free_length(robot, q_home))
    q = inverse_kinematics(robot, x).q
    return q - cable.elongation_from_force(robot, f_x, cable.total_free_length(robot, q)) + offset
