"""The stability check behind the OSPC and CFC nodes' parameter validation (issue 28, item 5):
cfc_instability and ospc_instability (thesis 3.4) pass the shipped gain sets of both robots and
name the margins of the unstable sets of issue 28 (OSPC K_p x100, CFC K_p 10 with T_i 1 ms, T_i
1 ms alone). The nodes' refusal itself: tests/graph/test_force_watch_graph.py."""
from dataclasses import replace

import numpy as np
import pytest

from cdpr_control.analysis.stability import (cfc_instability, controller_params, margins, ospc_instability,
                                             ospc_open_loop, platform_model)
from cdpr_control.model.robot import load_robot

ROBOTS = ["ipanema3_mini", "ipanema3"]


@pytest.mark.parametrize("name", ROBOTS)
def test_the_shipped_gains_are_stable(name):
    robot = load_robot(name)
    cfc, ospc, dt = controller_params(robot)
    assert cfc_instability(robot, cfc, dt) is None
    assert ospc_instability(robot, ospc, dt) is None


@pytest.mark.parametrize("name", ROBOTS)
@pytest.mark.parametrize("change", [{"K_p": 10.0, "T_i": 1e-3}, {"T_i": 1e-3}])
def test_unstable_cfc_gains_are_named_with_their_margins(name, change):
    robot = load_robot(name)
    cfc, _, dt = controller_params(robot)
    reason = cfc_instability(robot, replace(cfc, **change), dt)
    assert reason is not None and "cable force control (3.21)" in reason and "T_i 0.001 s" in reason
    gain_dB = float(reason.split("gain margin ")[1].split(" dB")[0])
    phase = float(reason.split("phase margin ")[1].split(" deg")[0])
    assert gain_dB <= 0.0 or phase <= 0.0


def test_ospc_x100_is_unstable_and_x10_on_the_mini_is_unstable_only_in_y():
    robot = load_robot("ipanema3_mini")
    _, ospc, dt = controller_params(robot)
    unstable = replace(ospc, K_p=np.full(6, 7.0))
    reason = ospc_instability(robot, unstable, dt)
    # the margin named is axis x's at home (with the shipped T_i 0.06 s: -12.9 dB; -12.8 dB with 0.18 s)
    gain_dB = margins(ospc_open_loop(robot, platform_model(robot, robot.home), 0, unstable, dt)).gain_dB
    assert reason is not None and "axis x with K_p 7" in reason
    assert f"gain margin {gain_dB:.1f} dB" in reason and gain_dB < -12.0     # critical K_p 1.6 (x, minimal tension)
    reason = ospc_instability(robot, replace(ospc, K_p=10 * ospc.K_p), dt)
    assert reason is not None and "axis y with K_p 0.7" in reason
