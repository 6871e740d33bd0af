"""Fault isolation and the pieces of the fault handling, without a closed loop: an exception in a
cdpr node's callback neither ends a composed launch nor the node (issue 18, item 1); the message
checks; stamp jumps; the joint command's braking hold; a program aborted with the reason."""
import math

import numpy as np
import pytest

from required import import_or_skip  # noqa: E402  (a missing rclpy fails in CI)
rclpy = import_or_skip("rclpy")
from builtin_interfaces.msg import Time  # noqa: E402
from cdpr_msgs.msg import CableForces, ControllerState, OperationalSetpoint  # noqa: E402
from diagnostic_msgs.msg import DiagnosticArray  # noqa: E402
from geometry_msgs.msg import Pose, PoseStamped, Quaternion  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402
from std_msgs.msg import Header, Int32  # noqa: E402

from cdpr_control.motion.gcode import parse_gcode  # noqa: E402
from cdpr_control.motion.interpolation import Interpolator, ProgramState  # noqa: E402
from cdpr_control.control.joint_command import JointCommand  # noqa: E402
from cdpr_control.model.kinematics import inverse_kinematics  # noqa: E402
from cdpr_control.ros.conversions import pose_to_msg  # noqa: E402
from cdpr_control.ros.sync import StampJumps, input_problem  # noqa: E402
from cdpr_control.model.robot import load_robot  # noqa: E402
from cdpr_test_nodes.graph import Collector, Spinner, wait_for  # noqa: E402
from cdpr_tools.launch import LaunchDescription, Launcher, NodeSpec  # noqa: E402

M = 8


@pytest.fixture(scope="module")
def robot():
    return load_robot("ipanema3_mini")


def test_a_raising_cdpr_callback_neither_ends_the_launch_nor_the_node():
    """Before: the launcher stopped every node of the composed graph on the first exception."""
    spinner = Spinner()
    try:
        collector = spinner.add(Collector, topics={"/diagnostics": DiagnosticArray, "/heard": Int32})
        poke = spinner.add(rclpy.node.Node, node_name="poker").create_publisher(Int32, "/failing_cdpr/poke", 10)
        launcher = Launcher(LaunchDescription(nodes=[NodeSpec(module="cdpr_test_nodes.failing_cdpr"),
                                                     NodeSpec(module="cdpr_test_nodes.talker"),
                                                     NodeSpec(module="cdpr_test_nodes.listener")]))
        with launcher:
            wait_for(lambda: poke.get_subscription_count() > 0, what="the failing node's subscription")
            poke.publish(Int32(data=7))
            messages = lambda: [s.message for a in collector.messages("/diagnostics") for s in a.status]  # noqa: E731
            wait_for(lambda: any("timer raised RuntimeError: boom" in m for m in messages()), what="the timer fault")
            wait_for(lambda: any("subscription failing_cdpr/poke raised ValueError: bad poke 7" in m
                                 for m in messages()), what="the subscription fault")
            failing = next(n for n in launcher.nodes if n.get_name() == "failing_cdpr")
            ticks = failing.ticks
            wait_for(lambda: failing.ticks >= ticks + 5, what="the failing timer to run on")
            heard = collector.count("/heard")
            wait_for(lambda: collector.count("/heard") >= heard + 3, what="the other nodes to run on")
            assert not launcher.wait(0) and launcher.errors == []
            assert failing.callback_errors >= 6
    finally:
        spinner.close()


