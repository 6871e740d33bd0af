"""The node hybrid_force_controller where the pose's contact capacity leaves less than the controller
regulates (session 13): M103 (``enabled: true``) is refused with the reason, which fails the program
that asked; and its /diagnostics while F_d is limited and x_d moves: a change of reason at once, the
changing numbers at most once a second (each period until session 13)."""
import numpy as np
import pytest

from required import import_or_skip  # noqa: E402  (a missing rclpy fails in CI)
rclpy = import_or_skip("rclpy")
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus  # noqa: E402
from cdpr_msgs.msg import ControllerState, ForceDistribution, OperationalSetpoint  # noqa: E402
from geometry_msgs.msg import PoseStamped, WrenchStamped  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402

from cdpr_control.control.hybrid_force_control import contact_capacity  # noqa: E402
from cdpr_control.model.dynamics import gravity_wrench  # noqa: E402
from cdpr_control.model.robot import load_robot  # noqa: E402
from cdpr_control import kernels  # noqa: E402
from cdpr_control.nodes.hybrid_force_controller import HybridForceControllerNode  # noqa: E402
from cdpr_control.ros.base import CdprNode  # noqa: E402
from cdpr_control.ros.conversions import pose_to_msg, vector3, wrench_to_msg  # noqa: E402
from cdpr_control.ros.qos import CONTROL  # noqa: E402
from cdpr_tools.validate.grid import planned_f_min, sweep_poses  # noqa: E402
from node_harness import node_graph, spin_until  # noqa: E402

ROBOT = load_robot("ipanema3_mini")
X = np.asarray(sweep_poses(ROBOT)[35].x, dtype=float)      # a border pose (capacity 3.06 N as shipped)


def f_max_for(capacity: float) -> float:
    """A common f_max with which the capacity along -z at X is ``capacity`` [N] (bisection)."""
    AT, = kernels.inverse_kinematics_fields(ROBOT, X, "AT")
    f_min, w_g, z = planned_f_min(ROBOT), gravity_wrench(ROBOT, X), np.array([0.0, 0.0, -1.0])
    lo, hi = float(np.max(f_min)), float(np.max(ROBOT.cable.f_max))
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if contact_capacity(AT, w_g, z, f_min, np.full(ROBOT.m, mid)) < capacity else (lo, mid)
    return hi


@pytest.fixture(scope="module")
def graph():
    def make_nodes():
        return [HybridForceControllerNode(parameter_overrides=[Parameter("robot", value="ipanema3_mini"),
                                                               Parameter("F_th", value=1.0)])]   # (the Mini's file)
    with node_graph(make_nodes) as graph:
        yield graph


def test_m103_refused_where_the_capacity_leaves_too_little_and_diagnostics_at_most_once_a_second(graph):
    (hpfc,), probe, executor = graph
    pubs = {name: probe.create_publisher(t, topic, CONTROL) for name, t, topic in (
        ("sp", OperationalSetpoint, "setpoint"), ("w", WrenchStamped, "platform/wrench"),
        ("pose", PoseStamped, "platform/pose"), ("fd", ForceDistribution, "force_distribution"))}
    states, diagnostics = [], []
    probe.create_subscription(ControllerState, "hybrid_force_controller/state", states.append, CONTROL)
    probe.create_subscription(DiagnosticArray, "/diagnostics",
                              lambda msg: diagnostics.extend(s for s in msg.status if "hybrid" in s.name), 100)
    assert spin_until(executor, lambda: all(p.get_subscription_count() > 0 for p in pubs.values()))
    w = np.r_[ROBOT.platform.mass * np.asarray(ROBOT.gravity, dtype=float), 0.0, 0.0, 0.0]   # no contact
    f_min = planned_f_min(ROBOT)

    def period(k, f_max, dx=0.0, stamp_ns=None):
        header = CdprNode.header(k * 1_000_000 if stamp_ns is None else stamp_ns)
        x_d = X + [dx, 0.0, 0.0, 0.0, 0.0, 0.0]
        pubs["fd"].publish(ForceDistribution(header=header, f_d=[20.0] * ROBOT.m, f_min=list(f_min),
                                             f_max=[f_max] * ROBOT.m))
        pubs["sp"].publish(OperationalSetpoint(header=header, pose=pose_to_msg(x_d), force=vector3([0, 0, -10.0])))
        pubs["w"].publish(WrenchStamped(header=header, wrench=wrench_to_msg(w)))
        pubs["pose"].publish(PoseStamped(header=header, pose=pose_to_msg(X)))
        assert spin_until(executor, lambda: len(states) >= k, timeout=10.0), (k, len(states))

    tiny = f_max_for(1.2)                         # 1.2 / 1.2 = 1.0 N left, below F_th / 0.8 = 1.25 N
    for k in range(1, 4):
        period(k, tiny)
    result = hpfc.set_parameters([Parameter("enabled", value=True)])[0]          # what M103 does
    assert not result.successful and "contact refused" in result.reason and "F_d 10 N" in result.reason
    assert "1.2 N" in result.reason and f"{X[0]:.4g}" in result.reason
    assert not hpfc.get_parameter("enabled").value

    limited = f_max_for(2.0)                      # 1.67 N to regulate: limited, not refused
    for k in range(4, 6):
        period(k, limited)
    assert hpfc.set_parameters([Parameter("enabled", value=True)])[0].successful
    n = len(diagnostics)
    # x_d moves each period (the capacity and the pose in the message change): 2.8 s of periods
    # stamped 40 ms apart (the node's sync takes at most 50 periods ahead) -> the WARN's numbers
    # three times (at 0.045, 1.045, 2.045 s), not 70 times
    for j, k in enumerate(range(6, 76)):
        period(k, limited, dx=1e-5 * j, stamp_ns=5_000_000 + 40_000_000 * (j + 1))
    spin_until(executor, lambda: False, timeout=0.5)
    warns = [s for s in diagnostics[n:] if s.level == DiagnosticStatus.WARN and "capacity" in s.message]
    assert len(warns) == 3, [s.message for s in diagnostics[n:]]
    assert len(diagnostics[n:]) <= 4 + 2          # (and the state's changes: I -> A)
