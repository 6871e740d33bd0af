"""Stiffness (thesis 2.18)-(2.22) and eigenfrequencies (4.8): closed forms against finite
differences."""

import numpy as np
import pytest

from cdpr_control.model import cable
from cdpr_control.model.dynamics import mass_matrix
from cdpr_control.model.kinematics import inverse_kinematics, kardan_rate_matrix
from poses import random_poses
from cdpr_control.model.stiffness import (cable_stiffness, eigenfrequencies, geometric_stiffness,
    modal_frequencies, operational_stiffness)


def kardan_map(x):
    T = np.eye(6)
    T[3:, 3:] = kardan_rate_matrix(x[3:])
    return T


def rel_err(a, b):
    return np.max(np.abs(a - b)) / np.max(np.abs(b))


def central_difference(fun, x, h=1e-6):
    cols = []
    for k in range(6):
        e = np.zeros(6)
        e[k] = h
        cols.append((fun(x + e) - fun(x - e)) / (2 * h))
    return np.stack(cols, axis=-1)


@pytest.mark.parametrize("pulleys", [True, False])
def test_geometric_stiffness_matches_finite_differences(robot, pulleys):
    """K_g = -(dA^T/dx) f at constant f (2.22), 1e-6 relative."""
    rng = np.random.default_rng(10)
    for x in random_poses(robot, 5, rng):
        f = rng.uniform(robot.cable.f_min, robot.cable.f_max)
        K_g = geometric_stiffness(inverse_kinematics(robot, x, pulleys), f)
        fd = central_difference(lambda y: -inverse_kinematics(robot, y, pulleys).AT @ f, x)
        assert rel_err(K_g @ kardan_map(x), fd) < 1e-6


def test_operational_stiffness_matches_finite_differences(robot):
    """K_x = K_g + A^T K_l A: dw/dx of w = -A^T f(IK(x) - theta) with the elastic cables (2.17)."""
    rng = np.random.default_rng(11)
    for x in random_poses(robot, 5, rng):
        ik = inverse_kinematics(robot, x)
        l_t = cable.total_free_length(robot, ik.q)
        f = rng.uniform(robot.cable.f_min, robot.cable.f_max)
        theta = ik.q - cable.elongation_from_force(robot, f, l_t)  # winch lengths holding f at x

        def wrench(y):
            ik_y = inverse_kinematics(robot, y)
            return -ik_y.AT @ cable.force_from_elongation(robot, ik_y.q - theta, l_t)

        K_x = operational_stiffness(ik, f, cable.tangent_stiffness(robot, f, l_t))
        assert rel_err(K_x @ kardan_map(x), central_difference(wrench, x, h=1e-7)) < 1e-6


def test_cable_stiffness_is_symmetric_positive_semidefinite(robot):
    ik = inverse_kinematics(robot, robot.home)
    K_c = cable_stiffness(ik, np.full(robot.m, 1e5))
    np.testing.assert_allclose(K_c, K_c.T, atol=1e-9 * np.abs(K_c).max())
    assert np.linalg.eigvalsh(K_c).min() > 0.0  # 8 cables span all 6 DOF


def test_geometric_stiffness_of_translations_is_string_stiffness(robot):
    """Without pulleys the translational block of K_g is sum f_i (I - u_i u_i^T) / l_i."""
    ik = inverse_kinematics(robot, robot.home, pulleys=False)
    f = np.linspace(1.0, 2.0, robot.m)
    expected = sum(
        f[i] * (np.eye(3) - np.outer(ik.u[i], ik.u[i])) / ik.q[i] for i in range(robot.m)
    )
    np.testing.assert_allclose(geometric_stiffness(ik, f)[:3, :3], expected, rtol=1e-12, atol=1e-12)


def test_batch_stiffness_equals_single(robot):
    rng = np.random.default_rng(12)
    X = random_poses(robot, 3, rng)
    f = rng.uniform(robot.cable.f_min, robot.cable.f_max, (3, robot.m))
    K = operational_stiffness(inverse_kinematics(robot, X), f, np.full((3, robot.m), 1e4))
    for k in range(3):
        np.testing.assert_allclose(
            K[k],
            operational_stiffness(inverse_kinematics(robot, X[k]), f[k], np.full(robot.m, 1e4)),
            rtol=1e-13,
        )


def _oscillation_frequency(k, m, periods=4):
    """Frequency [Hz] of x'' = -(k / m) x from a time integration (symplectic Euler, 2000 steps
    per period) and its zero crossings: an independent route to (4.8)."""
    omega_guess = np.sqrt(k / m)
    dt = 2 * np.pi / omega_guess / 2000
    x, v, t, crossings = 1.0, 0.0, 0.0, []
    while len(crossings) < 2 * periods + 1:
        v -= k / m * x * dt
        x_new = x + v * dt
        if x > 0.0 >= x_new or x < 0.0 <= x_new:
            crossings.append(t + dt * x / (x - x_new))
        x, t = x_new, t + dt
    return periods / (crossings[-1] - crossings[0])


def test_eigenfrequency_is_4_8(robot):
    """(4.8) per axis against the oscillation of the mass on that axis' stiffness."""
    K_x = np.diag([4.0e5, 5.0e5, 6.0e5, 1.0e4, 2.0e4, 3.0e4])
    M = mass_matrix(robot, np.zeros(6))
    f = eigenfrequencies(K_x, M)
    for j in range(6):
        assert f[j] == pytest.approx(_oscillation_frequency(K_x[j, j], M[j, j]), rel=1e-5)
    # centre of gravity in the origin and a diagonal K_x: the modes are the axes
    if np.all(robot.platform.center_of_gravity == 0.0) and np.allclose(
        robot.platform.inertia, np.diag(np.diag(robot.platform.inertia))
    ):
        np.testing.assert_allclose(np.sort(f), modal_frequencies(K_x, M), rtol=1e-12)


def test_modal_frequencies_solve_the_eigenproblem(robot):
    ik = inverse_kinematics(robot, robot.home)
    f = np.full(robot.m, 0.5 * (robot.cable.f_min + robot.cable.f_max))
    l_t = cable.total_free_length(robot, ik.q)
    K_x = operational_stiffness(ik, f, cable.tangent_stiffness(robot, f, l_t))
    M = mass_matrix(robot, robot.home)
    w = 2 * np.pi * modal_frequencies(K_x, M)
    K_s = 0.5 * (K_x + K_x.T)
    for omega in w:
        assert abs(
            np.linalg.det(np.linalg.solve(M, K_s) - omega**2 * np.eye(6))
        ) < 1e-6 * np.prod(w**2)
