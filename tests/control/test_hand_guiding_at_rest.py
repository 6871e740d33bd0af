"""Hand guiding (thesis 5.2) with nobody pushing holds still on both robots, on the default
(mismatched) and the nominal plant, at home and near the border of the wrench-feasible workspace;
the shipped admittance sets keep the loop margins of `cdpr analyze stability`."""
import numpy as np
import pytest

from cdpr_control.control.bumpless import START_RAMP
from cdpr_control.control.admittance import settings_from
from cdpr_control.control.admittance_zones import per_axis
from cdpr_control.analysis.stability import (MIN_GAIN_MARGIN_DB, MIN_PHASE_MARGIN_DEG, NOISE_DEAD_BAND_SIGMAS,
                                             admittance_margins, admittance_values, wrench_noise)
from cdpr_control.control.params import control_loop_params
from cdpr_control.model.dynamics import gravity_wrench
from cdpr_control.model.robot import load_robot
from cdpr_control.model.workspace import feasible_poses
from cdpr_sim.closed_loop import hold, run
from cdpr_sim.hand_guiding import guiding_run
from cdpr_sim.simulator import SimConfig

ROBOTS = {name: load_robot(name) for name in ("ipanema3", "ipanema3_mini")}
# 90 % of the way from home to the border of the WFW (QP, zero orientation, the f_min the force
# distribution plans with) along a direction: within 10 % of the hull's border
BORDER = {"ipanema3": [[-3.434, 3.434, 2.217], [1.175, -0.588, -0.675]],
          "ipanema3_mini": [[-0.163, 0.163, 0.082], [0.269, -0.134, -0.269]]}
# a virtual workspace small enough for its hard box to fit near the border
SMALL_ZONES = {"ipanema3": {"zones.free.box": [0.03, 0.03, 0.03, 0.005, 0.005, 0.005], "zones.rest.radius": 0.02,
                            "zones.wall.c": [8000.0, 8000.0, 8000.0, 2000.0, 2000.0, 2000.0],
                            "v_max": [0.1, 0.1, 0.1, 0.02, 0.02, 0.02]},
               "ipanema3_mini": {"zones.free.box": [0.006, 0.006, 0.006, 0.002, 0.002, 0.002], "zones.rest.radius": 0.004,
                                 "zones.wall.c": [3000.0, 3000.0, 3000.0, 50.0, 50.0, 50.0],
                                 "v_max": [0.05, 0.05, 0.05, 0.02, 0.02, 0.02], "w_max": [10.0, 10.0, 10.0, 0.2, 0.2, 0.2]}}
# s: switched on once the start-up transient has settled (the forces raised to the planned f_min;
# near the IPAnema 3's border its z oscillation after start-up lasts about 1 s)
ENABLE, DURATION = 1.0, 2.0


def _poses(name):
    robot = ROBOTS[name]
    return [("home", np.array(robot.home, dtype=float), {})] + [
        (f"border{i}", np.r_[p, 0.0, 0.0, 0.0], SMALL_ZONES[name]) for i, p in enumerate(BORDER[name])]


def test_the_border_poses_are_near_the_border():
    for name, robot in ROBOTS.items():
        f_min = control_loop_params(robot).force.f_min
        for p in BORDER[name]:
            x = np.r_[p, 0.0, 0.0, 0.0]
            home = np.array(robot.home, dtype=float)
            beyond = home + (x - home) / 0.9 * 1.01                     # 1 % past the border
            assert feasible_poses(robot, np.array([x, beyond]), "qp", f_min=f_min).tolist() == [True, False]


@pytest.mark.parametrize("name", ROBOTS)
def test_shipped_admittance_sets_keep_the_margins_at_home_and_near_the_border(name):
    robot = ROBOTS[name]
    for _, x, zones_override in _poses(name):
        values = {**admittance_values(robot), **zones_override}
        params, zones, _ = settings_from(values, robot, check_workspace=False)
        for zone, per_zone in zip(zones.zones, admittance_margins(robot, x, zones, params.user.T_filter)):
            for axis, m in enumerate(per_zone):
                assert m.gain_dB >= MIN_GAIN_MARGIN_DB and m.phase_deg >= MIN_PHASE_MARGIN_DEG, (name, x, zone.name, axis, m)


def test_the_ipanema3_admittance_of_before_was_unstable():
    """The set that excited itself (virtual masses 20 kg, 2 kg m^2 < the platform's 25 kg, 5.25 kg m^2)."""
    robot = ROBOTS["ipanema3"]
    values = {**admittance_values(robot), "T_filter": 0.003,
              **{f"zones.{z}.m": [20.0, 20.0, 20.0, 2.0, 2.0, 2.0] for z in ("rest", "free", "wall")},
              **{f"zones.{z}.d": [600.0, 600.0, 600.0, 20.0, 20.0, 20.0] for z in ("rest", "free", "wall")}}
    params, zones, _ = settings_from(values, robot, check_workspace=False)
    worst = min(m.gain_dB for per_zone in admittance_margins(robot, robot.home, zones, 0.003) for m in per_zone)
    assert worst < 0.0


@pytest.mark.parametrize("name", ROBOTS)
def test_dead_band_lies_above_the_filtered_sensor_noise(name):
    robot = ROBOTS[name]
    params, _, _ = settings_from(admittance_values(robot), robot, check_workspace=False)
    for _, x, _ in _poses(name):
        noise = wrench_noise(robot, x, params.user.T_filter)
        assert np.all(per_axis(params.user.dead_band, "dead_band") >= NOISE_DEAD_BAND_SIGMAS * noise * 0.999)


@pytest.mark.parametrize("pose", [0, 1, 2])
@pytest.mark.parametrize("plant", ["mismatched", "nominal"])
@pytest.mark.parametrize("name", ROBOTS)
def test_guided_platform_at_rest_stands_still(name, plant, pose):
    """Nobody pushing: the platform moves < 1 mm, the user wrench stays < 5 % of w_max, every cable
    keeps f_min, at home and near the border."""
    robot = ROBOTS[name]
    label, x, zones_override = _poses(name)[pose]
    g = guiding_run([], DURATION, zones_override, robot_name=name, x_hold=x, config=SimConfig(plant=plant),
                    enable_at=ENABLE)
    r = g.run
    on = r.t > ENABLE + 2e-3
    w_user = np.array([o.w_user for o in g.source.outputs])[-int(on.sum()):]
    moved = np.abs(r.x[on, :3] - r.x[on, :3][0]).max()
    assert g.source.controller.active
    assert moved < 1e-3, moved
    assert np.all(np.abs(w_user) < 0.05 * g.source.controller.user.w_max), np.abs(w_user).max(axis=0)
    assert r.f[on].min() >= robot.cable.f_min.min(), r.f[on].min()


def test_the_noise_model_is_the_simulated_idle_wrench():
    """wrench_noise (the basis of the dead band) against the measured wrench of the IPAnema 3
    holding home on the nominal plant, unfiltered (the PT1's factor on white noise is arithmetic),
    over the half second after the start ramp (START_RAMP, docs/control.md) has ended."""
    robot = ROBOTS["ipanema3"]
    w = []
    start = int(round(2 * START_RAMP / 1e-3))
    run(robot, hold(robot.home), 2 * START_RAMP + 0.5, config=SimConfig(plant="nominal"),
        before_step=lambda k, loop, sim: w.append(loop.state.w.copy()) if k > start else None)
    w = np.array(w) - gravity_wrench(robot, robot.home)
    np.testing.assert_allclose(w.std(axis=0), wrench_noise(robot, robot.home, 0.0), rtol=0.15)
