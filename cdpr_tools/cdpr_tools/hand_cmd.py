"""``cdpr hand PROFILE``: a simulated hand pushing the platform (thesis 5.2), through the
simulator's ``/sim/apply_wrench`` service at the profile's simulation times.

PROFILE is one segment per ``;``: ``T SHAPE DURATION FX FY FZ [MX MY MZ]`` or ``T release``
(see :mod:`cdpr_sim.hand`), times relative to the simulation time when the command starts
(``--absolute``: to t = 0). Together with hand guiding:

    cdpr param set /admittance_controller hand_guiding true
    cdpr hand "0.5 half_sine 0.5 13 0 0; 2 step 0 4 0 0; 4 release"
"""
from __future__ import annotations

import argparse

from cdpr_msgs.srv import ApplyWrench
from geometry_msgs.msg import Point
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock

from cdpr_control.ros.conversions import wrench_to_msg
from cdpr_sim.hand import Hand, Segment
from cdpr_tools.ros_graph import DISCOVERY_TIMEOUT, graph_node, spin_future, spin_until


def request(segment: Segment) -> ApplyWrench.Request:
    """The service request that starts a segment (a release is a zero step that replaces the push)."""
    if segment.release:
        return ApplyWrench.Request(wrench=wrench_to_msg([0.0] * 6), shape=ApplyWrench.Request.SHAPE_STEP)
    return ApplyWrench.Request(wrench=wrench_to_msg(segment.wrench), point=Point(x=float(segment.point[0]),
                               y=float(segment.point[1]), z=float(segment.point[2])),
                               shape=segment.shape, duration=float(segment.duration))


def apply_profile(hand: Hand, service: str = "/sim/apply_wrench", absolute: bool = False,
                  timeout: float = 600.0, log=print) -> None:
    """Send each segment when the simulation clock (``/clock``) reaches its time."""
    with graph_node("hand") as node:
        now = {"t": None}

        def on_clock(msg):
            now["t"] = msg.clock.sec + msg.clock.nanosec * 1e-9

        node.create_subscription(Clock, "/clock", on_clock, QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT))
        client = node.create_client(ApplyWrench, service)
        if not spin_until(node, lambda: client.service_is_ready() and now["t"] is not None, DISCOVERY_TIMEOUT):
            raise LookupError(f"no simulator: {service} or /clock not found")
        t0 = 0.0 if absolute else now["t"]
        for segment in hand.segments:
            if not spin_until(node, lambda: now["t"] >= t0 + segment.t, timeout):
                raise TimeoutError(f"the simulation clock did not reach {t0 + segment.t:.3f} s")
            response = spin_future(node, client.call_async(request(segment)), DISCOVERY_TIMEOUT, service)
            if not response.success:
                raise ValueError(f"{service} refused the segment at {segment.t} s: {response.message}")
            what = "release" if segment.release else f"{segment.shape} {list(segment.wrench)} for {segment.duration} s"
            log(f"t = {now['t']:.3f} s: {what}")


def add_parser(sub) -> None:
    p = sub.add_parser("hand", help="push the simulated platform by hand (a user wrench profile)",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("profile", help="segments 'T SHAPE DURATION FX FY FZ [MX MY MZ]' or 'T release', ';'-separated")
    p.add_argument("--service", default="/sim/apply_wrench", help="the simulator's ApplyWrench service")
    p.add_argument("--absolute", action="store_true", help="segment times are simulation times, not relative")
    p.set_defaults(run=lambda args: apply_profile(Hand.parse(args.profile), args.service, args.absolute))
