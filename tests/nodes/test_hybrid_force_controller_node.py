"""Node hybrid_force_controller on typed topics (lockstep): state published every period enabled or
not, M103-style enable, the ControllerState mapping, the OSPC's selection and the CFC's pause
driven by that state, and live parameter validation."""
import numpy as np
import pytest

from required import import_or_skip  # noqa: E402  (a missing rclpy fails in CI)
rclpy = import_or_skip("rclpy")
from cdpr_msgs.msg import CableForces, ControllerState, ForceDistribution, OperationalSetpoint  # noqa: E402
from geometry_msgs.msg import PoseStamped, WrenchStamped  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402

from cdpr_control.control.hybrid_force_control import parse_state  # noqa: E402
from cdpr_control.model.kinematics import inverse_kinematics  # noqa: E402
from cdpr_control.ros.base import CdprNode  # noqa: E402
from cdpr_control.nodes.cable_force_controller import CableForceControllerNode  # noqa: E402
from cdpr_control.nodes.force_distribution import ForceDistributionNode  # noqa: E402
from cdpr_control.ros.conversions import pose_to_msg, vector3, wrench_to_msg  # noqa: E402
from cdpr_control.nodes.hybrid_force_controller import HybridForceControllerNode  # noqa: E402
from cdpr_control.nodes.ospc import OSPCNode  # noqa: E402
from cdpr_control.ros.qos import CONTROL  # noqa: E402
from cdpr_control.model.robot import load_robot  # noqa: E402
from node_harness import node_graph, spin_until  # noqa: E402

ROBOT = load_robot("ipanema3_mini")


@pytest.fixture(scope="module")
def graph():
    def make_nodes():
        base = [Parameter("robot", value="ipanema3_mini")]
        coupled = base + [Parameter("force_controller", value="hybrid_force_controller")]
        nodes = [HybridForceControllerNode(parameter_overrides=base + [Parameter("F_th", value=1.0),
                                                                       Parameter("v_max", value=0.002)]),
                 OSPCNode(parameter_overrides=coupled), CableForceControllerNode(parameter_overrides=coupled)]
        return nodes
    with node_graph(make_nodes) as graph:
        yield graph


def test_state_every_period_approach_and_the_coupled_controllers(graph):
    nodes, probe, executor = graph
    hpfc, ospc, cfc = nodes
    m = ROBOT.m
    pubs = {name: probe.create_publisher(t, topic, CONTROL) for name, t, topic in (
        ("sp", OperationalSetpoint, "setpoint"), ("w", WrenchStamped, "platform/wrench"),
        ("pose", PoseStamped, "platform/pose"), ("theta", JointState, "winch/state"),
        ("f", CableForces, "cable_forces"), ("fd", ForceDistribution, "force_distribution"))}
    states, ospc_states, cfc_states = [], [], []
    probe.create_subscription(ControllerState, "hybrid_force_controller/state", states.append, CONTROL)
    probe.create_subscription(ControllerState, "ospc/state", ospc_states.append, CONTROL)
    probe.create_subscription(ControllerState, "cable_force_controller/state", cfc_states.append, CONTROL)
    hand_overs = []
    probe.create_subscription(ControllerState, "cable_force_controller/hand_over", hand_overs.append, CONTROL)
    assert spin_until(executor, lambda: all(p.get_subscription_count() > 0 for p in pubs.values()))
    x_d = ROBOT.home.copy()
    x = x_d + [0.0, 0.0, -0.003, 0.0, 0.0, 0.0]                 # 3 mm below x_d
    w = np.r_[ROBOT.platform.mass * ROBOT.gravity, 0, 0, 0]        # free: no contact force
    q = inverse_kinematics(ROBOT, x_d).q
    f = np.full(m, 7.0)

    def period(k, f_d=f):
        header = CdprNode.header(k * 1_000_000)
        pubs["sp"].publish(OperationalSetpoint(header=header, pose=pose_to_msg(x_d), force=vector3([0, 0, -10.0])))
        pubs["w"].publish(WrenchStamped(header=header, wrench=wrench_to_msg(w)))
        pubs["pose"].publish(PoseStamped(header=header, pose=pose_to_msg(x)))
        pubs["theta"].publish(JointState(header=header, position=q.tolist(), velocity=[0.0] * m, effort=f.tolist()))
        pubs["f"].publish(CableForces(header=header, f=f.tolist(), f_min=[5.0] * m, f_max=[40.0] * m))
        pubs["fd"].publish(ForceDistribution(header=header, f_d=f_d.tolist(), f_min=[5.0] * m, f_max=[40.0] * m))
        assert spin_until(executor, lambda: len(states) >= k and len(ospc_states) >= k and len(cfc_states) >= k)

    for k in range(1, 3):                                          # disabled: published, idle, zero
        period(k)
    s = states[-1]
    assert parse_state(s.controller) == "I" and not s.enabled and list(s.output) == [0.0] * 6
    assert list(s.names) == ["x", "y", "z", "a", "b", "c"] and list(s.reference[:3]) == [0.0, 0.0, -10.0]
    assert ospc_states[-1].output[2] > 0.0                         # OSPC acts on the 3 mm along z
    dq_free = np.asarray(cfc_states[-1].output)

    assert hpfc.set_parameters([Parameter("enabled", value=True)])[0].successful      # what M103 does
    for k in range(3, 8):
        period(k, f_d=f + 3.0)                                     # a changed f_d: a running CFC would move
    s = states[-1]
    assert parse_state(s.controller) == "A" and s.enabled
    assert list(s.output) == list(s.feedforward)                   # A: all of x_t is position-controlled
    assert s.output[2] < 0.0 and abs(s.output[2]) <= 0.002 * 5e-3  # along F_d,0 (down) at most v_max
    # the OSPC stops integrating along the force axis; the CFC runs on in A's first PRE_TENSION_TIME
    # + PRE_TENSION_SETTLE (0.45 s), tensioning the cables for the contact to come
    # (pre_contact_forces, since session 11), and is held only after that
    z_integrator = [st.integrator[2] for st in ospc_states[-4:]]
    assert max(z_integrator) - min(z_integrator) == 0.0
    assert not np.array_equal(cfc_states[-1].output, dq_free)
    # the coupled CFC publishes its hand-over every period: applied, nothing handed over while paused
    assert spin_until(executor, lambda: len(hand_overs) >= 7)
    assert [h.header.stamp.nanosec for h in hand_overs[-7:]] == [k * 1_000_000 for k in range(1, 8)]
    assert hand_overs[-1].enabled and list(hand_overs[-1].output) == [0.0] * 6


