"""Intra-process delivery: nodes that share a process pass messages as Python objects.

In the spirit of rclcpp's intra-process communication. Every publisher and subscription a
:class:`IntraProcessNode` creates is still an ordinary rclpy (DDS) entity, so the graph looks the
same to every tool, but the nodes of one rclpy ``Context`` also register them in a per-context
:class:`IntraProcess` registry keyed by the resolved topic name (after remapping, the name
``Publisher.topic_name`` reports):

- ``publish(msg)`` hands the message object to the local subscriptions of that topic, in
  publication order (no serialization, no DDS, no executor), and publishes it over DDS as well,
  before the local deliveries so that outside a message comes before those it causes,
  only when a subscription that is *not* local matches (``get_subscription_count()`` counts the
  local ones too, the registry knows how many those are). A ``cdpr topic echo``, a recorder in
  another process or a node on another host therefore sees every message, while a composed graph
  alone never serializes. The count is asked at most every ``MATCH_POLL_S`` (and at once when the
  local subscriptions change), not at every publication: 17 topics a period asked it for 11-40 us
  of the loop; DDS's own discovery of a new reader takes longer than the poll's delay.
- A local subscription drops what DDS brings it from local publishers (it already has those
  messages): when every publisher matched to it is local, everything DDS brings is such a copy;
  otherwise (local and remote publishers on one topic) a DDS message equal to one of the last
  local deliveries is such a copy. Messages of remote publishers are delivered as usual.
- Deliveries go through one FIFO queue per process drained in a loop, not by recursion: a
  callback that publishes appends to the queue, so the lockstep ring (simulator -> controllers ->
  simulator) runs without growing the stack. The thread that publishes drains the queue when it
  is the executor's thread (or no executor spins yet, e.g. during construction); any other thread
  only appends and wakes the executor. After ``BUDGET_S`` of draining the rest of the queue is
  handed to the executor (a one-shot timer), so timers, services and DDS messages keep their turn.
- An ``urgent`` subscription (``create_subscription(..., urgent=True)``) has its deliveries queued
  in a second FIFO, drained before the first: the robot's command path (winch state -> cable forces
  -> CFC -> joint command -> winch command) marks its inputs so, and a free-running period's command
  goes out before the rest of the graph computes that period. Each subscription still receives its
  topic in publication order; in lockstep, where a node computes a period when all of its inputs are
  there, the order of deliveries changes nothing.
- A ``tap`` subscription (``create_subscription(..., tap=True)``) is called inside ``publish``, not
  through the queue: for a callback that only takes the message away (the bag recorder, 20 topics a
  period), the queue's append, pop and executor dispatch would cost more than the callback itself.
  A tap must be short, must not publish and must not raise.
- A payload (adapted.py: the arrays and stamp a node's stage computed, standing for a message of
  the publisher's type) is published like a message: a subscription created with ``adapted=True``
  receives the payload itself, every other local subscription the message built from it, once per
  publication (``Payload.to_msg``, cached); nothing builds it when only adapted subscriptions take
  the topic. Type adaptation in the spirit of REP 2007.
- What leaves the process, DDS and ``raw`` subscriptions, gets the CDR bytes encoded from the payload
  or message itself (cdr.py), written with ``publish_raw``: rclpy's ``publish`` would build the
  message, copy it field by field into its C struct and serialize that (measured for /cable_forces
  with one subscriber outside: 14 us of the publishing thread's CPU against 6 us). Types cdr.py does
  not cover, and values it cannot pack as rclpy would, go through rclpy.
- The nodes' TimeSources (``use_sim_time``) take /clock as one delivery per message: the time is
  converted once and set on every node's clock (rather than one callback per node and period).
- Transient-local publishers keep their last ``depth`` messages for local subscriptions that
  join later, as DDS would; QoS that DDS would not match (best-effort publisher to a reliable
  subscription, volatile publisher to a transient-local one) is not matched here either.

Subscribers share the published object: a callback must not modify a received message, and a
publisher must not modify a message after publishing it (build a new one each period). The
EventsExecutor of these rclpy wheels supports no guard conditions, hence the timer for waking it.
"""
from __future__ import annotations

import os
import threading
import time
import weakref
from collections import deque

