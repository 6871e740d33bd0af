"""winch_platform_sim node: lockstep protocol with /clock, missed deadlines, services, parameters."""
import time

import numpy as np
import pytest

from required import import_or_skip  # noqa: E402  (a missing rclpy fails in CI)
rclpy = import_or_skip("rclpy")
from cdpr_msgs.msg import CableForces  # noqa: E402
from cdpr_msgs.srv import ApplyWrench, SetPayload  # noqa: E402
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus  # noqa: E402
from geometry_msgs.msg import PoseStamped  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from rosgraph_msgs.msg import Clock  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402

from cdpr_control.model.kinematics import inverse_kinematics  # noqa: E402
from cdpr_control.ros.qos import CONTROL  # noqa: E402
from cdpr_sim.nodes.winch_platform_sim import CLOCK_QOS, WinchPlatformSimNode  # noqa: E402
from node_harness import node_graph, spin_until  # noqa: E402


@pytest.fixture()
def graph(request):
    extra = getattr(request, "param", [])
    with node_graph(lambda: [WinchPlatformSimNode(parameter_overrides=[
            Parameter("robot", value="ipanema3_mini"), Parameter("lockstep_timeout", value=0.2)] + extra)]) \
            as ((sim,), probe, executor):
        yield sim, probe, executor


def _ns(msg):
    return msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec


# no wall-clock deadline here: a loaded machine may pause the test's spin longer than the module's
# 0.2 s (the missed deadline has a test of its own below)
@pytest.mark.parametrize("graph", [[Parameter("lockstep_timeout", value=600.0)]], indirect=True)
def test_lockstep_echo_loop_advances_one_period_per_command(graph):
    sim, probe, executor = graph
    assert sim.get_parameter("lockstep_timeout").value == 600.0
    states, clocks, poses, forces = [], [], [], []
    command = probe.create_publisher(JointState, "winch/command", CONTROL)

    def controller(msg):                      # hold the measured lengths, stamped with the state's time
        states.append(msg)
        command.publish(JointState(header=msg.header, position=list(msg.position)))

    probe.create_subscription(JointState, "winch/state", controller, CONTROL)
    probe.create_subscription(Clock, "/clock", clocks.append, CLOCK_QOS)
    probe.create_subscription(PoseStamped, "ground_truth/pose", poses.append, CONTROL)
    probe.create_subscription(CableForces, "ground_truth/cable_forces", forces.append, CONTROL)
    assert spin_until(executor, lambda: len(states) >= 200)
    stamps = np.array([_ns(m) for m in states])
    assert stamps[0] == 0                                           # the start is announced at t = 0
    assert np.all(np.diff(stamps) == 1_000_000)                     # then one period per command
    assert sim.missed_deadlines == 0 and sim.late_commands == 0
    assert clocks and clocks[-1].clock.sec * 1_000_000_000 + clocks[-1].clock.nanosec <= stamps[-1]
    robot = sim.robot
    # start-up calibration: the encoders read IK{home} at home under tension (2.3.2)
    np.testing.assert_allclose(states[0].position, inverse_kinematics(robot, robot.home).q, atol=1e-6)
    assert np.all(np.asarray(forces[-1].f) > robot.cable.f_min - 1e-6)
    assert abs(poses[-1].pose.position.z - robot.home[2]) < 1e-4        # holding theta keeps it there
    assert len(states[-1].effort) == robot.m and len(states[-1].velocity) == robot.m


def test_missed_deadline_advances_after_the_timeout(graph):
    sim, probe, executor = graph
    command = probe.create_publisher(JointState, "winch/command", CONTROL)
    states = []
    probe.create_subscription(JointState, "winch/state", states.append, CONTROL)
    assert spin_until(executor, lambda: len(states) >= 1)
    command.publish(JointState(header=states[-1].header, position=list(states[-1].position)))
    assert spin_until(executor, lambda: sim.sim.steps >= 1)
    # no further command: after 0.2 s the simulator advances anyway, holding the last command
    assert spin_until(executor, lambda: sim.missed_deadlines >= 2, timeout=5.0)
    assert sim.sim.steps == 1 + sim.missed_deadlines
    # a command answering an old state is late: counted, no step; it is held when newer than the
    # command held, and ignored when older (a second answer to a repeated start-up state must not
    # replace the newest command)
    steps = sim.sim.steps
    command.publish(JointState(header=states[0].header, position=[p + 0.01 for p in states[0].position]))
    assert spin_until(executor, lambda: sim.late_commands == 1)
    assert sim.sim.steps - steps <= 1                               # at most a timeout step
    np.testing.assert_allclose(sim.theta_d, np.asarray(states[0].position) + 0.01)  # as new as the held
    current = states[-1]
    command.publish(JointState(header=current.header, position=list(current.position)))
    assert spin_until(executor, lambda: sim.sim.steps * sim.period_ns > _ns(current))   # answered: a step
    command.publish(JointState(header=states[0].header, position=[p + 0.02 for p in states[0].position]))
    assert spin_until(executor, lambda: sim.late_commands == 2)
    np.testing.assert_array_equal(sim.theta_d, np.asarray(current.position))  # older than the held one
    # a command of wrong length is refused and does not advance time
    steps = sim.sim.steps
    command.publish(JointState(position=[1.0, 2.0]))
    assert spin_until(executor, lambda: sim.invalid_commands == 1)
    # a command stamped after the newest state (no controller can answer a state not yet sent) is
    # refused: it neither drives the winches nor advances time
    held, steps = sim.theta_d.copy(), sim.sim.steps
    future = JointState(position=[p + 0.05 for p in states[-1].position])
    future.header.stamp.sec = 5000
    command.publish(future)
    assert spin_until(executor, lambda: sim.invalid_commands == 2)
    np.testing.assert_array_equal(sim.theta_d, held)
    assert sim.sim.steps - steps <= 1                               # at most a timeout step
    assert sim.sim.steps - steps <= 1                               # at most a timeout step


