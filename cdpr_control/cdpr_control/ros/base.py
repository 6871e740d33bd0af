"""What every cdpr control node shares: the robot, the control period, stamps and diagnostics.

Node modules follow one convention so the launcher can compose them in one process or start them
one per process: a class deriving from :class:`CdprNode` whose constructor takes the keyword
arguments of ``rclpy.node.Node`` (``parameter_overrides``, ``cli_args``, ``namespace`` ...), and a
``main(args=None)`` that spins it alone.
"""
from __future__ import annotations

import inspect
import re
import time
import traceback

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from std_msgs.msg import Header

from cdpr_control.model.robot import load_robot

from cdpr_control.ros.conversions import bare
from cdpr_control.ros.intraprocess import IntraProcessNode, time_source_of
from cdpr_control.ros.parameters import ParamSpec
from cdpr_control.ros.qos import DIAGNOSTICS
from cdpr_control.ros.runner import run_node

COMMON_PARAMS = (
    ParamSpec("robot", "ipanema3_mini", "robot name or path of its YAML description", read_only=True),
    ParamSpec("control_period", 0.001, "control period T [s]", range=(1e-4, 0.1), read_only=True),
    ParamSpec("sync_mode", "exact", "exact: run once per stamp when all inputs of that stamp arrived "
              "(lockstep simulation); latest: run on each primary input with the newest others",
              choices=("exact", "latest"), read_only=True),
    ParamSpec("input_deadline", 50, "age of an input, in control periods behind the node's newest input, beyond "
              "which it is stale: reported on /diagnostics (the joint command holds); also the largest stamp "
              "jump an input may make", range=(1, 1_000_000), read_only=True),
)
_DIGITS = re.compile(r"[-+]?[0-9][0-9.e+-]*")
FAULT_REPORT_PERIOD = 1.0   # s: a repeating input fault or callback error is reported at most this often


