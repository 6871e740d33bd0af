"""The tare of hand guiding (the thesis' w_init of (5.9)) averaged over tare_time after switch-on."""
import numpy as np

from cdpr_control.control.admittance import UserWrench, UserWrenchParams
from cdpr_control.model.robot import load_robot

DT = 1e-3


def _user(tare_time):
    return UserWrench(load_robot("ipanema3"), DT, UserWrenchParams(T_filter=0.0, dead_band=[0.0, 0.0], w_max=[1e3, 1e3],
                                                                   tare_time=tare_time))


def test_the_tare_is_the_mean_over_tare_time_and_the_output_is_zero_meanwhile():
    rng = np.random.default_rng(1)
    raw = rng.normal(0.0, 3.0, (300, 6)) + np.arange(6)
    user = _user(0.1)
    user.reset(raw[0])
    out = np.array([user.update(r) for r in raw[1:]])
    np.testing.assert_array_equal(out[:99], 0.0)                 # periods 1 .. 99 still average
    np.testing.assert_allclose(user.tare, raw[:100].mean(axis=0), rtol=1e-12)
    np.testing.assert_allclose(out[99:], raw[100:] - raw[:100].mean(axis=0), rtol=1e-12)


def test_one_sample_tare_keeps_its_noise_and_the_mean_removes_it():
    rng = np.random.default_rng(2)
    errors = {}
    for tare_time in (0.0, 0.1):
        tares = []
        for _ in range(200):
            raw = rng.normal(0.0, 3.0, (101, 6))
            user = _user(tare_time)
            user.reset(raw[0])
            for r in raw[1:]:
                user.update(r)
            tares.append(user.tare.copy())
        errors[tare_time] = np.std(tares)
    assert 2.5 < errors[0.0] < 3.5 and errors[0.1] < 0.4          # sigma 3 and 3 / sqrt(100)
