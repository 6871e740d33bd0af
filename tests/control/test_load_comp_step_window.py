"""The window of (4.4) over a load step (docs/load_compensation.md, "The swing window over a load
step (session 14)"): a window matched to a swing must not reach back across the load change, and a
swing the step excites is still matched once the window no longer reaches the change."""
import numpy as np

from load_steps import RAMP, REST, payload as _payload, run as _load_step_run


def _run(mass, z, duration):
    """The payload put down as in the sweep (load_steps.run)."""
    return _load_step_run(lambda t: _payload(t, mass), z, duration)


def _blend(t, t0, t1, z0, z1):
    s = np.clip((t - t0) / (t1 - t0), 0.0, 1.0)
    return z0 + (z1 - z0) * 0.5 * (1.0 - np.cos(np.pi * s))


def _sag_and_return(t):
    """ipanema3 #8 under force control with the CFC's internal integral (default plant seed 1,
    35.7 kg): a wobble of the start-up (0.5 mm at 2 Hz until 0.5 s: turning points of its own), the
    sag to -13 mm at 0.97 s, the return past the set-point to +5.5 mm at 1.46 s and back over 1 s;
    the forward kinematics sees it all."""
    z = np.where(t < 0.5, 0.5e-3 * np.sin(2 * np.pi * 2.0 * t), 0.0)
    z = np.where(t >= REST, _blend(t, REST, 0.97, 0.0, -13e-3), z)
    z = np.where(t >= 0.97, _blend(t, 0.97, 1.46, -13e-3, 5.5e-3), z)
    z = np.where(t >= 1.46, _blend(t, 1.46, 2.5, 5.5e-3, 0.0), z)
    return z, z


def test_a_window_does_not_reach_back_across_a_load_step():
    """The sag and the return turn twice by more than 2 mm after the wobble's turning point: a swing
    of 0.98 s to the turning points alone, whose window (1 s from 0.6 s) reached back across the
    payload's ramp and read 35.7 kg 22.8 % off from 1 s after the step on (the session-13 window; 24.9 % at
    ipanema3 #8 in the closed loop). The thesis' T_filter estimate at the window's start differs
    from the one at its end by the payload: the window stays T_filter until the start's estimate has
    the payload but for what the sag's acceleration share allows (LOAD_CHANGE), and the estimate is
    within the sweep's band of 5 % from 1 s after the step on."""
    t, m_c, windows = _run(35.7, _sag_and_return, 3.0)
    judged = t >= REST + 1.0                         # the sweep's: from 1 s after the step began
    assert np.abs(m_c[judged] - 35.7).max() / 35.7 < 0.05
    # while its start's T_filter estimate still has the ramp (T_filter and h after it) it stays T_filter
    ramp = (t > REST) & (t < REST + RAMP + 0.24 + 0.2)
    assert np.all(windows[ramp] == 0.24)


def _step_and_swing(t, share=0.8):
    """115 kg put down and swinging as ipanema3 #38 (1.6 Hz, 60 mm decaying from the ramp's end),
    the forward kinematics seeing ``share`` of the swing."""
    sag = _blend(t, REST, REST + RAMP, 0.0, -0.03)
    swing = np.where(t >= REST + RAMP, 0.06 * np.exp(-0.6 * (t - REST - RAMP))
                     * np.sin(2 * np.pi * 1.6 * (t - REST - RAMP)), 0.0)
    return sag + swing, sag + share * swing


def test_a_swing_after_a_step_is_still_matched():
    """The step's own swing: the window is the swing's period (0.625 s) once it no longer reaches the
    load change, and the swing's acceleration share keeps a swing from reading as one; 115 kg read
    within 5 % from 1 s after the step (the sweep's band), within 2 % from 2 s."""
    t, m_c, windows = _run(115.0, _step_and_swing, 4.0)
    error = np.abs(m_c - 115.0) / 115.0
    assert error[t >= REST + 1.0].max() < 0.05
    assert error[t >= 2.0].max() < 0.02
    assert 0.55 <= windows[-1] <= 0.7
