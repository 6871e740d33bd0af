"""CFC, OSPC and joint-command nodes on typed topics: one lockstep period end to end with two offset
inputs, live parameter changes, and rejected parameters leaving the node running with its old value."""
import numpy as np
import pytest

from required import import_or_skip  # noqa: E402  (a missing rclpy fails in CI)
rclpy = import_or_skip("rclpy")
from cdpr_msgs.msg import CableForces, ControllerState, ForceDistribution, OperationalSetpoint  # noqa: E402
from geometry_msgs.msg import PoseStamped  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402

from cdpr_control.control.bumpless import START_FORCE_RANGE_TIME  # noqa: E402
from cdpr_control.model import cable  # noqa: E402
from cdpr_control.model.kinematics import inverse_kinematics  # noqa: E402
from cdpr_control.ros.base import CdprNode  # noqa: E402
from cdpr_control.nodes.cable_force_controller import CableForceControllerNode  # noqa: E402
from cdpr_control.ros.conversions import pose_to_msg  # noqa: E402
from cdpr_control.nodes.joint_command import JointCommandNode  # noqa: E402
from cdpr_control.nodes.ospc import OSPCNode  # noqa: E402
from cdpr_control.ros.qos import CONTROL  # noqa: E402
from cdpr_control.model.robot import load_robot  # noqa: E402
from node_harness import node_graph, spin_until  # noqa: E402


@pytest.fixture(scope="module")
def graph():
    def make_nodes():
        overrides = [Parameter("robot", value="ipanema3_mini")]
        cfc_linear = overrides + [Parameter("stiffness_model", value="linear")]     # the thesis' K_l (2.15)
        nodes = [CableForceControllerNode(parameter_overrides=cfc_linear), OSPCNode(parameter_overrides=overrides),
                 # a second offset input beside OSPC, published by the probe; no ramp, so that one period
                 # already shows the full sum of (5.10) (the ramp is tested in test_offset_inputs.py)
                 JointCommandNode(parameter_overrides=overrides + [
                     Parameter("v_max", value=100.0), Parameter("transfer_time", value=0.0),
                     Parameter("start_ramp", value=0.0),
                     Parameter("offset_inputs", value=["ospc", "probe_offset"])])]
        return nodes
    with node_graph(make_nodes) as graph:
        yield graph


def test_one_period_through_cfc_ospc_and_joint_command(graph):
    nodes, probe, executor = graph
    robot = load_robot("ipanema3_mini")
    m = robot.m
    pubs = {name: probe.create_publisher(t, topic, CONTROL) for name, t, topic in (
        ("theta", JointState, "winch/state"), ("f", CableForces, "cable_forces"),
        ("fd", ForceDistribution, "force_distribution"), ("sp", OperationalSetpoint, "setpoint"),
        ("pose", PoseStamped, "platform/pose"), ("offset", ControllerState, "probe_offset/state"))}
    commands, cfc_states = [], []
    probe.create_subscription(JointState, "winch/command", commands.append, CONTROL)
    probe.create_subscription(ControllerState, "cable_force_controller/state", cfc_states.append, CONTROL)
    assert spin_until(executor, lambda: all(p.get_subscription_count() > 0 for p in pubs.values()))

    x_d = np.array([0.02, -0.01, 0.03, 0.0, 0.0, 0.0])
    x = x_d + np.array([0.0, 0.0, -0.002, 0.0, 0.0, 0.0])      # sagged estimate
    q = inverse_kinematics(robot, x_d).q
    f = np.full(m, 10.0)
    f_d = np.full(m, 12.0)
    x_probe = np.array([0.0, 0.001, 0.0, 0.002, 0.0, 0.0])
    for k in range(1, 4):
        header = CdprNode.header(k * 1_000_000)
        pubs["theta"].publish(JointState(header=header, position=q.tolist(), velocity=[0.0] * m, effort=f.tolist()))
        pubs["f"].publish(CableForces(header=header, f=f.tolist(), f_min=robot.cable.f_min.tolist(), f_max=robot.cable.f_max.tolist()))
        pubs["fd"].publish(ForceDistribution(header=header, f_d=f_d.tolist(), f_min=robot.cable.f_min.tolist(), f_max=robot.cable.f_max.tolist()))
        pubs["sp"].publish(OperationalSetpoint(header=header, pose=pose_to_msg(x_d)))
        pubs["pose"].publish(PoseStamped(header=header, pose=pose_to_msg(x)))
        pubs["offset"].publish(ControllerState(header=header, controller="probe_offset", enabled=True,
                                               output=x_probe.tolist()))
        # (in-process, the command may reach the probe before the CFC state it was computed from)
        assert spin_until(executor, lambda: len(commands) >= k and len(cfc_states) >= k), f"no command for period {k}"
    last = commands[-1]
    assert last.header.stamp.nanosec == 3_000_000
    theta_d = np.asarray(last.position)
    assert np.all(np.isfinite(theta_d))
    # the command is IK of the set-point plus both offsets minus the CFC elongation (5.10)
    ospc = nodes[1].controller.pi.output
    dq = np.asarray(cfc_states[-1].output)
    np.testing.assert_allclose(theta_d, inverse_kinematics(robot, x_d + ospc + x_probe).q - dq, atol=1e-12)
    assert ospc[2] > 0.0                                        # pushes up against the sag
    # Δq_CFC (3.23) with Δq_0 = f_0 / K_l from the first measured force; the set-point rises from f
    # by (f_max - f_min) dt / START_FORCE_RANGE_TIME a period (the start ramp), so after three periods
    # f_c,out = f_ref,3 + K_p e_3 + K_p dt / T_i (e_1 + e_2 + e_3), e_k = f_ref,k - f  (3.19), (3.22)
    k_l = robot.cable.k_spec_nominal / cable.total_free_length(robot, q)
    step = (robot.cable.f_max - robot.cable.f_min) * 0.001 / START_FORCE_RANGE_TIME
    e = [k * step for k in (1, 2, 3)]
    f_out = f + e[2] + 0.85 * e[2] + 0.85 * 0.001 / 0.1 * sum(e)
    np.testing.assert_allclose(dq, f_out / k_l - f / k_l, rtol=1e-9)


