"""Pulley friction model (3.30)-(3.44): closed forms, inverses, Dahl hysteresis."""
import numpy as np
import pytest

from required import import_or_skip
from cdpr_control.model.friction import (PulleyFriction, PulleySeries, pulley_force, sensor_from_winch_force,
    winch_force_from_sensor, wrap_factor)
from cdpr_control.model.robot import load_robot

MU = np.array([0.016, 0.011, 0.02, 0.0])
F_PV = np.array([1.7, 3.5, 0.0, 2.0])
N_P = np.array([3, 4, 2, 1])
BETA_IN = np.deg2rad(90.0)


def test_wrap_factor_closed_forms():
    assert wrap_factor(np.pi) == pytest.approx(2.0)
    assert wrap_factor(np.pi / 2) == pytest.approx(np.sqrt(2.0))
    assert wrap_factor(0.0) == 0.0


@pytest.mark.parametrize("thetadot", [-0.3, 0.2])
def test_pulley_force_solves_the_balance_334(thetadot):
    F_prev, mu, F_pv, beta = 50.0, 0.02, 1.5, 1.2
    F = pulley_force(F_prev, thetadot, mu, F_pv, beta)
    s = np.sign(thetadot)
    balance = F_prev + s * mu * 0.5 * (F_prev + F) * wrap_factor(beta) + F_pv * thetadot   # (3.34)
    assert F == pytest.approx(balance, rel=1e-14)


def test_sensor_pulley_matches_340_at_the_thesis_wrap_angles():
    F_s = np.array([10.0, 20.0])
    for beta_1 in (np.pi / 2, np.pi):
        expected = 0.5 * F_s * (1.0 + np.sin(beta_1))                  # (3.40)
        np.testing.assert_allclose(winch_force_from_sensor(F_s, beta_1), expected, rtol=1e-14)
        np.testing.assert_allclose(sensor_from_winch_force(expected, beta_1), F_s, rtol=1e-14)


def _chain_by_hand(F_1, thetadot, beta_last):
    """(3.35) pulley by pulley: P2 .. P_np-1 at beta_inner, P_np at beta_last."""
    out = np.empty(len(MU))
    for i in range(len(MU)):
        betas = [BETA_IN] * max(N_P[i] - 2, 0) + ([beta_last[i]] if N_P[i] >= 2 else [])
        F = F_1[i]
        for beta in betas:
            F = pulley_force(F, thetadot[i], MU[i], F_PV[i], beta)
        out[i] = F
    return out


def test_series_equals_pulley_by_pulley_and_inverts():
    series = PulleySeries(MU, F_PV, N_P, BETA_IN)
    rng = np.random.default_rng(1)
    for _ in range(20):
        F_1 = rng.uniform(1.0, 40.0, 4)
        thetadot = rng.uniform(-0.5, 0.5, 4)
        beta_last = rng.uniform(0.3, 2.5, 4)
        F_np = series.platform_force(F_1, thetadot, beta_last)
        np.testing.assert_allclose(F_np, _chain_by_hand(F_1, thetadot, beta_last), rtol=1e-13)
        np.testing.assert_allclose(series.winch_force(F_np, thetadot, beta_last), F_1, rtol=1e-13)


def test_series_direction_and_standstill():
    series = PulleySeries(MU, F_PV, N_P, BETA_IN)
    F_1, beta = np.full(4, 20.0), np.full(4, 1.0)
    out = series.platform_force(F_1, np.full(4, 0.1), beta)       # paying out: the platform pulls more
    into = series.platform_force(F_1, np.full(4, -0.1), beta)     # pulling in: the sensor sees more
    assert np.all(out[:3] > F_1[:3]) and np.all(into[:3] < F_1[:3])
    assert out[3] == F_1[3] == into[3]                           # no pulley after the sensor
    np.testing.assert_array_equal(series.platform_force(F_1, np.zeros(4), beta), F_1)


def _single_pulley(sigma=1000.0, mu=0.02):
    """Two cables over the sensor pulley (90 deg, f_w = F_s) and one swivelling pulley, no viscosity."""
    return PulleyFriction(np.full(2, mu), np.full(2, sigma), np.zeros(2), np.full(2, 2), 0.0, np.pi / 2,
                          np.zeros(2), v_eps=1e-6)


