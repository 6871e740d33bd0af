"""Hand guiding in the closed loop (thesis 5.2.3), IPAnema 3 Mini in simulation with its shipped
parameter file: eigenfrequency of table 5.3 from the ground truth, the push sequence of Fig. 5.15,
cable limits, a wrench spike."""
import dataclasses

import numpy as np
import pytest
from scipy.optimize import curve_fit

from cdpr_control.control.admittance import damped_eigenfrequency
from cdpr_control.control.friction_compensation import FrictionCompensationParams
from cdpr_control.model.robot import load_robot
from cdpr_control.control.params import control_loop_params
from cdpr_sim.hand import Segment
from cdpr_sim.hand_guiding import guiding_run
from cdpr_tools.admittance_figure import PUSHES

DT = 1e-3
MINI = load_robot("ipanema3_mini")


def _guide(overrides: dict, segments, duration: float, before_step=None, loop_params=None):
    """Hand guiding from home, enabled at t = 0, the hand's segments applied to the simulator."""
    g = guiding_run(segments, duration, overrides, loop_params=loop_params, before_step=before_step)
    return g.run, g.source


def _assert_cables_within_limits(r, settled: float = 0.1):
    """True cable forces within [f_min, f_max] from ``settled`` on: the run starts under the robot
    file's f_min (5 N) and the force control first raises the cables to the planned 7.5 N (not
    hand guiding's doing; the start-up minimum was 5.03 N on the simulator's default plant)."""
    f = r.f[r.t >= settled]
    assert f.min() >= MINI.cable.f_min.min() and f.max() <= MINI.cable.f_max.max()


def _fit_frequency(t, y) -> float:
    """Damped sine + offset fitted to y(t) -> frequency [Hz]."""
    t = t - t[0]
    crossings = np.flatnonzero(np.diff(np.sign(y - y.mean())) != 0)
    f0 = 0.5 / np.mean(np.diff(t[crossings])) if len(crossings) > 1 else 1.0 / (2 * (t[-1]))
    model = lambda t, a, b, s, w, c: np.exp(-s * t) * (a * np.cos(w * t) + b * np.sin(w * t)) + c  # noqa: E731
    popt, _ = curve_fit(model, t, y, p0=[y[0] - y.mean(), 0.0, 0.1, 2 * np.pi * f0, y.mean()])
    return abs(popt[3]) / (2 * np.pi)


# table 5.3: c_x [N/m], d_x [N s/m], m_x [kg]; the push (force [N], length [s]) and the fitted window
@pytest.mark.parametrize("c, d, m, push, window", [
    (31.9, 5.0, 20.0, (2.0, 0.2), 5.0),
    (197.5, 5.0, 20.0, (2.0, 0.2), 2.0),
    (395.4, 5.0, 10.0, (2.0, 0.2), 1.0),
    (9870.2, 5.0, 10.0, (8.0, 0.05), 0.4),
])
def test_released_platform_oscillates_at_the_eigenfrequency_of_5_12(c, d, m, push, window):
    """Pushed out of the rest pose and released, the platform (ground truth) oscillates at omega_d
    of (5.12) within 2.5 % (the thesis measured at most 2.5 %, table 5.3)."""
    force, length = push
    zone = {"zones.rest.radius": 0.03, "zones.free.box": [0.05, 0.05, 0.05, 0.05, 0.05, 0.05],
            "zones.rest.c": [c, 1000.0, 1000.0, 20.0, 20.0, 20.0], "zones.rest.d": [d, 40.0, 40.0, 0.5, 0.5, 0.5],
            "zones.rest.m": [m, 2.0, 2.0, 0.01, 0.01, 0.01]}
    t_release = 0.05 + length
    r, _ = _guide(zone, [Segment(0.05, (force, 0, 0, 0, 0, 0), "rectangle", length)], t_release + 0.05 + window)
    sel = r.t > t_release + 0.05
    f_exp = _fit_frequency(r.t[sel], r.x[sel, 0])
    assert np.ptp(r.x[sel, 0]) > 1e-3                       # it did oscillate, by millimetres
    assert f_exp == pytest.approx(damped_eigenfrequency(c, d, m), rel=0.025)
    _assert_cables_within_limits(r)


