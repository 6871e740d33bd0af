"""The per-period fast paths of the friction compensation, forward kinematics, OSPC and cable force
controller nodes give the same numbers, bit for bit, as the computation they replace: the set-point's
x_d as the interpreter attaches it to its payload (converted once per publication) against a node
converting the message itself, the pulley IK at x_d kept while it repeats against a fresh one, the
winch command's θ̇_d computed where it is used against the quotient taken on arrival, and the
messages built in one constructor call."""
import array
import struct

import numpy as np
import pytest

from required import import_or_skip  # noqa: E402  (a missing rclpy fails in CI)
rclpy = import_or_skip("rclpy")
from builtin_interfaces.msg import Time  # noqa: E402
from cdpr_msgs.msg import CableForces, ControllerState, ForceDistribution, OperationalSetpoint  # noqa: E402
from geometry_msgs.msg import Point, Pose, PoseStamped, Quaternion  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402
from std_msgs.msg import Header  # noqa: E402

from cdpr_control.model import forward_kinematics as fk  # noqa: E402
from cdpr_control import kernels  # noqa: E402
from cdpr_control.model.kinematics import inverse_kinematics  # noqa: E402
from cdpr_control.nodes.cable_force_controller import CableForceControllerNode  # noqa: E402
from cdpr_control.ros.adapted import attach_values, payload_of  # noqa: E402
from cdpr_control.ros.conversions import pose_to_msg, setpoint_values  # noqa: E402
from cdpr_control.nodes.forward_kinematics import ForwardKinematicsNode  # noqa: E402
from cdpr_control.nodes.friction_compensation import FrictionCompensationNode  # noqa: E402
from cdpr_control.nodes.ospc import OSPCNode  # noqa: E402
from cdpr_control.model.robot import load_robot  # noqa: E402
from node_harness import node_graph  # noqa: E402

ROBOT = "ipanema3_mini"
PERIOD_NS = 1_000_000


def bits(value):
    """A message's fields as nested tuples, floats as their bytes (-0.0 is not 0.0, a NaN equals the same NaN)."""
    if hasattr(value, "get_fields_and_field_types"):
        return tuple((name, bits(getattr(value, name))) for name in value.get_fields_and_field_types())
    if isinstance(value, float):
        return struct.pack("d", value)
    if isinstance(value, (list, tuple, array.array, np.ndarray)):
        return tuple(bits(v) for v in (value.tolist() if isinstance(value, np.ndarray) else value))
    return value


def _pose(x, y, z, qx, qy, qz, qw) -> Pose:
    return Pose(position=Point(x=x, y=y, z=z), orientation=Quaternion(x=qx, y=qy, z=qz, w=qw))


def _set_points(robot) -> list:
    """Set-point poses that repeat, change, change only in the sign of a zero, and turn non-finite."""
    home = pose_to_msg(robot.home)
    moved = pose_to_msg(robot.home + np.array([0.003, -0.002, 0.004, 0.01, -0.02, 0.015]))
    zero = _pose(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0)
    signed = _pose(0.0, -0.0, 0.0, -0.0, 0.0, -0.0, 1.0)
    bad = _pose(float("nan"), 0.0, 0.0, 0.0, 0.0, 0.0, 1.0)
    return [home, home, home, moved, moved, zero, signed, signed, zero, bad, moved, home, home]


def _stamp(k: int) -> Header:
    return Header(stamp=Time(sec=0, nanosec=k * PERIOD_NS), frame_id="base")


class _Capture:
    def __init__(self, out: list):
        self.out = out

    def publish(self, msg):
        self.out.append(bits(msg))


def _captured(node) -> list:
    """The node's publishers and reports replaced by a list of what they get."""
    out: list = []
    for name, value in list(vars(node).items()):
        if hasattr(value, "publish") and hasattr(value, "topic_name"):
            setattr(node, name, _Capture(out))
    node.report = lambda *args, **kwargs: out.append(("report", args, tuple(sorted(kwargs.items()))))
    return out