def test_dahl_solves_342_and_is_continuous_at_reversal():
    fr = _single_pulley()
    beta, F_s, v = np.full(2, 1.2), np.array([20.0, 30.0]), 0.1
    alpha, _ = fr.series.gains(np.ones(2), beta)
    F_c = (alpha - 1.0) * F_s                                 # Coulomb level of the series (3.41)
    theta = np.zeros(2)
    for _ in range(300):                                      # pay out 30 mm >> F_c / sigma
        theta = theta + 1e-4
        f = fr.platform_force(F_s, theta, np.full(2, v), beta)
    np.testing.assert_allclose(f - F_s, F_c, rtol=1e-9)       # saturated: F_D = s F_c
    F_D_turn = fr.dahl.F_D.copy()
    # reverse: the stored friction is the start (continuity), then (3.42) with alpha = 1
    f_back = []
    thetas = theta - np.arange(1, 6)[:, None] * 1e-6
    for th in thetas:
        f_back.append(fr.platform_force(F_s, th, np.full(2, -v), beta) - F_s)
    np.testing.assert_array_equal(fr.dahl.F_0, F_D_turn)
    np.testing.assert_array_equal(fr.dahl.theta_0, theta)
    F_D = np.array(f_back)
    s_back = -1.0
    F_c_back = (1.0 - fr.series.gains(-np.ones(2), beta)[0]) * F_s
    slope = np.diff(F_D, axis=0) / np.diff(thetas, axis=0)
    mid = 0.5 * (F_D[1:] + F_D[:-1])
    np.testing.assert_allclose(slope, fr.dahl.sigma * (1.0 - mid * s_back / F_c_back), rtol=1e-4)
    for _ in range(300):                                      # 30 mm back: -F_c of that direction
        thetas[-1] = thetas[-1] - 1e-4
        f = fr.platform_force(F_s, thetas[-1], np.full(2, -v), beta)
    np.testing.assert_allclose(f - F_s, -F_c_back, rtol=1e-9)


def test_dahl_keeps_its_force_at_standstill():
    fr = _single_pulley()
    beta, F_s = np.full(2, 1.2), np.full(2, 20.0)
    fr.platform_force(F_s, np.full(2, 1e-3), np.full(2, 0.2), beta)
    held = fr.platform_force(F_s, np.full(2, 1e-3), np.full(2, 1e-7), beta)   # inside the standstill band
    assert np.all(fr.dahl.last_direction == 1.0)
    np.testing.assert_array_equal(fr.platform_force(F_s, np.full(2, 1e-3), np.zeros(2), beta), held)
    assert np.all(held > F_s)


def _trajectory(n=3000, dt=1e-3, seed=3):
    """Cable lengths with reversals and pauses, their period velocity, varying forces."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * dt
    theta = 0.004 * np.sin(2 * np.pi * 1.3 * t)[:, None] * rng.uniform(0.5, 1.5, 8)
    theta[n // 3:n // 2] = theta[n // 3 - 1]                 # a pause
    thetadot = np.vstack([np.zeros(8), np.diff(theta, axis=0) / dt])
    f = 20.0 + 5.0 * np.sin(2 * np.pi * 0.7 * t)[:, None] + rng.normal(0, 0.2, (n, 8))
    beta = np.full(8, 1.4)
    return theta, thetadot, f, beta


@pytest.mark.parametrize("robot_name", ["ipanema3", "ipanema3_mini"])
def test_compensation_inverts_the_forward_model(robot_name):
    robot = load_robot(robot_name)
    theta, thetadot, f, beta = _trajectory()
    scale = robot.cable.f_max[0] / 40.0
    f = f * scale
    forward = PulleyFriction.from_robot(robot, theta[0])
    inverse = PulleyFriction.from_robot(robot, theta[0])
    worst = 0.0
    for k in range(len(theta)):
        F_s = forward.sensor_force(f[k], theta[k], thetadot[k], beta)
        f_hat = inverse.platform_force(F_s, theta[k], thetadot[k], beta)
        worst = max(worst, float(np.max(np.abs(f_hat - f[k]))))
    assert worst < 1e-9 * scale


def test_sliding_friction_is_the_coulomb_viscous_series():
    """Far from a reversal, f - f_w is the macroscopic friction (3.41) of the pulley series."""
    robot = load_robot("ipanema3_mini")
    fr = PulleyFriction.from_robot(robot, np.zeros(8))
    beta = np.full(8, 1.2)
    v = 0.05
    theta = np.zeros(8)
    for _ in range(1200):                                  # 60 mm >> F_c / sigma
        theta = theta + v * 1e-3
        F_s = fr.sensor_force(np.full(8, 20.0), theta, np.full(8, v), beta)
    f_w = winch_force_from_sensor(F_s, robot.sensor.beta_1)
    expected = fr.series.platform_force(f_w, np.full(8, v), beta)
    np.testing.assert_allclose(np.full(8, 20.0), expected, rtol=1e-9)
    assert np.all(f_w < 20.0)


def test_the_steps_compile_with_numba_and_agree_with_numpy():
    """The simulator runs the friction steps compiled (cdpr_sim.simulator.compiled): same results."""
    import_or_skip("numba")
    from cdpr_sim.simulator import compiled

    robot = load_robot("ipanema3")
    theta, thetadot, f, beta = _trajectory(n=600)
    f = f * 75.0
    plain = [PulleyFriction.from_robot(robot, theta[0], 1e-7) for _ in range(2)]
    fast = [PulleyFriction.from_robot(robot, theta[0], 1e-7, jit=compiled) for _ in range(2)]
    for k in range(len(theta)):
        F_s = plain[0].sensor_force(f[k], theta[k], thetadot[k], beta)
        np.testing.assert_allclose(fast[0].sensor_force(f[k], theta[k], thetadot[k], beta), F_s, rtol=1e-12)
        np.testing.assert_allclose(fast[1].platform_force(F_s, theta[k], thetadot[k], beta),
                                   plain[1].platform_force(F_s, theta[k], thetadot[k], beta), rtol=1e-12)