from rclpy.clock import Clock, ClockType
from rclpy.event_handler import PublisherEventCallbacks, SubscriptionEventCallbacks
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.node import Node
from rclpy.publisher import Publisher
from rclpy.qos import DurabilityPolicy, ReliabilityPolicy
from rclpy.serialization import deserialize_message, serialize_message
from rclpy.time import Time
from rclpy.time_source import TimeSource

from cdpr_control.ros import cdr
from cdpr_control.ros.adapted import Payload, as_message, baseline, factory

BUDGET_S = 0.005        # longest time one drain keeps the executor from other events [s]
# runner.spin: longest slice of a lockstep chain between two executor turns [s]. One turn of the
# SingleThreadedExecutor rebuilds its wait set over every entity of the composed graph (about 1.6 ms
# for closed_loop.yaml's 14 nodes), so a turn every 5 ms cost a quarter of the loop; every 50 ms
# (measured: 20 ms 131, 50 ms 64 us of turns a period) leaves timers and services at most 50 ms late.
PUMP_SLICE_S = 0.05
_rcl_time_point = _rclpy.rcl_time_point_t
# how long a publisher trusts its last count of matched DDS subscriptions [s] (_dds_subscribers):
# a reader that joins is served from at most this much later (its discovery took longer)
MATCH_POLL_S = 0.02
RECENT = 64             # local messages per topic remembered to recognise their DDS copies
ENV = "CDPR_INTRA_PROCESS"  # "0": every node of the process uses DDS only (the baseline transport)


def incompatible_policy(pub_qos, sub_qos) -> str | None:
    """The policy for which DDS would not match these QoS (reliability or durability, the policies
    used here; named as rclpy's QoS events name them), None where it would."""
    if pub_qos.reliability == ReliabilityPolicy.BEST_EFFORT and sub_qos.reliability == ReliabilityPolicy.RELIABLE:
        return "RELIABILITY"
    if pub_qos.durability == DurabilityPolicy.VOLATILE and sub_qos.durability == DurabilityPolicy.TRANSIENT_LOCAL:
        return "DURABILITY"
    return None


def compatible(pub_qos, sub_qos) -> bool:
    """Whether DDS would match these QoS (:func:`incompatible_policy`)."""
    return incompatible_policy(pub_qos, sub_qos) is None


class LocalSubscription:
    """The in-process side of one subscription: its callback and the DDS subscription beside it."""

    def __init__(self, registry: "IntraProcess", callback, raw: bool, urgent: bool = False, tap: bool = False,
                 adapted: bool = False):
        self.registry, self.callback, self.raw, self.urgent, self.tap = registry, callback, raw, urgent, tap
        self.adapted = adapted      # takes payloads (adapted.py) as well as messages
        self.topic: Topic | None = None
        self.qos = None
        self.dds = None   # the rclpy Subscription and its node, set once created
        self.node: Node | None = None

    def from_dds(self, msg) -> None:
        """The DDS subscription's callback: deliver what no local publisher delivered already."""
        topic = self.topic
        if topic.publishers:
            local = sum(1 for p in topic.publishers if compatible(p.qos_profile, self.qos))
            if self.dds.get_publisher_count() <= local:
                return                                  # every publisher is local: a copy
            if topic.seen_locally(msg, self.raw):
                return
        item = ((self.callback, msg),)
        self.registry.post((), item) if self.urgent else self.registry.post(item)


def to_cdr(obj) -> bytes:
    """The CDR bytes of a message or payload (cdr.py; rclpy's where it cannot encode them)."""
    data = cdr.to_bytes(obj, obj.msg_type if isinstance(obj, Payload) else type(obj))
    return serialize_message(as_message(obj)) if data is None else data


def clock_fanout(sources: list[TimeSource]):
    """One callback for the /clock subscriptions of several TimeSources (rclpy 7.1
    ``TimeSource.clock_callback``, with the conversion done once). The Time is built and set through
    the handles directly, without the checks and handle guards of ``Time.from_msg`` and
    ``set_ros_time_override`` (4 us instead of 10 for 11 nodes, every period; the clocks belong to
    nodes this thread spins, and a removed node leaves the fan-out at the next publication)."""
    def deliver(msg) -> None:
        stamp = msg.clock
        t = Time.__new__(Time)
        t._time_handle = handle = _rcl_time_point(stamp.sec * 1_000_000_000 + stamp.nanosec, ClockType.ROS_TIME)
        for source in sources:
            source._last_time_set = t
            for clock in source._associated_clocks:
                clock.handle.set_ros_time_override(handle)
    return deliver


