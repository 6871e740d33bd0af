"""ControlLoop computes the IK of the set-point x_d once a period, and not at all while x_d repeats
(docs/kernels.md, "One IK of x_d a period"; docs/performance.md, "Session 10").

Friction compensation (β), the estimator (q, A^T, c^T, β) and the force set-point (A^T) take the
fields of one packed IK (kernels.inverse_kinematics_fields), as their nodes do. Every IK of a pose
in Python goes through the compiled ``ik_packed`` (kernels.inverse_kinematics and the shared
packed IK); the test counts its calls per period on the Mini's parameter file (hybrid force
control idle, its CFC coupling passing f_d through), holding home and on a moving set-point.
"""
import numpy as np
import pytest

from cdpr_control import kernels
from cdpr_control.kernels import model as kernels_model
from cdpr_control.model.robot import load_robot
from cdpr_sim.closed_loop import hold, run

PERIODS = 40


@pytest.fixture
def ik_calls(monkeypatch):
    """Counts of ik_packed calls (both of its Python call sites), one entry per period from the
    second on (the first computes the loop's start-up and the simulator's initial state)."""
    if not kernels.ENABLED:
        pytest.skip("CDPR_KERNELS=0: the numpy reference has no packed IK to count")
    counts = [0]
    compiled = kernels_model.ik_packed

    def counted(*args):
        counts[-1] += 1
        return compiled(*args)
    monkeypatch.setattr(kernels_model, "ik_packed", counted)      # kernels.model.inverse_kinematics
    monkeypatch.setattr(kernels, "ik_packed", counted)            # kernels._packed (the fields)
    return counts


def _per_period(counts):
    def before_step(k, loop, sim):
        counts.append(0)                   # the calls of period k go into the new entry
    return before_step


def test_holding_computes_no_ik_of_x_d(ik_calls):
    robot = load_robot("ipanema3_mini")
    run(robot, hold(robot.home), PERIODS * 1e-3, before_step=_per_period(ik_calls))
    assert ik_calls[2:] == [0] * (PERIODS - 1), ik_calls


def test_a_moving_set_point_computes_one_ik_of_x_d_a_period(ik_calls):
    robot = load_robot("ipanema3_mini")
    home = robot.home

    def line(t):                           # 1 mm/s along x: a new x_d every period
        return home + np.array([1e-3 * t, 0.0, 0.0, 0.0, 0.0, 0.0]), np.r_[1e-3, np.zeros(5)], np.zeros(6)
    run(robot, line, PERIODS * 1e-3, before_step=_per_period(ik_calls))
    assert ik_calls[2:] == [1] * (PERIODS - 1), ik_calls


def test_robots_of_one_file_share_the_ik_of_x_d(ik_calls):
    """Each node of a composed graph loads its own robot object: robots of equal constants share one
    RobotData and so the period's IK of x_d (three nodes computed it three times a period while it
    was keyed on the robot object, session 24); a robot of other constants does not."""
    robots = [load_robot("ipanema3_mini") for _ in range(3)]
    assert robots[0] is not robots[1]
    assert kernels.robot_data(robots[0]) is kernels.robot_data(robots[1]) is kernels.robot_data(robots[2])
    x_d = robots[0].home + np.array([0.01, -0.02, 0.03, 0.0, 0.01, 0.0])
    kernels._packed_memo.clear()
    fields = [kernels.inverse_kinematics_fields(robot, x_d, "AT")[0] for robot in robots]
    assert ik_calls == [1]
    assert fields[0] is fields[1] is fields[2]
    with kernels.numpy_reference():
        np.testing.assert_allclose(fields[0], kernels.inverse_kinematics(robots[2], x_d).AT, rtol=0, atol=1e-12)
    other = load_robot("ipanema3")
    assert kernels.robot_data(other) is not kernels.robot_data(robots[0])
    kernels.inverse_kinematics_fields(other, other.home, "AT")
    kernels.inverse_kinematics_fields(robots[0], other.home, "AT")      # the same pose, another robot
    assert ik_calls == [3]
