"""FailingCdpr: a cdpr node whose timer callback raises every time and whose subscription raises on
every message, to see the fault isolated: the node and the graph run on, the fault on /diagnostics."""
from std_msgs.msg import Int32

from cdpr_control.ros.base import CdprNode, spin_node


class FailingCdpr(CdprNode):
    def __init__(self, **kwargs):
        super().__init__("failing_cdpr", **kwargs)
        self.ticks = 0
        self.create_timer(0.02, self.tick)
        self.create_subscription(Int32, "failing_cdpr/poke", self.poke, 10)

    def tick(self) -> None:
        self.ticks += 1
        raise RuntimeError(f"boom {self.ticks}")

    def poke(self, msg) -> None:
        raise ValueError(f"bad poke {msg.data}")


def main(args=None):
    spin_node(FailingCdpr, args)
