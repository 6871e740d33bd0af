"""Discrete drive models (3.10) and (5.11): exact step responses, frequency response, limits."""
import math

import numpy as np
import pytest

from required import import_or_skip
from cdpr_sim.drive_models import DriveModel
from cdpr_control.model.robot import load_robot


def _step_response(drive, n):
    drive.reset(np.zeros(drive.m))
    return np.array([drive.step(np.ones(drive.m))[0] for _ in range(n)])


@pytest.mark.parametrize("T_d", [0.0, 0.003, 0.0063])
def test_pt1_deadtime_step_is_exact(T_d):
    dt, T_1 = 1e-3, 0.000745 * 3
    drive = DriveModel.pt1_deadtime(T_1, T_d, dt, 2)
    y = _step_response(drive, 40)
    t = dt * np.arange(1, 41)
    expected = np.where(t > T_d, 1.0 - np.exp(-np.maximum(t - T_d, 0.0) / T_1), 0.0)
    np.testing.assert_allclose(y, expected, atol=1e-12)


def test_pure_dead_time():
    drive = DriveModel.pt1_deadtime(0.0, 0.0025, 1e-3, 1)
    y = _step_response(drive, 6)
    np.testing.assert_array_equal(y, [0, 0, 1, 1, 1, 1])     # theta(t) = theta_d(t - 2.5 ms) at t = 3 ms on


def test_second_order_step_is_exact():
    dt, T_w, zeta, T_d = 1e-3, 0.0139, 0.587, 0.0015
    drive = DriveModel.second_order(T_w, zeta, T_d, dt, 1)
    y = _step_response(drive, 100)
    t = dt * np.arange(1, 101) - T_d
    wn = 1.0 / T_w
    wd = wn * math.sqrt(1.0 - zeta**2)
    exact = 1.0 - np.exp(-zeta * wn * t) * (np.cos(wd * t) + zeta / math.sqrt(1 - zeta**2) * np.sin(wd * t))
    np.testing.assert_allclose(y, np.where(t > 0, exact, 0.0), atol=1e-12)


@pytest.mark.parametrize("robot_name", ["ipanema3", "ipanema3_mini"])
@pytest.mark.parametrize("freq", [2.0, 5.0, 15.0])
def test_sampled_sine_follows_the_transfer_function(robot_name, freq):
    """Gain and phase of theta / theta_d from a simulated sine match G_a(j w) (ZOH adds dt/2)."""
    dt = 1e-3
    drive = DriveModel.from_robot(load_robot(robot_name), dt)
    drive.reset(np.zeros(drive.m))
    n = int(round(4.0 / dt))
    t = dt * np.arange(n)
    u = 0.005 * np.sin(2 * np.pi * freq * t)
    y = np.array([drive.step(np.full(drive.m, uk))[0] for uk in u])
    keep = t >= 1.0                                   # transient gone
    ty = t[keep] + dt                                 # y[k] holds at the end of step k
    basis = np.column_stack([np.sin(2 * np.pi * freq * ty), np.cos(2 * np.pi * freq * ty)])
    a, b = np.linalg.lstsq(basis, y[keep], rcond=None)[0]
    measured = (a + 1j * b) / 0.005 * np.exp(0j)      # y = Im(G e^{jwt}) -> a = Re G, b = Im G
    w = 2 * np.pi * freq
    model = drive.transfer_function(1j * w) * np.exp(-1j * w * dt / 2)
    assert 20 * np.log10(abs(measured) / abs(model)) == pytest.approx(0.0, abs=0.05)
    assert np.rad2deg(np.angle(measured / model)) == pytest.approx(0.0, abs=0.5)


def test_speed_limit_and_standstill():
    drive = DriveModel.pt1_deadtime(0.001, 0.0, 1e-3, 2, v_max=1.0)
    drive.reset(np.array([0.2, 0.3]))
    for _ in range(5):
        np.testing.assert_array_equal(drive.step(np.array([0.2, 0.3])), [0.2, 0.3])
    y = [drive.step(np.array([1.2, 0.3]))[0] for _ in range(10)]
    np.testing.assert_allclose(np.diff(y), 1e-3, rtol=1e-12)     # 1 m/s for 1 ms per step
    assert drive.thetadot[0] == pytest.approx(1.0)


def test_rejects_bad_parameters():
    with pytest.raises(ValueError):
        DriveModel.second_order(0.0, 0.5, 0.0, 1e-3, 1)
    with pytest.raises(ValueError):
        DriveModel.pt1_deadtime(0.001, -1.0, 1e-3, 1)
    with pytest.raises(ValueError):
        DriveModel.pt1_deadtime(0.001, 0.0, 0.0, 1)


@pytest.mark.parametrize("robot_name", ["ipanema3", "ipanema3_mini"])
def test_the_step_compiles_with_numba_and_agrees_with_numpy(robot_name):
    """The simulator runs drive_step compiled (cdpr_sim.simulator.compiled): the same numbers."""
    import_or_skip("numba")
    from cdpr_sim.simulator import compiled

    robot = load_robot(robot_name)
    plain, fast = DriveModel.from_robot(robot, 1e-3), DriveModel.from_robot(robot, 1e-3, jit=compiled)
    for drive in (plain, fast):
        drive.reset(np.zeros(robot.m))
    rng = np.random.default_rng(2)
    for k in range(300):
        u = 0.01 * np.sin(0.05 * k + np.arange(robot.m)) + (0.5 if k == 200 else 0.0) * rng.uniform(size=robot.m)
        np.testing.assert_allclose(fast.step(u), plain.step(u), rtol=1e-13, atol=1e-15)
        np.testing.assert_allclose(fast.thetadot, plain.thetadot, rtol=1e-12, atol=1e-12)
