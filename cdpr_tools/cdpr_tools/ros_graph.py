"""The ROS graph as the tools see it: a private node, discovery waits, names, QoS to subscribe with.

Without ros2cli's daemon every command discovers the graph itself, so lookups wait (up to a
timeout) for the node or topic asked for, and fail with the names that do exist.
"""
from __future__ import annotations

import contextlib
import os
import threading
import time
from typing import Callable, Iterator

import rclpy
from rclpy.context import Context
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

DISCOVERY_TIMEOUT = 5.0  # s to wait for a named node or topic to appear
SPIN_PERIOD = 0.05  # s, executor wake-up while waiting


def keep_discovery_local() -> None:
    """Unless the user says otherwise, ROS discovery of the tools stays on this machine."""
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")


def new_context() -> Context:
    """An initialised context of the tool's own, without signal handlers (Ctrl-C stays Python's)."""
    keep_discovery_local()
    context = Context()
    rclpy.init(args=[], context=context)
    return context


@contextlib.contextmanager
def graph_node(purpose: str) -> Iterator[Node]:
    """A hidden node in a context of its own, for one command's lifetime."""
    context = new_context()
    node = executor = None
    try:
        name = f"_cdpr_{purpose}_{os.getpid()}_{threading.get_ident() % 10000}"
        node = Node(name, context=context, start_parameter_services=False)
        executor = SingleThreadedExecutor(context=context)  # node.executor is a weak reference to it
        executor.add_node(node)
        yield node
    finally:
        if executor is not None:
            executor.shutdown()
        if node is not None:
            node.destroy_node()
        context.try_shutdown()


def spin_until(node: Node, done: Callable[[], bool], timeout: float | None) -> bool:
    """Spin ``node``'s executor until ``done()`` or ``timeout`` seconds; returns ``done()``."""
    deadline = None if timeout is None else time.monotonic() + timeout
    while not done():
        if deadline is not None and time.monotonic() >= deadline:
            return done()
        try:
            node.executor.spin_once(timeout_sec=SPIN_PERIOD)
        except ExternalShutdownException:
            return done()
    return True


def spin_future(node: Node, future, timeout: float, what: str):
    """Result of a future (a service call), or ``TimeoutError`` naming ``what`` was waited for."""
    if not spin_until(node, future.done, timeout):
        raise TimeoutError(f"no answer from {what} within {timeout:g} s")
    return future.result()


def fully_qualified(name: str) -> str:
    return name if name.startswith("/") else "/" + name


def node_names(node: Node, include_hidden: bool = False) -> list[str]:
    """Fully qualified names of the nodes in the graph, except the tool's own."""
    names = []
    for name, namespace in node.get_node_names_and_namespaces():
        if name.startswith("_") and not include_hidden:
            continue
        names.append(namespace.rstrip("/") + "/" + name)
    own = node.get_fully_qualified_name()
    return sorted(n for n in set(names) if n != own)


def settle(node: Node, quiet: float, timeout: float = DISCOVERY_TIMEOUT) -> None:
    """Spin until other nodes are seen and the graph stayed unchanged for ``quiet`` seconds.

    Discovery on one machine takes from a few ms to about 2 s here; without a daemon that knows the
    graph already, a fixed wait either wastes time or misses nodes.
    """
    state = {"snapshot": None, "since": time.monotonic()}

    def quiet_enough() -> bool:
        snapshot = (tuple(node_names(node)), tuple(sorted(topic_types(node, True))))
        now = time.monotonic()
        if snapshot != state["snapshot"]:
            state["snapshot"], state["since"] = snapshot, now
        return bool(snapshot[0]) and now - state["since"] >= quiet

    spin_until(node, quiet_enough, timeout)


def find_node(node: Node, name: str, timeout: float = DISCOVERY_TIMEOUT) -> str:
    """Fully qualified name of a running node, waiting for discovery; ``LookupError`` lists the nodes."""
    wanted = fully_qualified(name)
    if spin_until(node, lambda: wanted in node_names(node, include_hidden=True), timeout):
        return wanted
    raise LookupError(f"node {wanted} not found; running nodes: {', '.join(node_names(node)) or '(none)'}")


def topic_types(node: Node, include_hidden: bool = False) -> dict[str, list[str]]:
    """Topic -> types, as the graph knows them now."""
    return {name: types for name, types in node.get_topic_names_and_types()
            if include_hidden or not _hidden_topic(name)}


def _hidden_topic(name: str) -> bool:
    return any(part.startswith("_") for part in name.split("/"))


def find_topic(node: Node, topic: str, timeout: float = DISCOVERY_TIMEOUT, publishers: bool = False) -> str:
    """Type of ``topic``, waiting for it (and with ``publishers`` for one publisher) to appear."""
    topic = fully_qualified(topic)

    def known() -> bool:
        return topic in topic_types(node, True) and (not publishers or node.count_publishers(topic) > 0)

    if not spin_until(node, known, timeout):
        if topic in topic_types(node, True):
            raise LookupError(f"topic {topic} has no publisher")
        raise LookupError(f"topic {topic} not found; topics: {', '.join(sorted(topic_types(node))) or '(none)'}")
    types = topic_types(node, True)[topic]
    if len(types) > 1:
        raise LookupError(f"topic {topic} has several types ({', '.join(types)}); give the type explicitly")
    return types[0]


def adapted_qos(node: Node, topic: str, depth: int = 10) -> QoSProfile:
    """QoS that receives from every current publisher (rosbag2's ``adapt_request_to_offers``).

    Reliable only if all publishers are, transient local only if all are; otherwise the weaker
    policy, which is compatible with everyone.
    """
    offers = [info.qos_profile for info in node.get_publishers_info_by_topic(topic)]
    qos = QoSProfile(depth=depth)
    if offers and not all(q.reliability == ReliabilityPolicy.RELIABLE for q in offers):
        qos.reliability = ReliabilityPolicy.BEST_EFFORT
    if offers and all(q.durability == DurabilityPolicy.TRANSIENT_LOCAL for q in offers):
        qos.durability = DurabilityPolicy.TRANSIENT_LOCAL
    return qos
