"""Stability margins of CFC (3.21) and OSPC (3.17) with python-control, checked against the thesis'
numbers (Fig. 3.10-3.11) and against closed-loop steps in the simulator (both robots)."""
import numpy as np
import pytest
from scipy.signal import butter, sosfiltfilt

from cdpr_control.model import cable
from cdpr_control.analysis.stability import (THESIS_CFC_MARGINS, THESIS_OSPC_PHASE_MARGIN_105KG, Platform,
                                             cfc_open_loop, closed_loop_stable, controller_params, margins,
                                             ospc_open_loop, platform_model, stiffness_ratio)
from cdpr_control.control.cable_force_control import CFCParams
from cdpr_control.control.loop import ControlLoopParams
from cdpr_control.control.force_setpoint import ForceSetpointParams
from cdpr_control.control.ospc import OSPCParams
from cdpr_control.control.safety import SafetyConfig
from cdpr_control.model.robot import load_robot
from cdpr_sim.closed_loop import run
from cdpr_tools.cli import main as cdpr

ROBOTS = {name: load_robot(name) for name in ("ipanema3", "ipanema3_mini")}


# these tests drive the loops past their critical gains on purpose: the force watch, which would
# hold them (tests/control/test_force_watch.py), is off
UNWATCHED = SafetyConfig(force_watch=False)

def test_cfc_margins_of_fig_3_11():
    """Table 3.1 gains, PT1 + 6.3 ms dead time, Pade (3.18) of order 2, continuous controller."""
    m = margins(cfc_open_loop(ROBOTS["ipanema3"], CFCParams(), dt=0.0))
    assert m.gain_dB == pytest.approx(THESIS_CFC_MARGINS["gain_dB"], abs=1.0)
    assert m.phase_deg == pytest.approx(THESIS_CFC_MARGINS["phase_deg"], abs=5.0)


def test_ospc_margins_of_fig_3_10():
    """Section 3.3.2's example: c_z = 28,500 N/m, d = 83.3 N s/m, z axis, m_p = 25 and 105 kg."""
    robot = ROBOTS["ipanema3"]
    loops = {m: ospc_open_loop(robot, Platform(np.full(6, m), np.full(6, 28500.0), np.full(6, 83.3)), 2,
                               OSPCParams(), dt=0.0, absolute_damping=True) for m in (25.0, 105.0)}
    light, heavy = margins(loops[25.0]), margins(loops[105.0])
    assert light.gain_dB > 10.0 and light.phase_deg > 90.0                    # "higher than 10 dB, 90 deg"
    assert heavy.phase_deg == pytest.approx(THESIS_OSPC_PHASE_MARGIN_105KG, abs=1.5)


@pytest.mark.parametrize("name", ROBOTS)
def test_margins_agree_with_the_closed_loop_poles(name):
    robot = ROBOTS[name]
    L = cfc_open_loop(robot, CFCParams())
    m = margins(L)
    assert closed_loop_stable(0.9 * m.gain * L) and not closed_loop_stable(1.1 * m.gain * L)
    plat = platform_model(robot, robot.home)
    L = ospc_open_loop(robot, plat, 2, OSPCParams())
    m = margins(L)
    assert closed_loop_stable(0.9 * m.gain * L) and not closed_loop_stable(1.1 * m.gain * L)


def test_linear_stiffness_model_raises_the_loop_gain_at_high_tension():
    """The progressive cable is stiffer than k_spec / l_t: kappa > 1 grows with the force."""
    robot = ROBOTS["ipanema3"]
    kappa = stiffness_ratio(robot, np.array([100.0, 1500.0, 3000.0]), 5.0, "linear")
    assert 0.6 < kappa[0] < kappa[1] < kappa[2]
    np.testing.assert_allclose(stiffness_ratio(robot, np.array([100.0, 3000.0]), 5.0), 1.0)
    assert kappa[2] == pytest.approx(cable.tangent_stiffness(robot, 3000.0, 5.0) / (9e5 / 5.0))
    assert margins(cfc_open_loop(robot, kappa=kappa[2])).gain == pytest.approx(
        margins(cfc_open_loop(robot)).gain / kappa[2], rel=1e-6)


