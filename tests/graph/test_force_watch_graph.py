"""The force watch and the stability check in the composed node graph (IPAnema 3 Mini, lockstep,
default mismatched plant): gains that the stability analysis calls unstable are refused by the
OSPC and CFC nodes with the margins; forced through with ``allow_unstable``, they trip the joint
command's force watch, whose hold reaches /diagnostics (ERROR, the cable, the value, the limit)
and fails the running program; ``~/release_hold`` ends the hold. One launch serves the module.
"""
import pytest

from required import import_or_skip  # noqa: E402  (a missing rclpy fails in CI)
rclpy = import_or_skip("rclpy")
from cdpr_msgs.msg import ProgramStatus  # noqa: E402
from diagnostic_msgs.msg import DiagnosticStatus  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from std_srvs.srv import Trigger  # noqa: E402

from cdpr_test_nodes.fault_graph import FaultGraph  # noqa: E402
from cdpr_test_nodes.graph import wait_for  # noqa: E402


@pytest.fixture(scope="module")
def graph():
    g = FaultGraph("composed", lockstep_timeout=0.02, state_timeout=5.0)
    yield g
    g.close()


def node(graph, name):
    return next(n for n in graph.launcher.nodes if n.get_name() == name)


@pytest.mark.parametrize("name, parameters, words", [
    ("ospc", [Parameter("K_p", value=[7.0] * 6)], ["operational-space position control", "gain margin"]),
    ("cable_force_controller", [Parameter("K_p", value=10.0), Parameter("T_i", value=1e-3)],
     ["cable force control (3.21)", "gain margin"]),
    ("cable_force_controller", [Parameter("T_i", value=1e-3)], ["T_i 0.001 s", "phase margin"]),
])
def test_unstable_gains_are_refused_with_the_margins(graph, name, parameters, words):
    n = node(graph, name)
    before = {p.name: n.get_parameter(p.name).value for p in parameters}
    result = n.set_parameters_atomically(parameters)
    assert not result.successful
    for word in words + ["unstable by the stability analysis", "allow_unstable"]:
        assert word in result.reason, result.reason
    assert {p: n.get_parameter(p).value for p in before} == before          # nothing changed


def test_forced_unstable_gains_hold_report_and_fail_the_program(graph):
    ospc, joint_command = node(graph, "ospc"), node(graph, "joint_command")
    k_p = list(ospc.get_parameter("K_p").value)
    mark = graph.mark()
    running = graph.start_program("G21 G90\nG1 X30 F600\nM30", "diverge")
    graph.wait_program_state(ProgramStatus.RUNNING)
    graph.wait_running(periods=50)
    try:
        assert ospc.set_parameters_atomically([Parameter("allow_unstable", value=True)]).successful
        assert ospc.set_parameters_atomically([Parameter("K_p", value=[7.0] * 6)]).successful
        running["thread"].join(60)
        result = running["result"]
        assert not result.success and "joint_command holds: force watch: " in result.message, result.message
        holds = graph.wait_diagnosed("force watch: ", "holding", since=mark)
        status = holds[0]
        assert status.level == DiagnosticStatus.ERROR and status.name.endswith("joint_command")
        values = {kv.key: kv.value for kv in status.values}
        assert values["holding"] == "True" and values["abort"] == "True"
        assert "cable " in status.message or "position error" in status.message
        assert " beyond " in status.message or " ms (limit " in status.message
    finally:
        ospc.set_parameters_atomically([Parameter("K_p", value=k_p)])
        ospc.set_parameters_atomically([Parameter("allow_unstable", value=False)])
    assert joint_command.watch.fault is not None                          # still holding: latched
    graph.check_commands()                                                # finite, within the rate limit
    client = graph.probe.create_client(Trigger, "/joint_command/release_hold")
    assert client.wait_for_service(timeout_sec=10.0)
    future = client.call_async(Trigger.Request())
    wait_for(future.done, what="the release_hold answer")
    assert future.result().success and future.result().message.startswith("released: force watch")
    assert joint_command.watch.fault is None
