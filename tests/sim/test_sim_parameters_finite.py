"""winch_platform_sim refuses non-finite values of its live float parameters and keeps the old
one (issue 28: `cdpr param set /winch_platform_sim floor_height .nan` was accepted)."""
import math

import pytest
from rclpy.parameter import Parameter

from cdpr_sim.nodes.winch_platform_sim import WinchPlatformSimNode
from node_harness import node_graph

LIVE_FLOATS = ("floor_height", "realtime_factor", "lockstep_timeout", "contact_stiffness", "contact_damping",
               "contact_friction")


@pytest.fixture(scope="module")
def sim():
    with node_graph(lambda: [WinchPlatformSimNode(parameter_overrides=[Parameter("robot", value="ipanema3_mini")])]) \
            as ((node,), _, _):
        yield node


@pytest.mark.parametrize("name", LIVE_FLOATS)
@pytest.mark.parametrize("value", [math.nan, math.inf, -math.inf])
def test_non_finite_values_are_refused_and_the_old_one_kept(sim, name, value):
    before = sim.get_parameter(name).value
    result = sim.set_parameters([Parameter(name, value=value)])[0]
    assert not result.successful and result.reason
    assert sim.get_parameter(name).value == before


def test_a_finite_floor_height_is_taken(sim):
    assert sim.set_parameters([Parameter("floor_height", value=-0.3)])[0].successful
    assert sim.get_parameter("floor_height").value == -0.3
