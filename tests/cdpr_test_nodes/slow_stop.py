"""A node whose first timer callback blocks for ``pause`` seconds of wall time and then publishes (a
period of a composed graph that a loaded machine stretches past the launcher's stop)."""
import threading
import time

from rclpy.node import Node
from std_msgs.msg import String

from cdpr_control.ros.runner import run_node


class SlowStop(Node):
    def __init__(self, **kwargs):
        super().__init__("slow_stop", **kwargs)
        self.pause = self.declare_parameter("pause", 4.0).value
        self.publisher = self.create_publisher(String, "slow_stop/done", 10)
        self.blocking = threading.Event()   # the callback has started its pause
        self.finished = threading.Event()   # ... and published after it
        self.timer = self.create_timer(0.05, self.tick)

    def tick(self) -> None:
        self.timer.cancel()
        self.blocking.set()
        print("slow_stop: pausing", flush=True)     # (one process per node: the launcher prints it)
        time.sleep(self.pause)
        self.publisher.publish(String(data=self.get_fully_qualified_name()))
        self.finished.set()


def main(args=None):
    run_node(SlowStop, args)