def time_source_of(callback) -> TimeSource | None:
    source = getattr(callback, "__self__", None)
    return source if isinstance(source, TimeSource) and callback.__func__ is TimeSource.clock_callback else None


class Topic:
    def __init__(self, name: str):
        self.name = name
        self.publishers: list[IntraProcessPublisher] = []
        self.subscriptions: list[LocalSubscription] = []
        self.version = 0          # changes with the subscriptions (publishers cache their matches)
        self.recent: deque = deque(maxlen=RECENT)

    def seen_locally(self, msg, raw: bool) -> bool:
        """Whether ``msg`` (from DDS) equals a message delivered locally lately: its DDS copy (each
        local subscription gets one). A remote message equal to a recent local one (same stamp and
        content) is taken for a copy too."""
        if raw:
            return any(to_cdr(local) == msg for local in self.recent)
        return any(local == msg for local in self.recent)


class IntraProcess:
    """The registry of one rclpy Context (one per process for a composed graph)."""

    _registries: "weakref.WeakKeyDictionary" = weakref.WeakKeyDictionary()
    _lock = threading.Lock()

    def __init__(self, enabled: bool):
        self.enabled = enabled
        self.topics: dict[str, Topic] = {}
        self.queue: deque = deque()
        self.urgent: deque = deque()        # deliveries to urgent subscriptions, delivered first
        self.lock = threading.Lock()
        self.busy = False
        self.owner: int | None = None       # thread ident of the executor spinning these nodes
        self.pumped = False                 # runner.spin drains the queue between executor events
        self.wake_timer = None
        self.wake_node: Node | None = None
        self.nodes: list[Node] = []
        self.deliveries = 0                 # messages handed over in-process (for tests, benchmarks)
        # False where an executor that rebuilds its wait set every turn spins these nodes (a composed
        # lockstep graph's SingleThreadedExecutor, launch.py): subscriptions then get no QoS event
        # handlers (see IntraProcessNode.create_subscription) and the registry reports mismatched
        # local QoS itself (_check_qos)
        self.subscription_events = True
        self._qos_reported: set[tuple[int, int]] = set()

    @classmethod
    def of(cls, context) -> "IntraProcess":
        with cls._lock:
            registry = cls._registries.get(context)
            if registry is None:
                registry = cls._registries[context] = cls(os.environ.get(ENV, "1") != "0")
            return registry

    @classmethod
    def set_enabled(cls, context, enabled: bool) -> None:
        """Before the nodes of ``context`` are created: in-process delivery on (default) or off."""
        cls.of(context).enabled = enabled

    def topic(self, name: str) -> Topic:
        topic = self.topics.get(name)
        if topic is None:
            topic = self.topics[name] = Topic(name)
        return topic

    # -- the queue ---------------------------------------------------------------------------
    def pending(self) -> bool:
        return bool(self.queue or self.urgent)

    def post(self, items, urgent=()) -> None:
        """Append (callback, message) pairs (``urgent``: to the queue delivered first); drain now when
        this thread may run callbacks."""
        with self.lock:
            self.queue.extend(items)
            if urgent:
                self.urgent.extend(urgent)
            if self.busy:
                return                          # the running drain delivers them, in order
            if self.owner is not None and self.owner != threading.get_ident():
                self.wake()                     # another thread: let the executor's thread run them
                return
            self.busy = True
        self._drain()

    def _drain(self, budget: float = BUDGET_S) -> None:
        queue, urgent, deadline = self.queue, self.urgent, time.perf_counter() + budget
        try:
            while True:
                try:
                    callback, msg = urgent.popleft() if urgent else queue.popleft()
                except IndexError:
                    with self.lock:
                        if not queue and not urgent:
                            self.busy = False
                            return
                    continue
                self.deliveries += 1
                callback(msg)
                if (queue or urgent) and time.perf_counter() > deadline:
                    with self.lock:
                        self.busy = False
                        if not self.pumped:
                            self.wake()
                    return
        except BaseException:
            with self.lock:
                self.busy = False
            raise

    def pump(self) -> None:
        """Deliver what is queued (at most one budget's worth): called by runner.spin between
        executor events, so timers and services get their turn while a lockstep ring runs.
        (Handing over through a one-shot timer instead delays the EventsExecutor's other timers
        more and more: measured 0.16, 0.4, 0.7, 1.5, 3 s between ticks of a 10 Hz timer.)"""
        self._on_wake(PUMP_SLICE_S)

    def wake(self) -> None:
        """Have the executor drain the queue soon (a one-shot timer: no guard conditions here)."""
        if self.wake_timer is not None:
            self.wake_timer.reset()

    def _on_wake(self, budget: float = BUDGET_S) -> None:
        if self.wake_timer is not None:
            self.wake_timer.cancel()
        with self.lock:
            if self.busy or not (self.queue or self.urgent):
                return
            self.busy = True
        self._drain(budget)

    # -- registration ------------------------------------------------------------------------
    def add_node(self, node: Node) -> None:
        if node in self.nodes:
            return
        self.nodes.append(node)
        if self.wake_timer is None:
            self._make_wake_timer(node)

    def _make_wake_timer(self, node: Node) -> None:
        self.wake_node = node
        self.wake_timer = Node.create_timer(node, 1e-6, self._on_wake, clock=Clock(clock_type=ClockType.STEADY_TIME))
        self.wake_timer.cancel()

    def remove_node(self, node: Node) -> None:
        for topic in list(self.topics.values()):
            topic.publishers = [p for p in topic.publishers if p._ipc_node is not node]
            topic.subscriptions = [s for s in topic.subscriptions if s.node is not node]
            topic.version += 1
        if node in self.nodes:
            self.nodes.remove(node)
        if node is self.wake_node:
            self.wake_timer = self.wake_node = None
            if self.nodes:
                self._make_wake_timer(self.nodes[0])

    def add_subscription(self, local: LocalSubscription) -> None:
        topic = local.topic
        topic.subscriptions.append(local)
        topic.version += 1
        self._check_qos(topic)
        # transient local: what a DDS reader joining now would get from the publishers' history
        late = [(local.callback, self._as(local, msg)) for p in topic.publishers
                if p.history is not None and compatible(p.qos_profile, local.qos) for msg in p.history]
        if late and local.qos.durability == DurabilityPolicy.TRANSIENT_LOCAL:
            self.post(late)

    def _check_qos(self, topic: Topic) -> None:
        """Where subscriptions have no QoS event handlers (``subscription_events``), warn once per pair
        of a local publisher and subscription that DDS would not match, in the words of rclpy's
        default handler. (A publisher in another process reports such a mismatch on its side.)"""
        if self.subscription_events:
            return
        for p in topic.publishers:
            for s in topic.subscriptions:
                policy = incompatible_policy(p.qos_profile, s.qos)
                if policy is not None and (id(p), id(s)) not in self._qos_reported:
                    self._qos_reported.add((id(p), id(s)))
                    s.node.get_logger().warning(
                        f"New publisher discovered on topic '{topic.name}', offering incompatible QoS. "
                        f"No messages will be received from it. Last incompatible policy: {policy}")

    @staticmethod
    def _as(local: LocalSubscription, msg):
        """What ``local`` receives of a published ``msg`` (a message or a payload)."""
        if local.raw:
            return to_cdr(msg)
        return msg if local.adapted else as_message(msg)

    def remove_subscription(self, subscription) -> None:
        for topic in self.topics.values():
            topic.subscriptions = [s for s in topic.subscriptions if s.dds is not subscription]
            topic.version += 1

    def remove_publisher(self, publisher) -> None:
        topic = self.topics.get(publisher.topic_name)
        if topic is not None and publisher in topic.publishers:
            topic.publishers.remove(publisher)