class CdprNode(IntraProcessNode):
    """Publishers and subscriptions deliver in-process to the nodes of the same context (intraprocess.py).

    Fault isolation: every subscription, timer and service callback the node registers runs inside
    one ``try``: an exception is logged with its traceback (once per place), counted, reported on
    /diagnostics, and the node keeps running (the other nodes of a composed graph too). Invalid input
    messages are dropped by :class:`~cdpr_control.ros.sync.StampSync` and reported through
    :meth:`input_fault`, stale inputs through :meth:`report_stale`.
    """

    callback_errors = 0          # class defaults: rclpy creates services before __init__ below ends
    input_faults: dict = {}

    def __init__(self, name: str, **kwargs):
        kwargs.setdefault("automatically_declare_parameters_from_overrides", False)
        super().__init__(name, **kwargs)
        for spec in COMMON_PARAMS:
            self.declare_parameter(spec.name, spec.default, spec.descriptor())
        self.robot = load_robot(self.get_parameter("robot").value)
        self.dt = float(self.get_parameter("control_period").value)
        self.sync_mode = self.get_parameter("sync_mode").value
        self.input_deadline = int(self.get_parameter("input_deadline").value)
        self.input_faults = {}                      # (topic, reason) -> count
        self._fault_reported: dict = {}             # key -> monotonic time of its last report
        if self.sync_mode not in ("exact", "latest"):
            raise ValueError(f"sync_mode must be exact or latest, got {self.sync_mode!r}")
        self.diagnostics_pub = self.create_publisher(DiagnosticArray, "/diagnostics", DIAGNOSTICS)
        self._last_diagnostic = None

    _header_stamp: int | None = None
    _headers: dict = {}             # frame_id -> Header of _header_stamp

    @staticmethod
    def header(stamp_ns: int, frame_id: str = "base") -> Header:
        """A header stamped ``stamp_ns`` (built field by field: see conversions.bare; 1.5 us, not 7).

        Every node publishes period k with the stamp t_k, so the headers of the period are handed out
        again for the same stamp and frame (13 calls a period in closed_loop.yaml): one object in
        several messages, which is safe because a published message is never modified (intraprocess.py)."""
        if stamp_ns != CdprNode._header_stamp:
            CdprNode._header_stamp, CdprNode._headers = stamp_ns, {}
        h = CdprNode._headers.get(frame_id)
        if h is None:
            stamp = bare(Time)
            stamp._sec, stamp._nanosec = divmod(int(stamp_ns), 1_000_000_000)
            h = bare(Header)
            h._stamp, h._frame_id = stamp, str(frame_id)
            CdprNode._headers[frame_id] = h
        return h

    # -- fault isolation ----------------------------------------------------------------------
    def _guard(self, callback, where: str, fallback=None):
        """``callback`` inside one try: an exception is logged, counted and reported, not raised."""
        if inspect.iscoroutinefunction(callback) or time_source_of(callback) is not None:
            return callback                 # (TimeSource callbacks are recognised by intraprocess.py)

        def failed(exc: Exception):
            self.callback_errors += 1
            key = ("callback", where, type(exc).__name__)
            first = key not in self._fault_reported_map()
            if first:
                self.get_logger().error(f"{where} raised (node kept running):\n{traceback.format_exc().rstrip()}")
            self._report_fault(key, f"{where} raised {type(exc).__name__}: {exc}",
                               {"callback_errors": self.callback_errors})
            return fallback() if fallback is not None else None

        def guarded(*args):
            try:
                return callback(*args)
            except Exception as exc:        # noqa: BLE001 - the boundary of the callback
                return failed(exc)
        guarded.__wrapped__ = callback
        return guarded

    def _fault_reported_map(self) -> dict:
        if "_fault_reported" not in self.__dict__:
            self._fault_reported = {}
        return self._fault_reported

    def _report_fault(self, key, message: str, values: dict) -> None:
        """ERROR on /diagnostics for ``key``: the first time at once, then at most every FAULT_REPORT_PERIOD."""
        reported = self._fault_reported_map()
        now = time.monotonic()
        if now - reported.get(key, -1e9) < FAULT_REPORT_PERIOD:
            return
        reported[key] = now
        if hasattr(self, "diagnostics_pub"):
            self.report(DiagnosticStatus.ERROR, message, values, always=True)

    def create_subscription(self, msg_type, topic, callback, qos_profile, **kwargs):
        return super().create_subscription(msg_type, topic, self._guard(callback, f"subscription {topic}"),
                                           qos_profile, **kwargs)

    def create_timer(self, timer_period_sec, callback, *args, **kwargs):
        return super().create_timer(timer_period_sec, self._guard(callback, "timer"), *args, **kwargs)

    def create_service(self, srv_type, srv_name, callback, **kwargs):
        return super().create_service(srv_type, srv_name,
                                      self._guard(callback, f"service {srv_name}", srv_type.Response), **kwargs)

    def input_fault(self, topic: str, reason: str) -> None:
        """A message on ``topic`` was dropped for ``reason``: counted, warned and reported on /diagnostics."""
        key = (topic, _DIGITS.sub("#", reason))      # one key per kind of fault, whatever its numbers
        count = self.input_faults[key] = self.input_faults.get(key, 0) + 1
        if count == 1:
            self.get_logger().warn(f"dropped a message on {topic}: {reason}")
        self._report_fault(("input",) + key, f"dropped {topic}: {reason}",
                           {"topic": topic, "dropped": count, "dropped_total": sum(self.input_faults.values())})

    def report_stale(self, ages: dict, deadline: int, stamp_ns: int) -> None:
        """Stale inputs changed (``{topic: age in periods}``; empty: all fresh again)."""
        if ages:
            text = ", ".join(f"{topic} is {age:.0f} periods old" for topic, age in ages.items())
            self.get_logger().error(f"stale input: {text} (deadline {deadline})")
            self.report(DiagnosticStatus.ERROR, f"stale input: {text} (deadline {deadline} periods)",
                        {"stale": ",".join(ages)}, stamp_ns=stamp_ns)
        else:
            self.get_logger().info("inputs fresh again")
            self.report(DiagnosticStatus.OK, "inputs fresh again", stamp_ns=stamp_ns)

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
