"""gcode_interpreter node in-process: RunProgram action, set-points, status, parameter forwarding,
pause/resume, cancel and validated parameters."""
import time

import numpy as np
import pytest

from required import import_or_skip  # noqa: E402  (a missing rclpy fails in CI)
rclpy = import_or_skip("rclpy")
from action_msgs.msg import GoalStatus  # noqa: E402
from builtin_interfaces.msg import Time  # noqa: E402
from cdpr_msgs.action import RunProgram  # noqa: E402
from cdpr_msgs.msg import OperationalSetpoint, ProgramStatus  # noqa: E402
from rclpy.action import ActionClient  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from rosgraph_msgs.msg import Clock  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402
from std_msgs.msg import Header  # noqa: E402
from std_srvs.srv import Trigger  # noqa: E402

from cdpr_control.nodes.gcode_interpreter import GCodeInterpreterNode  # noqa: E402
from cdpr_control.ros.qos import CONTROL, STATUS  # noqa: E402


@pytest.fixture(scope="module")
def graph():
    rclpy.init()
    node = GCodeInterpreterNode(parameter_overrides=[Parameter("robot", value="ipanema3_mini"),
                                                     Parameter("command_timeout", value=0.3),
                                                     Parameter("sync_mode", value="latest")])
    target = rclpy.create_node("cable_force_controller")  # stands in for the node an M-code names
    target.declare_parameter("enabled", False)
    target.declare_parameter("f_ref", 10.0)
    target.declare_parameter("gain", 1)
    probe = rclpy.create_node("probe")
    executor = SingleThreadedExecutor()
    for n in (node, target, probe):
        executor.add_node(n)
    setpoints, statuses = [], []
    probe.create_subscription(OperationalSetpoint, "setpoint", setpoints.append, CONTROL)
    probe.create_subscription(ProgramStatus, "program_status", statuses.append, STATUS)
    client = ActionClient(probe, RunProgram, "run_program")
    assert client.wait_for_server(timeout_sec=5.0)
    yield node, target, probe, executor, client, setpoints, statuses
    client.destroy()
    for n in (node, target, probe):
        n.destroy_node()
    rclpy.shutdown()


def spin_until(executor, done, timeout=120.0):   # a hang guard, not a margin (busy machines)
    deadline = time.monotonic() + timeout
    while not done() and time.monotonic() < deadline:
        executor.spin_once(timeout_sec=0.01)
    return done()


def send(graph, program, name="test", dry_run=False, feedback=None):
    _, _, _, executor, client, _, _ = graph
    future = client.send_goal_async(RunProgram.Goal(program=program, name=name, dry_run=dry_run),
                                    feedback_callback=feedback)
    assert spin_until(executor, future.done)
    handle = future.result()
    assert handle.accepted
    return handle


def result_of(graph, handle):
    executor = graph[3]
    future = handle.get_result_async()
    assert spin_until(executor, future.done)
    return future.result()


PROGRAM = """G21 G90
M101
(M100 would set force_distribution.tension_level)
#<cable_force_controller.f_ref> = 80  (integer literal for a double parameter)
#<cable_force_controller.gain> = 3.0  (and the other way round)
G1 X20 W-5 F6000
"""


def test_runs_a_program_publishes_setpoints_and_forwards_parameters(graph):
    node, target, _, _, _, setpoints, statuses = graph
    feedback = []
    handle = send(graph, PROGRAM, "params", feedback=lambda msg: feedback.append(msg.feedback))
    response = result_of(graph, handle)
    assert response.status == GoalStatus.STATUS_SUCCEEDED
    assert response.result.success and response.result.duration > 0.2
    assert target.get_parameter("enabled").value is True
    assert target.get_parameter("f_ref").value == 80.0
    assert target.get_parameter("gain").value == 3
    last = setpoints[-1]
    assert last.pose.position.x == pytest.approx(0.02) and last.force.z == pytest.approx(-5.0)
    assert last.velocity.linear.x == 0.0 and last.line == 6
    moving = [s for s in setpoints if s.line == 6]
    speed = max(s.velocity.linear.x for s in moving)
    assert speed == pytest.approx(0.1, rel=1e-2)  # F6000 mm/min
    dt_ns = int(node.dt * 1e9)
    assert all((s.header.stamp.nanosec % dt_ns) == 0 for s in setpoints[-50:])  # stamps on the period grid
    assert {f.line for f in feedback} >= {6} and feedback[-1].progress <= 1.0
    assert statuses[-1].state == ProgramStatus.SUCCEEDED and statuses[-1].program == "params"


