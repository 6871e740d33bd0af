"""The launcher's stop waits for a callback that is still running before it destroys the nodes."""
import time

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
