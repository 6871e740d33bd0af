"""Talker: publishes ``greeting`` + a counter on ``chatter`` at ``rate`` Hz."""
from rcl_interfaces.msg import FloatingPointRange, ParameterDescriptor, SetParametersResult
from rclpy.node import Node
from std_msgs.msg import String

from cdpr_control.ros.runner import run_node

RATE_RANGE = (0.1, 1000.0)


class Talker(Node):
    def __init__(self, **kwargs):
        super().__init__("talker", **kwargs)
        self.declare_parameter("rate", 20.0, ParameterDescriptor(
            description="publishing rate [Hz]",
            floating_point_range=[FloatingPointRange(from_value=RATE_RANGE[0], to_value=RATE_RANGE[1])]))
        self.declare_parameter("greeting", "hello")
        self.declare_parameter("frame", "base", ParameterDescriptor(read_only=True))
        self.declare_parameter("gains.kp", 1.5)
        self.declare_parameter("gains.axes", [1, 2, 3])
        self.publisher = self.create_publisher(String, "chatter", 10)
        self.count = 0
        self.timer = self.create_timer(1.0 / self.get_parameter("rate").value, self.tick)
        self.add_on_set_parameters_callback(self.on_set)

    def on_set(self, params) -> SetParametersResult:
        for p in params:
            if p.name == "rate":  # the range is checked before this callback
                self.timer.timer_period_ns = int(1e9 / p.value)
        return SetParametersResult(successful=True)

    def tick(self) -> None:
        self.count += 1
        self.publisher.publish(String(data=f"{self.get_parameter('greeting').value} {self.count}"))


def main(args=None):
    run_node(Talker, args)
