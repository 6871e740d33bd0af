"""The per-period fast paths of the force distribution and joint command give the same numbers, bit for
bit, as the computation they replace: the compiled joint command period (kernels.model.joint_command_period), the model
wrench handed to ForceSetpoint, and the force distribution node against its stage, fed the set-point
as a message or as the interpreter's payload with x_d, ẋ_d, ẍ_d attached."""
import copy
import numpy as np
import pytest

from required import import_or_skip  # noqa: E402  (a missing rclpy fails in CI)
rclpy = import_or_skip("rclpy")
from cdpr_control import kernels  # noqa: E402
from cdpr_control.control.force_setpoint import ForceSetpoint, ForceSetpointParams  # noqa: E402
from cdpr_control.control.joint_command import JointCommand  # noqa: E402
from cdpr_control.kernels.model import joint_command_period  # noqa: E402
from cdpr_control.kernels.robot_data import robot_data  # noqa: E402
from cdpr_control.model.kinematics import inverse_kinematics  # noqa: E402
from cdpr_control.control.load_compensation import payload_wrench  # noqa: E402

DT = 1e-3


def same_bits(a, b) -> bool:
    """Equal bit for bit (-0.0 is not 0.0, a NaN equals the same NaN)."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    return a.shape == b.shape and np.array_equal(a.view(np.int64), b.view(np.int64))


def _poses(robot, n, rng, scale=0.03):
    return [robot.home + rng.uniform(-scale, scale, 6) * np.r_[1, 1, 1, 0.3, 0.3, 0.3] for _ in range(n)]


def test_joint_command_period_is_the_step_it_replaces(robot):  # noqa: F811
    """x_d + offset, model.joint_command_step, Δθ / dt and θ_d + Δθ: the same bits in one call."""
    rng = np.random.default_rng(3)
    d = robot_data(robot)
    m = robot.m
    for x_d in _poses(robot, 50, rng):
        offset = rng.uniform(-2e-3, 2e-3, 6)
        dq = rng.uniform(-1e-3, 1e-3, m)
        theta_d = inverse_kinematics(robot, x_d).q + rng.uniform(-5e-3, 5e-3, m)
        for step in (1e-4, 1.0):                          # rate-limited and free
            theta_next, velocity = np.empty(m), np.empty(m)
            assert joint_command_period(x_d, offset, d.a, d.b, d.R_A, d.r_p, d.pulleys, dq, theta_d, step, DT,
                                        theta_next, velocity)
            delta = kernels.joint_command_step(robot, x_d + offset, dq, theta_d, step)
            assert same_bits(velocity, delta / DT) and same_bits(theta_next, theta_d + delta)
    bad = np.full(6, np.nan)
    assert not joint_command_period(bad, np.zeros(6), d.a, d.b, d.R_A, d.r_p, d.pulleys, np.zeros(m),
                                    np.zeros(m), 1.0, DT, np.empty(m), np.empty(m))


def _step_reference(jc, x_d, offset, dq):
    """JointCommand.update's general path (model.joint_command_step), as before the compiled period."""
    delta = kernels.joint_command_step(jc.robot, x_d + offset, dq, jc.theta_d, jc.v_max * jc.dt)
    return jc.theta_d + delta, delta / jc.dt


