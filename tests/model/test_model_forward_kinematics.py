"""Forward kinematics (thesis 2.34)-(2.38) and (3.7)-(3.9): round trips through the IK, recovery of
an elastic equilibrium, static equilibrium at the solution and honest failure reports."""

import numpy as np
import pytest

from cdpr_control.model import cable
from cdpr_control.model.dynamics import gravity_wrench
from cdpr_control.model.forward_kinematics import CONVERGED, MAX_ITERATIONS, NON_FINITE, ForwardKinematics
from cdpr_control.model.kinematics import inverse_kinematics
from cdpr_control.model.robot import load_robot
from poses import random_poses


def equilibrium(robot, x):
    """Cable forces balancing the platform weight at x (A^T f = -w, (2.10)) around the mid force,
    and the winch lengths theta that hold them with the elastic cables (2.17)."""
    ik = inverse_kinematics(robot, x)
    w = gravity_wrench(robot, x)
    f_mid = 0.5 * (robot.cable.f_min + robot.cable.f_max)
    f = f_mid - np.linalg.pinv(ik.AT) @ (ik.AT @ f_mid + w)
    assert np.all(f > 0.0)
    theta = ik.q - cable.elongation_from_force(robot, f, cable.total_free_length(robot, ik.q))
    return f, theta, w


def offset(robot, rng, size):
    """A pose error of about `size` metres at the platform's anchor points."""
    lever = np.mean(np.linalg.norm(robot.b, axis=1))
    return np.r_[rng.normal(size=3) * size, rng.normal(size=3) * size / lever] / np.sqrt(6)


def anchor_error(robot, x, y):
    """Largest distance [m] between the platform anchor points B_i at poses x and y."""
    B = [inverse_kinematics(robot, p).Rb + p[:3] for p in (x, y)]
    return np.max(np.linalg.norm(B[0] - B[1], axis=1))


def test_ik_then_rigid_fk_returns_the_pose(robot):
    """1000 random poses of the workspace box, FK started at the home pose: 1e-9 m / 1e-9 rad."""
    rng = np.random.default_rng(30)
    X = random_poses(robot, 1000, rng)
    Q = inverse_kinematics(robot, X).q
    fk = ForwardKinematics(robot)
    for x, q in zip(X, Q):
        res = fk.joint_space(q, robot.home)
        assert res.converged and res.termination == CONVERGED
        assert np.max(np.abs(res.x[:3] - x[:3])) < 1e-9
        assert np.max(np.abs(res.x[3:] - x[3:])) < 1e-9
        assert res.residual_norm < 1e-9


def test_rigid_fk_without_pulleys():
    from dataclasses import replace

    robot = replace(load_robot("ipanema3"), swivelling_pulleys=False)
    x = np.array([1.0, -0.5, 1.2, 0.1, -0.05, 0.2])
    res = ForwardKinematics(robot).joint_space(inverse_kinematics(robot, x).q, robot.home)
    assert res.converged and np.max(np.abs(res.x - x)) < 1e-9


def test_elastic_fk_recovers_pose_from_elongated_lengths_and_forces(robot):
    """theta and f simulated at a true pose; FK (3.7)-(3.9) from x_d = true pose + 1 mm."""
    rng = np.random.default_rng(31)
    fk = ForwardKinematics(robot)
    for x in random_poses(robot, 10, rng, angle=0.1):
        f, theta, _ = equilibrium(robot, x)
        x_d = x + offset(robot, rng, 1e-3)
        full = fk.elastic(theta, f, x_d, pulleys="full")
        assert full.converged and np.max(np.abs(full.x - x)) < 1e-9
        # section 3.2: leave points frozen at x_d, an error second order in |x - x_d|
        frozen = fk.elastic(theta, f, x_d)
        assert frozen.converged and anchor_error(robot, frozen.x, x) < 1e-7
        frozen_at_truth = fk.elastic(theta, f, x)
        assert np.max(np.abs(frozen_at_truth.x - x)) < 1e-9


