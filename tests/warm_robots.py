"""The shipped robots with the compiled kernels loaded, for the modules that compare kernels with
their numpy reference (import ``robot`` into a test module to use the fixture)."""
import pytest

from cdpr_control import kernels
from cdpr_control.model.robot import load_robot

ROBOTS = ("ipanema3_mini", "ipanema3")


@pytest.fixture(scope="module", params=ROBOTS)
def robot(request):
    robot = load_robot(request.param)
    kernels.warm_up(robot)
    return robot
