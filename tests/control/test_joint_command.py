"""Joint command (5.10) with rate limit and hold, and the safety monitor."""
import numpy as np
import pytest

from cdpr_control.control.joint_command import JointCommand
from cdpr_control.model.kinematics import inverse_kinematics
from cdpr_control.model.robot import load_robot
from cdpr_control.control.safety import (FK_NOT_CONVERGED, FORCE_LIMIT, NON_FINITE, POSITION_LAG, STALE_INPUT,
    SafetyConfig, SafetyMonitor)


@pytest.fixture(scope="module")
def robot():
    return load_robot("ipanema3_mini")


def test_command_is_ik_of_offset_setpoint_minus_dq_cfc(robot):
    jc = JointCommand(robot, dt=0.001, v_max=1e9)
    x_d = np.array([0.05, -0.02, 0.03, 0.01, 0.0, -0.02])
    x_ospc = np.array([0.001, 0.0, -0.002, 0.0, 0.001, 0.0])
    dq = np.linspace(-1e-3, 1e-3, robot.m)
    jc.reset(inverse_kinematics(robot, x_d).q)
    theta_d = jc.update(x_d, [x_ospc], dq)
    np.testing.assert_allclose(theta_d, inverse_kinematics(robot, x_d + x_ospc).q - dq, atol=1e-15)


def test_rate_limit_and_no_jump(robot):
    jc = JointCommand(robot, dt=0.001)
    q0 = inverse_kinematics(robot, robot.home).q
    jc.reset(q0)
    far = robot.home + np.array([0.1, 0, 0, 0, 0, 0])
    steps = [jc.update(far) for _ in range(3)]
    diffs = np.abs(np.diff(np.vstack([q0] + steps), axis=0))
    assert np.all(diffs <= robot.drive.v_max * 0.001 + 1e-15)
    assert np.any(diffs > 0.5 * robot.drive.v_max * 0.001)


def test_hold_and_nan_keep_last_command(robot):
    jc = JointCommand(robot, dt=0.001)
    q0 = inverse_kinematics(robot, robot.home).q
    jc.reset(q0)
    held = jc.update(robot.home + 0.01, hold=True)
    np.testing.assert_array_equal(held, q0)
    assert jc.held
    nan_pose = np.full(6, np.nan)
    out = jc.update(nan_pose)
    assert jc.held and np.all(np.isfinite(out))
    np.testing.assert_array_equal(out, q0)
    # outside the geometric model: anchor 1 inside the circle of its pulley, the IK is not finite
    inside = np.r_[robot.a[0] - robot.b[0] + np.array([-0.02, -0.006, 0.0]), 0.0, 0.0, 0.0]
    with np.errstate(invalid="ignore", divide="ignore"):
        assert not np.all(np.isfinite(inverse_kinematics(robot, inside).q))
        out = jc.update(inside)
    assert jc.held
    np.testing.assert_array_equal(out, q0)


def test_far_valid_pose_is_approached_at_v_max_not_held(robot):
    """A pose far outside the frame still has a finite IK: the command is not held but moves at the
    drives' v_max (the safety monitor's position-lag fault is what stops a runaway set-point)."""
    jc = JointCommand(robot, dt=0.001)
    q0 = inverse_kinematics(robot, robot.home).q
    jc.reset(q0)
    far = np.array([10.0, 10.0, 10.0, 0, 0, 0])
    target = inverse_kinematics(robot, far).q
    out = jc.update(far)
    assert not jc.held
    np.testing.assert_allclose(np.abs(out - q0), robot.drive.v_max * 0.001, rtol=1e-12)
    assert np.all(np.sign(out - q0) == np.sign(target - q0))


def test_reset_rejects_bad_lengths(robot):
    with pytest.raises(ValueError):
        JointCommand(robot, 0.001).reset(np.full(robot.m, np.nan))