@pytest.mark.skipif(not kernels.ENABLED, reason="CDPR_KERNELS=0: JointCommand runs the numpy reference")
def test_joint_command_update_with_one_offset_is_the_general_path(robot):  # noqa: F811
    rng = np.random.default_rng(4)
    jc = JointCommand(robot, DT)
    jc.reset(inverse_kinematics(robot, robot.home).q)
    for x_d in _poses(robot, 30, rng, scale=0.002):
        offset, dq = rng.uniform(-1e-3, 1e-3, 6), rng.uniform(-1e-4, 1e-4, robot.m)
        theta_ref, velocity_ref = _step_reference(jc, x_d, offset, dq)
        theta_d = jc.update(x_d, [offset], dq)
        assert same_bits(theta_d, theta_ref) and same_bits(jc.theta_d, theta_ref)
        assert same_bits(jc.velocity, velocity_ref) and not jc.held
        theta_d[:] = 0.0                                  # the caller's copy, not the state
        assert same_bits(jc.theta_d, theta_ref)
    velocity = jc.velocity.copy()
    jc.update(np.full(6, np.nan), [np.zeros(6)], np.zeros(robot.m))     # not finite: brakes on the path
    assert jc.held and np.all(np.abs(jc.velocity) <= np.abs(velocity))


def test_force_setpoint_with_the_loops_AT_equals_the_one_that_takes_its_own(robot):  # noqa: F811
    """ControlLoop hands the force set-point A^T (2.10) of its kernels.setpoint_ik; a node's stage
    takes A^T itself: the same results, bit for bit, where the IK of the set-point is computed
    afresh for the stage that takes its own, and the set-point moves, holds or flips a zero's sign.
    A^T of another pose handed over gives other forces: the stage uses what it is handed."""
    rng = np.random.default_rng(5)
    params = ForceSetpointParams(tension_level=0.2)
    a, b, c = (ForceSetpoint(robot, DT, params) for _ in range(3))
    weight = np.r_[robot.platform.mass * robot.gravity, 0, 0, 0]
    x_d, xdot_d, xddot_d = robot.home.copy(), np.zeros(6), np.zeros(6)
    other = kernels.setpoint_ik(robot, robot.home + np.array([0.05, 0.0, 0.02, 0.0, 0.0, 0.0])).AT.copy()
    for k in range(60):
        if k % 4 == 1:                                     # one value of the set-point changes
            v = (x_d, xdot_d, xddot_d)[k % 3].copy()
            v[k % 6] += rng.uniform(-1e-3, 1e-3)
            x_d, xdot_d, xddot_d = (v if i == k % 3 else u for i, u in enumerate((x_d, xdot_d, xddot_d)))
        if k % 9 == 8:
            xdot_d = np.where(xdot_d == 0.0, -xdot_d, xdot_d)     # -0.0 for 0.0: the same value
        w = -weight + rng.normal(0, 0.5, 6)
        w_model = payload_wrench(robot, x_d, xdot_d, xddot_d, 0.5)
        ra = a.update(x_d, xdot_d, xddot_d, w, w_model=w_model, AT=kernels.setpoint_ik(robot, x_d).AT)
        kernels._packed_memo.clear()                       # b: the IK of x_d computed afresh
        rb = b.update(x_d.copy(), xdot_d.copy(), xddot_d.copy(), w, w_model=w_model)
        assert same_bits(a.w_d, b.w_d) and same_bits(ra.f, rb.f), f"period {k}"
        assert (ra.status, ra.residual, ra.iterations) == (rb.status, rb.residual, rb.iterations)
        rc = c.update(x_d, xdot_d, xddot_d, w, w_model=w_model, AT=other)
        assert not np.allclose(rc.f, ra.f), f"period {k}"


# --- the node: its stage, the set-point as a message or the interpreter's payload -------------------

@pytest.fixture(scope="module")
def context():
    rclpy.init()
    yield
    rclpy.shutdown()


def _setpoint(x_d, xdot_d, xddot_d):
    from cdpr_msgs.msg import OperationalSetpoint
    from cdpr_control.ros.conversions import accel_to_msg, pose_to_msg, twist_to_msg
    return OperationalSetpoint(pose=pose_to_msg(x_d), velocity=twist_to_msg(xdot_d), acceleration=accel_to_msg(xddot_d))


def _signed_zero_pose(pose):
    """The pose with +0.0 in place of -0.0 and the other way round (the same value, other bits)."""
    for v in (pose.position, pose.orientation):
        for name in ("x", "y", "z") + (("w",) if hasattr(v, "w") else ()):
            if getattr(v, name) == 0.0:
                setattr(v, name, -getattr(v, name))
    return pose


