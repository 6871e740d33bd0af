"""The identified payload in the force set-point (force_distribution.payload_input): the disturbance
filter of (3.24)-(3.26) stretched with the platform's total mass (force_setpoint.payload_filter_time)."""
import numpy as np
import pytest

from cdpr_control.model.dynamics import platform_wrench
from cdpr_control.control.force_setpoint import ForceSetpoint, ForceSetpointParams, payload_filter_time
from cdpr_control.model.robot import load_robot

DT = 1e-3
IPANEMA3 = load_robot("ipanema3")


@pytest.mark.parametrize("a_z", [0.0, 3.0])
def test_filter_time_grows_with_the_square_root_of_the_total_mass(a_z):
    """A payload of 3 m_p quadruples the mass: the vertical mode's frequency halves, the time
    constant doubles, at rest and accelerating (the ratio is that of the masses either way)."""
    robot, x_d = IPANEMA3, IPANEMA3.home
    xddot = np.r_[0.0, 0.0, a_z, 0.0, 0.0, 0.0]
    fs = ForceSetpoint(robot, DT)
    w_dyn = platform_wrench(robot, x_d, np.zeros(6), xddot)
    w_payload = fs.payload_wrench(x_d, np.zeros(6), xddot, 3.0 * robot.platform.mass, np.zeros(3))
    assert payload_filter_time(0.3, w_dyn, w_payload) == pytest.approx(0.6, rel=1e-9)
    assert payload_filter_time(0.3, w_dyn, np.zeros(6)) == 0.3
    # an estimate below zero (sensor offsets) does not shorten the filter
    assert payload_filter_time(0.3, w_dyn, -0.5 * w_payload) == 0.3


def test_the_force_setpoint_filters_with_the_stretched_time_and_returns_without_payload():
    robot, x_d, zero = IPANEMA3, IPANEMA3.home, np.zeros(6)
    fs = ForceSetpoint(robot, DT, ForceSetpointParams(T_wrench_filter=0.3))
    w_dyn = platform_wrench(robot, x_d, zero, zero)
    w_payload = fs.payload_wrench(x_d, zero, zero, 90.0, np.zeros(3))
    fs.update(x_d, zero, zero, w_dyn + w_payload, w_model=w_payload)
    m_p = robot.platform.mass
    assert fs.wrench_filter.T == pytest.approx(0.3 * np.sqrt((m_p + 90.0) / m_p), rel=1e-9)
    assert fs.wrench_filter.alpha == pytest.approx(1.0 - np.exp(-DT / fs.wrench_filter.T))
    fs.update(x_d, zero, zero, w_dyn)
    assert fs.wrench_filter.T == 0.3
