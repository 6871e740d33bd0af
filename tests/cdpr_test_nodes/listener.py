"""Listener: counts ``chatter`` messages and republishes the count on ``heard``."""
from rclpy.node import Node
from std_msgs.msg import Int32, String

from cdpr_control.ros.runner import run_node


class Listener(Node):
    def __init__(self, **kwargs):
        super().__init__("listener", **kwargs)
        self.heard = 0
        self.publisher = self.create_publisher(Int32, "heard", 10)
        self.create_subscription(String, "chatter", self.on_chatter, 10)

    def on_chatter(self, msg: String) -> None:
        self.heard += 1
        self.publisher.publish(Int32(data=self.heard))

    def destroy_node(self) -> None:
        self.get_logger().info(f"listener stopped after {self.heard} messages")
        super().destroy_node()


def main(args=None):
    run_node(Listener, args)