def test_rejected_parameter_keeps_old_value_and_says_why(graph):
    nodes, _, _ = graph
    cfc, ospc, jc = nodes
    result = cfc.set_parameters([Parameter("K_p", value=-1.0)])[0]
    assert not result.successful and result.reason
    assert cfc.get_parameter("K_p").value == 0.85 and cfc.stage.params.K_p == 0.85
    result = ospc.set_parameters([Parameter("T_i", value=[0.18] * 5)])[0]
    assert not result.successful and "T_i" in result.reason
    assert len(ospc.get_parameter("T_i").value) == 6
    result = cfc.set_parameters([Parameter("stiffness_model", value="cubic")])[0]
    assert not result.successful and "linear" in result.reason
    result = jc.set_parameters([Parameter("mode", value="torque")])[0]
    assert not result.successful and "force_control" in result.reason
    assert jc.mode == "force_control"
    result = jc.set_parameters([Parameter("offsets.probe_offset.deadline", value=-1.0)])[0]
    assert not result.successful and result.reason
    assert jc.offsets.configs["probe_offset"].deadline == 0.005


def test_parameters_apply_live(graph):
    nodes, _, _ = graph
    cfc, ospc, jc = nodes
    assert cfc.set_parameters([Parameter("K_p", value=0.5)])[0].successful
    assert cfc.stage.params.K_p == 0.5 and cfc.stage.controller.pi.K_p[0] == 0.5
    assert jc.set_parameters([Parameter("mode", value="ik_only")])[0].successful and jc.mode == "ik_only"
    assert jc.set_parameters([Parameter("mode", value="force_control")])[0].successful
    assert jc.set_parameters([Parameter("offsets.probe_offset.enabled", value=False)])[0].successful
    assert not jc.offsets.configs["probe_offset"].enabled and jc.offsets.configs["ospc"].enabled
    assert ospc.set_parameters([Parameter("x_sat", value=[0.01] * 6)])[0].successful
    np.testing.assert_allclose(ospc.controller.pi.u_pos, 0.01)


