"""What every cdpr control node shares: the robot, the control period, stamps and diagnostics.

Node modules follow one convention so the launcher can compose them in one process or start them
one per process: a class deriving from :class:`CdprNode` whose constructor takes the keyword
arguments of ``rclpy.node.Node`` (``parameter_overrides``, ``cli_args``, ``namespace`` ...), and a
``main(args=None)`` that spins it alone.
"""
from __future__ import annotations

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from std_msgs.msg import Header

from cdpr_control.robot import load_robot

from .conversions import bare
from .intraprocess import IntraProcessNode
from .parameters import ParamSpec
from .qos import DIAGNOSTICS
from .runner import run_node

COMMON_PARAMS = (
    ParamSpec("robot", "ipanema3_mini", "robot name or path of its YAML description", read_only=True),
    ParamSpec("control_period", 0.001, "control period T [s]", range=(1e-4, 0.1), read_only=True),
    ParamSpec("sync_mode", "exact", "exact: run once per stamp when all inputs of that stamp arrived "
              "(lockstep simulation); latest: run on each primary input with the newest others",
              choices=("exact", "latest"), read_only=True),
)


class CdprNode(IntraProcessNode):
    """Publishers and subscriptions deliver in-process to the nodes of the same context (intraprocess.py)."""

    def __init__(self, name: str, **kwargs):
        kwargs.setdefault("automatically_declare_parameters_from_overrides", False)
        super().__init__(name, **kwargs)
        for spec in COMMON_PARAMS:
            self.declare_parameter(spec.name, spec.default, spec.descriptor())
        self.robot = load_robot(self.get_parameter("robot").value)
        self.dt = float(self.get_parameter("control_period").value)
        self.sync_mode = self.get_parameter("sync_mode").value
        if self.sync_mode not in ("exact", "latest"):
            raise ValueError(f"sync_mode must be exact or latest, got {self.sync_mode!r}")
        self.diagnostics_pub = self.create_publisher(DiagnosticArray, "/diagnostics", DIAGNOSTICS)
        self._last_diagnostic = None

    @staticmethod
    def header(stamp_ns: int, frame_id: str = "base") -> Header:
        """A header stamped ``stamp_ns`` (built field by field: see conversions.bare; 1.5 us, not 7)."""
        stamp = bare(Time)
        stamp._sec, stamp._nanosec = divmod(int(stamp_ns), 1_000_000_000)
        h = bare(Header)
        h._stamp, h._frame_id = stamp, str(frame_id)
        return h

    def report(self, level: bytes, message: str, values: dict | None = None, stamp_ns: int | None = None,
               always: bool = False) -> None:
        """Publish this node's status on /diagnostics when it changed (level or message), or ``always``
        (a periodic report whose values matter, e.g. timing)."""
        key = (level, message)
        if key == self._last_diagnostic and not always:
            return
        self._last_diagnostic = key
        status = DiagnosticStatus(level=level, name=self.get_fully_qualified_name(), message=message,
                                  hardware_id=self.robot.name,
                                  values=[KeyValue(key=k, value=str(v)) for k, v in (values or {}).items()])
        header = self.header(stamp_ns) if stamp_ns is not None else Header(stamp=self.get_clock().now().to_msg())
        self.diagnostics_pub.publish(DiagnosticArray(header=header, status=[status]))


def spin_node(node_class, args=None) -> None:
    """main() of a node module: the node alone on an EventsExecutor until SIGINT/SIGTERM."""
    run_node(node_class, args)