def header(stamp_ns: int = 0, frame: str = "base") -> Header:
    return Header(stamp=Time(sec=stamp_ns // 1_000_000_000, nanosec=stamp_ns % 1_000_000_000), frame_id=frame)


@pytest.mark.parametrize("msg, words", [
    (JointState(position=[1.0] * 3), "3 values"),
    (JointState(position=[1.0] * M, effort=[math.nan] * M), "non-finite"),
    (CableForces(f=[10.0] * M, f_max=[40.0] * 5), "5 values"),
    (CableForces(f=[math.inf] + [10.0] * (M - 1)), "non-finite"),
    (ControllerState(output=[0.0] * 3), "3 values"),
    (ControllerState(output=[math.nan] * 6), "non-finite"),
    (PoseStamped(header=header(frame="map"), pose=pose_to_msg(np.zeros(6))), "frame_id 'map'"),
    (PoseStamped(header=header(), pose=pose_to_msg([0, 0, math.nan, 0, 0, 0])), "non-finite"),
    (OperationalSetpoint(header=header(), pose=Pose(orientation=Quaternion(w=0.0))), "zero quaternion"),
])
def test_invalid_messages_are_named(msg, words):
    assert words in input_problem(msg, M)


def test_valid_messages_pass():
    assert input_problem(JointState(position=[1.0] * M), M) is None
    assert input_problem(CableForces(f=[10.0] * M), M) is None
    assert input_problem(PoseStamped(header=header(frame=""), pose=pose_to_msg(np.zeros(6))), M) is None
    assert input_problem(OperationalSetpoint(header=header(), pose=pose_to_msg(np.zeros(6))), M) is None
    assert input_problem(ControllerState(output=[0.0] * 6), M, size=6) is None
    assert "need 8" in input_problem(ControllerState(output=[0.0] * 6), M, size=M)


def test_a_message_checked_for_one_subscriber_is_judged_alike_for_the_next():
    """In-process every subscriber gets the same object: its check is kept, per robot and output size."""
    state = ControllerState(output=[0.0] * 6)
    assert input_problem(state, M, size=6) is None
    assert "need 8" in input_problem(state, M, size=M)
    assert input_problem(state, M, size=6) is None
    forces = CableForces(f=[10.0] * M)
    assert input_problem(forces, M) is None
    assert "robot has 4 cables" in input_problem(forces, 4)    # another robot: checked again
    assert input_problem(forces, M) is None
    bad = JointState(position=[math.nan] * M)
    assert "non-finite" in input_problem(bad, M)
    assert "non-finite" in input_problem(bad, M)


def test_a_stamp_jump_is_refused_unless_the_stream_continues_from_it():
    period = 1_000_000
    jumps = StampJumps(50, 50 * period)
    assert jumps.check("s", 10 * period) is None
    assert "ahead" in jumps.check("s", 5000 * 1_000_000_000)        # one spoofed far stamp
    assert jumps.check("s", 11 * period) is None                    # the real stream goes on
    assert "older" in jumps.check("s", 2 * period)
    assert jumps.check("s", 12 * period) is None
    assert jumps.newest["s"] == 12 * period
    assert "ahead" in jumps.check("s", 900 * period)               # a restarted publisher ...
    assert jumps.check("s", 901 * period) is None                   # ... continues from there
    assert jumps.check("s", 950 * period, reference=lambda: 0) is None
    assert jumps.check("s", 2000 * period, reference=lambda: 1990 * period) is None   # the clock is there


def test_a_hold_brakes_on_the_path_without_a_step(robot):
    """CNC-style: the cable velocities scale down together at a_brake, then θ_d stands."""
    dt = 0.001
    jc = JointCommand(robot, dt, a_brake=5.0)
    q0 = inverse_kinematics(robot, robot.home).q
    jc.reset(q0)
    far = robot.home + np.array([0.3, 0.0, 0.0, 0.0, 0.0, 0.0])
    for _ in range(5):
        jc.update(far)
    v0 = jc.velocity.copy()
    assert np.abs(v0).max() > 0.5 * robot.drive.v_max
    held = [jc.update(None, hold=True) for _ in range(2000)]
    assert jc.held
    v = np.diff(np.vstack(held), axis=0) / dt
    speeds = np.abs(v).max(axis=1)
    assert np.all(np.diff(speeds) <= 1e-12) and speeds[-1] == 0.0          # braking, then standing
    np.testing.assert_allclose(np.abs(np.diff(speeds[:10])), 5.0 * dt, rtol=1e-6)   # at a_brake
    moving = speeds > 0
    ratio = v[moving] / np.linalg.norm(v[moving], axis=1, keepdims=True)
    np.testing.assert_allclose(ratio, np.broadcast_to(v0 / np.linalg.norm(v0), ratio.shape), atol=1e-9)  # on the path
    stop = np.abs(v0).max() ** 2 / (2 * 5.0)
    assert np.abs(held[-1] - held[0]).max() == pytest.approx(stop, rel=0.02)


def test_an_aborted_program_fails_with_its_reason():
    program = parse_gcode("G21 G90\nG1 X20 F600\nG1 X0\nM30")
    interp = Interpolator(program, dt=0.001)
    for _ in range(200):
        interp.step()
    assert interp.abort("joint_command holds: stale input")
    assert not interp.abort("again")                                    # the first reason stays
    states = {interp.step().state for _ in range(2000)}
    assert interp.state is ProgramState.FAILED and ProgramState.CANCELLED not in states
    assert interp.error == "line 2: joint_command holds: stale input"
    at_once = Interpolator(program, dt=0.001)
    at_once.step()
    assert at_once.abort("no winch/state", brake=False) and at_once.state is ProgramState.FAILED


def test_stamps_ahead_of_the_clock_are_refused_every_time():
    """Issue 28: a stream of the same far-future stamp passed for a restarted publisher (its second
    message "continued" from the first) and stopped the loop for good. Against a clock of its own
    (simulated time) nothing ahead of the clock by more than the limit is ever accepted; without a
    clock (None: /clock not running yet) the restart rule still applies."""
    period = 1_000_000
    jumps = StampJumps(50, 50 * period)
    clock = lambda: 12 * period                                     # noqa: E731
    assert jumps.check("s", 10 * period, clock=clock) is None
    for _ in range(5):                                              # 20 Hz of stamp.sec 5000
        assert "ahead of the clock" in jumps.check("s", 5000 * 1_000_000_000, clock=clock)
        assert jumps.check("s", jumps.newest["s"] + period, clock=clock) is None   # the real stream goes on
    assert jumps.newest["s"] == 15 * period
    assert jumps.check("s", 100 * period, clock=lambda: 80 * period) is None   # ahead of its stream, not of the clock
    assert "ahead" in jumps.check("s", 5000 * period, clock=lambda: None)
    assert jumps.check("s", 5001 * period, clock=lambda: None) is None   # no clock yet: a restarted publisher
    assert jumps.newest["s"] == 5001 * period


def test_a_stream_behind_the_clock_is_refused_and_a_restart_with_the_clock_is_taken():
    """A stamp behind its stream and more than the limit behind the simulated clock is a second,
    older stream: refused every time (the restart rule let every second one through). A simulator
    that restarts takes the clock back with it: then the restart rule applies as before."""
    period = 1_000_000
    jumps = StampJumps(50, 50 * period)
    clock = [400 * period]
    now = lambda: clock[0]                                          # noqa: E731
    assert jumps.check("s", 400 * period, clock=now) is None
    for k in range(1, 6):
        assert "behind the clock" in jumps.check("s", (100 + k) * period, clock=now)
        clock[0] = (400 + k) * period
        assert jumps.check("s", (400 + k) * period, clock=now) is None
    assert jumps.newest["s"] == 405 * period
    clock[0] = 3 * period                                           # the simulator restarted
    assert "older" in jumps.check("s", 2 * period, clock=now)
    assert jumps.check("s", 3 * period, clock=now) is None          # continues from there: taken
    assert jumps.newest["s"] == 3 * period
