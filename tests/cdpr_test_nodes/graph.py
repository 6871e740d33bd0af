"""Test-side graph helpers: nodes spun in a background thread, and a node that collects messages."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

from rclpy.experimental import EventsExecutor
from rclpy.node import Node
from rclpy.qos import QoSProfile

from cdpr_control.ros.runner import spin
from cdpr_tools.ros_graph import new_context

TESTS_DIR = Path(__file__).resolve().parents[1]
DISCOVERY = 15.0  # s: generous, the test machine is shared and loaded
# s a launched child may take to exit after SIGINT (Launcher's stop_timeout): under a load of about 6
# on two cores a node still being built, or exiting its interpreter, took more than the default 10 s
STOPPING = 120.0


class Spinner:
    """A context of its own with an EventsExecutor thread; ``add(NodeClass, **kwargs)`` builds nodes in it."""

    def __init__(self):
        self.context = new_context()
        self.executor = EventsExecutor(context=self.context)
        self.nodes: list[Node] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=spin, args=(self.executor, self._stop), daemon=True)
        self._thread.start()

    def add(self, node_class, **kwargs) -> Node:
        node = node_class(context=self.context, **kwargs)
        self.nodes.append(node)
        self.executor.add_node(node)
        return node

    def close(self) -> None:
        self._stop.set()
        self._thread.join(5)
        for node in self.nodes:
            node.destroy_node()
        self.context.try_shutdown()


class Collector(Node):
    """Subscribes to ``topics`` ({name: msg class}) and keeps (monotonic arrival time, message) pairs."""

    def __init__(self, topics: dict, qos: QoSProfile | None = None, **kwargs):
        super().__init__(f"collector_{os.getpid()}_{id(self) % 100000}", **kwargs)
        self.received: dict[str, list] = {t: [] for t in topics}
        self.lock = threading.Lock()
        for topic, msg_class in topics.items():
            self.create_subscription(msg_class, topic, self._callback(topic), qos or QoSProfile(depth=1000))

    def _callback(self, topic):
        def on_message(msg) -> None:
            with self.lock:
                self.received[topic].append((time.monotonic(), msg))
        return on_message

    def count(self, topic: str) -> int:
        with self.lock:
            return len(self.received[topic])

    def messages(self, topic: str) -> list:
        with self.lock:
            return [m for _, m in self.received[topic]]


def wait_for(condition, timeout: float = DISCOVERY, what: str = "condition") -> None:
    deadline = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {timeout:g} s waiting for {what}")
        time.sleep(0.02)


def cdpr(env: dict, *argv: str, timeout: float) -> subprocess.CompletedProcess:
    """`cdpr ARGV` in a process of its own with ``env``; it must end within ``timeout`` s (else it hangs)."""
    return subprocess.run([sys.executable, "-m", "cdpr_tools.cli", *argv], capture_output=True, text=True,
                          env=env, timeout=timeout)


def kill_daemon(pid: int) -> None:
    """SIGKILL the graph daemon of ``pid`` if that process is one (a pid file may outlive its process)."""
    try:
        if b"cdpr_tools.daemon.server" in Path(f"/proc/{pid}/cmdline").read_bytes():
            os.kill(pid, signal.SIGKILL)
    except OSError:
        pass


def subprocess_env() -> dict:
    """Environment for `cdpr` subprocesses: this test's ROS domain, and the test nodes importable."""
    path = os.pathsep.join(p for p in (str(TESTS_DIR), os.environ.get("PYTHONPATH", "")) if p)
    return {**os.environ, "PYTHONPATH": path, "PYTHONUNBUFFERED": "1"}
