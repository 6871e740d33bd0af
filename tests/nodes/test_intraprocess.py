"""Intra-process delivery (cdpr_control.ros.intraprocess): nodes of one context pass messages as
Python objects, and DDS still carries every message to subscribers outside the process."""
from __future__ import annotations

import threading
import time
from unittest import mock

import pytest
from rclpy.experimental import EventsExecutor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import JointState
from std_msgs.msg import Int64

from cdpr_control.ros.intraprocess import MATCH_POLL_S, IntraProcess, IntraProcessNode, IntraProcessPublisher
from cdpr_control.ros.qos import CONTROL, STATUS
from cdpr_control.ros.runner import spin
from cdpr_tools.ros_graph import new_context

TIMEOUT = 20.0  # s for discovery and deliveries on a loaded machine
# deep enough that DDS loses nothing of a burst while the GIL is busy elsewhere (CONTROL keeps 10)
DEEP = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1000, reliability=ReliabilityPolicy.RELIABLE)


class Spinning:
    """A context with an EventsExecutor spinning in a thread of its own (like a composed launch)."""

    def __init__(self):
        self.context = new_context()
        self.executor = EventsExecutor(context=self.context)
        self.nodes = []
        self._stop = threading.Event()
        self._thread = None

    def node(self, name, cls=IntraProcessNode, **kwargs):
        node = cls(name, context=self.context, **kwargs)
        self.nodes.append(node)
        self.executor.add_node(node)
        return node

    def start(self):
        self._thread = threading.Thread(target=spin, args=(self.executor, self._stop), daemon=True)
        self._thread.start()
        return self

    def close(self):
        self._stop.set()
        if self._thread is not None:
            self._thread.join(5)
        for node in self.nodes:
            node.destroy_node()
        self.context.try_shutdown()


@pytest.fixture
def spaces():
    made = []

    def make():
        made.append(Spinning())
        return made[-1]
    yield make
    for space in reversed(made):
        space.close()


def wait_for(condition, what: str, timeout: float = TIMEOUT) -> None:
    deadline = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out waiting for {what() if callable(what) else what}")
        time.sleep(0.01)


def joint_state(k: int) -> JointState:
    msg = JointState(name=["cable_1", "cable_2"], position=[0.001 * k, -0.5 * k], velocity=[1.0, float(k)])
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(k * 1_000_000, 1_000_000_000)
    return msg


def key(msg: JointState) -> tuple:
    return (msg.header.stamp.sec, msg.header.stamp.nanosec, tuple(msg.name), tuple(msg.position), tuple(msg.velocity))


def test_in_process_and_dds_subscribers_receive_identical_streams(spaces):
    """A remapped in-process subscription and a DDS subscription in another context get the same
    messages, in the same order, once each; the in-process one gets the very objects published."""
    graph, outside = spaces(), spaces()
    publisher_node = graph.node("ipc_publisher", cli_args=["--ros-args", "-r", "__ns:=/ipc"])
    subscriber_node = graph.node("ipc_subscriber", cli_args=["--ros-args", "-r", "measured:=/ipc/state"])
    local, remote = [], []
    subscriber_node.create_subscription(JointState, "measured", local.append, DEEP)
    outside.node("ipc_outside", cls=Node).create_subscription(JointState, "/ipc/state", remote.append, DEEP)
    publisher = publisher_node.create_publisher(JointState, "state", DEEP)
    graph.start(), outside.start()
    wait_for(lambda: publisher.get_subscription_count() == 2, "both subscriptions to match")
    sent = [joint_state(k) for k in range(300)]
    for msg in sent:
        publisher.publish(msg)              # from a foreign thread: the executor's thread delivers
    wait_for(lambda: len(local) == len(sent) and len(remote) == len(sent),
             lambda: f"every message at both (in-process {len(local)}, DDS {len(remote)} of {len(sent)})")
    time.sleep(0.3)                         # DDS copies of the local messages must not come on top
    assert len(local) == len(remote) == len(sent)
    assert [key(m) for m in local] == [key(m) for m in remote] == [key(m) for m in sent]
    assert all(a is b for a, b in zip(local, sent))  # in-process: the objects, not copies
    assert IntraProcess.of(graph.context).deliveries >= len(sent)


