"""Pose <-> message conversions: Kardan angles R = Rx Ry Rz (2.1.1) against the model's rotation."""
import numpy as np
import pytest

from required import import_or_skip  # noqa: E402  (a missing ROS fails in CI)

import_or_skip("geometry_msgs")
from cdpr_control.model.kinematics import rotation_matrix  # noqa: E402
from cdpr_control.ros.conversions import pose_from_msg, pose_to_msg  # noqa: E402


def _quat_matrix(q):
    x, y, z, w = q
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def test_quaternion_is_the_kardan_rotation_and_round_trips():
    rng = np.random.default_rng(3)
    for _ in range(200):
        x = np.r_[rng.uniform(-1, 1, 3), rng.uniform(-3.1, 3.1), rng.uniform(-1.5, 1.5), rng.uniform(-3.1, 3.1)]
        msg = pose_to_msg(x)
        q = np.array([msg.orientation.x, msg.orientation.y, msg.orientation.z, msg.orientation.w])
        assert np.linalg.norm(q) == pytest.approx(1.0, abs=1e-12)
        np.testing.assert_allclose(_quat_matrix(q), rotation_matrix(x[3:]), atol=1e-12)
        np.testing.assert_allclose(pose_from_msg(msg), x, atol=1e-9)
