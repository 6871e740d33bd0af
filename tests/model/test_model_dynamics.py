"""Platform dynamics (thesis 2.33) and the gravity wrench, checked against a cloud of point masses
with the same mass, centre of gravity and inertia, and against the closed form (4.3)."""

from dataclasses import replace

import numpy as np
import pytest

from cdpr_control.model.dynamics import dynamic_wrench, gravity_wrench, mass_matrix, platform_wrench
from cdpr_control.model.kinematics import rotation_matrix
from cdpr_control.model.robot import load_robot


@pytest.fixture(scope="module")
def robot():
    """IPAnema 3 with an offset centre of gravity and a full inertia tensor."""
    r = load_robot("ipanema3")
    rng = np.random.default_rng(20)
    Q = np.linalg.qr(rng.normal(size=(3, 3)))[0]
    inertia = Q @ np.diag([4.0, 3.0, 2.0]) @ Q.T
    platform = replace(r.platform, center_of_gravity=np.array([0.05, -0.1, 0.2]), inertia=inertia)
    return replace(r, platform=platform)


def point_masses(platform):
    """Seven point masses (platform frame) with the platform's mass, centre of gravity, inertia."""
    J = platform.inertia
    E = 0.5 * np.trace(J) * np.eye(3) - J  # second moment about the centre of gravity
    e, V = np.linalg.eigh(E)
    mu = platform.mass / 10.0
    points, masses = [platform.center_of_gravity], [platform.mass - 6 * mu]
    for k in range(3):
        s = np.sqrt(e[k] / (2 * mu))
        for sign in (1, -1):
            points.append(platform.center_of_gravity + sign * s * V[:, k])
            masses.append(mu)
    return np.array(points), np.array(masses)


def test_dynamic_wrench_equals_point_mass_newton_euler(robot):
    rng = np.random.default_rng(21)
    points, masses = point_masses(robot.platform)
    for _ in range(5):
        x = np.r_[rng.normal(size=3), rng.uniform(-0.5, 0.5, 3)]
        xdot, xddot = rng.normal(size=6), rng.normal(size=6)
        s = points @ rotation_matrix(x[3:]).T  # body points in the base frame
        w, w_dot = xdot[3:], xddot[3:]
        acc = xddot[:3] + np.cross(w_dot, s) + np.cross(w, np.cross(w, s))
        F = (masses[:, None] * acc).sum(0)
        tau = (np.cross(s, masses[:, None] * acc)).sum(0)
        np.testing.assert_allclose(
            dynamic_wrench(robot, x, xdot, xddot), np.r_[F, tau], rtol=1e-10, atol=1e-10
        )


def test_mass_matrix_is_symmetric_positive_definite(robot):
    M = mass_matrix(robot, np.array([0, 0, 0, 0.3, -0.2, 0.1]))
    np.testing.assert_allclose(M, M.T, atol=1e-12)
    assert np.linalg.eigvalsh(M).min() > 0


def test_circle_wrench_is_4_3():
    """Translational circle of the load identification, (4.2)-(4.3)."""
    r = load_robot("ipanema3")
    c = np.array([0.01, -0.02, 0.3])
    r = replace(r, platform=replace(r.platform, center_of_gravity=c))
    r_c, w_c, th = 0.5, np.pi, 0.7
    xddot = np.r_[-r_c * w_c**2 * np.array([np.cos(th), np.sin(th), 0.0]), np.zeros(3)]
    m = r.platform.mass
    expected = (
        m
        * r_c
        * w_c**2
        * np.array(
            [
                -np.cos(th),
                -np.sin(th),
                0.0,
                c[2] * np.sin(th),
                -c[2] * np.cos(th),
                c[1] * np.cos(th) - c[0] * np.sin(th),
            ]
        )
    )
    np.testing.assert_allclose(
        dynamic_wrench(r, np.zeros(6), np.zeros(6), xddot), expected, atol=1e-12
    )


def test_gravity_wrench_and_platform_wrench(robot):
    x = np.array([0.1, 0.2, 0.3, 0.2, -0.1, 0.4])
    p = robot.platform
    w = gravity_wrench(robot, x)
    F = p.mass * robot.gravity
    np.testing.assert_allclose(
        w, np.r_[F, np.cross(rotation_matrix(x[3:]) @ p.center_of_gravity, F)]
    )
    np.testing.assert_allclose(platform_wrench(robot, x), w)
    xdot, xddot = np.ones(6), -np.ones(6)
    np.testing.assert_allclose(
        platform_wrench(robot, x, xdot, xddot), w - dynamic_wrench(robot, x, xdot, xddot)
    )


def test_batch_dynamics(robot):
    rng = np.random.default_rng(22)
    X, V, A = rng.normal(size=(4, 6)), rng.normal(size=(4, 6)), rng.normal(size=(4, 6))
    batch = dynamic_wrench(robot, X, V, A)
    for k in range(4):
        np.testing.assert_allclose(batch[k], dynamic_wrench(robot, X[k], V[k], A[k]), rtol=1e-13)
    assert gravity_wrench(robot, X).shape == (4, 6) and mass_matrix(robot, X).shape == (4, 6, 6)
