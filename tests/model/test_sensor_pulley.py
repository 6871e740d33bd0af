"""Sensor pulley P1 (issue 17, item 5): f_w = F_1 from the sensor force, (3.36)-(3.40).

The code solves the force balance (3.36) along the sensor axis, F_1 = F_s / (1 - cos beta_1); the
thesis' summary (3.40), F_s (1 + sin beta_1) / 2, agrees with it only at 90 and 180 degrees. The
tests build the pulley's load from the two cable force vectors at several wrap angles."""
import numpy as np
import pytest

from cdpr_control.model.friction import PulleyFriction, sensor_from_winch_force, winch_force_from_sensor

ANGLES = (30.0, 60.0, 90.0, 120.0, 135.0, 150.0, 180.0)


def _sensor_reading(F, beta_1):
    """The load of P1 from both cable segments (each pulls away from the pulley with force F),
    projected on the sensor axis along the cable leaving towards the platform."""
    u_1 = np.array([1.0, 0.0])                                    # leaving segment, F_1
    u_0 = np.array([np.cos(np.pi - beta_1), np.sin(np.pi - beta_1)])   # drum segment, F_0
    load = F * u_0 + F * u_1
    return float(load @ u_1)


@pytest.mark.parametrize("deg", ANGLES)
def test_force_balance_3_36_is_inverted_at_every_wrap_angle(deg):
    beta = np.deg2rad(deg)
    F = 123.4
    F_s = _sensor_reading(F, beta)
    assert F_s == pytest.approx(F * (1.0 - np.cos(beta)), rel=1e-12)         # (3.36) with F_0 = F_1
    assert winch_force_from_sensor(F_s, beta) == pytest.approx(F, rel=1e-12)
    assert sensor_from_winch_force(F, beta) == pytest.approx(F_s, rel=1e-12)


@pytest.mark.parametrize("deg", ANGLES)
def test_the_summary_3_40_holds_only_at_90_and_180_degrees(deg):
    beta = np.deg2rad(deg)
    F_s = 100.0
    printed = 0.5 * F_s * (1.0 + np.sin(beta))                                 # (3.40) as printed
    balance = winch_force_from_sensor(F_s, beta)
    if deg in (90.0, 180.0):
        assert balance == pytest.approx(printed, rel=1e-12)
    else:
        assert abs(balance / printed - 1.0) > 0.05


def test_the_thesis_designs():
    """IPAnema 3 (90 deg): the sensor reads F_1 (3.37); the Mini (180 deg): twice F_1, (3.39) at mu = 0."""
    assert winch_force_from_sensor(50.0, np.pi / 2) == pytest.approx(50.0)
    assert winch_force_from_sensor(50.0, np.pi) == pytest.approx(25.0)


@pytest.mark.parametrize("deg", (60.0, 135.0))
def test_friction_model_without_friction_uses_the_force_balance(deg):
    """With mu = F_pv = 0 the platform force is the winch force of (3.36) at any wrap angle."""
    beta = np.deg2rad(deg)
    m = 2
    pf = PulleyFriction(np.zeros(m), np.full(m, 1e3), np.zeros(m), np.full(m, 3), np.pi / 2, beta, np.zeros(m))
    F_s = np.array([40.0, 80.0])
    f = pf.platform_force(F_s, np.zeros(m), np.zeros(m), np.full(m, np.pi / 2))
    np.testing.assert_allclose(f, F_s / (1.0 - np.cos(beta)), rtol=1e-12)
