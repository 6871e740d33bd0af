"""Running a G-code program on a running graph through the RunProgram action (the client side)."""
from __future__ import annotations

import time
from typing import Callable

from cdpr_msgs.action import RunProgram
from rclpy.action import ActionClient
from rclpy.experimental import EventsExecutor

from cdpr_tools.ros_graph import new_context


def run_program(text: str, name: str, action: str = "/run_program", timeout: float = 600.0,
                feedback: Callable[[int, float], None] | None = None, server_timeout: float = 30.0):
    """Send the program, wait for its end; returns the RunProgram result (success, message, ...).

    ``server_timeout`` [s]: how long to wait for the action server to appear; ``timeout`` [s]: the
    wall-clock limit from sending the goal to the program's end. The server's answer to the goal
    counts against ``timeout``, not ``server_timeout``: a composed graph answers between two periods
    of its loop, which on a busy machine can take longer than discovery's few seconds."""
    context = new_context()
    node = None
    try:
        from rclpy.node import Node

        node = Node("cdpr_program_client", context=context)
        executor = EventsExecutor(context=context)
        executor.add_node(node)
        client = ActionClient(node, RunProgram, action)
        deadline = time.monotonic() + server_timeout
        while not client.server_is_ready():
            if time.monotonic() > deadline:
                raise TimeoutError(f"no RunProgram action server at {action} after {server_timeout:g} s: is a graph "
                                   "running? (`cdpr launch closed_loop.yaml` starts one; `cdpr demo` runs the main job)")
            executor.spin_once(timeout_sec=0.1)
        on_feedback = None if feedback is None else (lambda m: feedback(m.feedback.line, m.feedback.progress))
        sent = client.send_goal_async(RunProgram.Goal(program=text, name=name), feedback_callback=on_feedback)
        end = time.monotonic() + timeout
        if not _spin_until(executor, sent.done, end):
            raise TimeoutError(f"{action} did not answer the goal of program {name!r} within {timeout:g} s")
        handle = sent.result()
        if not handle.accepted:
            raise RuntimeError(f"program {name!r} was rejected by {action}")
        done = handle.get_result_async()
        if not _spin_until(executor, done.done, end):
            handle.cancel_goal_async()
            raise TimeoutError(f"program {name!r} did not finish within {timeout:.0f} s")
        return done.result().result
    finally:
        if node is not None:
            node.destroy_node()
        context.try_shutdown()


def _spin_until(executor, done, deadline: float) -> bool:
    while not done() and time.monotonic() < deadline:
        executor.spin_once(timeout_sec=0.05)
    return done()
