"""Margins of the contact force loop in D (cdpr_control.analysis.contact_margin): the sampled plant
against its continuous model, a closed form, the margins against a brute-force run of the
discrete closed loop (stable just below the gain margin, growing just above it) per case type,
and IPAnema 3 sweep pose #33 against what the simulation showed (docs/hybrid_force_control.md,
"Session 14" and "Contact margin (session 14)")."""
from dataclasses import replace

import numpy as np
import pytest

from cdpr_control.analysis.contact_margin import (ContactLoop, DriveModel, case_margins, closed_loop_response,
                                                  discretise, loop_of, margins, platform_plant, pressing_forces)
from cdpr_control.control.hybrid_force_control import HPFCParams
from cdpr_control.control.params import load_params_file
from cdpr_control.model.robot import load_robot
from cdpr_sim.contacts import default_tool

DT = 1e-3
POSE_33 = [-7.2685344097211875, 3.305209819739374, 1.2619961939683546, 0.0, 0.0, 0.0]   # IPAnema 3, border
K_MET_33 = 46744.0          # N/m, met in B there (seed 2, 1e5 N/m floor, 500 N)
DOWN = np.array([0.0, 0.0, -1.0])


def shipped(robot_name):
    values = load_params_file(robot_name)["hybrid_force_controller"]
    return HPFCParams(**{k: float(v) for k, v in values.items() if k in HPFCParams.__dataclass_fields__})


def tool_point(robot):
    radius, centre = default_tool(np.asarray(robot.b))
    return np.asarray(centre) - np.array([0.0, 0.0, radius])


def growth(loop, scale, periods=6000):
    """The force's swing (max - min) over the last 1000 periods after a unit step of F_d."""
    return float(np.ptp(closed_loop_response(loop, periods, scale)[-1000:]))


@pytest.mark.parametrize("model,T_d,T_1,T_w,zeta", [("pt1_deadtime", 0.0063, 0.000745, 0.0, 1.0),
                                                     ("pt1_deadtime", 0.00758, 0.000672, 0.0, 1.0),
                                                     ("second_order", 0.0013, 0.0, 0.0139, 0.587)])
def test_the_sampled_drive_follows_its_continuous_model_with_half_a_period_of_hold(model, T_d, T_1, T_w, zeta):
    drive = DriveModel(model, T_d, T_1, T_w, zeta)
    for f in (0.5, 2.0, 5.0):
        w = 2.0 * np.pi * f
        s = 1j * w
        rational = 1.0 / (1.0 + T_1 * s) if model == "pt1_deadtime" else 1.0 / (1.0 + 2 * zeta * T_w * s + (T_w * s) ** 2)
        # the hold's e^{-s dt / 2} and sinc, one period of the loop's sampling (the command of k acts from k on,
        # the sample at k + 1 sees it): e^{-s dt} dt-delay of the sample; together e^{-s (T_d + dt / 2)} sinc
        expected = rational * np.exp(-s * (T_d + DT / 2)) * np.sinc(f * DT)
        got = discretise(drive, DT).response(np.array([np.exp(s * DT)]))[0]
        assert abs(got - expected) < 2e-3 * abs(expected)


@pytest.mark.parametrize("N", [0, 3, 7])
def test_a_p_loop_over_a_whole_period_dead_time_has_the_closed_form_gain_margin(N):
    # L = (k_met / k_pid) z^-(N+1): unstable exactly where the gain reaches 1, crossing at pi / ((N + 1) dt)
    loop = ContactLoop(DT, K_p=1e12, T_i=1e12, T_d=0.0, T_F=0.0, k_pid=50000.0, k_met=20000.0,
                       drive=DriveModel("pt1_deadtime", N * DT, 0.0))
    m = margins(loop)
    assert m.gain == pytest.approx(2.5, rel=1e-6)
    assert m.w_phase == pytest.approx(np.pi / ((N + 1) * DT), rel=1e-6)
    assert m.phase_deg == np.inf                                     # |L| < 1 everywhere
    assert growth(loop, 0.97 * m.gain, 3000) < 1e-3 < growth(loop, 1.03 * m.gain, 3000)


def _platform_33(drive=None, k_pid=None):
    robot = load_robot("ipanema3")
    p = shipped("ipanema3")
    r_c = tool_point(robot)
    f = pressing_forces(robot, POSE_33, DOWN, 500.0, r_c, 150.0, robot.cable.f_max)
    plant = platform_plant(robot, POSE_33, f, DOWN, r_c, K_MET_33)
    return loop_of(p, robot.drive if drive is None else drive, DT, K_MET_33, k_pid, plant), plant