def test_ik_only_holds_the_integrators_of_ospc_and_cfc(graph):
    """joint_command's mode reaches the OSPC and CFC nodes (joint_command/mode): in IK-only their
    outputs are not applied and their integrators hold (no wind-up, bumpless back, issue 17 item 2)."""
    nodes, probe, executor = graph
    cfc, ospc, jc = nodes
    robot = load_robot("ipanema3_mini")
    m = robot.m
    pubs = {name: probe.create_publisher(t, topic, CONTROL) for name, t, topic in (
        ("theta", JointState, "winch/state"), ("f", CableForces, "cable_forces"),
        ("fd", ForceDistribution, "force_distribution"), ("sp", OperationalSetpoint, "setpoint"),
        ("pose", PoseStamped, "platform/pose"), ("offset", ControllerState, "probe_offset/state"))}
    states = {"cfc": [], "ospc": []}
    probe.create_subscription(ControllerState, "cable_force_controller/state", states["cfc"].append, CONTROL)
    probe.create_subscription(ControllerState, "ospc/state", states["ospc"].append, CONTROL)
    assert spin_until(executor, lambda: all(p.get_subscription_count() > 0 for p in pubs.values()))
    x_d = np.zeros(6)
    x = x_d - np.array([0.0, 0.0, 0.002, 0.0, 0.0, 0.0])         # a sag: both integrators run
    q, f, f_d = inverse_kinematics(robot, x_d).q, np.full(m, 10.0), np.full(m, 12.0)
    period = [3]           # continues the stamps of the first test: a jump beyond input_deadline is dropped

    def step():
        period[0] += 1
        header = CdprNode.header(period[0] * 1_000_000)
        n = len(states["cfc"]), len(states["ospc"])
        lim = dict(f_min=robot.cable.f_min.tolist(), f_max=robot.cable.f_max.tolist())
        pubs["theta"].publish(JointState(header=header, position=q.tolist(), velocity=[0.0] * m, effort=f.tolist()))
        pubs["f"].publish(CableForces(header=header, f=f.tolist(), **lim))
        pubs["fd"].publish(ForceDistribution(header=header, f_d=f_d.tolist(), **lim))
        pubs["sp"].publish(OperationalSetpoint(header=header, pose=pose_to_msg(x_d)))
        pubs["pose"].publish(PoseStamped(header=header, pose=pose_to_msg(x)))
        pubs["offset"].publish(ControllerState(header=header, controller="probe_offset", enabled=True, output=[0.0] * 6))
        assert spin_until(executor, lambda: len(states["cfc"]) > n[0] and len(states["ospc"]) > n[1])
        return np.asarray(states["cfc"][-1].integrator), np.asarray(states["ospc"][-1].integrator)

    def integrating():
        before = step()
        after = step()
        return np.all(np.abs(after[0] - before[0]) > 0.0), abs(after[1][2] - before[1][2]) > 0.0

    assert integrating() == (True, True)
    assert jc.set_parameters([Parameter("mode", value="ik_only")])[0].successful
    assert spin_until(executor, lambda: ospc.controller.pi.hold and cfc.stage.controller.pi.hold)
    assert integrating() == (False, False)                   # held: no wind-up while not applied
    assert jc.set_parameters([Parameter("mode", value="force_control")])[0].successful
    assert spin_until(executor, lambda: not (ospc.controller.pi.hold or cfc.stage.controller.pi.hold))
    assert integrating() == (True, True)


def test_home_calibration_parameter_keeps_the_fk_unbiased_away_from_home(graph):
    """home_forces (the forces recorded when the encoders were set at home, 2.3.2) give the FK and
    CFC nodes their Δq_0: a start 1 m from home is then not biased by the start-up forces (issue 17
    item 4; the library's test_bumpless_calibration.py without a node)."""
    from cdpr_control.nodes.forward_kinematics import ForwardKinematicsNode
    from cdpr_sim.startup import startup_forces
    from poses import encoder_lengths

    robot = load_robot("ipanema3")
    x0 = robot.home + np.r_[1.0, 0.5, -0.3, 0, 0, 0]
    f_home, f_x = startup_forces(robot, robot.home, 0.3), startup_forces(robot, x0, 0.3)
    theta = encoder_lengths(robot, x0, f_x, f_home)
    overrides = [Parameter("robot", value="ipanema3"), Parameter("home_forces", value=f_home.tolist())]
    fk = ForwardKinematicsNode(namespace="calibration_test", parameter_overrides=overrides)
    cfc = CableForceControllerNode(namespace="calibration_test", parameter_overrides=overrides)
    try:
        header = CdprNode.header(1_000_000)
        msgs = {"theta": JointState(header=header, position=theta.tolist()),
                "f": CableForces(header=header, f=f_x.tolist()),
                "setpoint": OperationalSetpoint(header=header, pose=pose_to_msg(x0))}
        for k in range(3):
            fk._cycle(msgs, (k + 1) * 1_000_000)
        assert np.linalg.norm(fk.estimator.x[:3] - x0[:3]) < 2e-5     # with the first sample: > 1 mm
        assert cfc.stage.calibration.from_home and np.array_equal(cfc.stage.calibration.f_0, f_home)
        assert fk.get_parameter("calibration_window").value == 100
        with pytest.raises(ValueError, match="positive"):      # a slack cable in the home calibration
            ForwardKinematicsNode(namespace="calibration_test", parameter_overrides=[
                Parameter("robot", value="ipanema3"), Parameter("home_forces", value=[0.0] * 7 + [1.0])])
    finally:
        fk.destroy_node()
        cfc.destroy_node()
