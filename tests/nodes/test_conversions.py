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


def test_a_set_point_payload_carries_its_conversion_for_every_subscriber():
    """The interpreter converts its set-point once (gcode_interpreter._setpoint_body) and attaches
    x_d, ẋ_d, ẍ_d to the payload; a subscriber reads those, bit for bit what converting the message
    gives (a subscriber in another process converts it itself), and cannot write them."""
    from cdpr_msgs.msg import OperationalSetpoint
    from std_msgs.msg import Header

    from cdpr_control.nodes.gcode_interpreter import _setpoint_body
    from cdpr_control.ros.adapted import attach_values, attached_values, payload_class
    from cdpr_control.ros.conversions import accel_from_msg, setpoint_from_msg, setpoint_pose, twist_from_msg
    q = np.array([0.12, -0.21, 0.33, 0.05, -0.04, 0.03, 0.0, 0.0, 5.0])
    xd = np.array([0.1, -0.05, 0.02, 0.3, -0.2, 0.1])
    xdd = np.array([-1.0, 0.5, 2.0, 0.7, 0.1, -0.3])
    fields, values = _setpoint_body(q, xd, xdd, 7)
    payload = payload_class(OperationalSetpoint)(header=Header(), **fields)
    attach_values(payload, values)
    message = payload.to_msg()
    attach_values(message, values)                      # a message stays as it is (type adaptation off)
    assert attached_values(message) is None
    assert type(message) is OperationalSetpoint and message.line == 7
    converted = setpoint_from_msg(message)              # a plain message: converted here
    assert all(type(v) is np.ndarray and v.shape == (6,) for v in converted)
    assert setpoint_from_msg(payload) is values and setpoint_pose(payload) is values[0]
    for attached, fresh in zip(values, converted):
        assert attached.tobytes() == fresh.tobytes()
        with pytest.raises(ValueError):
            attached[0] = 1.0                           # shared by every subscriber: read only
    np.testing.assert_array_equal(setpoint_pose(message), pose_from_msg(message.pose))
    np.testing.assert_allclose(values[0], q[:6], atol=1e-12)
    assert converted[1].tobytes() == twist_from_msg(message.velocity).tobytes()
    assert converted[2].tobytes() == accel_from_msg(message.acceleration).tobytes()
    # a payload its publisher attached nothing to is converted like a message
    bare = payload_class(OperationalSetpoint)(header=Header(), **fields)
    assert setpoint_pose(bare).tobytes() == values[0].tobytes()
