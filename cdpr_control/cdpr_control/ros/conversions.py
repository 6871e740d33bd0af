"""Messages <-> numpy arrays for the nodes (library code stays message-free).

Poses in the library are x = [x, y, z, a, b, c] with Kardan angles R = Rx(a) Ry(b) Rz(c)
(thesis 2.1.1); in messages they are geometry_msgs/Pose with a unit quaternion. Twists in both are
[v; omega] with omega the angular velocity in the base frame.

These run several times per control period in every node, so new messages are built by
:func:`bare` and their fields set directly: the generated constructors first build a default for
every field (``Pose()`` builds a Point and a Quaternion that the caller replaces at once) and
import inside ``__init__``, about 10 us a Pose here against 2 us. Only the fixed-size types below,
with every field set, are built so; the messages are equal to (and serialize like) constructed ones.
Other messages the nodes build every period come from ``message_builders.builder``.
"""
from __future__ import annotations

import math

import numpy as np
from geometry_msgs.msg import Accel, Point, Pose, Quaternion, Twist, Vector3, Wrench

from cdpr_control.ros.adapted import attached_values


def bare(cls):
    """A message instance without any field set (each must be set, through its ``_name`` slot)."""
    msg = cls.__new__(cls)
    msg._check_fields = False      # what the constructor sets unless ROS_PYTHON_CHECK_FIELDS=1
    return msg


def kardan_to_quaternion(a: float, b: float, c: float) -> tuple[float, float, float, float]:
    """(x, y, z, w) of R = Rx(a) Ry(b) Rz(c): the product q_x(a) q_y(b) q_z(c), in closed form
    (these conversions run several times per control period in every node)."""
    ca, sa = math.cos(0.5 * a), math.sin(0.5 * a)
    cb, sb = math.cos(0.5 * b), math.sin(0.5 * b)
    cc, sc = math.cos(0.5 * c), math.sin(0.5 * c)
    return (sa * cb * cc + ca * sb * sc,
            ca * sb * cc - sa * cb * sc,
            ca * cb * sc + sa * sb * cc,
            ca * cb * cc - sa * sb * sc)


def quaternion_to_kardan(x: float, y: float, z: float, w: float) -> tuple[float, float, float]:
    """Kardan angles (a, b, c) of a unit quaternion, b in [-pi/2, pi/2] (R_02 = sin b)."""
    n = x * x + y * y + z * z + w * w
    s = 2.0 / n if n > 0.0 else 0.0
    r02 = s * (x * z + w * y)
    r12 = s * (y * z - w * x)
    r22 = 1.0 - s * (x * x + y * y)
    r01 = s * (x * y - w * z)
    r00 = 1.0 - s * (y * y + z * z)
    return math.atan2(-r12, r22), math.asin(max(-1.0, min(1.0, r02))), math.atan2(-r01, r00)


def pose_to_msg(x, msg: Pose | None = None) -> Pose:
    if msg is None:
        p, o = bare(Point), bare(Quaternion)
        p._x, p._y, p._z = float(x[0]), float(x[1]), float(x[2])
        o._x, o._y, o._z, o._w = kardan_to_quaternion(float(x[3]), float(x[4]), float(x[5]))
        msg = bare(Pose)
        msg._position, msg._orientation = p, o
        return msg
    msg.position.x, msg.position.y, msg.position.z = float(x[0]), float(x[1]), float(x[2])
    o = msg.orientation
    o.x, o.y, o.z, o.w = kardan_to_quaternion(float(x[3]), float(x[4]), float(x[5]))
    return msg


def pose_from_msg(msg: Pose) -> np.ndarray:
    try:
        p, q = msg._position, msg._orientation      # the slots: several times a period in every node
        return np.array([p._x, p._y, p._z, *quaternion_to_kardan(q._x, q._y, q._z, q._w)])
    except AttributeError:                          # a message of another reader (rosbags, mcap_ros2)
        p, q = msg.position, msg.orientation
        return np.array([p.x, p.y, p.z, *quaternion_to_kardan(q.x, q.y, q.z, q.w)])


def setpoint_values(pose: Pose, velocity: Twist, acceleration: Accel) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(x_d, ẋ_d, ẍ_d) of a set-point's fields as read-only arrays: what a publisher attaches to its
    payload (:func:`cdpr_control.ros.adapted.attach_values`) for every subscriber to share."""
    values = pose_from_msg(pose), twist_from_msg(velocity), accel_from_msg(acceleration)
    for v in values:
        v.flags.writeable = False
    return values


def setpoint_from_msg(sp) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(x_d, ẋ_d, ẍ_d) of a cdpr_msgs/OperationalSetpoint (pose, velocity, acceleration): the values
    its publisher attached (a payload of this process, :func:`setpoint_values`: one conversion per
    publication, shared by its subscribers, so read only) or else converted here, the same numbers."""
    values = attached_values(sp)
    if values is not None:
        return values
    return pose_from_msg(sp.pose), twist_from_msg(sp.velocity), accel_from_msg(sp.acceleration)


def setpoint_pose(sp) -> np.ndarray:
    """x_d of a cdpr_msgs/OperationalSetpoint: its pose of :func:`setpoint_from_msg` (read only)."""
    values = attached_values(sp)
    return values[0] if values is not None else pose_from_msg(sp.pose)


def vector3(v, msg: Vector3 | None = None) -> Vector3:
    if msg is None:
        msg = bare(Vector3)
        msg._x, msg._y, msg._z = float(v[0]), float(v[1]), float(v[2])
        return msg
    msg.x, msg.y, msg.z = float(v[0]), float(v[1]), float(v[2])
    return msg


def _pair(cls, first: str, second: str, a, b):
    msg = bare(cls)
    setattr(msg, first, a)
    setattr(msg, second, b)
    return msg


def from_vector3(msg: Vector3) -> np.ndarray:
    try:
        return np.array([msg._x, msg._y, msg._z])
    except AttributeError:                          # a message of another reader
        return np.array([msg.x, msg.y, msg.z])


def twist_to_msg(xdot) -> Twist:
    return _pair(Twist, "_linear", "_angular", vector3(xdot[:3]), vector3(xdot[3:6]))


def _six(msg, first: str, second: str) -> np.ndarray:
    try:
        a, b = getattr(msg, "_" + first), getattr(msg, "_" + second)
        return np.array([a._x, a._y, a._z, b._x, b._y, b._z])
    except AttributeError:                          # a message of another reader
        a, b = getattr(msg, first), getattr(msg, second)
        return np.array([a.x, a.y, a.z, b.x, b.y, b.z])


def twist_from_msg(msg: Twist) -> np.ndarray:
    return _six(msg, "linear", "angular")


def accel_to_msg(xddot) -> Accel:
    return _pair(Accel, "_linear", "_angular", vector3(xddot[:3]), vector3(xddot[3:6]))


def accel_from_msg(msg: Accel) -> np.ndarray:
    return _six(msg, "linear", "angular")


def wrench_to_msg(w) -> Wrench:
    """w = [force; torque] [N, N m] -> geometry_msgs/Wrench."""
    return _pair(Wrench, "_force", "_torque", vector3(w[:3]), vector3(w[3:6]))


def wrench_from_msg(msg: Wrench) -> np.ndarray:
    return _six(msg, "force", "torque")