class IntraProcessPublisher(Publisher):
    """A publisher that delivers to local subscriptions first and to DDS when someone else listens."""

    _ipc_registry: IntraProcess | None = None
    _ipc_topic: Topic | None = None
    _ipc_node: Node | None = None
    _ipc_version = -1
    _ipc_matched: list = []
    _ipc_others: list = []          # matched, but for the TimeSources and the taps
    _ipc_taps: list = []            # matched taps: called inside publish
    _ipc_clocks = None              # the matched TimeSources' callback (clock_fanout)
    _ipc_dds_count = 0              # matched DDS subscriptions (local ones included) at ...
    _ipc_dds_polled = -1.0          # ... this time.monotonic() (< 0: ask at the next publication)
    history: deque | None = None

    def _rematch(self, topic: Topic) -> None:
        self._ipc_version = topic.version
        self._ipc_matched = [s for s in topic.subscriptions if compatible(self.qos_profile, s.qos)]
        sources = [time_source_of(s.callback) for s in self._ipc_matched]
        others = [s for s, source in zip(self._ipc_matched, sources) if source is None]
        self._ipc_others = [s for s in others if not s.tap]
        self._ipc_taps = [s for s in others if s.tap]
        sources = [source for source in sources if source is not None]
        self._ipc_clocks = clock_fanout(sources) if sources else None
        self._ipc_dds_polled = -1.0

    def _dds_subscribers(self) -> int:
        """The matched DDS subscriptions, local ones included, as rcl counted them at most
        MATCH_POLL_S ago (rcl's count without rclpy's handle guard: this thread owns the publisher)."""
        now = time.monotonic()
        if now - self._ipc_dds_polled >= MATCH_POLL_S:
            self._ipc_dds_count = self._Publisher__publisher.get_subscription_count()
            self._ipc_dds_polled = now
        return self._ipc_dds_count

    def to_dds(self, msg, data: bytes | None = None) -> None:
        """Write ``msg`` (a message, its payload or its CDR bytes ``data``) to DDS as CDR bytes, so that
        rclpy converts nothing; through rclpy's ``publish`` where cdr.py cannot encode it (rclpy
        then converts or refuses it as usual)."""
        if data is None:
            data = msg if isinstance(msg, bytes) else cdr.to_bytes(msg, self.msg_type)
            if data is None:
                return super().publish(as_message(msg))
        # rcl's write without rclpy's handle guard (this thread owns the publisher, as in publish)
        self._Publisher__publisher.publish_raw(data)

    def publish(self, msg) -> None:
        topic = self._ipc_topic
        if topic is None:
            return super().publish(as_message(msg))
        if isinstance(msg, bytes):
            obj = deserialize_message(msg, self.msg_type) if topic.subscriptions or self.history is not None else None
        elif isinstance(msg, self.msg_type) or (isinstance(msg, Payload) and msg.msg_type is self.msg_type):
            obj = msg
        else:
            raise TypeError(f"Expected {self.msg_type} or its payload, got {type(msg)}")
        if self._ipc_version != topic.version:      # the local subscriptions changed: match again
            self._rematch(topic)
        matched, items, urgent, data = self._ipc_matched, [], [], None
        if obj is not None:
            if self.history is not None:
                self.history.append(obj)
            if matched:
                if self._ipc_clocks is not None:
                    items.append((self._ipc_clocks, as_message(obj)))
                for s in self._ipc_others:
                    if s.raw:
                        data = to_cdr(obj) if data is None else data
                        (urgent if s.urgent else items).append((s.callback, data))
                    else:
                        (urgent if s.urgent else items).append((s.callback, obj if s.adapted else as_message(obj)))
                topic.recent.append(obj)
        # transient local: always, so that DDS keeps the history for a reader that joins later
        if self.history is not None or self._dds_subscribers() > len(matched):
            self.to_dds(msg, data)              # first: outside, a message is seen before those it causes
        if obj is not None and matched:
            for s in self._ipc_taps:
                if s.raw:
                    data = to_cdr(obj) if data is None else data
                    s.callback(data)
                else:
                    s.callback(obj if s.adapted else as_message(obj))
            if items or urgent:
                self._ipc_registry.post(items, urgent)


