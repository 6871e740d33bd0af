"""The node tests' harness: the nodes under test beside a "probe" node on one SingleThreadedExecutor,
spun by the test itself (each test publishes inputs from the probe and spins until outputs arrive)."""
from __future__ import annotations

import contextlib
import time
from typing import Callable, Iterator


@contextlib.contextmanager
def node_graph(make_nodes: Callable[[], list]) -> Iterator[tuple[list, object, object]]:
    """rclpy initialised, ``make_nodes()``'s nodes and the probe on one executor: ``(nodes, probe,
    executor)``; everything destroyed and rclpy shut down afterwards."""
    import rclpy
    from rclpy.executors import SingleThreadedExecutor

    rclpy.init()
    made = []
    try:
        nodes = list(make_nodes())
        made.extend(nodes)
        probe = rclpy.create_node("probe")
        made.append(probe)
        executor = SingleThreadedExecutor()
        for node in made:
            executor.add_node(node)
        yield nodes, probe, executor
    finally:
        for node in made:
            node.destroy_node()
        rclpy.shutdown()


def spin_until(executor, done: Callable[[], bool], timeout: float = 120.0, step: float = 0.02) -> bool:
    """Spin ``executor`` until ``done()`` or ``timeout`` [s]; returns ``done()``. The default timeout is
    a hang guard, not a margin: a busy machine may take many times the idle time to get there."""
    deadline = time.monotonic() + timeout
    while not done() and time.monotonic() < deadline:
        executor.spin_once(timeout_sec=step)
    return done()
