"""Cable model of the simulator against the model core (cdpr_control kinematics and cable)."""
import numpy as np
import pytest

from cdpr_control.model import cable
from cdpr_control.model.kinematics import inverse_kinematics, rotation_matrix
from cdpr_control.model.robot import load_robot
from cdpr_sim.cables import CableModel
from cdpr_sim.platform import kardan_angles, principal_axes

ROBOTS = ["ipanema3", "ipanema3_mini"]


def _random_pose(robot, rng, spread=0.3):
    span = robot.workspace_max - robot.workspace_min
    x = np.empty(6)
    x[:3] = robot.home[:3] + rng.uniform(-spread, spread, 3) * span / 2
    x[3:] = rng.uniform(-0.1, 0.1, 3)
    return x


@pytest.mark.parametrize("name", ROBOTS)
def test_forces_and_wrench_equal_the_model_core(name):
    """f = (2.17) of dq = IK{x} - theta over l_t = q + l_0, and the wrench on the platform is A^T f."""
    robot = load_robot(name)
    model = CableModel(robot, damping_time=0.0)
    rng = np.random.default_rng(0)
    for _ in range(10):
        x = _random_pose(robot, rng)
        ik = inverse_kinematics(robot, x)
        l_t = cable.total_free_length(robot, ik.q)
        f_true = rng.uniform(0.0, 1.5, robot.m) * robot.cable.f_max
        theta = ik.q - cable.elongation_from_force(robot, f_true, l_t)
        model.refresh(x)
        f, F, T, anchors = model.wrench(x[:3], rotation_matrix(x[3:]), np.zeros(3), np.zeros(3), theta, np.zeros(robot.m))
        np.testing.assert_allclose(f, cable.force_from_elongation(robot, ik.q - theta, l_t),
                                   rtol=1e-7, atol=2e-8 * robot.cable.f_max[0])
        np.testing.assert_allclose(np.r_[F, T], ik.AT @ f, rtol=1e-12, atol=1e-9)
        np.testing.assert_allclose(anchors, ik.Rb + x[:3], atol=1e-15)


@pytest.mark.parametrize("name", ROBOTS)
def test_frozen_pulleys_stay_close_within_the_refresh_distance(name):
    robot = load_robot(name)
    model = CableModel(robot, damping_time=0.0)
    x0 = robot.home.copy()
    model.refresh(x0)
    ik0 = inverse_kinematics(robot, x0)
    theta = ik0.q - 0.002 * cable.total_free_length(robot, ik0.q) * robot.cable.f_max[0] / robot.cable.k0
    x = x0 + np.array([3e-3, -3e-3, 2e-3, 0.0, 0.0, 0.0])          # 4.7 mm < refresh distance
    ik = inverse_kinematics(robot, x)
    f, *_ = model.wrench(x[:3], rotation_matrix(x[3:]), np.zeros(3), np.zeros(3), theta, np.zeros(robot.m))
    f_full = cable.force_from_elongation(robot, ik.q - theta, cable.total_free_length(robot, ik.q))
    assert np.max(np.abs(f - f_full)) < 1e-3 * robot.cable.f_min[0]
    assert not model.needs_refresh()
    x[0] += 2e-3                                                      # now 5.8 mm
    model.wrench(x[:3], rotation_matrix(x[3:]), np.zeros(3), np.zeros(3), theta, np.zeros(robot.m))
    assert model.needs_refresh()


def test_slack_cables_pull_nothing_and_no_cable_pushes():
    robot = load_robot("ipanema3_mini")
    model = CableModel(robot, damping_time=0.01)
    x = robot.home.copy()
    model.refresh(x)
    q = inverse_kinematics(robot, x).q
    theta = q - 1e-3
    theta[:2] = q[:2] + 1e-4                                        # longer than the path: slack
    thetadot = np.zeros(robot.m)
    thetadot[2] = 50.0                                              # paying out fast: damping < spring
    f, F, T, _ = model.wrench(x[:3], np.eye(3), np.zeros(3), np.zeros(3), theta, thetadot)
    assert f[0] == f[1] == 0.0
    assert f[2] == 0.0 and np.all(f[3:] > 0.0)


def test_damping_force_follows_the_elongation_rate():
    """Kelvin-Voigt: d f = tau k_t / l_t (q_dot - theta_dot) with q_dot = -A xdot (2.12)."""
    robot = load_robot("ipanema3")
    tau = 0.003
    model = CableModel(robot, damping_time=tau)
    x = robot.home.copy()
    model.refresh(x)
    ik = inverse_kinematics(robot, x)
    l_t = cable.total_free_length(robot, ik.q)
    theta = ik.q - cable.elongation_from_force(robot, np.full(robot.m, 800.0), l_t)
    xdot = np.array([0.01, -0.02, 0.03, 0.02, -0.01, 0.03])
    thetadot = np.linspace(-0.01, 0.01, robot.m)
    f0, *_ = model.wrench(x[:3], np.eye(3), np.zeros(3), np.zeros(3), theta, np.zeros(robot.m))
    f0 = f0.copy()
    f1, *_ = model.wrench(x[:3], np.eye(3), xdot[:3], xdot[3:], theta, thetadot)
    qdot = -ik.AT.T @ xdot
    k_t = cable.tangent_stiffness(robot, f0, l_t)
    np.testing.assert_allclose(f1 - f0, tau * k_t * (qdot - thetadot), rtol=1e-5)


def test_kardan_angles_invert_the_rotation_matrix():
    rng = np.random.default_rng(4)
    for phi in rng.uniform(-1.4, 1.4, (50, 3)):
        np.testing.assert_allclose(kardan_angles(rotation_matrix(phi)), phi, atol=1e-12)


def test_principal_axes_diagonalise_the_inertia():
    J = np.array([[2.0, 0.3, -0.1], [0.3, 1.0, 0.2], [-0.1, 0.2, 1.5]])
    moments, V = principal_axes(J)
    np.testing.assert_allclose(V @ np.diag(moments) @ V.T, J, atol=1e-14)
    assert np.linalg.det(V) == pytest.approx(1.0)
    moments, V = principal_axes(np.diag([3.0, 1.0, 2.0]))
    np.testing.assert_array_equal(V, np.eye(3))
    np.testing.assert_array_equal(moments, [3.0, 1.0, 2.0])
