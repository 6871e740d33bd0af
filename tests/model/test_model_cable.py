"""Cable model (thesis 2.1.2): l_t (2.14), k_spec (2.16), stiffness (2.15), spring law (2.17) and
its inverse (3.7)."""

import numpy as np
import pytest

from cdpr_control.model import cable
from cdpr_control.model.robot import load_robot


def test_total_free_length_adds_l0(robot):
    q = np.linspace(1.0, 2.0, robot.m)
    np.testing.assert_allclose(cable.total_free_length(robot, q), q + robot.l_0)


def test_force_and_elongation_are_inverse(robot):
    f = np.linspace(0.0, 3.0 * robot.cable.f_max[0], 50)
    l_t = 7.3
    dq = cable.elongation_from_force(robot, f, l_t)
    np.testing.assert_allclose(
        cable.force_from_elongation(robot, dq, l_t), f, rtol=1e-12, atol=1e-9
    )
    # (2.17) itself: f = k_spec(f) dq / l_t
    np.testing.assert_allclose(
        cable.specific_stiffness(robot, f) * dq / l_t, f, rtol=1e-12, atol=1e-12
    )


def test_ipanema3_cable_matches_thesis_datum():
    """Section 2.1.2: 3000 N on 19.5 m of the 6 mm cable elongate it by 75 mm."""
    robot = load_robot("ipanema3")
    assert cable.elongation_from_force(robot, 3000.0, 19.5) == pytest.approx(0.075, rel=1e-9)


def test_slack_cable_carries_no_force(robot):
    assert np.all(cable.force_from_elongation(robot, np.array([-0.01, 0.0]), 2.0) == 0.0)
    assert np.all(cable.tangent_stiffness(robot, np.array([-1.0, 0.0]), 2.0) == 0.0)


def test_beyond_model_range_is_nan(robot):
    c = robot.cable
    f_vertex = np.sqrt(c.k0 / c.k2)  # the largest force (2.17) can describe
    dq_max = cable.elongation_from_force(robot, f_vertex, 1.0)
    assert np.isnan(cable.force_from_elongation(robot, 1.01 * dq_max, 1.0))
    assert np.isfinite(cable.force_from_elongation(robot, 0.99 * dq_max, 1.0))


def test_tangent_stiffness_is_derivative_of_spring_law(robot):
    l_t, h = 5.0, 1e-9
    dq = cable.elongation_from_force(robot, np.linspace(1.0, robot.cable.f_max[0], 20), l_t)
    fd = (
        cable.force_from_elongation(robot, dq + h, l_t)
        - cable.force_from_elongation(robot, dq - h, l_t)
    ) / (2 * h)
    f = cable.force_from_elongation(robot, dq, l_t)
    np.testing.assert_allclose(cable.tangent_stiffness(robot, f, l_t), fd, rtol=1e-6)


def test_linear_cable_reduces_to_2_15(robot):
    from dataclasses import replace

    linear = replace(robot, cable=replace(robot.cable, k1=0.0, k2=0.0))
    f, l_t = np.array([10.0, 30.0]), 3.0
    np.testing.assert_allclose(cable.tangent_stiffness(linear, f, l_t), robot.cable.k0 / l_t)
    np.testing.assert_allclose(cable.stiffness(linear, f, l_t), robot.cable.k0 / l_t)
    np.testing.assert_allclose(
        cable.elongation_from_force(linear, f, l_t), f * l_t / robot.cable.k0
    )


def test_secant_stiffness_is_2_15(robot):
    f, l_t = np.array([5.0, 20.0]), 4.0
    c = robot.cable
    np.testing.assert_allclose(
        cable.stiffness(robot, f, l_t), (c.k0 + c.k1 * f + c.k2 * f * f) / l_t
    )


def test_elongation_from_winch_length_inverts_spring_law(robot):
    """dq from (f, theta) is consistent with f = spring(dq, l_t = theta + dq + l_0)."""
    theta = np.linspace(0.5, 9.0, robot.m)
    f = np.linspace(1.0, robot.cable.f_max[0], robot.m)
    dq = cable.elongation_from_force_and_winch_length(robot, f, theta)
    l_t = cable.total_free_length(robot, theta + dq)
    np.testing.assert_allclose(cable.force_from_elongation(robot, dq, l_t), f, rtol=1e-12)
