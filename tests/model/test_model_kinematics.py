"""Kinematics (thesis 2.1.1): Kardan rotation, pulley kinematics (2.3)-(2.9), IK (2.2)/(2.7),
structure matrix (2.10), its derivative and the maps (2.12)/(2.13), checked against finite
differences and an independent construction of the pulley leave point."""

import numpy as np
import pytest
from scipy.optimize import brentq

from cdpr_control.model.kinematics import (cable_accelerations, cable_velocities, inverse_kinematics,
    kardan_rate_matrix, pulley_frames, rotation_matrix, skew, structure_matrix_derivative,
    twist_from_pose_rates)
from poses import random_poses


def rel_err(a, b):
    return np.max(np.abs(a - b)) / np.max(np.abs(b))


def test_rotation_is_rx_ry_rz():
    a, b, c = 0.3, -0.7, 1.1
    Rx = np.array([[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]])
    Ry = np.array([[np.cos(b), 0, np.sin(b)], [0, 1, 0], [-np.sin(b), 0, np.cos(b)]])
    Rz = np.array([[np.cos(c), -np.sin(c), 0], [np.sin(c), np.cos(c), 0], [0, 0, 1]])
    np.testing.assert_allclose(rotation_matrix([a, b, c]), Rx @ Ry @ Rz, atol=1e-15)


def test_kardan_rate_matrix_gives_angular_velocity():
    rng = np.random.default_rng(1)
    phi, dphi, h = rng.uniform(-1, 1, 3), rng.normal(size=3), 1e-6
    R_dot = (rotation_matrix(phi + h * dphi) - rotation_matrix(phi - h * dphi)) / (2 * h)
    W = R_dot @ rotation_matrix(phi).T
    omega = np.array([W[2, 1], W[0, 2], W[1, 0]])
    np.testing.assert_allclose(kardan_rate_matrix(phi) @ dphi, omega, rtol=1e-8)


def test_twist_derivative_matches_finite_differences():
    rng = np.random.default_rng(2)
    x, dx, ddx, h = rng.uniform(-1, 1, 6), rng.normal(size=6), rng.normal(size=6), 1e-5
    _, xddot = twist_from_pose_rates(x, dx, ddx)

    def twist(t):
        return twist_from_pose_rates(x + dx * t + ddx * t * t / 2, dx + ddx * t)[0]

    np.testing.assert_allclose(xddot, (twist(h) - twist(-h)) / (2 * h), rtol=1e-8)
    # the same through the batched (numpy) path, which one pose skips for scalar math
    batched = twist_from_pose_rates(x[None], dx[None], ddx[None])
    np.testing.assert_allclose(twist_from_pose_rates(x, dx, ddx)[0], batched[0][0], atol=1e-14)
    np.testing.assert_allclose(xddot, batched[1][0], atol=1e-14)
    np.testing.assert_allclose(twist(h), twist_from_pose_rates((x + dx * h + ddx * h * h / 2)[None],
                                                               (dx + ddx * h)[None])[0][0], atol=1e-14)


@pytest.mark.parametrize("pulleys", [True, False])
def test_structure_matrix_is_minus_jacobian_of_cable_lengths(robot, pulleys):
    """dq = -A [dr; H dphi] (2.12): A^T against central differences of q, 1e-6 relative."""
    rng = np.random.default_rng(3)
    h = 1e-6
    for x in random_poses(robot, 5, rng):
        ik = inverse_kinematics(robot, x, pulleys)
        T = np.eye(6)
        T[3:, 3:] = kardan_rate_matrix(x[3:])
        J = np.empty((robot.m, 6))
        for k in range(6):
            e = np.zeros(6)
            e[k] = h
            J[:, k] = (
                inverse_kinematics(robot, x + e, pulleys).q
                - inverse_kinematics(robot, x - e, pulleys).q
            ) / (2 * h)
        assert rel_err(-ik.AT.T @ T, J) < 1e-6


@pytest.mark.parametrize("pulleys", [True, False])
def test_structure_matrix_derivative_matches_finite_differences(robot, pulleys):
    rng = np.random.default_rng(4)
    h = 1e-6
    for x in random_poses(robot, 5, rng):
        dx = rng.normal(size=6)
        xdot, _ = twist_from_pose_rates(x, dx)
        ATdot = structure_matrix_derivative(inverse_kinematics(robot, x, pulleys), xdot)
        fd = (
            inverse_kinematics(robot, x + h * dx, pulleys).AT
            - inverse_kinematics(robot, x - h * dx, pulleys).AT
        ) / (2 * h)
        assert rel_err(ATdot, fd) < 1e-6


def test_velocity_and_acceleration_maps(robot):
    """q_dot = -A xdot (2.12) and q_ddot = -A xddot - A_dot xdot (2.13) along a pose trajectory."""
    rng = np.random.default_rng(5)
    x0 = random_poses(robot, 1, rng)[0]
    dx, ddx, h = rng.normal(size=6) * 0.5, rng.normal(size=6), 1e-3
    q = [inverse_kinematics(robot, x0 + dx * t + ddx * t * t / 2).q for t in (-h, 0.0, h)]
    ik = inverse_kinematics(robot, x0)
    xdot, xddot = twist_from_pose_rates(x0, dx, ddx)
    assert rel_err(cable_velocities(ik, xdot), (q[2] - q[0]) / (2 * h)) < 1e-6
    assert rel_err(cable_accelerations(ik, xdot, xddot), (q[2] - 2 * q[1] + q[0]) / h**2) < 1e-5