def test_safety_monitor_reports_each_fault():
    mon = SafetyMonitor(SafetyConfig(force_tolerance=1.0, max_position_lag=0.01, stale_timeout=0.05))
    f_min, f_max = np.full(3, 10.0), np.full(3, 100.0)
    ok = mon.check(1.0, f=np.array([20.0, 50.0, 99.0]), f_min=f_min, f_max=f_max,
                   x_d=np.zeros(6), x=np.full(6, 1e-4), input_times={"f": 0.99})
    assert ok == []
    faults = mon.check(1.0, f=np.array([5.0, 50.0, 120.0]), f_min=f_min, f_max=f_max,
                       x_d=np.zeros(6), x=np.array([0.02, 0, 0, 0, 0, 0]), fk_converged=False,
                       input_times={"theta": 0.9})
    codes = [f.code for f in faults]
    assert codes.count(FORCE_LIMIT) == 2 and POSITION_LAG in codes and FK_NOT_CONVERGED in codes and STALE_INPUT in codes
    assert "cable 1" in faults[0].message and "cable 3" in faults[1].message
    assert not any(f.holds for f in faults if f.code == FORCE_LIMIT)   # report-only by default
    nan = mon.check(0.0, f=np.array([np.nan, 1.0, 1.0]), f_min=f_min, f_max=f_max)
    assert nan[0].code == NON_FINITE and nan[0].holds


def test_start_ramp_follows_a_cosine_from_the_measured_lengths(robot):
    """reset(θ_0, ramp_time): θ_d = θ_0 + s (target - θ_0), s = (1 - cos(π k / n)) / 2, then the target."""
    dt, ramp = 0.001, 0.05
    jc = JointCommand(robot, dt=dt, v_max=1e9)
    target = inverse_kinematics(robot, robot.home).q
    theta_0 = target + np.linspace(-2e-3, 2e-3, robot.m)     # the plant's lengths at power-on
    jc.reset(theta_0, ramp)
    n = int(round(ramp / dt))
    for k in range(1, n):
        assert jc.starting
        s = 0.5 - 0.5 * np.cos(np.pi * k / n)
        np.testing.assert_allclose(jc.update(robot.home), theta_0 + s * (target - theta_0), atol=1e-14)
    np.testing.assert_allclose(jc.update(robot.home), target, atol=1e-14)
    assert not jc.starting


def test_start_ramp_steps_are_smooth_and_rate_limited(robot):
    """No period of the ramp moves a cable by more than the ramp's peak slope, π/2 |gap| / n, nor
    by more than v_max dt; without a ramp the same gap is closed in one period."""
    dt, ramp = 0.001, 0.5
    target = inverse_kinematics(robot, robot.home).q
    gap = np.linspace(-1e-3, 1e-3, robot.m)
    jc = JointCommand(robot, dt=dt)
    jc.reset(target + gap, ramp)
    theta = [target + gap] + [jc.update(robot.home) for _ in range(int(ramp / dt) + 5)]
    steps = np.abs(np.diff(np.array(theta), axis=0))
    assert steps.max() <= np.pi / 2 * np.abs(gap).max() / (ramp / dt) * (1 + 1e-9)
    assert steps.max() <= robot.drive.v_max * dt + 1e-15
    np.testing.assert_allclose(theta[-1], target, atol=1e-14)
    unramped = JointCommand(robot, dt=dt, v_max=1e9)
    unramped.reset(target + gap)
    np.testing.assert_allclose(unramped.update(robot.home), target, atol=1e-14)


def test_hold_during_the_start_ramp_brakes_and_bad_ramp_is_refused(robot):
    jc = JointCommand(robot, dt=0.001)
    q0 = inverse_kinematics(robot, robot.home).q
    jc.reset(q0 + 1e-3, 0.2)
    jc.update(robot.home)
    held = jc.update(robot.home, hold=True)
    assert jc.held and np.all(np.isfinite(held))
    for bad in (-0.1, np.nan, np.inf):
        with pytest.raises(ValueError, match="ramp_time"):
            jc.reset(q0, bad)