def _as_published(msgs: dict) -> dict:
    """The period's inputs with the set-point as the interpreter publishes it in a composed graph: a
    payload carrying x_d, ẋ_d, ẍ_d (adapted.attach_values, conversions.setpoint_values)."""
    sp = msgs["setpoint"]
    payload = payload_of(sp)
    attach_values(payload, setpoint_values(sp.pose, sp.velocity, sp.acceleration))
    return {**msgs, "setpoint": payload}


def _run_pair(make, periods, before_plain=lambda: None):
    """The same periods into two fresh nodes, the set-point as the interpreter's payload into one
    (the values attached to it) and as a message into the other (which converts it), with
    ``before_plain()`` before each of the latter's periods -> both outputs."""
    with node_graph(lambda: [make(), make()]) as (nodes, _, _):
        adapted, plain = nodes
        outs = _captured(adapted), _captured(plain)
        for k, msgs in enumerate(periods):
            t_ns = k * PERIOD_NS
            adapted._cycle(_as_published(msgs), t_ns)
            before_plain()
            plain._cycle(dict(msgs), t_ns)
        return outs


@pytest.fixture(scope="module")
def robot():
    robot = load_robot(ROBOT)
    kernels.warm_up(robot)
    return robot


def _overrides(**values):
    return [Parameter("robot", value=ROBOT)] + [Parameter(k, value=v) for k, v in values.items()]


def _winch_state(robot, k, x, rng) -> JointState:
    q = inverse_kinematics(robot, x).q
    return JointState(header=_stamp(k), position=(q + rng.uniform(-1e-4, 1e-4, robot.m)).tolist(),
                      velocity=rng.uniform(-2e-3, 2e-3, robot.m).tolist(),
                      effort=rng.uniform(20.0, 60.0, robot.m).tolist())


def test_friction_compensation_reads_the_published_set_point(robot):
    rng = np.random.default_rng(11)
    periods = [{"state": _winch_state(robot, k, robot.home, rng),
                "setpoint": OperationalSetpoint(header=_stamp(k), pose=pose)}
               for k, pose in enumerate(_set_points(robot)) if k != 9]       # a NaN pose is the IK's to refuse

    adapted, plain = _run_pair(lambda: FrictionCompensationNode(parameter_overrides=_overrides()), periods)
    assert len(adapted) == len(periods) and adapted == plain