def test_rejected_parameter_keeps_the_old_value(graph):
    hpfc = graph[0][0]
    result = hpfc.set_parameters([Parameter("K_p", value=0.0)])[0]
    assert not result.successful
    assert hpfc.get_parameter("K_p").value == 22000.0 and hpfc.stage.control.params.K_p == 22000.0
    assert hpfc.set_parameters([Parameter("T_i", value=1.5)])[0].successful
    assert hpfc.stage.control.params.T_i == 1.5


def test_force_distribution_plans_for_the_expected_contact_force(graph):
    """Section 5.1.2: with ``force_controller`` set, the force distribution node replaces the
    measured contact force along the task axis by F_d while the hybrid force controller acts."""
    _, probe, executor = graph
    node = ForceDistributionNode(parameter_overrides=[
        Parameter("robot", value="ipanema3_mini"), Parameter("force_controller", value="hybrid_force_controller"),
        Parameter("T_wrench_filter", value=0.0)])               # w_d follows w without lag
    executor.add_node(node)
    try:
        pubs = {name: probe.create_publisher(t, topic, CONTROL) for name, t, topic in (
            ("sp", OperationalSetpoint, "setpoint"), ("w", WrenchStamped, "platform/wrench"),
            ("hpfc", ControllerState, "hybrid_force_controller/state"))}
        out = []
        probe.create_subscription(ForceDistribution, "force_distribution", out.append, CONTROL)
        assert spin_until(executor, lambda: all(p.get_subscription_count() > 0 for p in pubs.values()))
        weight = ROBOT.platform.mass * ROBOT.gravity
        w = np.r_[weight + [0.0, 0.0, 3.0], 0, 0, 0]             # the floor pushes up with 3 N

        def period(k, state):
            header = CdprNode.header(k * 1_000_000)
            pubs["hpfc"].publish(ControllerState(header=header, controller=f"hybrid_force_controller:{state}",
                                                 reference=[0.0, 0.0, -10.0, 0.0, 0.0, 0.0],
                                                 feedback=[0.0, 0.0, -3.0, 0.0, 0.0, 0.0],    # F = 3 N
                                                 output=[0.0] * 6))       # (a valid state has its offset)
            pubs["sp"].publish(OperationalSetpoint(header=header, pose=pose_to_msg(ROBOT.home),
                                                   force=vector3([0, 0, -10.0])))
            pubs["w"].publish(WrenchStamped(header=header, wrench=wrench_to_msg(w)))
            assert spin_until(executor, lambda: len(out) >= k)
            return out[-1].w_d.force.z

        assert period(1, "I") == pytest.approx(w[2], abs=1e-6)    # idle: the measured wrench
        for k in range(2, 5):
            w_z = period(k, "D")
        assert w_z == pytest.approx(weight[2] + 10.0, abs=1e-6)  # in contact: F_d = 10 N, not 3 N
    finally:
        executor.remove_node(node)
        node.destroy_node()
