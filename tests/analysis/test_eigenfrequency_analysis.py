"""Eigenfrequencies over the workspace (thesis 4.3): tension shift, K_g definiteness, coupled modes
against the simulator's free oscillation."""
import numpy as np
import pytest
from scipy.optimize import least_squares

from cdpr_control.analysis.eigenfrequencies import (TABLE_4_5, THESIS_SHIFT, modes, shift_statistics,
                                                    stiffness_map, workspace_study)
from cdpr_control.model.dynamics import mass_matrix
from cdpr_control.model.robot import load_robot
from cdpr_control.model import cable
from cdpr_control.model.kinematics import inverse_kinematics
from cdpr_control.model.stiffness import geometric_stiffness
from cdpr_sim.simulator import SimConfig, Simulator
from cdpr_sim.startup import startup_state
from cdpr_tools.cli import main as cdpr

IPANEMA3 = load_robot("ipanema3")


def test_map_uses_4_8_with_the_tangent_cable_stiffness_at_the_qp_forces():
    x = np.array([1.0, -0.5, 0.8, 0.0, 0.0, 0.0])
    s = stiffness_map(IPANEMA3, x, 0.3, payload=20.0)
    f = s.f[0]
    assert np.allclose(load_robot("ipanema3").with_payload(20.0).platform.mass, 45.0)
    # z axis by hand: c_z = sum_i k_i u_iz^2 + (K_g)_zz, (4.8) with m_p = 45 kg
    ik = inverse_kinematics(IPANEMA3, x)
    k = cable.tangent_stiffness(IPANEMA3, f, cable.total_free_length(IPANEMA3, ik.q))
    c_z = np.sum(k * ik.AT[2] ** 2) + geometric_stiffness(ik, f)[2, 2]
    assert s.f_axis[0, 2] == pytest.approx(np.sqrt(c_z / 45.0) / (2 * np.pi), rel=1e-12)
    freq, _ = modes(IPANEMA3.with_payload(20.0), x, f)
    np.testing.assert_allclose(s.f_modes[0], freq, rtol=1e-9)


def test_tension_shift_over_the_workspace_matches_section_4_3():
    """The thesis measures 15-30 % from the lowest to the highest tension level (own weight)."""
    study = workspace_study(IPANEMA3, step=0.5, payloads=(0.0, 80.0))
    s = shift_statistics(study, 0.0)
    assert s["poses"] > 300
    lo, median, hi = s["axis_z"]
    assert THESIS_SHIFT[0] <= median <= THESIS_SHIFT[1]
    assert lo > 0.05 and hi < 0.35
    # with payload the relative shift is smaller (section 4.4.3: less room for internal forces)
    assert shift_statistics(study, 80.0)["axis_z"][1] < median
    # every feasible map point: stiffer with more tension
    low, high = study.maps[("minimal", 0.0)], study.maps[("maximal", 0.0)]
    ok = low.feasible & high.feasible
    assert np.all(high.f_axis[ok, 2] > low.f_axis[ok, 2])


def test_payload_halves_the_z_frequency_as_fig_4_26():
    x = [0.0, 0.0, 0.5, 0.0, 0.0, 0.0]
    f25 = stiffness_map(IPANEMA3, x, 0.5).f_axis[0, 2]
    f105 = stiffness_map(IPANEMA3, x, 0.5, payload=80.0).f_axis[0, 2]
    assert f105 / f25 == pytest.approx(np.sqrt(25.0 / 105.0), rel=0.1)   # thesis: 7.0 -> 3.5 Hz


def test_geometric_stiffness_definiteness_depends_on_tension_as_section_4_3():
    """Section 4.3 (m_p = 105 kg): at points 1, 2 and 4 of Table 4.5 the minimal eigenvalue of K_g
    is positive only for the higher tension levels."""
    x = np.hstack([TABLE_4_5, np.zeros((7, 3))])
    low = stiffness_map(IPANEMA3, x, 0.0, payload=80.0)
    high = stiffness_map(IPANEMA3, x, 1.0, payload=80.0)
    for i in (0, 1, 3):
        assert low.eig_K_g[i, 0] < 0.0 < high.eig_K_g[i, 0]
    # the cable stiffness is one to two magnitudes above the geometric one (Fig. 4.28)
    ratio = high.eig_K_c[:, 1] / high.eig_K_g[:, 1]
    assert np.all((ratio > 10.0) & (ratio < 1000.0))


def _fit_frequency(t, y):
    """Undamped frequency [Hz] of a damped oscillation y(t) (least squares, started at the FFT peak)."""
    n = 8 * len(y)
    spectrum = np.abs(np.fft.rfft(y - y.mean(), n))
    f0 = np.fft.rfftfreq(n, t[1] - t[0])[np.argmax(spectrum[1:]) + 1]

    def residual(p):
        A, B, sigma, omega, c = p
        return np.exp(-sigma * t) * (A * np.cos(omega * t) + B * np.sin(omega * t)) + c - y

    fits = [least_squares(residual, (y[0], 0.0, 1.0, 2 * np.pi * f, 0.0), x_scale="jac") for f in (0.9 * f0, f0, 1.1 * f0)]
    _, _, sigma, omega, _ = min(fits, key=lambda s: s.cost).x
    return np.hypot(omega, sigma) / (2 * np.pi)


@pytest.mark.parametrize("point", [0, 5])
def test_coupled_modes_match_the_simulated_free_oscillation(point):
    """Table 4.5 points 1 and 6, medium tension: a knock on the held platform (drives hold, no
    controller); the motion projected on each model mode oscillates at that mode's frequency."""
    robot = IPANEMA3
    x0 = np.concatenate([TABLE_4_5[point], np.zeros(3)])
    f = stiffness_map(robot, x0, 0.5).f[0]
    freq, Phi = modes(robot, x0, f)
    M = mass_matrix(robot, x0)
    _, theta0, _ = startup_state(robot, x0, 0.5, calibrate_home=False)
    w = np.array([0.3, 0.4, 1.0, 0.03, 0.04, 0.035]) * 0.3 * robot.platform.mass * 9.81
    with Simulator(robot, SimConfig(substeps=5, friction=False, noise_std=0.0), x0=x0, theta0=theta0) as sim:
        sim.apply_pulse(w, shape="rectangle", duration=0.002)
        x = np.array([sim.step(theta0).x for _ in range(1400)])
    t = np.arange(1, 1401) * 1e-3
    eta = (x - x0) @ M @ Phi                                   # modal coordinates
    for j in range(6):
        window = (t > 0.005) & (t < 0.005 + 6.0 / freq[j])     # six periods of the mode
        f_sim = _fit_frequency(t[window], eta[window, j])
        assert f_sim == pytest.approx(freq[j], rel=0.05), (j, f_sim, freq[j])


def test_cli_eigenfrequencies(tmp_path, capsys):
    assert cdpr(["analyze", "eigenfrequencies", "--step", "1.0", "--plot-dir", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "thesis: 15-30 %" in out
    assert (tmp_path / "eigenfrequency_maps_80kg.png").stat().st_size > 1000
    assert (tmp_path / "stiffness_points.png").stat().st_size > 1000