def test_payload_and_wrench_services(graph):
    sim, probe, executor = graph
    payload = probe.create_client(SetPayload, "sim/set_payload")
    wrench = probe.create_client(ApplyWrench, "sim/apply_wrench")
    assert payload.wait_for_service(timeout_sec=5.0) and wrench.wait_for_service(timeout_sec=5.0)

    def call(client, request):
        future = client.call_async(request)
        assert spin_until(executor, future.done)
        return future.result()

    request = SetPayload.Request()
    request.payload.m = 0.5
    request.payload.com.z = -0.05
    response = call(payload, request)
    assert response.success and response.total_mass == pytest.approx(sim.sim.robot.platform.mass)
    assert response.total_mass == pytest.approx(1.5)
    request.payload.m = -1.0
    response = call(payload, request)
    assert not response.success and "mass" in response.message

    request = ApplyWrench.Request(shape=ApplyWrench.Request.SHAPE_HALF_SINE, duration=0.1)
    request.wrench.force.x = 2.0
    assert call(wrench, request).success
    request.duration = 0.0                                           # a half sine needs a duration
    response = call(wrench, request)
    assert not response.success and "duration" in response.message


def test_payload_beyond_the_robot_is_accepted_with_a_warning(graph):
    """100 kg on the Mini: simulated (an overload to test faults against) but the response and
    /diagnostics say that no cable forces within the limits hold it."""
    sim, probe, executor = graph
    payload = probe.create_client(SetPayload, "sim/set_payload")
    diagnostics = []
    probe.create_subscription(DiagnosticArray, "/diagnostics", diagnostics.append, 10)
    assert payload.wait_for_service(timeout_sec=5.0)
    # a lockstep node reports on change only: the probe must hear the first report
    assert spin_until(executor, lambda: sim.diagnostics_pub.get_subscription_count() > 0)
    request = SetPayload.Request()
    request.payload.m = 100.0
    future = payload.call_async(request)
    assert spin_until(executor, future.done)
    response = future.result()
    assert response.success and response.total_mass == pytest.approx(101.0)
    assert "beyond what the robot can hold" in response.message and "[5, 40] N" in response.message

    def warned():
        return any(s.level == DiagnosticStatus.WARN and "beyond what the robot can hold" in s.message
                   for d in diagnostics for s in d.status if "winch_platform_sim" in s.name)
    assert spin_until(executor, warned, timeout=5.0)
    request.payload.m = 0.5
    future = payload.call_async(request)
    assert spin_until(executor, future.done)
    assert future.result().success and future.result().message == ""


def test_parameters_are_validated_on_set(graph):
    sim, _, _ = graph
    ok = sim.set_parameters([Parameter("lockstep_timeout", value=0.5)])[0]
    assert ok.successful and sim.lockstep_timeout == 0.5
    out_of_range = sim.set_parameters([Parameter("realtime_factor", value=-1.0)])[0]
    assert not out_of_range.successful and sim.realtime_factor == 1.0
    read_only = sim.set_parameters([Parameter("seed", value=3)])[0]
    assert not read_only.successful


@pytest.mark.parametrize("graph", [[Parameter("sync_mode", value="latest"), Parameter("realtime_factor", value=0.5)]],
                         indirect=True)
def test_free_running_keeps_pace_with_the_wall_clock(graph):
    sim, probe, executor = graph
    states = []
    probe.create_subscription(JointState, "winch/state", states.append, CONTROL)
    start = time.monotonic()
    spin_until(executor, lambda: time.monotonic() - start > 1.0, timeout=1.5)
    expected = (time.monotonic() - sim._wall_start) * 0.5 / sim.dt
    assert 0.5 * expected < sim.sim.steps <= expected + 1
    stamps = np.array([_ns(m) for m in states])
    assert len(stamps) > 100 and np.all(np.diff(stamps) > 0) and np.all(stamps % 1_000_000 == 0)
    assert sim.missed_deadlines == 0                      # no controller yet: nothing was missed
