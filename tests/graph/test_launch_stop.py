"""The launcher's stop waits for a callback that is still running before it destroys the nodes; a
child process gets SIGTERM only after the launcher's stop timeout."""
import time

import pytest

from cdpr_test_nodes.graph import wait_for
from cdpr_tools.launch import EXECUTOR_STOP_TIMEOUT, LaunchDescription, Launcher, NodeSpec

PAUSE = 4.0  # s: longer than the 3 s the stop used to wait for an executor thread


def test_stop_lets_a_running_callback_end_before_destroying_its_node(capfd):
    """A callback still running when the graph stops ends normally (it publishes on its node's
    publisher), and only then are the nodes destroyed: no InvalidHandle traceback, no error."""
    description = LaunchDescription(nodes=[NodeSpec(module="cdpr_test_nodes.slow_stop",
                                                    parameters=[{"pause": PAUSE}])])
    launch = Launcher(description, mode="composed").start()
    try:
        node = launch.nodes[0]
        wait_for(node.blocking.is_set, what="the slow callback to start")
        started = time.monotonic()
    finally:
        launch.stop()
    assert node.finished.is_set()                 # it published after its pause, on a live publisher
    assert time.monotonic() - started < PAUSE + EXECUTOR_STOP_TIMEOUT
    out, err = capfd.readouterr()
    assert "Traceback" not in out + err and "InvalidHandle" not in out + err, out + err
    assert launch.errors == []


@pytest.mark.parametrize("stop_timeout,pause,code", [(0.5, 60.0, -9), (120.0, 3.0, 0)])
def test_a_child_gets_sigterm_after_the_stop_timeout_not_before(capfd, stop_timeout, pause, code):
    """One process per node: a child in a callback that runs on past SIGINT (as a loaded machine
    stretches building a node or exiting its interpreter) ends by itself within ``stop_timeout``
    with code 0; past it, it gets SIGTERM (which it also takes as a stop) and 3 s later SIGKILL."""
    description = LaunchDescription(nodes=[NodeSpec(module="cdpr_test_nodes.slow_stop",
                                                    parameters=[{"pause": pause}])])
    output = []
    with Launcher(description, mode="processes", stop_timeout=stop_timeout) as launch:
        wait_for(lambda: output.append(capfd.readouterr().out) or "slow_stop: pausing" in "".join(output),
                 timeout=120, what="the child's slow callback to start")
    output.append(capfd.readouterr().out)
    text = "".join(output)
    assert launch.exit_codes == {"slow_stop": code}, text
    escalated = f"did not stop within {stop_timeout:g} s, sending SIGTERM" in text
    assert escalated == (code != 0), text
