"""Energy of a recorded run (cdpr analyze energy BAG): the balance of section 4.4 closes."""
import json

import numpy as np
import pytest

from cdpr_control.analysis.energy import platform_work
from cdpr_control.model.robot import load_robot
from cdpr_tools.analyze_energy import bag_power, record_lift
from cdpr_tools.bag import BagReader
from cdpr_tools.cli import main as cdpr

HEIGHT = 0.3


@pytest.fixture(scope="module")
def lift_bag(tmp_path_factory):
    """The IPAnema 3 platform (25 kg) lifted 0.3 m at 0.3 m/s in the simulator, IK-only control."""
    path = tmp_path_factory.mktemp("energy") / "lift"
    return record_lift(path, "ipanema3", height=HEIGHT, velocity=0.3, lower=False, pause=0.2)


def test_platform_work_plus_losses_equal_electrical_energy(lift_bag):
    robot = load_robot("ipanema3")
    flow, x, f = bag_power(BagReader(lift_bag), robot)
    E = flow.energies()
    # mechanical work at the platform from the laser-tracker pose, independent of the winch side
    W_platform = float(np.trapezoid(platform_work(robot, flow.t, x, f), flow.t))
    m_g_h = robot.platform.mass * 9.81 * (x[-1, 2] - x[0, 2])
    assert x[-1, 2] - x[0, 2] == pytest.approx(HEIGHT, abs=2e-3)
    assert W_platform == pytest.approx(m_g_h, rel=0.01)
    losses = E["E_pulley"] + E["E_winch"] + E["E_inertia"] + E["E_servo"] + E["E_cabinet"]
    drawn = E["E_el"] - robot.energy.P_0 * (flow.t[-1] - flow.t[0])    # beyond the idle power
    assert abs(W_platform + losses - E["E_el"]) < 0.01 * drawn
    assert W_platform > 0.15 * drawn                                    # the work is not negligible


def test_cli_reports_the_bag(lift_bag, tmp_path, capsys):
    out = tmp_path / "energy.json"
    png = tmp_path / "energy.png"
    assert cdpr(["analyze", "energy", str(lift_bag), "--robot", "ipanema3", "--json", str(out),
                 "--plot", str(png)]) == 0
    result = json.loads(out.read_text())["run"]
    assert result["E_mech_Wh"] == pytest.approx(25.0 * 9.81 * HEIGHT / 3600.0, rel=0.02)
    assert sum(result["loss_shares"].values()) == pytest.approx(1.0)
    assert png.stat().st_size > 1000
    assert "loss shares" in capsys.readouterr().out


def test_cli_trajectory_at_three_tension_levels(tmp_path):
    out = tmp_path / "trip.json"
    assert cdpr(["analyze", "energy", "--trajectory", "reference_trip_ipanema3", "--start", "0", "-1.2", "0.5",
                 "--payload", "100", "--json", str(out)]) == 0
    r = json.loads(out.read_text())
    assert r["minimal"]["E_el_Wh"] < r["medium"]["E_el_Wh"] < r["maximal"]["E_el_Wh"]


def test_sensor_forces_through_the_friction_compensation_give_the_same_energy(lift_bag):
    """Without ground truth (a real robot): F_s through (3.44) instead of the reference forces."""
    robot = load_robot("ipanema3")
    reference, _, _ = bag_power(BagReader(lift_bag), robot)
    sensor, _, _ = bag_power(BagReader(lift_bag), robot, sensor=True)
    idle = robot.energy.P_0 * (reference.t[-1] - reference.t[0])
    assert sensor.energy("P_el") - idle == pytest.approx(reference.energy("P_el") - idle, rel=0.05)
    assert sensor.energy("P_mech") == pytest.approx(reference.energy("P_mech"), rel=0.05)