def test_nothing_goes_over_dds_without_a_subscriber_outside_the_process(spaces):
    graph, outside = spaces(), spaces()
    node = graph.node("ipc_alone")
    local = []
    node.create_subscription(Int64, "/ipc_alone/n", local.append, CONTROL)
    publisher = node.create_publisher(Int64, "/ipc_alone/n", CONTROL)
    wait_for(lambda: publisher.get_subscription_count() == 1, "the local subscription to match over DDS")
    with mock.patch.object(IntraProcessPublisher, "to_dds", autospec=True, side_effect=IntraProcessPublisher.to_dds) as dds:
        for k in range(50):
            publisher.publish(Int64(data=k))
        ours = lambda: sum(1 for call in dds.call_args_list if call.args[0] is publisher)  # noqa: E731
        assert ours() == 0
        assert [m.data for m in local] == list(range(50))
        remote = []
        outside.node("ipc_listener", cls=Node).create_subscription(Int64, "/ipc_alone/n", remote.append, CONTROL)
        outside.start()
        wait_for(lambda: publisher.get_subscription_count() == 2, "the outside subscription to match")
        time.sleep(MATCH_POLL_S)            # (the publisher's count of DDS subscriptions is that old at most)
        publisher.publish(Int64(data=50))
        assert ours() == 1
    wait_for(lambda: remote, "the message over DDS")
    assert [m.data for m in remote] == [50]
    assert [m.data for m in local] == list(range(51))


def test_a_publisher_asks_dds_for_its_subscriptions_at_most_every_poll(spaces):
    """Whether to write to DDS too: rcl's count of matched subscriptions is asked at most every
    MATCH_POLL_S (17 topics a period asked it at every publication), and again at once when the local
    subscriptions change."""
    graph = spaces()
    node = graph.node("ipc_poll")
    publisher = node.create_publisher(Int64, "/ipc_poll/n", CONTROL)
    node.create_subscription(Int64, "/ipc_poll/n", lambda msg: None, CONTROL)
    real, asked = publisher._Publisher__publisher, []

    class Counting:                     # rcl's publisher, its count calls noted
        def __getattr__(self, name):
            return getattr(real, name)

        def get_subscription_count(self):
            asked.append(time.monotonic())
            return real.get_subscription_count()
    publisher._Publisher__publisher = Counting()
    try:
        start = time.monotonic()
        for k in range(300):
            publisher.publish(Int64(data=k))
        elapsed = time.monotonic() - start
        assert 1 <= len(asked) <= elapsed / MATCH_POLL_S + 1
        node.create_subscription(Int64, "/ipc_poll/n", lambda msg: None, CONTROL)
        before = len(asked)
        publisher.publish(Int64(data=300))
        assert len(asked) == before + 1     # the local subscriptions changed: asked again
    finally:
        publisher._Publisher__publisher = real


def test_local_and_remote_publishers_on_one_topic_reach_a_local_subscriber_once_each(spaces):
    """Mixed publishers: DDS copies of local messages are recognised, remote messages delivered."""
    graph, outside = spaces(), spaces()
    node = graph.node("ipc_mixed")
    local = []
    node.create_subscription(Int64, "/ipc_mixed/n", local.append, DEEP)
    publisher = node.create_publisher(Int64, "/ipc_mixed/n", DEEP)
    other = outside.node("ipc_remote", cls=Node)
    remote_publisher = other.create_publisher(Int64, "/ipc_mixed/n", DEEP)
    echoed = []
    other.create_subscription(Int64, "/ipc_mixed/n", echoed.append, DEEP)  # makes the local one publish to DDS
    graph.start(), outside.start()
    wait_for(lambda: publisher.get_subscription_count() == 2 and remote_publisher.get_subscription_count() == 2,
             "publishers and subscriptions to match")
    for k in range(20):
        publisher.publish(Int64(data=k))
        remote_publisher.publish(Int64(data=1000 + k))
    wait_for(lambda: len(local) >= 40 and len(echoed) >= 40, "40 messages at both subscriptions")
    time.sleep(0.3)
    assert sorted(m.data for m in local) == sorted(m.data for m in echoed) == sorted(
        [*range(20), *range(1000, 1020)])
    assert [m.data for m in local if m.data < 1000] == list(range(20))  # in order per publisher
    assert [m.data for m in local if m.data >= 1000] == list(range(1000, 1020))


def test_a_publishing_ring_runs_as_a_queue_and_the_executor_keeps_its_turn(spaces):
    """Two nodes answering each other (the lockstep ring) neither recurse nor starve the executor:
    the ring stops only when a timer of the same executor has fired."""
    graph = spaces()
    a, b = graph.node("ipc_ring_a"), graph.node("ipc_ring_b")
    ping, pong = a.create_publisher(Int64, "/ipc_ring/ping", CONTROL), b.create_publisher(Int64, "/ipc_ring/pong", CONTROL)
    seen, ticks = [], []
    a.create_subscription(Int64, "/ipc_ring/pong", lambda m: ticks or ping.publish(Int64(data=m.data + 1)), CONTROL)
    b.create_subscription(Int64, "/ipc_ring/ping", lambda m: (seen.append(m.data), pong.publish(m)), CONTROL)
    a.create_timer(0.02, lambda: ticks.append(1))
    ping.publish(Int64(data=0))             # no executor yet: this thread runs the ring for a budget
    graph.start()
    wait_for(lambda: ticks, "the timer to fire during the ring")
    wait_for(lambda: len(seen) > 2000 or seen[-1] == len(seen) - 1 and ticks, "the ring to stop")
    assert seen == list(range(len(seen)))   # every hop, in order
    assert len(seen) > 1000                 # far beyond any recursion limit


