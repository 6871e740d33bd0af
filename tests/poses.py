"""Random platform poses for the model tests (positions in the robot's workspace box)."""
import numpy as np


def random_poses(robot, n, rng, angle=0.2):
    """n poses: positions uniform in robot.workspace_min..max, Kardan angles uniform in ±angle rad."""
    r = rng.uniform(robot.workspace_min, robot.workspace_max, (n, 3))
    return np.hstack([r, rng.uniform(-angle, angle, (n, 3))])
