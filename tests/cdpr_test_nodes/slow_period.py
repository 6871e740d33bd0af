"""A node that makes some control periods of a composed lockstep graph slow: every ``every``-th
winch/state it takes, its callback blocks for ``pause`` seconds of wall time (a process descheduled on
a loaded machine, seen from the graph). In-process, as the graph's own nodes: it takes every state."""
import time

from sensor_msgs.msg import JointState

from cdpr_control.ros.intraprocess import IntraProcessNode
from cdpr_control.ros.qos import CONTROL


class SlowPeriod(IntraProcessNode):
    def __init__(self, **kwargs):
        super().__init__("slow_period", **kwargs)
        self.every = self.declare_parameter("every", 200).value
        self.pause = self.declare_parameter("pause", 0.3).value
        self.taken = 0
        self.paused = 0
        self.create_subscription(JointState, "winch/state", self.on_state, CONTROL)

    def on_state(self, msg: JointState) -> None:
        self.taken += 1
        if self.taken % self.every == 0:
            time.sleep(self.pause)
            self.paused += 1
