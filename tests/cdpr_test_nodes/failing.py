"""Failing: a node whose timer callback raises, to see the launcher end the launch and report it."""
from rclpy.node import Node

from cdpr_control.ros.runner import run_node


class Failing(Node):
    def __init__(self, **kwargs):
        super().__init__("failing", **kwargs)
        self.create_timer(0.05, self.tick)

    def tick(self) -> None:
        raise RuntimeError("boom")


def main(args=None):
    run_node(Failing, args)
