"""The ROS graph as the tools see it: a private node, discovery waits, names, QoS to subscribe with.

A command discovers the graph itself, or runs inside the graph daemon (``cdpr_tools.daemon``),
whose node knows the graph already: there ``graph_node`` hands out the daemon's shared node, spun
by the daemon's executor, and waits look again (or wait for an event a callback sets) instead of
spinning. Lookups wait (up to a timeout) for the node or topic asked for, and fail with the names
that do exist.
"""
from __future__ import annotations

import contextlib
import os
import re
import threading
import time
from typing import Callable, Iterator

import rclpy
from rcl_interfaces.msg import ParameterDescriptor
from rclpy.clock import Clock, ClockType
from rclpy.context import Context
from rclpy.exceptions import ParameterUninitializedException
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.parameter_client import AsyncParameterClient
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

DISCOVERY_TIMEOUT = 5.0  # s to wait for a named node or topic to appear
SPIN_PERIOD = 0.05  # s, executor wake-up while waiting
POLL_PERIOD = 0.005  # s between looks at a shared node, which another thread spins
WAKE_PERIOD = 0.1  # s, the longest wait for a ``wake`` event before looking again


def keep_discovery_local() -> None:
    """Unless the user says otherwise, ROS discovery of the tools stays on this machine."""
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")


def new_context() -> Context:
    """An initialised context of the tool's own, without signal handlers (Ctrl-C stays Python's)."""
    keep_discovery_local()
    context = Context()
    rclpy.init(args=[], context=context)
    return context


class SharedNode:
    """The graph daemon's node, which every command run inside the daemon uses instead of its own.

    Another thread spins it; ``settled`` is set once its first discovery has settled, and
    ``parameter_clients`` keeps one parameter client per remote node, whose services stay
    discovered between commands.
    """

    def __init__(self, node: Node):
        self.node = node
        self.settled = threading.Event()
        self.parameter_clients: dict[str, AsyncParameterClient] = {}
        self.lock = threading.Lock()


_shared: SharedNode | None = None


def share_node(shared: SharedNode | None) -> None:
    """Make ``shared`` the node of every later ``graph_node`` in this process (the daemon), or stop."""
    global _shared
    _shared = shared


def _is_shared(node: Node) -> bool:
    return _shared is not None and node is _shared.node


@contextlib.contextmanager
def graph_node(purpose: str) -> Iterator[Node]:
    """A hidden node in a context of its own, for one command's lifetime (in the daemon: its node)."""
    if _shared is not None:
        yield _shared.node
        return
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


def spin_until(node: Node, done: Callable[[], bool], timeout: float | None,
               wake: threading.Event | None = None) -> bool:
    """Spin ``node``'s executor until ``done()`` or ``timeout`` seconds; returns ``done()``.

    A shared node (the daemon's) is spun by another thread: then this only looks at ``done()``,
    every POLL_PERIOD, or when ``wake`` is set (by the callback that makes ``done()`` true: one
    wake-up instead of one every 5 ms, each of which waits for a core on a loaded machine).
    """
    deadline = None if timeout is None else time.monotonic() + timeout
    while not done():
        if deadline is not None and time.monotonic() >= deadline:
            return done()
        if _is_shared(node):
            if wake is None:
                time.sleep(POLL_PERIOD)
            else:
                wake.wait(WAKE_PERIOD if deadline is None else min(WAKE_PERIOD, max(0.0, deadline - time.monotonic())))
                wake.clear()    # done() is looked at next, so a set between the two is not lost
            continue
        try:
            node.executor.spin_once(timeout_sec=SPIN_PERIOD)
        except ExternalShutdownException:
            return done()
    return True


def spin_future(node: Node, future, timeout: float, what: str):
    """Result of a future (a service call), or ``TimeoutError`` naming ``what`` was waited for."""
    wake = threading.Event()
    future.add_done_callback(lambda _future: wake.set())
    if not spin_until(node, future.done, timeout, wake):
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
    graph already, a fixed wait either wastes time or misses nodes. The daemon's node settles once,
    when the daemon starts (``settle_shared``), and answers from then on at once.
    """
    if _is_shared(node):
        _shared.settled.wait(timeout)
        return
    spin_until(node, _graph_quiet(node, quiet), timeout)


def settle_shared(quiet: float, timeout: float = DISCOVERY_TIMEOUT) -> None:
    """Let the shared node's first discovery settle (the daemon calls it once, in a thread of its own)."""
    spin_until(_shared.node, _graph_quiet(_shared.node, quiet), timeout)
    _shared.settled.set()


