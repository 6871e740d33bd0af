"""Node ``visualization``: the robot as ``visualization_msgs/MarkerArray`` on ``visualization/markers``.

Shows the frame (anchor points a_i and its bounding box), the pulleys, the cables coloured by force
relative to [f_min, f_max] (blue at f_min, green between, red at f_max, magenta beyond a limit), the
platform (hull of the B_i), the set-point x_d and the wrench w (force arrow), all in frame ``base``
from :mod:`cdpr_control.model.scene`. Inputs: ``platform/pose`` (the estimate of the forward kinematics;
remap to ``ground_truth/pose`` to see the simulator's), ``cable_forces``, ``setpoint``,
``platform/wrench``.

The inputs are only kept (the newest of each, keep-last 1): composed with the loop they arrive as
in-process objects, about a microsecond a message; a timer at ``rate`` [Hz] (steady clock, so also
in a lockstep simulation running slower than real time) draws them into one MarkerArray (frame and
anchors included every time, so a viewer that joins late has them) while anything subscribes. The figure is in
docs/visualization.md (benchmarks/bench_visualization.py).

tf2_msgs is not among the ROS 2 wheels on PyPI, so there is no ``/tf``: every marker is in ``base``
and the platform pose is drawn directly (Foxglove and RViz display ``base`` as the fixed frame).
"""
from __future__ import annotations

import numpy as np
from builtin_interfaces.msg import Duration
from cdpr_msgs.msg import CableForces, OperationalSetpoint
from geometry_msgs.msg import Point, PoseStamped, Vector3, WrenchStamped
from rclpy.clock import Clock, ClockType
from rclpy.qos import QoSProfile, ReliabilityPolicy
from std_msgs.msg import ColorRGBA
from visualization_msgs.msg import Marker, MarkerArray

from cdpr_control.model import scene as sc
from cdpr_control.ros.message_builders import builder

from cdpr_control.ros.base import CdprNode, spin_node
from cdpr_control.ros.conversions import pose_from_msg, setpoint_pose, wrench_from_msg
from cdpr_control.ros.intraprocess import has_subscribers
from cdpr_control.ros.parameters import ParameterSet, ParamSpec
from cdpr_control.ros.qos import CONTROL

FRAME = "base"
PARAMS = [
    ParamSpec("rate", 10.0, "markers published per second of wall time [Hz]", range=(0.1, 100.0), read_only=True),
    ParamSpec("force_scale", 0.0, "length of the force arrow per newton [m/N]; 0: a tenth of the frame "
              "diagonal for the mean f_max", range=(0.0, 10.0)),
]


def parameters(robot) -> list[ParamSpec]:
    """Every parameter of the node besides CdprNode's (docs/parameters.md)."""
    return list(PARAMS)
INPUTS = {"pose": (PoseStamped, "platform/pose"), "forces": (CableForces, "cable_forces"),
          "setpoint": (OperationalSetpoint, "setpoint"), "wrench": (WrenchStamped, "platform/wrench")}
SAMPLED = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE)  # only the newest message is kept


class VisualizationNode(CdprNode):
    def __init__(self, **kwargs):
        super().__init__("visualization", **kwargs)
        self.params = ParameterSet(self, parameters(self.robot), lambda v: None, self._apply)
        self.marker_pub = self.create_publisher(MarkerArray, "visualization/markers", CONTROL)
        self.latest: dict = {}
        for key, (cls, topic) in INPUTS.items():
            self.create_subscription(cls, topic, self._keep(key), SAMPLED, adapted=True)   # (reads fields only)
        rate = self.get_parameter("rate").value
        self.markers = Markers()
        self.create_timer(1.0 / rate, self.publish_markers, clock=Clock(clock_type=ClockType.STEADY_TIME))

    def _apply(self, v: dict) -> None:
        self.force_scale = float(v["force_scale"]) or None

    def _keep(self, key: str):
        def keep(msg) -> None:
            self.latest[key] = msg
        return keep

    def publish_markers(self) -> None:
        pose = self.latest.get("pose")
        if pose is None or not has_subscribers(self.marker_pub):
            return          # (a scene costs milliseconds: none for nobody; a viewer that joins gets the next)
        x = pose_from_msg(pose.pose)
        forces, setpoint, wrench = (self.latest.get(k) for k in ("forces", "setpoint", "wrench"))
        f = np.asarray(forces.f, float) if forces is not None and len(forces.f) == self.robot.m else None
        view = sc.scene(self.robot, x, f=f, x_d=None if setpoint is None else setpoint_pose(setpoint),
                        w=None if wrench is None else wrench_from_msg(wrench.wrench), force_scale=self.force_scale)
        if not np.all(np.isfinite(view.cables)):
            return  # a pose outside the model (cable inside a pulley): nothing sensible to draw
        self.marker_pub.publish(self.markers.build(view, pose.header.stamp))


