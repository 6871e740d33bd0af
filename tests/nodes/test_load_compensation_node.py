"""Node ``load_compensation`` on typed topics: lockstep periods publish the state (x_d,LC) and the
payload (geometry_msgs/InertiaStamped) every period, enabled or not; a live disable zeroes the output;
a rejected parameter keeps the old value; the force distribution takes the payload as the known part of its disturbance;
the ~/tare service makes the estimate read the known payload."""
import numpy as np
import pytest

from required import import_or_skip  # noqa: E402  (a missing rclpy fails in CI)
rclpy = import_or_skip("rclpy")
from cdpr_msgs.msg import CableForces, ControllerState, ForceDistribution, OperationalSetpoint  # noqa: E402
from geometry_msgs.msg import InertiaStamped, PoseStamped, WrenchStamped  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from std_srvs.srv import Trigger  # noqa: E402

from cdpr_control.model.dynamics import platform_wrench  # noqa: E402
from cdpr_control.force_distribution import ForceDistributor  # noqa: E402
from cdpr_control.model.kinematics import inverse_kinematics  # noqa: E402
from cdpr_control.control.load_compensation import payload_wrench  # noqa: E402
from cdpr_control.ros.base import CdprNode  # noqa: E402
from cdpr_control.ros.conversions import pose_to_msg, wrench_to_msg  # noqa: E402
from cdpr_control.nodes.force_distribution import ForceDistributionNode  # noqa: E402
from cdpr_control.nodes.load_compensation import LoadCompensationNode  # noqa: E402
from cdpr_control.ros.qos import CONTROL  # noqa: E402
from cdpr_control.model.robot import load_robot  # noqa: E402
from node_harness import node_graph, spin_until  # noqa: E402

ROBOT = load_robot("ipanema3_mini")


@pytest.fixture(scope="module")
def graph():
    def make_nodes():
        overrides = [Parameter("robot", value="ipanema3_mini")]
        nodes = [LoadCompensationNode(parameter_overrides=overrides + [Parameter("T_output", value=0.0),
                                                                      Parameter("time_shift", value=0.0)]),
                 ForceDistributionNode(parameter_overrides=overrides + [Parameter("payload_input", value=True),
                                                                        Parameter("wrench_source", value="model")])]
        return nodes
    with node_graph(make_nodes) as graph:
        yield graph


def test_state_and_payload_every_period_and_live_disable(graph):
    (lc, fd), probe, executor = graph
    x = ROBOT.home
    m_c = 0.4
    w = platform_wrench(ROBOT, x) + payload_wrench(ROBOT, x, np.zeros(6), np.zeros(6), m_c)
    AT = inverse_kinematics(ROBOT, x).AT
    c = ROBOT.cable
    f = ForceDistributor(ROBOT.m, c.f_min, c.f_max, method="qp").solve(AT, w, 1e-3).f
    pubs = {name: probe.create_publisher(t, topic, CONTROL) for name, t, topic in (
        ("sp", OperationalSetpoint, "setpoint"), ("f", CableForces, "cable_forces"),
        ("pose", PoseStamped, "platform/pose"), ("wrench", WrenchStamped, "platform/wrench"))}
    got = {"state": [], "payload": [], "fd": []}
    probe.create_subscription(ControllerState, "load_compensation/state", got["state"].append, CONTROL)
    probe.create_subscription(InertiaStamped, "load_compensation/payload", got["payload"].append, CONTROL)
    probe.create_subscription(ForceDistribution, "force_distribution", got["fd"].append, CONTROL)
    spin_until(executor, lambda: pubs["sp"].get_subscription_count() >= 2 and pubs["f"].get_subscription_count() >= 1
                and probe.count_publishers("load_compensation/payload") >= 1, 5.0)

    def period(k):
        header = CdprNode.header(k * 1_000_000)
        pubs["sp"].publish(OperationalSetpoint(header=header, pose=pose_to_msg(x)))
        pubs["pose"].publish(PoseStamped(header=header, pose=pose_to_msg(x)))
        pubs["wrench"].publish(WrenchStamped(header=header, wrench=wrench_to_msg(-AT @ f)))
        pubs["f"].publish(CableForces(header=header, f=f.tolist()))
        assert spin_until(executor, lambda: len(got["state"]) > k and len(got["payload"]) > k and len(got["fd"]) > k)

    for k in range(300):                                  # longer than the 240 ms window
        period(k)
    state, payload = got["state"][-1], got["payload"][-1]
    assert state.enabled and state.controller == "load_compensation" and len(state.output) == 6
    assert payload.inertia.m == pytest.approx(m_c, rel=1e-6) and payload.header.frame_id == "platform"
    assert state.output[2] > 0.0 and np.all(np.isfinite(state.output))
    # the distribution's model wrench (wrench_source: model) carries the identified payload
    w_d = got["fd"][-1].w_d
    assert w_d.force.z == pytest.approx(w[2], rel=1e-6)

    assert not lc.set_parameters([Parameter("stiffness_model", value="spline")])[0].successful
    assert lc.stage.params.stiffness_model == "nonlinear"
    assert lc.set_parameters([Parameter("enabled", value=False)])[0].successful
    period(300)
    state = got["state"][-1]
    assert not state.enabled and list(state.output) == [0.0] * 6
    assert got["payload"][-1].inertia.m == pytest.approx(m_c, rel=1e-6)   # identification goes on

    # the tare at a known state: the estimate reads tare_payload from then on
    assert lc.set_parameters([Parameter("tare_payload", value=0.1)])[0].successful
    client = probe.create_client(Trigger, "/load_compensation/tare")
    assert client.wait_for_service(timeout_sec=5.0)
    future = client.call_async(Trigger.Request())
    assert spin_until(executor, future.done) and future.result().success
    period(301)
    assert got["payload"][-1].inertia.m == pytest.approx(0.1, abs=1e-6)