def test_a_program_with_errors_is_refused_with_line_and_column(graph):
    response = result_of(graph, send(graph, "G1 X1 F100\nG1 Q5\nG7", "bad"))
    assert response.status == GoalStatus.STATUS_ABORTED
    r = response.result
    assert not r.success and (r.error_line, r.error_column) == (2, 4)
    assert r.message.startswith("2:4: ") and "3:1: " in r.message


def test_a_program_leaving_the_workspace_is_refused_before_it_moves(graph):
    node = graph[0]
    before = node.q.copy()
    # the Mini's wrench-feasible workspace ends near x = 0.42 m: line 2 crosses it, line 3 comes back
    r = result_of(graph, send(graph, "G90 G1 X0 F6000\nG1 X600\nG1 X0", "outside")).result
    assert not r.success and r.error_line == 2 and "wrench-feasible workspace" in r.message
    np.testing.assert_array_equal(node.q, before)


def test_a_move_too_long_to_plan_is_refused_with_its_line(graph):
    r = result_of(graph, send(graph, "G91\nG1 X300 F1", "slow")).result
    assert not r.success and r.error_line == 2 and "raise F or split the move" in r.message


def test_dry_run_plans_without_moving(graph):
    node = graph[0]
    before = node.q.copy()
    r = result_of(graph, send(graph, "G91 G1 X100 F6000", dry_run=True)).result
    # jerk-limited line that never reaches a_max: T = L / v + 2 sqrt(v / j_max)
    assert r.success and r.duration == pytest.approx(1.0 + 2 * np.sqrt(0.1 / 20.0), abs=2e-3)
    np.testing.assert_array_equal(node.q, before)


def test_cancel_brakes_without_velocity_jump(graph):
    node, _, _, executor, _, setpoints, _ = graph
    start = len(setpoints)
    handle = send(graph, "G91 G1 X200 F30000", "long")
    assert spin_until(executor, lambda: len(setpoints) > start and setpoints[-1].velocity.linear.x > 0.3)
    cancel = handle.cancel_goal_async()
    response = result_of(graph, handle)
    assert cancel.done() and response.status == GoalStatus.STATUS_CANCELED
    v = np.array([s.velocity.linear.x for s in setpoints[start:]])
    a_max, dt = node.limits.translation.acceleration, node.dt
    assert np.max(np.abs(np.diff(v))) <= a_max * dt * (1 + 1e-9)
    assert v[-1] == 0.0 and setpoints[-1].pose.position.x < 0.02 + 0.2  # stopped short of the end


def test_the_loop_runs_while_a_program_is_planned(graph, monkeypatch):
    """Issue 28: planning happens off the loop's thread. The plan is held (an event, no timing) until
    the node has published 20 more set-points; meanwhile a second program is refused. Then it runs."""
    import threading
    from cdpr_control.nodes import gcode_interpreter
    node, _, _, executor, client, setpoints, _ = graph
    release, entered = threading.Event(), threading.Event()
    original = gcode_interpreter.check_program

    def slow_check(*args, **kwargs):
        entered.set()
        assert release.wait(timeout=60.0), "the test never released the plan"
        return original(*args, **kwargs)

    monkeypatch.setattr(gcode_interpreter, "check_program", slow_check)
    handle = send(graph, "G91 G1 X10 F6000", "planned slowly")
    assert spin_until(executor, entered.is_set)
    start = len(setpoints)
    assert spin_until(executor, lambda: len(setpoints) >= start + 20)     # set-points go on meanwhile
    assert node.planning == "planned slowly" and node.active is None
    second = client.send_goal_async(RunProgram.Goal(program="G91 G1 Y1 F100", name="second"))
    assert spin_until(executor, second.done) and not second.result().accepted
    release.set()
    response = result_of(graph, handle)
    assert response.status == GoalStatus.STATUS_SUCCEEDED and node.planning is None


def test_a_planning_error_fails_the_goal_with_its_reason(graph, monkeypatch):
    from cdpr_control.nodes import gcode_interpreter

    def broken(*args, **kwargs):
        raise RuntimeError("solver exploded")

    monkeypatch.setattr(gcode_interpreter, "check_program", broken)
    response = result_of(graph, send(graph, "G91 G1 X1 F100", "broken"))
    assert response.status == GoalStatus.STATUS_ABORTED
    assert response.result.message == "planning failed: RuntimeError: solver exploded"
    assert graph[0].planning is None


