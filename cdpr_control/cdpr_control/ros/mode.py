"""The joint command's mode (``force_control`` or ``ik_only``, section 2.3.2) on a latched topic.

``joint_command`` owns the mode (its parameter ``mode``) and publishes it on ``joint_command/mode``
(std_msgs/String, STATUS QoS: transient-local, so a controller started later gets it at once).
The OSPC and CFC nodes follow it: while joint_command runs IK-only their outputs are not applied,
so they hold their integrators (no wind-up); the outputs stay continuous, and joint_command ramps
them out and back in over its ``transfer_time`` (bumpless transfer, :mod:`cdpr_control.control.bumpless`).
"""
from __future__ import annotations

from std_msgs.msg import String

from cdpr_control.ros.qos import STATUS

MODE_TOPIC = "joint_command/mode"
IK_ONLY = "ik_only"


def mode_publisher(node):
    return node.create_publisher(String, MODE_TOPIC, STATUS)


def publish_mode(publisher, mode: str) -> None:
    publisher.publish(String(data=mode))


def follow_mode(node, on_ik_only):
    """Subscribe ``node`` to the mode; ``on_ik_only(bool)`` on every change."""
    return node.create_subscription(String, MODE_TOPIC, lambda msg: on_ik_only(msg.data == IK_ONLY), STATUS)