def has_subscribers(publisher) -> bool:
    """Whether anything would receive what ``publisher`` publishes now (a subscription in this process
    or over DDS): a node may skip building a message nobody takes."""
    topic = getattr(publisher, "_ipc_topic", None)
    if topic is not None:
        if publisher._ipc_version != topic.version:
            publisher._rematch(topic)
        if publisher._ipc_matched or publisher.history is not None:
            return True
        return publisher._dds_subscribers() > 0
    # rcl's count without rclpy's handle guard, as in publish (four a period in the simulator)
    return publisher._Publisher__publisher.get_subscription_count() > 0


class IntraProcessNode(Node):
    """An rclpy Node whose publishers and subscriptions use intra-process delivery in its context.

    NO_EVENTS: its publishers have no QoS event handlers unless the caller passes ``event_callbacks``.
    rclpy gives every publisher and subscription two by default (incompatible QoS, incompatible type)
    that log a warning; each is an entity every turn of a SingleThreadedExecutor waits on and checks
    against all the others (closed_loop.yaml: 221 of 388 entities; a turn between two slices of the
    lockstep ring 3.2 -> 2.5 ms without the publishers'). The subscription's handler reports the same
    mismatch ("New publisher discovered on topic ..., offering incompatible QoS"); where the registry's
    ``subscription_events`` is off (a composed lockstep launch) subscriptions have none either and the
    registry reports local mismatches itself (IntraProcess._check_qos).
    """

    def _intra_process(self) -> IntraProcess | None:
        registry = IntraProcess.of(self.context)
        if not registry.enabled:
            return None
        registry.add_node(self)
        return registry

    def message_factory(self, msg_type):
        """What this node builds its outputs of ``msg_type`` with, from keyword arguments named like the
        fields (adapted.factory): payloads where intra-process delivery and type adaptation are on, else
        ROS messages. Chosen once per node and type (a node of the baseline stays one)."""
        factories = self.__dict__.setdefault("_message_factories", {})
        made = factories.get(msg_type)
        if made is None:
            made = factories[msg_type] = (factory(msg_type) if IntraProcess.of(self.context).enabled
                                          else baseline(msg_type))
        return made

    def create_publisher(self, msg_type, topic, qos_profile, **kwargs):
        kwargs.setdefault("event_callbacks", PublisherEventCallbacks(use_default_callbacks=False))  # see NO_EVENTS
        registry = self._intra_process()
        if registry is None or kwargs.get("publisher_class", Publisher) is not Publisher:
            return super().create_publisher(msg_type, topic, qos_profile, **kwargs)
        publisher = super().create_publisher(msg_type, topic, qos_profile, publisher_class=IntraProcessPublisher,
                                             **kwargs)
        qos = publisher.qos_profile
        publisher.history = (deque(maxlen=max(1, qos.depth)) if qos.durability == DurabilityPolicy.TRANSIENT_LOCAL
                             else None)
        publisher._ipc_registry, publisher._ipc_node = registry, self
        publisher._ipc_topic = topic_entry = registry.topic(publisher.topic_name)
        topic_entry.publishers.append(publisher)
        registry._check_qos(topic_entry)
        return publisher

    def create_subscription(self, msg_type, topic, callback, qos_profile, *, raw: bool = False,
                            urgent: bool = False, tap: bool = False, adapted: bool = False, **kwargs):
        """``urgent``: in-process deliveries to this subscription go before the others queued (the
        robot's command path: a free-running period's command does not wait for the rest of the graph).
        ``tap``: they are made inside ``publish`` (see the module's docstring); DDS messages of other
        processes come through the executor as usual. ``adapted``: the callback takes the payload a
        local publisher publishes (adapted.py) as well as a message, and only reads its fields."""
        registry = self._intra_process()
        if registry is None:
            return super().create_subscription(msg_type, topic, callback, qos_profile, raw=raw, **kwargs)
        local = LocalSubscription(registry, callback, raw, urgent, tap, adapted)
        if not registry.subscription_events:
            # rclpy gives each subscription two QoS event handlers (incompatible QoS and type), each a
            # waitable that a SingleThreadedExecutor re-adds to its wait set and checks against all
            # the others every turn: closed_loop.yaml's 130 of 302 entities, a turn between two slices
            # of the lockstep ring 3.2 -> 1.7 ms (session 19). The registry reports local mismatches.
            kwargs.setdefault("event_callbacks", SubscriptionEventCallbacks(use_default_callbacks=False))
        subscription = super().create_subscription(msg_type, topic, local.from_dds, qos_profile, raw=raw, **kwargs)
        local.dds, local.node, local.qos = subscription, self, subscription.qos_profile
        local.topic = registry.topic(subscription.topic_name)
        registry.add_subscription(local)
        return subscription

    def destroy_publisher(self, publisher) -> bool:
        if isinstance(publisher, IntraProcessPublisher) and publisher._ipc_registry is not None:
            publisher._ipc_registry.remove_publisher(publisher)
            publisher._ipc_topic = None
        return super().destroy_publisher(publisher)

    def destroy_subscription(self, subscription) -> bool:
        IntraProcess.of(self.context).remove_subscription(subscription)
        return super().destroy_subscription(subscription)

    def destroy_node(self):
        IntraProcess.of(self.context).remove_node(self)
        return super().destroy_node()