def call(graph, service):
    _, _, probe, executor, _, _, _ = graph
    client = probe.create_client(Trigger, f"/gcode_interpreter/{service}")
    assert client.wait_for_service(timeout_sec=5.0)
    future = client.call_async(Trigger.Request())
    assert spin_until(executor, future.done)
    probe.destroy_client(client)
    return future.result()


def test_pause_and_resume_services(graph):
    node, _, _, executor, _, _, statuses = graph
    assert not call(graph, "pause").success  # nothing running
    handle = send(graph, "G91 G1 Y50 F12000", "pausable")
    assert spin_until(executor, lambda: node.active is not None and node.active.interp.t > 0.1)
    assert call(graph, "pause").success
    assert spin_until(executor, lambda: statuses and statuses[-1].state == ProgramStatus.PAUSED)
    assert call(graph, "resume").success
    assert result_of(graph, handle).result.success


def test_a_parameter_command_to_a_missing_node_fails_the_program(graph):
    r = result_of(graph, send(graph, "#<nobody.x> = 1\nG91 G1 X1 F100", "missing")).result
    assert not r.success and "nobody" in r.message and r.error_line == 1


def test_m103_without_the_hybrid_force_controller_names_the_node(graph):
    r = result_of(graph, send(graph, "G21 G90\nM103\nG91 G1 X1 F100", "no_hpfc")).result
    assert not r.success and r.error_line == 2
    assert "'hybrid_force_controller' is not running" in r.message


def test_limit_parameters_are_validated(graph):
    node = graph[0]
    assert not node.set_parameters([Parameter("v_max", value=-1.0)])[0].successful
    assert not node.set_parameters([Parameter("j_max", value=1e9)])[0].successful
    assert node.get_parameter("v_max").value == 0.5
    assert node.set_parameters([Parameter("v_max", value=0.25)])[0].successful
    assert node.limits.translation.velocity == 0.25
    assert node.set_parameters([Parameter("v_max", value=0.5)])[0].successful


def test_set_points_follow_sim_time(graph):
    """With use_sim_time the cycle runs on /clock: one set-point per period, stamped in sim time."""
    _, _, probe, executor, _, _, _ = graph
    sim = GCodeInterpreterNode(namespace="sim", parameter_overrides=[
        Parameter("robot", value="ipanema3_mini"), Parameter("use_sim_time", value=True),
        Parameter("sync_mode", value="latest")])
    executor.add_node(sim)
    clock = probe.create_publisher(Clock, "/clock", 10)
    got = []
    probe.create_subscription(OperationalSetpoint, "/sim/setpoint", got.append, CONTROL)
    assert spin_until(executor, lambda: clock.get_subscription_count() > 0)
    for k in range(1, 40):
        clock.publish(Clock(clock=Time(sec=7, nanosec=k * 1_000_000)))
        spin_until(executor, lambda: False, timeout=0.01)
    executor.remove_node(sim)
    sim.destroy_node()
    assert got and all(m.header.stamp.sec == 7 and m.header.stamp.nanosec % 1_000_000 == 0 for m in got)
    stamps = [m.header.stamp.nanosec for m in got]
    assert stamps == sorted(set(stamps))  # one set-point per period, in order


def test_lockstep_set_points_follow_the_winch_state(graph):
    """sync_mode exact: one period per new winch state, its set-point with its stamp (also for t = 0);
    a repeated state (the simulator's start-up handshake) repeats that period's set-point for nodes
    that subscribed after it went out, without advancing the program."""
    _, _, probe, executor, _, _, _ = graph
    node = GCodeInterpreterNode(namespace="lockstep", parameter_overrides=[
        Parameter("robot", value="ipanema3_mini"), Parameter("sync_mode", value="exact")])
    executor.add_node(node)
    state = probe.create_publisher(JointState, "/lockstep/winch/state", CONTROL)
    got = []
    probe.create_subscription(OperationalSetpoint, "/lockstep/setpoint", got.append, CONTROL)
    assert spin_until(executor, lambda: state.get_subscription_count() > 0)
    for k in (0, 0, 1, 2, 2, 3):                    # repeated states (the simulator's handshake)
        state.publish(JointState(header=Header(stamp=Time(sec=0, nanosec=k * 1_000_000))))
        spin_until(executor, lambda: False, timeout=0.02)
    assert spin_until(executor, lambda: len(got) >= 6)
    executor.remove_node(node)
    node.destroy_node()
    assert [m.header.stamp.nanosec for m in got] == [0, 0, 1_000_000, 2_000_000, 2_000_000, 3_000_000]
    assert got[0] is got[1] or got[0] == got[1]
