"""Bumpless transfer (issue 17, item 2) and the start-up calibration of Δq_0 (item 4)."""
import numpy as np
import pytest

from cdpr_control.model import cable
from cdpr_control.control.bumpless import Blend
from cdpr_control.control.params import control_loop_params
from cdpr_control.control.pose_estimator import PoseEstimator
from cdpr_control.model.kinematics import inverse_kinematics
from cdpr_control.model.robot import load_robot
from cdpr_sim.closed_loop import hold, run
from cdpr_sim.startup import startup_forces
from poses import encoder_lengths


def test_blend_ramps_both_ways():
    b = Blend(0.01, 1e-3, active=False)
    values = [b.update(True) for _ in range(12)]
    assert values[0] == pytest.approx(0.1) and values[9] == pytest.approx(1.0) and values[-1] == 1.0
    assert [round(b.update(False), 6) for _ in range(2)] == [0.9, 0.8]


def _switch_run(robot, switch, duration=4.0, payload=3.0):
    """Hold home with an unknown payload; ``switch(k, loop)`` changes the configuration live.
    Returns the run and the commanded θ_d per period (default, mismatched plant)."""
    thetas = []

    def before(k, loop, sim):
        switch(k, loop)
        if loop.command.theta_d is not None:
            thetas.append(loop.command.theta_d.copy())

    params = control_loop_params(robot, mode="ik_only")
    # IK only with a payload it does not know leaves cable 5 of the Mini slack (0 N) before the
    # switch: the force watch would hold there (rightly; tests/control/test_force_watch.py), and
    # these tests are about the switch itself
    params.safety.force_watch = False
    r = run(robot, hold(robot.home), duration, params, payload=payload, before_step=before)
    return r, np.array(thetas)


def test_switch_from_ik_only_to_force_control_is_bumpless():
    """2 s IK-only with a 3 kg payload the controller does not know (the OSPC would wind up to
    x_sat, the CFC saturate), then force control: θ_d moves by less than 20 um per period
    (before: up to v_max dt = 2 mm) and the platform does not jump."""
    robot = load_robot("ipanema3_mini")

    def switch(k, loop):
        if k == 2000:
            loop.params.mode = "force_control"

    r, theta_d = _switch_run(robot, switch)
    step = np.abs(np.diff(theta_d[1990:], axis=0)).max()
    assert step < 20e-6
    z = r.x[1990:, 2]
    assert np.abs(np.diff(z)).max() < 20e-6              # no jump of the platform
    assert abs(r.x[-1, 2] - robot.home[2]) < abs(r.x[1999, 2] - robot.home[2])   # and the sag is removed


def test_cfc_enabled_live_is_blended_in():
    """Force control with the OSPC only, then the CFC enabled live (the OSPC cannot be switched
    off on the Mini: K_g is indefinite there, tests/control/test_stability_preconditions.py)."""
    robot = load_robot("ipanema3_mini")

    def switch(k, loop):
        if k == 0:
            loop.params.mode = "force_control"
            loop.params.cfc_enabled = False
            loop.blend_cfc.value = 0.0
            loop.blend_ospc.value = 1.0
        if k == 1500:
            loop.params.cfc_enabled = True

    r, theta_d = _switch_run(robot, switch, duration=2.5)
    assert np.abs(np.diff(theta_d[1490:], axis=0)).max() < 20e-6
    assert np.abs(np.diff(r.x[1490:, 2])).max() < 20e-6


def test_start_away_from_home_with_the_home_calibration_has_no_bias():
    robot = load_robot("ipanema3")
    x0 = robot.home + np.r_[1.0, 0.5, -0.3, 0, 0, 0]
    f_home, f_x = startup_forces(robot, robot.home, 0.3), startup_forces(robot, x0, 0.3)
    theta = encoder_lengths(robot, x0, f_x, f_home)
    first_sample = PoseEstimator(robot)
    home = PoseEstimator(robot)
    home.calibration.set_home(robot, f_home)
    for _ in range(3):
        x_first, _ = first_sample.update(theta, f_x, x0)
        x_home, _ = home.update(theta, f_x, x0)
    # 11 um left: the FK takes l_t of the encoder length, this test of the IK length (2.14)
    assert np.linalg.norm(x_home[:3] - x0[:3]) < 2e-5
    assert np.linalg.norm(x_first[:3] - x0[:3]) > 1e-3      # the start-up sample's forces bias it


def test_one_noisy_start_up_sample_does_not_bias_the_fk():
    """A start at home whose first force sample carries 3 sigma of noise (IPAnema 3: 6 N): averaged
    over the 100-sample window the pose estimate is 5x closer than with that one sample."""
    robot = load_robot("ipanema3")
    f = startup_forces(robot, robot.home, 0.3)
    theta = encoder_lengths(robot, robot.home, f, f)
    rng = np.random.default_rng(4)
    noise = rng.normal(0.0, 2.0, (200, robot.m))
    noise[0] = 6.0 * np.sign(noise[0])
    est, single = PoseEstimator(robot), PoseEstimator(robot, calibration_window=1)
    for k in range(200):
        x, _ = est.update(theta, f + noise[k], robot.home)
        single.update(theta, f + noise[k], robot.home)
    x, _ = est.update(theta, f, robot.home)
    x_single, _ = single.update(theta, f, robot.home)
    err, err_single = np.linalg.norm(x[:3] - robot.home[:3]), np.linalg.norm(x_single[:3] - robot.home[:3])
    assert err < 0.2 * err_single
