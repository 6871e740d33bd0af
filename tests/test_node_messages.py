"""Messages the node layer builds field by field (conversions.bare) equal the generated
constructors' and serialize to the same bytes, and the DDS side reads them back unchanged."""
import importlib
import math

import numpy as np
import pytest
from builtin_interfaces.msg import Time
from geometry_msgs.msg import Accel, Point, Pose, PoseStamped, Quaternion, Twist, Vector3, Wrench
from rclpy.serialization import deserialize_message, serialize_message
from std_msgs.msg import Header

from cdpr_control.nodes.base import CdprNode
from cdpr_control.nodes.conversions import (accel_to_msg, kardan_to_quaternion, pose_from_msg, pose_to_msg,
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


@pytest.fixture
def fast_constructors(monkeypatch):
    """message_init's constructors installed for one test: the suite runs with
    ROS_PYTHON_CHECK_FIELDS=1 (tests/conftest.py), under which every class keeps its generated,
    field-checking constructor; the generated ones are back afterwards, also when the test fails."""
    from cdpr_control.nodes import message_init

    generated = {cls: cls.__init__ for package in message_init.PACKAGES
                 for cls in vars(importlib.import_module(f"{package}.msg")).values()
                 if isinstance(cls, type) and hasattr(cls, "SLOT_TYPES")}
    monkeypatch.setenv("ROS_PYTHON_CHECK_FIELDS", "0")
    try:
        message_init.install()
        yield
    finally:
        for cls, init in generated.items():
            cls.__init__ = init


def test_fast_constructors_build_the_generated_messages(fast_constructors):
    """message_init's constructors: defaults and given values equal the generated constructor's,
    serialize alike, and numeric sequences are copied into array.array as the generated one does."""
    import array

    from cdpr_msgs.msg import CableForces, ControllerState, OperationalSetpoint
    from sensor_msgs.msg import JointState

    from cdpr_control.nodes import message_init
    installed = message_init.install()  # already installed on import: nothing left to change
    assert installed == []
    for cls in (ControllerState, OperationalSetpoint, CableForces, JointState, PoseStamped, Header, Pose):
        assert "message_init" in cls.__init__.__doc__
        same(cls(), cls(check_fields=True))
    values = np.array([1.0, -2.5, 3.25])
    fast = ControllerState(header=CdprNode.header(7, "base"), controller="c", enabled=True, names=["a", "b", "c"],
                           reference=values, feedback=[0.5, 0.25, 0.0], saturated=[True, False, True])
    generated = ControllerState(check_fields=True, header=CdprNode.header(7, "base"), controller="c", enabled=True,
                                names=["a", "b", "c"], reference=values.tolist(), feedback=[0.5, 0.25, 0.0],
                                saturated=[True, False, True])
    same(fast, generated)
    assert isinstance(fast.reference, array.array) and fast.reference.typecode == "d"
    values[0] = 99.0                          # a copy, not a view of the caller's array
    assert fast.reference[0] == 1.0
    js = JointState(header=CdprNode.header(3), name=["q1"], position=[0.1], velocity=[0.2], effort=[0.3])
    same(js, JointState(check_fields=True, header=CdprNode.header(3), name=["q1"], position=[0.1],
                        velocity=[0.2], effort=[0.3]))