def _envelope(signal, early, late):
    """Peak-to-peak of the largest channel in two windows (index slices)."""
    return np.ptp(signal[early], axis=0).max(), np.ptp(signal[late], axis=0).max()


@pytest.mark.parametrize("name", ROBOTS)
def test_cfc_gain_margin_predicts_the_simulated_loop(name):
    """A step of the force set-point at home (tension level 0 -> 0.1 at t = 0) with K_p at 0.7 and
    1.6 times the critical gain of the margins: the forces settle to a ripple below 10 % of the PI's
    output range, resp. end in a limit cycle across half of it."""
    robot = ROBOTS[name]
    cfc, ospc, dt = controller_params(robot)
    critical = cfc.K_p * margins(cfc_open_loop(robot, cfc, dt=dt)).gain
    amplitude = {}
    for factor in (0.7, 1.6):
        params = ControlLoopParams(cfc=CFCParams(**{**cfc.__dict__, "K_p": factor * critical}), ospc=ospc,
                                   force=ForceSetpointParams(tension_level=0.1, tension_rate=0.0),
                                   safety=UNWATCHED)
        r = run(robot, lambda t: (robot.home, np.zeros(6), np.zeros(6)), 1.2, params, tension_level=0.0)
        assert np.mean(r.f_d[0] - r.f[0]) > 0.02 * np.max(robot.cable.f_max - robot.cable.f_min)
        amplitude[factor] = _envelope(r.f, slice(100, 400), slice(900, 1200))
    output_range = cfc.F_sat_n + cfc.F_sat_p
    early, late = amplitude[0.7]
    assert late < 0.1 * output_range and late < early, amplitude
    assert amplitude[1.6][1] > 0.5 * output_range, amplitude


@pytest.mark.parametrize("name, axis", [("ipanema3", 2), ("ipanema3_mini", 1)])
def test_ospc_gain_margin_predicts_the_simulated_step(name, axis):
    """A 1 mm (Mini 0.2 mm) step on the axis with the least margin, CFC off as in (3.17): at 0.5
    times the critical gain the platform oscillation decays, at 2.5 times it grows (or already
    swings across half the OSPC's output range)."""
    robot = ROBOTS[name]
    cfc, ospc, dt = controller_params(robot)
    plat = platform_model(robot, robot.home)
    critical = ospc.K_p[axis] * margins(ospc_open_loop(robot, plat, axis, ospc, dt)).gain
    f_n = np.sqrt(plat.c[axis] / plat.m[axis]) / (2 * np.pi)
    band = butter(2, [0.5 * f_n, 2.0 * f_n], btype="band", fs=1.0 / dt, output="sos")
    step = np.array(robot.home, dtype=float)
    step[axis] += 1e-3 if name == "ipanema3" else 2e-4
    n = int(round((2.0 if name == "ipanema3" else 0.8) / dt))
    amplitude = {}
    for factor in (0.5, 2.5):
        K_p = np.array(ospc.K_p, dtype=float)
        K_p[axis] = factor * critical
        params = ControlLoopParams(cfc_enabled=False, cfc=cfc, ospc=OSPCParams(K_p, ospc.T_i, ospc.x_sat),
                                   safety=UNWATCHED)
        r = run(robot, lambda t: (step if t >= 0.05 else robot.home, np.zeros(6), np.zeros(6)), n * dt, params)
        y = sosfiltfilt(band, r.x[:, axis])[100:-100, None]
        w = len(y) // 5
        amplitude[factor] = _envelope(y, slice(0, w), slice(4 * w, 5 * w))
    early, late = amplitude[0.5]
    assert late < 0.5 * early, amplitude
    early, late = amplitude[2.5]
    assert late > 1.5 * early or late > ospc.x_sat[axis], amplitude


def test_cli_stability(tmp_path, capsys):
    assert cdpr(["analyze", "stability", "--robot", "ipanema3", "--plot-dir", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "critical K_p" in out and "CFC (3.21)" in out and "OSPC (3.17)" in out
    assert (tmp_path / "stability_ipanema3.png").stat().st_size > 1000
