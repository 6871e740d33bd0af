"""Test-session environment: ROS 2 traffic stays on this machine, in a domain of its own."""
import os
import random

# Discovery only on localhost (no multicast leaves the machine), and a random domain so that
# concurrent test runs on one machine do not see each other's nodes.
os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
os.environ.setdefault("ROS_DOMAIN_ID", str(random.Random(os.getpid()).randint(1, 100)))
# Generated message classes check the type of every field they are given (read when a message
# module is imported, so before any test imports one): a wrong type fails a test with a Python
# error instead of asserting in the C conversion and aborting the process (issue 28, exit 134).
os.environ.setdefault("ROS_PYTHON_CHECK_FIELDS", "1")


import pytest  # noqa: E402


@pytest.fixture(scope="session")
def friction_bag(tmp_path_factory):
    """A short friction identification run of the IPAnema 3 Mini (section 3.7.2 trajectory: a few
    seconds of stop-and-go and alternating moves, then faster ones), recorded once per session."""
    from cdpr_tools.identify import experiments

    return experiments.record_friction_run(
        tmp_path_factory.mktemp("identification") / "friction", "ipanema3_mini", seed=3,
        amplitudes=(0.0005, 0.002, 0.005), pause=0.05, fast_amplitude=0.01, fast_velocities=(0.2, 0.4))