def _graph_quiet(node: Node, quiet: float) -> Callable[[], bool]:
    """A check that is true once other nodes are seen and the graph stayed unchanged for ``quiet`` s."""
    state = {"snapshot": None, "since": time.monotonic()}

    def quiet_enough() -> bool:
        snapshot = (tuple(node_names(node)), tuple(sorted(topic_types(node, True))))
        now = time.monotonic()
        if snapshot != state["snapshot"]:
            state["snapshot"], state["since"] = snapshot, now
        return bool(snapshot[0]) and now - state["since"] >= quiet

    return quiet_enough


def find_node(node: Node, name: str, timeout: float = DISCOVERY_TIMEOUT) -> str:
    """Fully qualified name of a running node, waiting for discovery; ``LookupError`` lists the nodes."""
    wanted = fully_qualified(name)
    if spin_until(node, lambda: wanted in node_names(node, include_hidden=True), timeout):
        return wanted
    raise LookupError(f"node {wanted} not found; running nodes: {', '.join(node_names(node)) or '(none)'}")


def parameter_client(node: Node, name: str) -> AsyncParameterClient:
    """A client of node ``name``'s parameter services: new, or the daemon's kept one for that node."""
    if not _is_shared(node):
        return AsyncParameterClient(node, name)
    with _shared.lock:
        if name not in _shared.parameter_clients:
            _shared.parameter_clients[name] = AsyncParameterClient(node, name)
        return _shared.parameter_clients[name]


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
            raise LookupError(f"topic {topic} has no publisher (waited {timeout:g} s)")
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


class TopicSelection:
    """Which topics a recorder or bridge node takes, and the discovery of new ones, as parameters:
    ``topics`` (empty or unset: every topic), ``exclude`` (a regular expression),
    ``include_hidden_topics``, ``discovery_period`` [s]. Every ``discovery_period`` (steady clock:
    with use_sim_time the node's clock waits for /clock) it calls ``take(topic, type_name)`` for each
    wanted topic that has a publisher (the offered QoS decides how to subscribe) and that ``take``
    has not taken: ``take`` returns True (taken), False (it cannot take it: not offered again) or
    None (not now: offered again at the next discovery)."""

    def __init__(self, node: Node, what: str, discovery_period: float, take: Callable[[str, str], bool | None]):
        node.declare_parameter("topics", Parameter.Type.STRING_ARRAY, ParameterDescriptor(
            description=f"topics to {what}; empty or unset: every topic", read_only=True))
        node.declare_parameter("exclude", "", ParameterDescriptor(
            description=f"regular expression of topics not to {what}", read_only=True))
        node.declare_parameter("include_hidden_topics", False, ParameterDescriptor(read_only=True))
        node.declare_parameter("discovery_period", discovery_period, ParameterDescriptor(
            description="how often to look for new topics [s]", read_only=True))
        try:
            topics = node.get_parameter("topics").value or []
        except ParameterUninitializedException:  # declared without a value: every topic
            topics = []
        self.selected = {fully_qualified(t) for t in topics if t}
        exclude = node.get_parameter("exclude").value
        self.exclude = re.compile(exclude) if exclude else None
        self.include_hidden = node.get_parameter("include_hidden_topics").value
        self.node, self._take = node, take
        self.seen: set[str] = set()
        node.create_timer(node.get_parameter("discovery_period").value, self.discover,
                          clock=Clock(clock_type=ClockType.STEADY_TIME))

    def wanted(self, topic: str) -> bool:
        if self.selected and topic not in self.selected:
            return False
        return not (self.exclude and self.exclude.fullmatch(topic))

    def discover(self) -> None:
        """Hand wanted topics that have publishers and were not handed yet to ``take``."""
        for topic, types in topic_types(self.node, self.include_hidden).items():
            if topic in self.seen or not self.wanted(topic) or self.node.count_publishers(topic) == 0:
                continue
            if self._take(topic, types[0]) is not None:
                self.seen.add(topic)