def test_frozen_pulley_error_is_second_order(robot):
    rng = np.random.default_rng(32)
    x = random_poses(robot, 1, rng, angle=0.1)[0]
    f, theta, _ = equilibrium(robot, x)
    fk = ForwardKinematics(robot)
    d = offset(robot, rng, 1e-2)
    e1 = anchor_error(robot, fk.elastic(theta, f, x + d).x, x)
    e2 = anchor_error(robot, fk.elastic(theta, f, x + d / 4).x, x)
    assert e2 < e1 / 8


def test_elastic_fk_accounts_for_start_up_elongation(robot):
    rng = np.random.default_rng(33)
    x = random_poses(robot, 1, rng, angle=0.1)[0]
    f, theta, _ = equilibrium(robot, x)
    dq0 = np.linspace(-1e-3, 1e-3, robot.m)
    res = ForwardKinematics(robot).elastic(theta + dq0, f, x, dq0=dq0, pulleys="full")
    assert res.converged and np.max(np.abs(res.x - x)) < 1e-9


def test_operational_space_fk_finds_static_equilibrium(robot):
    """(2.36)-(2.38): at the FK pose the forces from the elongation satisfy A^T f = -w."""
    rng = np.random.default_rng(34)
    fk = ForwardKinematics(robot)
    for x in random_poses(robot, 5, rng, angle=0.1):
        f, theta, w = equilibrium(robot, x)
        res = fk.operational_space(theta, x + offset(robot, rng, 1e-3))
        assert res.converged and np.max(np.abs(res.x - x)) < 1e-9
        ik = inverse_kinematics(robot, res.x)
        f_fk = cable.force_from_elongation(
            robot, ik.q - theta, cable.total_free_length(robot, ik.q)
        )
        np.testing.assert_allclose(f_fk, f, rtol=1e-6)
        assert np.max(np.abs(ik.AT @ f_fk + gravity_wrench(robot, res.x))) < 1e-7 * np.max(
            np.abs(w)
        )


def test_elastic_fk_solution_is_in_static_equilibrium(robot):
    """The elastic JS-FK pose (3.9) balances the weight with the forces from the elongation."""
    rng = np.random.default_rng(35)
    x = random_poses(robot, 1, rng, angle=0.1)[0]
    f, theta, w = equilibrium(robot, x)
    res = ForwardKinematics(robot).elastic(theta, f, x + offset(robot, rng, 1e-3), pulleys="full")
    ik = inverse_kinematics(robot, res.x)
    f_fk = cable.force_from_elongation(robot, ik.q - theta, cable.total_free_length(robot, ik.q))
    assert np.max(np.abs(ik.AT @ f_fk + w)) < 1e-6 * np.max(np.abs(w))


def test_non_converged_solve_says_so(robot):
    rng = np.random.default_rng(36)
    x = random_poses(robot, 1, rng)[0]
    q = inverse_kinematics(robot, x).q
    res = ForwardKinematics(robot, max_iterations=1).joint_space(q, robot.home)
    assert not res.converged and res.termination == MAX_ITERATIONS and res.iterations == 1
    res = ForwardKinematics(robot).joint_space(np.full(robot.m, np.nan), robot.home)
    assert not res.converged and res.termination == NON_FINITE
    # elongations beyond the cable model's range give no force: reported, not returned as a pose
    res = ForwardKinematics(robot).operational_space(q - 0.5 * q, x)
    assert not res.converged and res.termination == NON_FINITE


def test_inconsistent_lengths_converge_to_least_squares(robot):
    """Noisy lengths have no exact solution: the solve converges with a non-zero residual whose
    gradient vanishes (normal equations of (2.35))."""
    rng = np.random.default_rng(37)
    x = random_poses(robot, 1, rng)[0]
    q = inverse_kinematics(robot, x).q + rng.normal(size=robot.m) * 1e-4
    res = ForwardKinematics(robot).joint_space(q, x)
    assert res.converged and res.residual_norm > 1e-6
    ik = inverse_kinematics(robot, res.x)
    assert np.max(np.abs(ik.AT @ (ik.q - q))) < 1e-9