def test_batch_equals_single_poses(robot):
    rng = np.random.default_rng(6)
    X = random_poses(robot, 7, rng)
    batch = inverse_kinematics(robot, X)
    assert batch.q.shape == (7, robot.m) and batch.AT.shape == (7, 6, robot.m)
    for k, x in enumerate(X):
        single = inverse_kinematics(robot, x)
        for name in ("q", "u", "AT", "c", "beta", "gamma", "l_f", "n", "kappa"):
            np.testing.assert_allclose(
                getattr(batch, name)[k], getattr(single, name), rtol=0, atol=1e-14
            )
    grid = inverse_kinematics(robot, X.reshape(7, 1, 6))
    assert grid.q.shape == (7, 1, robot.m)


def test_without_pulleys_q_is_distance_to_anchor(robot):
    x = np.array([0.01, -0.02, 0.03, 0.05, -0.04, 0.1])
    ik = inverse_kinematics(robot, x, pulleys=False)
    B = x[:3] + robot.b @ rotation_matrix(x[3:]).T
    np.testing.assert_allclose(ik.q, np.linalg.norm(robot.a - B, axis=1), rtol=1e-15)
    assert np.all(ik.beta == 0.0)


def _first_root(fun, lo, hi, n=181):
    """Smallest root of fun in [lo, hi]: first sign change on a grid, polished by brentq."""
    grid = np.linspace(lo, hi, n)
    values = np.array([fun(t) for t in grid])
    k = np.flatnonzero(np.sign(values[:-1]) != np.sign(values[1:]))[0]
    return brentq(fun, grid[k], grid[k + 1], xtol=1e-15, rtol=1e-15)


def _numerical_leave_point(a, R_A, r_p, B):
    """Shortest taut cable from the pulley entry A around the swivelling pulley to B, built
    numerically without (2.4)-(2.8): the pulley turns about its z-axis until B lies in its plane
    (on the side of the pulley centre); the wrap length r_p beta grows with beta, so the shortest
    path that does not cut into the pulley leaves at the first beta where the straight cable
    stops pointing into the pulley, (B - C) . (C - M) = 0."""
    z, d = R_A[:, 2], B - a

    def x_axis(gamma):
        return R_A @ np.array([np.cos(gamma), np.sin(gamma), 0.0])

    def in_plane(gamma):
        return np.cross(z, x_axis(gamma)) @ d

    gamma = _first_root(in_plane, -np.pi, np.pi)
    if x_axis(gamma) @ d < 0:  # the other root is the side where B is
        gamma = _first_root(in_plane, gamma + 1e-6, gamma + np.pi + 1e-6)
    x_g = x_axis(gamma)
    M = a + r_p * x_g

    def circle(beta):
        return M + r_p * (-np.cos(beta) * x_g + np.sin(beta) * z)

    beta = _first_root(lambda b: (B - circle(b)) @ (circle(b) - M), 0.0, np.pi)
    C = circle(beta)
    return C, beta, r_p * beta + np.linalg.norm(B - C)


def test_leave_point_and_wrap_angle_match_numerical_construction(robot):
    """c_i (2.8), beta (2.6) and q (2.7) against the shortest path around the pulley: 1e-9 m."""
    rng = np.random.default_rng(7)
    R_A = pulley_frames(robot)
    for x in random_poses(robot, 3, rng):
        ik = inverse_kinematics(robot, x, pulleys=True)
        B = x[:3] + robot.b @ rotation_matrix(x[3:]).T
        for i in range(robot.m):
            C, beta, q = _numerical_leave_point(robot.a[i], R_A[i], robot.r_p[i], B[i])
            assert np.linalg.norm(ik.c[i] - C) < 1e-9
            assert abs(ik.beta[i] - beta) * robot.r_p[i] < 1e-9
            assert abs(ik.q[i] - q) < 1e-9


def test_cable_leaves_pulley_tangentially(robot):
    x = np.array([0.05, 0.02, 0.1, 0.1, -0.05, 0.2])
    ik = inverse_kinematics(robot, x)
    R_A = pulley_frames(robot)
    gamma = ik.gamma
    M = robot.a + robot.r_p[:, None] * np.einsum(
        "mij,mj->mi", R_A, np.stack([np.cos(gamma), np.sin(gamma), 0 * gamma], 1)
    )
    np.testing.assert_allclose(np.linalg.norm(ik.c - M, axis=1), robot.r_p, rtol=1e-12)
    np.testing.assert_allclose(np.einsum("mi,mi->m", ik.c - M, ik.u), 0.0, atol=1e-12)
    np.testing.assert_allclose(np.einsum("mi,mi->m", ik.n, ik.u), 0.0, atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(ik.l, axis=1), ik.l_f, rtol=1e-12)


def test_skew_is_cross_product():
    v, w = np.array([1.0, -2.0, 0.5]), np.array([0.3, 0.2, -4.0])
    np.testing.assert_allclose(skew(v) @ w, np.cross(v, w))


def test_pulley_frames_follow_the_robot_geometry(robot):
    """The cached pulley frames belong to the geometry, not to the first robot object seen."""
    from dataclasses import replace

    x = robot.home + 0.01
    turned = replace(robot, pulley_orientation=robot.pulley_orientation + np.array([0.0, 0.0, 0.3]))
    np.testing.assert_allclose(pulley_frames(turned), rotation_matrix(turned.pulley_orientation))
    # turning a pulley frame about its own z-axis moves gamma but not the cable
    np.testing.assert_allclose(inverse_kinematics(turned, x).q, inverse_kinematics(robot, x).q)
    np.testing.assert_allclose(
        inverse_kinematics(turned, x).gamma,
        np.angle(np.exp(1j * (inverse_kinematics(robot, x).gamma - 0.3))),
    )
    tilted = replace(robot, pulley_orientation=robot.pulley_orientation + np.array([0.2, 0.0, 0.0]))
    assert np.max(np.abs(inverse_kinematics(tilted, x).q - inverse_kinematics(robot, x).q)) > 1e-4
