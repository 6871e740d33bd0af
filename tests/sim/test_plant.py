"""The simulator's plant (cdpr_sim.plant): its own parameters, seeded, within the stated bounds;
the perfect-model option; settlement under load (section 4.1.3)."""
import numpy as np
import pytest

from cdpr_control.model.kinematics import inverse_kinematics
from cdpr_control.model.robot import load_robot
from cdpr_sim.plant import Settlement, build_plant, mismatch_bounds
from cdpr_sim.simulator import SimConfig, Simulator, plant_of
from cdpr_sim.startup import calibration_forces, startup_state


@pytest.mark.parametrize("name", ["ipanema3", "ipanema3_mini"])
def test_mismatched_plant_differs_within_the_bounds_and_is_seeded(name):
    robot = load_robot(name)
    b = mismatch_bounds(name)
    p = build_plant(robot, "mismatched", seed=1)
    t = p.robot
    assert 0.2 * b["geometry"]["a"] < np.abs(t.a - robot.a).max() <= b["geometry"]["a"]
    assert 0.2 * b["geometry"]["b"] < np.abs(t.b - robot.b).max() <= b["geometry"]["b"]
    assert 0.0 < abs(t.cable.k0 / robot.cable.k0 - 1.0) <= b["cable"]["k0"]
    rel_mu = np.abs(t.friction.mu / robot.friction.mu - 1.0)
    assert 0.0 < rel_mu.max() <= b["friction"]["mu"]
    lo, hi = b["drive"]["extra_dead_time"]
    assert lo <= t.drive.T_d - robot.drive.T_d <= hi
    assert 0.0 < np.abs(p.gamma_1 - 1.0).max() <= b["sensor"]["gamma_1"]
    assert np.abs(p.gamma_0).max() <= b["sensor"]["gamma_0"] * robot.sensor.range
    again, other = build_plant(robot, "mismatched", seed=1), build_plant(robot, "mismatched", seed=2)
    np.testing.assert_array_equal(again.robot.a, t.a)
    assert not np.array_equal(other.robot.a, t.a)
    # the robot file itself is untouched
    np.testing.assert_array_equal(load_robot(name).a, robot.a)


def test_nominal_plant_is_the_robot_file():
    robot = load_robot("ipanema3_mini")
    p = build_plant(robot, "nominal")
    assert p.robot is robot and p.settlement_ratio == 0.0
    np.testing.assert_array_equal(p.gamma_1, robot.sensor.gamma_1)
    with pytest.raises(ValueError):
        SimConfig(plant="perfect")


def test_simulator_runs_the_plant_and_the_encoders_read_the_nominal_ik_at_home():
    robot = load_robot("ipanema3")
    config = SimConfig(noise_std=0.0, encoder_counts=0)
    x0, theta0, offset = startup_state(robot, robot.home, 0.3, calibrate_home=True, config=config)
    with Simulator(robot, config, x0=x0, theta0=theta0, encoder_offset=offset) as sim:
        assert sim.robot is not robot and sim.plant.robot is sim.robot
        np.testing.assert_allclose(sim.output.theta, inverse_kinematics(robot, robot.home).q, atol=1e-9)
        for _ in range(300):
            out = sim.step(sim.output.theta)
        assert np.abs(out.x[:3] - robot.home[:3]).max() < 1e-5       # at rest where it started
        # the sensors read the plant's forces through its own (off) lines
        f_cal = calibration_forces(sim, 0.3)
        assert 0.0 < np.abs(f_cal / out.f - 1.0).max() < 0.05


def test_settlement_grows_under_raised_load_and_never_shrinks():
    s = Settlement(ratio=0.3, T=2.0, k0=6e5, dt=1e-3, m=2)
    s.reset([1000.0, 1000.0])
    l_t = np.array([8.0, 8.0])
    for _ in range(20000):                                  # 20 s at +1000 N on cable 1
        s.update(np.array([2000.0, 1000.0]), l_t)
    assert s.s[0] == pytest.approx(0.3 * 8.0 * 1000.0 / 6e5, rel=1e-3)    # 4 mm
    assert s.s[1] == 0.0
    peak = s.s[0]
    for _ in range(1000):
        s.update(np.array([1000.0, 1000.0]), l_t)
    assert s.s[0] == peak                                   # lasting, as in section 4.1.3


def test_plant_of_is_what_the_simulator_runs():
    robot = load_robot("ipanema3_mini")
    config = SimConfig(plant_seed=5)
    with Simulator(robot, config) as sim:
        np.testing.assert_array_equal(sim.plant.robot.a, plant_of(robot, config).robot.a)