@pytest.fixture(scope="module")
def push_run():
    """Fig. 5.15 by numbers: light pulses in zone 1, a push into zone 2, into the wall, back."""
    return _guide({}, PUSHES, 8.5)


def test_push_sequence_reproduces_fig_5_15(push_run):
    r, source = push_run
    x, t = r.x[:, 0], r.t
    zone = np.array([-1] + [o.zone for o in source.outputs])     # the set-point of t_k came from t_k-1
    at = lambda s: int(round(s / DT)) - 1                          # noqa: E731
    # pulses inside zone 1 return to the origin
    assert 1.5e-3 < x[at(0.65)] < 2.6e-3 and zone[at(0.65)] == 0
    assert -2.0e-3 < x[at(1.45)] < -0.8e-3
    assert abs(x[at(1.95)]) < 2e-4
    # a push into zone 2: leaves zone 1, moves damped, stays where it was left
    assert zone[at(2.5)] == 1 and x[at(2.5)] > 0.01
    assert abs(x[at(2.95)] - x[at(2.6)]) < 3e-4
    # the border: stopped in the wall zone within the workspace, pushed back to the border on release
    assert zone[at(4.9)] == 2 and np.max(x[: at(5.0)]) < 0.03 + 4.0 / 1000 + 1e-3
    assert x[at(5.9)] == pytest.approx(0.03, abs=5e-4)           # (the wall spring ends at the border)
    # back towards the origin: zone 1 catches it
    assert abs(x[-1]) < 5e-4 and zone[-1] == 0


def test_push_sequence_keeps_the_cables_within_limits(push_run):
    r, _ = push_run
    _assert_cables_within_limits(r)


def test_a_measured_wrench_spike_saturates_safely():
    """A 2 kN spike for 5 ms on the measured wrench (far above w_max): the user wrench saturates,
    the set-point keeps its velocity limit and the hard box, the cables their limits."""
    def spike(k, loop, sim):
        if 300 <= k < 305 and loop.state is not None:
            loop.state.w = loop.state.w + np.array([2000.0, -2000.0, 2000.0, 50.0, -50.0, 50.0])

    r, source = _guide({}, [], 1.0, spike)
    controller = source.controller
    w_user = np.array([o.w_user for o in source.outputs])
    xd = np.array([o.xd for o in source.outputs])
    assert np.all(np.abs(w_user) <= controller.user.w_max + 1e-12)
    assert np.abs(w_user[:, 0]).max() == controller.user.w_max[0]     # it did saturate
    assert np.all(np.abs(xd) <= controller.system.v_max + 1e-12)
    lo, hi = controller.system.limit_box
    assert np.all(r.x_d >= lo - 1e-12) and np.all(r.x_d <= hi + 1e-12)
    assert not any(f.holds for faults in r.faults for f in faults)
    assert not any(r.faults[10:])                   # (the start-up reports f = 0 of the first 2 periods)
    _assert_cables_within_limits(r)


def test_pulley_friction_compensation_keeps_the_guided_platform_still():
    """Section 5.2.4 as far as the simulator shows it (dead band off, so nothing hides it): after a
    3 N push the uncompensated pulley friction (Dahl hysteresis) reads as a user force and moves the
    released platform on; with the friction compensation of 3.7 it stays within noise."""
    def ptp_after_push(compensated: bool) -> float:
        lp = dataclasses.replace(control_loop_params(MINI),
                                 friction=FrictionCompensationParams(enabled=compensated))
        r, _ = _guide({"dead_band": [0.0] * 6}, [Segment(0.1, (3.0, 0, 0, 0, 0, 0), "rectangle", 0.2)], 2.0,
                      loop_params=lp)
        return float(np.ptp(r.x[r.t > 1.0, 0]))

    with_fc, without = ptp_after_push(True), ptp_after_push(False)
    assert with_fc < 0.1e-3                             # m: sensor noise level (0.02 mm measured)
    assert without > 3.0 * with_fc