def test_friction_compensation_command_velocity_is_the_quotient_on_arrival():
    """θ̇_d computed in the period that uses it: the difference quotient _keep_command took on
    arrival before (zero for the first command and for one not later than the last)."""
    rng = np.random.default_rng(12)
    node = FrictionCompensationNode.__new__(FrictionCompensationNode)
    node._commands = (None, None)
    assert node.command is None
    last = None
    for t_ns in (5_000_000, 6_000_000, 6_000_000, 5_000_000, 7_000_000, 9_000_000):
        theta_d = rng.uniform(1.0, 2.0, 8)
        msg = JointState(header=Header(stamp=Time(sec=t_ns // 1_000_000_000, nanosec=t_ns % 1_000_000_000)),
                         position=theta_d.tolist())
        node._keep_command(msg)
        t = msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec
        ref_theta = np.asarray(msg.position, dtype=float)
        ref_rate = (np.zeros_like(ref_theta) if last is None or t <= last[0]
                    else (ref_theta - last[1]) / (t - last[0]))
        last = (t, ref_theta)
        got_t, got_theta, got_rate = node.command
        assert got_t == t and bits(got_theta) == bits(ref_theta) and bits(got_rate) == bits(ref_rate)


def test_forward_kinematics_reads_the_published_set_point(robot):
    rng = np.random.default_rng(13)
    periods = []
    for k, pose in enumerate(_set_points(robot)):
        state = _winch_state(robot, k, robot.home + rng.uniform(-1e-3, 1e-3, 6), rng)
        forces = CableForces(header=_stamp(k), f=rng.uniform(20.0, 60.0, robot.m).tolist())
        periods.append({"theta": state, "f": forces, "setpoint": OperationalSetpoint(header=_stamp(k), pose=pose)})

    adapted, plain = _run_pair(lambda: ForwardKinematicsNode(parameter_overrides=_overrides()), periods,
                               kernels._packed_memo.clear)     # the plain node's IK of x_d computed afresh
    for out in (adapted, plain):                    # the wall-clock solve time aside
        out[:] = [tuple((name, b"" if name == "solve_time" else v) for name, v in msg) if msg[0] != "report"
                  else msg for msg in out]
    assert adapted == plain


def test_forward_kinematics_solver_keeps_the_ik_of_a_repeated_x_d(robot):
    """ForwardKinematics.elastic (compiled, frozen pulleys): the pulley IK at x_d kept for the same
    bytes of x_d (kernels' shared IK of the last pose, also after the caller changed its array in
    place) gives a fresh solver's numbers."""
    if not kernels.ENABLED:
        pytest.skip("CDPR_KERNELS=0: the numpy reference takes no kept IK")
    rng = np.random.default_rng(14)
    kept = fk.ForwardKinematics(robot, xtol=1e-8, max_iterations=30)
    x_d = robot.home.copy()
    for k in range(12):
        if k in (4, 8):
            x_d += rng.uniform(-2e-3, 2e-3, 6)          # in place: the same array, other bytes
        theta = inverse_kinematics(robot, x_d + rng.uniform(-1e-3, 1e-3, 6)).q
        f = rng.uniform(20.0, 60.0, robot.m)
        a = kept.elastic(theta, f, x_d)
        b = fk.ForwardKinematics(robot, xtol=1e-8, max_iterations=30).elastic(theta, f, x_d.copy())
        assert bits(a.x) == bits(b.x) and (a.termination, a.iterations) == (b.termination, b.iterations)
        assert bits(float(a.residual_norm)) == bits(float(b.residual_norm))


def test_ospc_reads_the_published_set_point(robot):
    rng = np.random.default_rng(15)
    periods = []
    for k, pose in enumerate(_set_points(robot)):
        x = robot.home + rng.uniform(-1e-3, 1e-3, 6)
        periods.append({"setpoint": OperationalSetpoint(header=_stamp(k), pose=pose),
                        "pose": PoseStamped(header=_stamp(k), pose=pose_to_msg(x)),
                        "hpfc": ControllerState(header=_stamp(k), controller="hybrid_force_controller:I",
                                                reference=[0.0] * 6, output=[0.0] * 6)})

    overrides = _overrides(force_controller="hybrid_force_controller")
    adapted, plain = _run_pair(lambda: OSPCNode(parameter_overrides=overrides), periods)
    assert len(adapted) == len(periods) and adapted == plain


def test_cable_force_controller_state_message(robot):
    """The state message built in one call: the fields the message built and then filled held."""
    rng = np.random.default_rng(16)
    m = robot.m
    with node_graph(lambda: [CableForceControllerNode(parameter_overrides=_overrides())]) as (nodes, _, _):
        node, = nodes
        out = _captured(node)
        for k in range(60):
            f_d = rng.uniform(20.0, 60.0, m)
            f = f_d + rng.uniform(-3.0, 3.0, m)
            if k == 30:
                f[2] = float("nan")
            msgs = {"f_d": ForceDistribution(header=_stamp(k), f_d=f_d.tolist(), f_min=[5.0] * m,
                                             f_max=[200.0] * m),
                    "f": CableForces(header=_stamp(k), f=f.tolist()),
                    "theta": _winch_state(robot, k, robot.home, rng)}
            c = node.stage.controller
            node._cycle(msgs, k * PERIOD_NS)
            state = [msg for msg in out if msg[0] != "report"][-1]
            fields = dict(state)
            assert fields["reference"] == bits(f_d) and fields["controller"] == "cable_force_controller"
            if k == 30:
                assert fields["output"] == bits([0.0] * m) and fields["feedback"] == bits(f)
                continue
            f_fb = c.f_filtered
            assert fields["feedback"] == bits(f_fb) and fields["error"] == bits(f_d - f_fb)
            assert fields["integrator"] == bits(c.pi.integrator) and fields["feedforward"] == bits(f_d)
            assert fields["output"] == bits(node.dq_held) and fields["saturated"] == tuple(c.pi.saturated.tolist())