def test_urgent_subscriptions_are_delivered_before_the_queue_in_their_own_order(spaces):
    """What a callback publishes is queued; deliveries to urgent subscriptions go first, each
    subscription still in publication order."""
    graph = spaces()
    node = graph.node("ipc_urgent")
    order = []
    node.create_subscription(Int64, "/ipc_urgent/slow", lambda m: order.append(("slow", m.data)), CONTROL)
    node.create_subscription(Int64, "/ipc_urgent/fast", lambda m: order.append(("fast", m.data)), CONTROL,
                             urgent=True)
    slow = node.create_publisher(Int64, "/ipc_urgent/slow", CONTROL)
    fast = node.create_publisher(Int64, "/ipc_urgent/fast", CONTROL)

    def burst(_):
        slow.publish(Int64(data=1))
        fast.publish(Int64(data=1))
        slow.publish(Int64(data=2))
        fast.publish(Int64(data=2))
    node.create_subscription(Int64, "/ipc_urgent/go", burst, CONTROL)
    node.create_publisher(Int64, "/ipc_urgent/go", CONTROL).publish(Int64(data=0))
    assert order == [("fast", 1), ("fast", 2), ("slow", 1), ("slow", 2)]


def test_a_tap_takes_each_message_inside_publish_and_dds_messages_through_the_executor(spaces):
    """A tap gets in-process messages before ``publish`` returns (queued subscriptions later), as
    objects or serialized for a raw tap; a publisher in another process still reaches it, once each."""
    graph, outside = spaces(), spaces()
    node = graph.node("ipc_tap")
    tapped, raw, queued = [], [], []
    node.create_subscription(Int64, "/ipc_tap/x", tapped.append, DEEP, tap=True)
    node.create_subscription(Int64, "/ipc_tap/x", raw.append, DEEP, raw=True, tap=True)
    node.create_subscription(Int64, "/ipc_tap/x", queued.append, DEEP)
    publisher = node.create_publisher(Int64, "/ipc_tap/x", DEEP)
    seen_inside = []

    def burst(_):
        for k in range(3):
            msg = Int64(data=k)
            publisher.publish(msg)
            seen_inside.append((tapped[-1] is msg, raw[-1] == serialize_message(msg), len(queued)))
    node.create_subscription(Int64, "/ipc_tap/go", burst, CONTROL)
    node.create_publisher(Int64, "/ipc_tap/go", CONTROL).publish(Int64(data=0))
    assert seen_inside == [(True, True, 0)] * 3     # inside publish; the queue delivers after the callback
    assert [m.data for m in queued] == [0, 1, 2]
    remote = outside.node("ipc_tap_remote", cls=Node).create_publisher(Int64, "/ipc_tap/x", DEEP)
    graph.start(), outside.start()
    wait_for(lambda: remote.get_subscription_count() == 3, "the remote publisher to match")
    remote.publish(Int64(data=42))
    wait_for(lambda: len(tapped) == 4 and len(raw) == 4 and len(queued) == 4, "the remote message at each")
    time.sleep(0.3)                                 # and no DDS copy of the local ones on top
    assert [m.data for m in tapped] == [m.data for m in queued] == [0, 1, 2, 42]
    assert [deserialize_message(d, Int64).data for d in raw] == [0, 1, 2, 42]


def test_transient_local_history_reaches_a_late_local_subscriber(spaces):
    graph = spaces()
    node = graph.node("ipc_latched")
    publisher = node.create_publisher(Int64, "/ipc_latched/status", STATUS)
    for k in range(3):
        publisher.publish(Int64(data=k))
    late, volatile = [], []
    node.create_subscription(Int64, "/ipc_latched/status", late.append, STATUS)
    node.create_subscription(Int64, "/ipc_latched/status", volatile.append, CONTROL)
    assert [m.data for m in late] == [2]    # depth 1, as DDS would keep it
    assert volatile == []
    best_effort = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1, reliability=ReliabilityPolicy.BEST_EFFORT,
                             durability=DurabilityPolicy.VOLATILE)
    lossy = node.create_publisher(Int64, "/ipc_latched/lossy", best_effort)
    reliable = []
    node.create_subscription(Int64, "/ipc_latched/lossy", reliable.append, CONTROL)
    lossy.publish(Int64(data=7))
    assert reliable == []                   # DDS would not match these QoS either


