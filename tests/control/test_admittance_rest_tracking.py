"""The tare's tracking at rest (``rest_tracking_time``, docs/admittance.md): while the user wrench
(5.9) is inside the dead band on every axis the tare follows the filtered remainder with a PT1, so a
slow drift (the friction compensation's model error at rest) stays inside the band; a push beyond
the band freezes it, so the push is not tared away."""
import numpy as np
import pytest

from cdpr_control.control.admittance import UserWrench, UserWrenchParams, default_parameters, settings_from
from cdpr_control.model.robot import load_robot

DT = 1e-3
ROBOT = load_robot("ipanema3")
BAND = [5.0, 5.0, 5.0, 3.2, 3.2, 3.2]


def user(T_track: float) -> UserWrench:
    u = UserWrench(ROBOT, DT, UserWrenchParams(T_filter=0.02, dead_band=BAND, w_max=[100.0] * 3 + [10.0] * 3,
                                               rest_tracking_time=T_track))
    u.reset(np.zeros(6))
    return u


def run(u: UserWrench, raw_of_t, duration: float) -> np.ndarray:
    return np.array([u.update(raw_of_t(k * DT)) for k in range(1, int(round(duration / DT)) + 1)])


def test_a_slow_drift_stays_inside_the_dead_band_at_the_ramps_steady_lag():
    """A drift of 2 N/s on x and 1 N m/s about z: untracked it leaves the band (5 N) after 2.5 s;
    tracked with T, the remainder settles at the ramp's steady lag rate * T (a PT1 following a ramp)."""
    rate = np.array([2.0, 0, 0, 0, 0, 1.0])
    T = 0.5
    assert np.abs(run(user(0.0), lambda t: rate * t, 4.0)[-1, 0]) > 1.0
    u = user(T)
    w = run(u, lambda t: rate * t, 4.0)
    assert not np.any(w)                                            # never out of the band
    remainder = u.filter.y
    assert remainder[0] == pytest.approx(rate[0] * T, rel=2e-2)
    assert remainder[5] == pytest.approx(rate[5] * T, rel=2e-2)
    assert u.tare[0] == pytest.approx(rate[0] * (4.0 - T), rel=2e-2)


def test_a_push_beyond_the_band_is_not_tared_away():
    """A 30 N push along y held 2 s: the tare moves only while the filtered push is still inside the
    band (the first few ms), then freezes; a tracker that ran regardless would tare it to zero."""
    push = np.array([0.0, 30.0, 0, 0, 0, 0])
    untracked = run(user(0.0), lambda t: push, 2.0)
    u = user(0.2)
    tracked = run(u, lambda t: push, 2.0)
    assert untracked[-1, 1] == pytest.approx(25.0, abs=1e-6)        # 30 N less the 5 N band
    assert tracked[-1, 1] == pytest.approx(untracked[-1, 1], abs=0.1)
    assert abs(u.tare[1]) < 0.1


def test_off_by_default_and_validated():
    assert default_parameters()["rest_tracking_time"] == 0.0
    params, _, _ = settings_from({"rest_tracking_time": 0.5}, ROBOT, check_workspace=False)
    assert params.user.rest_tracking_time == 0.5
    with pytest.raises(ValueError, match="rest_tracking_time"):
        settings_from({"rest_tracking_time": -1.0}, ROBOT, check_workspace=False)