def test_force_distribution_node_is_the_stage_period_by_period(context):
    """The node (the set-point a message, or in every other period the interpreter's payload with its
    attached values; the message built field by field) against the stage fed the message conversions
    every period: the same messages, bit for bit."""
    from cdpr_msgs.msg import ForceDistribution
    from geometry_msgs.msg import Inertia, InertiaStamped, WrenchStamped
    from rclpy.parameter import Parameter

    from cdpr_control.ros.adapted import attach_values, payload_of
    from cdpr_control.ros.conversions import (accel_from_msg, pose_from_msg, setpoint_values, twist_from_msg,
        wrench_from_msg, wrench_to_msg)
    from cdpr_control.nodes.force_distribution import ForceDistributionNode

    node = ForceDistributionNode(parameter_overrides=[Parameter("robot", value="ipanema3_mini"),
                                                      Parameter("payload_input", value=True)])
    try:
        robot = node.robot
        reference = ForceSetpoint(robot, node.dt, node.stage.params)
        out = []
        node.publisher.publish = out.append
        rng = np.random.default_rng(6)
        weight = np.r_[robot.platform.mass * robot.gravity, 0, 0, 0]
        x_d, xdot_d, xddot_d = robot.home.copy(), np.zeros(6), np.zeros(6)
        mass = 0.0
        for k in range(60):
            if k % 7 == 3:                                 # the set-point moves now and then
                x_d = x_d + rng.uniform(-1e-3, 1e-3, 6) * np.r_[1, 1, 1, 0.1, 0.1, 0.1]
                xdot_d, xddot_d = rng.uniform(-0.05, 0.05, 6), rng.uniform(-0.5, 0.5, 6)
            if k % 5 == 0:                                 # the payload estimate now and then
                mass = float(rng.uniform(0.0, 0.3))
            sp = _setpoint(x_d, xdot_d, xddot_d)
            if k % 11 == 10:
                _signed_zero_pose(sp.pose)
            w = -weight + rng.normal(0, 0.3, 6)
            published = payload_of(sp)
            attach_values(published, setpoint_values(sp.pose, sp.velocity, sp.acceleration))
            msgs = {"setpoint": published if k % 2 else sp, "wrench": WrenchStamped(wrench=wrench_to_msg(w))}
            if k not in (17, 31):       # (an optional input: missing while the set-point moves, back unchanged)
                msgs["payload"] = InertiaStamped(inertia=Inertia(m=mass))
            node._cycle(msgs, k * 1_000_000)
            px, pv, pa = pose_from_msg(sp.pose), twist_from_msg(sp.velocity), accel_from_msg(sp.acceleration)
            w_model = payload_wrench(robot, px, pv, pa, mass, (0.0, 0.0, 0.0)) if "payload" in msgs else None
            res = reference.update(px, pv, pa, wrench_from_msg(msgs["wrench"].wrench), w_model=w_model)
            expected = ForceDistribution(
                header=node.header(k * 1_000_000), f_d=res.f.tolist(), f_ref=res.f_ref.tolist(),
                f_min=res.f_min.tolist(), f_max=res.f_max.tolist(), w_d=wrench_to_msg(reference.w_d),
                method=res.method, status=int(res.status), max_violation=float(res.max_violation),
                residual=float(res.residual), iterations=int(res.iterations), solve_time=0.0)
            # the published payload's message (or the message: CDPR_TYPE_ADAPT=0), a copy of it
            got = copy.deepcopy(out[-1].to_msg() if hasattr(out[-1], "to_msg") else out[-1])
            got.solve_time = 0.0                           # (a wall-clock measurement)
            assert repr(got) == repr(expected), f"period {k}"
            assert got == expected
    finally:
        node.destroy_node()
