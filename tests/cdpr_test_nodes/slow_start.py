"""A node slow to start, for stopping a launch during start-up: with ``CDPR_TEST_SLOW=import`` its
module takes a minute to import, with ``CDPR_TEST_SLOW=build`` its constructor takes three seconds;
each says so on stdout first."""
import os
import time

from rclpy.node import Node

from cdpr_control.ros.runner import run_node

SLOW = os.environ.get("CDPR_TEST_SLOW", "")
if SLOW == "import":
    print("slow_start: importing", flush=True)
    time.sleep(60.0)


class SlowStart(Node):
    def __init__(self, **kwargs):
        super().__init__("slow_start", **kwargs)
        if SLOW == "build":
            print("slow_start: building", flush=True)
            time.sleep(3.0)

    def destroy_node(self) -> None:
        self.get_logger().info("slow_start destroyed")
        super().destroy_node()


def main(args=None):
    run_node(SlowStart, args)
