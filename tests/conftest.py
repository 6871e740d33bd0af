"""Test-session environment: ROS 2 traffic stays on this machine, in a domain of its own."""
import os
import random

# Discovery only on localhost (no multicast leaves the machine), and a random domain so that
# concurrent test runs on one machine do not see each other's nodes.
os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
os.environ.setdefault("ROS_DOMAIN_ID", str(random.Random(os.getpid()).randint(1, 100)))


import pytest  # noqa: E402


@pytest.fixture(scope="session")
def friction_bag(tmp_path_factory):
    """A short friction identification run of the IPAnema 3 Mini (section 3.7.2 trajectory: a few
    seconds of stop-and-go and alternating moves, then faster ones), recorded once per session."""
    from cdpr_tools.identify import experiments

    return experiments.record_friction_run(
        tmp_path_factory.mktemp("identification") / "friction", "ipanema3_mini", seed=3,
        amplitudes=(0.0005, 0.002, 0.005), pause=0.05, fast_amplitude=0.01, fast_velocities=(0.2, 0.4))


@pytest.fixture(scope="module", params=("ipanema3_mini", "ipanema3"))
def robot(request):
    """Each shipped robot (thesis tables 2.1-2.4) with the compiled kernels loaded for it, for the
    tests that hold on both; a module with a robot of its own defines its own ``robot``."""
    from cdpr_control import kernels
    from cdpr_control.model.robot import load_robot

    robot = load_robot(request.param)
    kernels.warm_up(robot)
    return robot