def _points(array) -> list[Point]:
    point = builder(Point)
    return [point(x=x, y=y, z=z) for x, y, z in np.asarray(array, dtype=float).reshape(-1, 3).tolist()]


class Markers:
    """Builds the MarkerArray of a scene. The Marker messages are made once and updated in place:
    constructing one (with its nested defaults) costs far more than filling in its points."""

    def __init__(self):
        self._made: dict[tuple, Marker] = {}

    def _marker(self, ns: str, kind: int, stamp, rgba, scale=(1.0, 1.0, 1.0), id: int = 0) -> Marker:
        m = self._made.get((ns, id))
        if m is None:
            m = self._made[ns, id] = Marker(ns=ns, id=id, type=kind, action=Marker.ADD, lifetime=Duration())
            m.header.frame_id = FRAME
            m.pose.orientation.w = 1.0
            m.color = builder(ColorRGBA)(r=rgba[0], g=rgba[1], b=rgba[2], a=rgba[3])
        m.header.stamp = stamp
        m.scale = builder(Vector3)(x=float(scale[0]), y=float(scale[1]), z=float(scale[2]))
        return m

    def build(self, view: sc.Scene, stamp, static: bool = True) -> MarkerArray:
        """Markers by namespace: frame and anchors (only if ``static``: they never move, and viewers
        keep a marker until it is replaced), pulleys (one disc each, id = cable index), cables,
        platform, setpoint, wrench."""
        size = float(np.linalg.norm(np.ptp(view.anchors, axis=0)))
        line, dot = 0.002 * size, 0.01 * size
        out = []
        if static:
            m = self._marker("frame", Marker.LINE_LIST, stamp, (0.5, 0.5, 0.5, 1.0), (line, 0, 0))
            m.points = _points(view.frame_edges)
            a = self._marker("anchors", Marker.SPHERE_LIST, stamp, (0.2, 0.2, 0.2, 1.0), (dot, dot, dot))
            a.points = _points(view.anchors)
            out += [m, a]
        centres, turns = _points(view.pulley_centres), sc.z_to(view.pulley_normals).tolist()  # disc axis = normal
        for i, (centre, (qx, qy, qz, qw), r_p) in enumerate(zip(centres, turns, view.pulley_radii)):
            m = self._marker("pulleys", Marker.CYLINDER, stamp, (0.15, 0.15, 0.15, 0.9), (2 * r_p, 2 * r_p, 0.3 * r_p), i)
            m.pose.position = centre
            o = m.pose.orientation
            o.x, o.y, o.z, o.w = qx, qy, qz, qw
            out.append(m)
        m = self._marker("cables", Marker.LINE_LIST, stamp, (1.0, 1.0, 1.0, 1.0), (1.5 * line, 0, 0))
        m.points = _points(view.cables)
        colour = builder(ColorRGBA)
        m.colors = [colour(r=c[0], g=c[1], b=c[2], a=1.0) for c in map(sc.force_colour, view.force_level)
                    for _ in (0, 1)]
        out.append(m)
        m = self._marker("platform", Marker.TRIANGLE_LIST, stamp, (0.95, 0.6, 0.1, 0.8))
        m.points = _points(view.platform_triangles)
        out.append(m)
        if view.setpoint is not None:
            m = self._marker("setpoint", Marker.SPHERE, stamp, (0.0, 0.8, 0.2, 0.6), (dot, dot, dot))
            m.pose.position = _points(view.setpoint)[0]
            out.append(m)
        if view.force_arrow is not None:  # scale: shaft diameter, head diameter, head length
            m = self._marker("wrench", Marker.ARROW, stamp, (0.8, 0.1, 0.8, 1.0), (line * 2, line * 4, line * 6))
            m.points = _points(view.force_arrow)
            out.append(m)
        return builder(MarkerArray)(markers=out)


def main(args=None):
    spin_node(VisualizationNode, args)


if __name__ == "__main__":
    main()