def _mini_home():
    robot = load_robot("ipanema3_mini")
    p = shipped("ipanema3_mini")
    r_c = tool_point(robot)
    f = pressing_forces(robot, np.zeros(6), DOWN, 10.0, r_c, 5.0, robot.cable.f_max)
    k_met = 0.8 * p.K_p
    return loop_of(p, robot.drive, DT, k_met, None, platform_plant(robot, np.zeros(6), f, DOWN, r_c, k_met))


@pytest.mark.parametrize("case", ["ipanema3 static", "ipanema3 #33 platform", "ipanema3 #33 platform, old P gain",
                                  "mini home platform"])
def test_the_gain_margin_separates_a_decaying_from_a_growing_discrete_closed_loop(case):
    if case == "ipanema3 static":
        robot = load_robot("ipanema3")
        loop = loop_of(shipped("ipanema3"), robot.drive, DT, K_MET_33)
    elif case == "ipanema3 #33 platform":
        loop, _ = _platform_33()
    elif case == "ipanema3 #33 platform, old P gain":
        loop, _ = _platform_33(k_pid=shipped("ipanema3").K_p)
    else:
        loop = _mini_home()
    m = margins(loop)
    assert np.isfinite(m.gain)
    assert growth(loop, 0.95 * m.gain) < 0.2 < 1e3 < growth(loop, 1.05 * m.gain)


def test_the_platform_model_meets_the_stiffness_b_measured_at_rest_and_the_cables_above_its_modes():
    loop, plant = _platform_33()
    assert plant.static_gain() == pytest.approx(K_MET_33, rel=1e-9)
    dd = loop.sampled
    slow = dd.response(np.array([np.exp(1j * 2 * np.pi * 0.05 * DT)]))[0]
    assert abs(slow) == pytest.approx(K_MET_33, rel=2e-3)
    # well above the platform's modes (<= 42 Hz here) the force follows the winches with the cables'
    # stiffness along z_t, many times k_met (the finding of session 14's #33)
    fast = abs(dd.response(np.array([np.exp(1j * 2 * np.pi * 52.0 * DT)]))[0])
    assert fast > 5.0 * K_MET_33


def test_sweep_pose_33_old_gain_unstable_session_14_gain_three_to_six_db_on_seed_2s_drive():
    """The simulation (seed 2): P over K_p grew at 52 Hz (held), over k_met / 1.8 held, over
    k_met / 1.5 passed, over k_met: 1.5-1.8 from the edge (3.5-5 dB)."""
    robot = load_robot("ipanema3")
    seed_2 = replace(DriveModel.of(robot.drive), T_d=0.00758, T_1=0.000672)    # the plant's (cdpr_sim.plant, seed 2)
    K_p = shipped("ipanema3").K_p
    old = margins(_platform_33(seed_2, K_p)[0])
    assert old.gain_dB < 0.0
    assert 45.0 < old.f_phase < 65.0                                  # the simulation's 52 Hz
    assert margins(_platform_33(seed_2, K_MET_33 / 1.8)[0]).gain_dB < 0.5
    assert margins(_platform_33(seed_2, K_MET_33 / 1.5)[0]).gain_dB > 0.0
    assert 3.0 < margins(_platform_33(seed_2, K_MET_33)[0]).gain_dB < 6.0
    # the controller's own drive model (the robot file) gives more: the plant's extra dead time
    assert margins(_platform_33()[0]).gain_dB > margins(_platform_33(seed_2)[0]).gain_dB


def test_case_margins_is_the_platform_loop_at_the_pressing_forces():
    robot = load_robot("ipanema3")
    p = shipped("ipanema3")
    m = case_margins(robot, p, DT, POSE_33, DOWN, 500.0, tool_point(robot), K_MET_33, K_MET_33, 150.0,
                     robot.cable.f_max)
    assert m.gain == pytest.approx(margins(_platform_33()[0]).gain, rel=1e-9)


def test_the_p_part_over_k_met_keeps_6_db_at_pose_33_on_the_robot_files_drive_and_1_15_k_met_with_1_5_ms_more():
    """The controller's P part over P_MARGIN_FACTOR k_met (1, session 14's): 6 dB and 45 deg at #33
    (the sweep's worst case) on the robot file's drive, not with the mismatch file's 1.5 ms of extra
    dead time, which over 1.15 k_met (tried, not kept: docs) keeps 6 dB."""
    from cdpr_control.control.hybrid_force_control import P_MARGIN_FACTOR
    robot = load_robot("ipanema3")
    nominal = DriveModel.of(robot.drive)
    slow = replace(nominal, T_d=robot.drive.T_d + 0.0015)
    assert margins(_platform_33(nominal, P_MARGIN_FACTOR * K_MET_33)[0]).meets(6.0, 45.0)
    assert not margins(_platform_33(slow, K_MET_33)[0]).meets(6.0, 45.0)
    assert margins(_platform_33(slow, 1.15 * K_MET_33)[0]).meets(6.0, 45.0)
