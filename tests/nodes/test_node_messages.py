"""Messages the node layer builds field by field (conversions.bare) equal the generated
constructors' and serialize to the same bytes, and the DDS side reads them back unchanged."""
import math

import numpy as np
from builtin_interfaces.msg import Time
from geometry_msgs.msg import Accel, Point, Pose, PoseStamped, Quaternion, Twist, Vector3, Wrench
from rclpy.serialization import deserialize_message, serialize_message
from std_msgs.msg import Header

from cdpr_control.ros.base import CdprNode
from cdpr_control.ros.conversions import (accel_to_msg, kardan_to_quaternion, pose_from_msg, pose_to_msg,
    twist_to_msg, vector3, wrench_to_msg)


def same(built, constructed) -> None:
    assert built == constructed
    data = serialize_message(built)
    assert data == serialize_message(constructed)
    assert deserialize_message(data, type(constructed)) == constructed


def test_header_is_the_constructed_header():
    for stamp_ns, frame in ((0, "base"), (1_234_567_890_123, "world"), (999_999_999, "")):
        sec, nanosec = divmod(stamp_ns, 1_000_000_000)
        same(CdprNode.header(stamp_ns, frame), Header(stamp=Time(sec=sec, nanosec=nanosec), frame_id=frame))


def test_geometry_messages_are_the_constructed_ones():
    x = np.array([0.1, -0.2, 1.3, 0.05, -0.4, 2.9])
    qx, qy, qz, qw = kardan_to_quaternion(*x[3:])
    pose = Pose(position=Point(x=0.1, y=-0.2, z=1.3), orientation=Quaternion(x=qx, y=qy, z=qz, w=qw))
    same(pose_to_msg(x), pose)
    np.testing.assert_allclose(pose_from_msg(pose_to_msg(x)), x, atol=1e-12)
    same(PoseStamped(header=CdprNode.header(5), pose=pose_to_msg(x)), PoseStamped(header=CdprNode.header(5), pose=pose))
    v = [1.5, -2.0, math.pi]
    same(vector3(v), Vector3(x=1.5, y=-2.0, z=math.pi))
    w = np.arange(6.0) - 2.5
    halves = (Vector3(x=-2.5, y=-1.5, z=-0.5), Vector3(x=0.5, y=1.5, z=2.5))
    same(twist_to_msg(w), Twist(linear=halves[0], angular=halves[1]))
    same(accel_to_msg(w), Accel(linear=halves[0], angular=halves[1]))
    same(wrench_to_msg(w), Wrench(force=halves[0], torque=halves[1]))
    reused = pose_to_msg(np.zeros(6))            # filling a given message still works
    assert pose_to_msg(x, reused) is reused and reused == pose
