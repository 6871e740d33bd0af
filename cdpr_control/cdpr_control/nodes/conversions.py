"""Messages <-> numpy arrays for the nodes (library code stays message-free).

Poses in the library are x = [x, y, z, a, b, c] with Kardan angles R = Rx(a) Ry(b) Rz(c)
(thesis 2.1.1); in messages they are geometry_msgs/Pose with a unit quaternion. Twists in both are
[v; omega] with omega the angular velocity in the base frame.
"""
from __future__ import annotations

import numpy as np
from geometry_msgs.msg import Accel, Pose, Twist, Vector3, Wrench
from scipy.spatial.transform import Rotation

KARDAN = "XYZ"    # intrinsic x-y-z = Rx Ry Rz


def pose_to_msg(x, msg: Pose | None = None) -> Pose:
    msg = Pose() if msg is None else msg
    msg.position.x, msg.position.y, msg.position.z = (float(v) for v in x[:3])
    qx, qy, qz, qw = Rotation.from_euler(KARDAN, x[3:6]).as_quat()
    msg.orientation.x, msg.orientation.y, msg.orientation.z, msg.orientation.w = float(qx), float(qy), float(qz), float(qw)
    return msg


def pose_from_msg(msg: Pose) -> np.ndarray:
    q = msg.orientation
    phi = Rotation.from_quat([q.x, q.y, q.z, q.w]).as_euler(KARDAN)
    return np.array([msg.position.x, msg.position.y, msg.position.z, *phi])


def vector3(v, msg: Vector3 | None = None) -> Vector3:
    msg = Vector3() if msg is None else msg
    msg.x, msg.y, msg.z = float(v[0]), float(v[1]), float(v[2])
    return msg


def from_vector3(msg: Vector3) -> np.ndarray:
    return np.array([msg.x, msg.y, msg.z])


def twist_to_msg(xdot) -> Twist:
    return Twist(linear=vector3(xdot[:3]), angular=vector3(xdot[3:6]))


def twist_from_msg(msg: Twist) -> np.ndarray:
    return np.concatenate([from_vector3(msg.linear), from_vector3(msg.angular)])


def accel_to_msg(xddot) -> Accel:
    return Accel(linear=vector3(xddot[:3]), angular=vector3(xddot[3:6]))


def accel_from_msg(msg: Accel) -> np.ndarray:
    return np.concatenate([from_vector3(msg.linear), from_vector3(msg.angular)])


def wrench_to_msg(w) -> Wrench:
    """w = [force; torque] [N, N m] -> geometry_msgs/Wrench."""
    return Wrench(force=vector3(w[:3]), torque=vector3(w[3:6]))


def wrench_from_msg(msg: Wrench) -> np.ndarray:
    return np.concatenate([from_vector3(msg.force), from_vector3(msg.torque)])