def test_transient_local_history_reaches_a_late_subscriber_outside_the_process(spaces):
    """A latched message published while nobody outside listened still reaches a reader in another
    process that joins later (DDS keeps the history only of what went over DDS)."""
    graph, outside = spaces(), spaces()
    publisher = graph.node("ipc_latched_out").create_publisher(Int64, "/ipc_latched_out/status", STATUS)
    graph.start()
    publisher.publish(Int64(data=41))
    publisher.publish(Int64(data=42))
    late = []
    outside.node("ipc_late_reader", cls=Node).create_subscription(Int64, "/ipc_latched_out/status", late.append, STATUS)
    outside.start()
    wait_for(lambda: late, "the latched message at the late reader")
    time.sleep(0.2)
    assert [m.data for m in late] == [42]   # depth 1, the newest


def test_clock_reaches_every_sim_time_node_in_one_delivery(spaces):
    """/clock sets every local node's ROS clock (use_sim_time), converted once per message."""
    from rclpy.parameter import Parameter
    from rosgraph_msgs.msg import Clock

    graph = spaces()
    sim_time = [Parameter("use_sim_time", value=True)]
    nodes = [graph.node(f"ipc_clocked_{i}", parameter_overrides=sim_time) for i in range(3)]
    clock_qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1, reliability=ReliabilityPolicy.BEST_EFFORT)
    publisher = graph.node("ipc_clock_source").create_publisher(Clock, "/clock", clock_qos)
    registry = IntraProcess.of(graph.context)
    for sec in (7, 8):
        before = registry.deliveries
        msg = Clock()
        msg.clock.sec, msg.clock.nanosec = sec, 250_000_000
        publisher.publish(msg)
        assert registry.deliveries == before + 1
        assert [n.get_clock().now().nanoseconds for n in nodes] == [sec * 10**9 + 250_000_000] * 3


def test_has_subscribers_sees_local_and_outside_subscriptions(spaces):
    """has_subscribers (nodes skip building messages nobody takes, e.g. the simulator's ground truth):
    false alone, true with a subscription in the process, true with one only over DDS."""
    from cdpr_control.ros.intraprocess import has_subscribers
    graph, outside = spaces(), spaces()
    node = graph.node("ipc_wanted")
    publisher = node.create_publisher(Int64, "/ipc_wanted/n", CONTROL)
    assert not has_subscribers(publisher)
    subscription = node.create_subscription(Int64, "/ipc_wanted/n", lambda msg: None, CONTROL)
    assert has_subscribers(publisher)
    node.destroy_subscription(subscription)
    wait_for(lambda: publisher.get_subscription_count() == 0, "the local subscription to go")
    assert not has_subscribers(publisher)
    outside.node("ipc_wanted_outside", cls=Node).create_subscription(Int64, "/ipc_wanted/n", lambda msg: None, CONTROL)
    wait_for(lambda: has_subscribers(publisher), "the outside subscription to be seen")
    plain = outside.node("ipc_plain", cls=Node).create_publisher(Int64, "/ipc_plain/n", CONTROL)
    assert not has_subscribers(plain)   # a plain rclpy publisher: its DDS count


def test_without_subscription_events_local_qos_mismatches_are_reported_once(spaces):
    """Where an executor rebuilds its wait set every turn (a composed lockstep launch), subscriptions
    get no QoS event handlers (each a waitable re-added every turn); the registry then warns of a
    local publisher that DDS would not match, once, in rclpy's words, and of none that it would."""
    graph = spaces()
    plain = graph.node("ipc_events")
    plain.create_subscription(Int64, "/ipc_events/n", lambda msg: None, CONTROL)
    assert len(list(plain.waitables)) > 0              # rclpy's default: incompatible QoS (and type)
    IntraProcess.of(graph.context).subscription_events = False
    node = graph.node("ipc_lean")
    warned = []
    with mock.patch.object(node.get_logger(), "warning", side_effect=warned.append):
        node.create_subscription(Int64, "/ipc_lean/n", lambda msg: None, CONTROL)       # reliable
        assert list(node.waitables) == []
        best_effort = QoSProfile(depth=10, reliability=ReliabilityPolicy.BEST_EFFORT)
        node.create_publisher(Int64, "/ipc_lean/n", best_effort)
        node.create_publisher(Int64, "/ipc_lean/n", CONTROL)                          # compatible
        node.create_subscription(Int64, "/ipc_lean/n", lambda msg: None, best_effort)  # takes both
    assert warned == ["New publisher discovered on topic '/ipc_lean/n', offering incompatible QoS. "
                      "No messages will be received from it. Last incompatible policy: RELIABILITY"]
