"""Listener: counts ``chatter`` messages and republishes the count on ``heard``; logs "heard has N
subscribers" whenever the count of readers its publisher has matched changes (the writer's side of
DDS matching, which a test cannot see from the reader's side)."""
from rclpy.node import Node
from std_msgs.msg import Int32, String

from cdpr_control.ros.runner import run_node


class Listener(Node):
    def __init__(self, **kwargs):
        super().__init__("listener", **kwargs)
        self.heard = 0
        self.subscribers = 0
        self.publisher = self.create_publisher(Int32, "heard", 10)
        self.create_subscription(String, "chatter", self.on_chatter, 10)

    def on_chatter(self, msg: String) -> None:
        self.heard += 1
        self.publisher.publish(Int32(data=self.heard))
        subscribers = self.publisher.get_subscription_count()
        if subscribers != self.subscribers:
            self.subscribers = subscribers
            self.get_logger().info(f"heard has {subscribers} subscribers")

    def destroy_node(self) -> None:
        self.get_logger().info(f"listener stopped after {self.heard} messages")
        super().destroy_node()


def main(args=None):
    run_node(Listener, args)
