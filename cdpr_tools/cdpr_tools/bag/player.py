"""BagPlayer: publish a bag's messages again, with their types, recorded QoS and relative timing.

As ``ros2 bag play``: the serialized messages go out unchanged, spaced by their log times divided
by ``rate``; publishers offer the QoS the recorded publishers offered; optionally ``/clock`` is
published at a fixed rate with the bag time, so nodes with ``use_sim_time`` follow the bag.
"""
from __future__ import annotations

import math
import threading
import time
from typing import Callable, Iterable

from builtin_interfaces.msg import Time
from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.qos import QoSProfile
from rosgraph_msgs.msg import Clock

from cdpr_tools.bag.qos import playback_qos
from cdpr_tools.bag.reader import BagReader
from cdpr_tools.message_convert import message_class

PROGRESS_PERIOD = 1.0  # s of wall time between progress reports

DEFAULT_CLOCK_HZ = 40.0  # rosbag2's default for `ros2 bag play --clock`
MAX_CLOCK_HZ = 10_000.0  # /clock rates above it add nothing a node could use (and 1e300 Hz would never tick on)
MAX_SECONDS = 1e9        # s: longest offset or wait taken (a bag's nanosecond times overflow at 9.2e9 s)
WAIT_SLICE = 1.0         # s: the longest single wait, so that any rate > 0 waits without overflowing


class BagPlayer:
    """Plays ``bag`` on ``node``'s publishers.

    ``topics``: only these (default all); ``start_offset``: seconds into the bag to start at;
    ``clock_hz``: publish /clock at this rate (0: not at all); ``loop``: start over at the end;
    ``remap``: bag topic -> topic to publish it on (as ``ros2 bag play --remap``); ``progress(done,
    total)``: called about once a second of wall time with the bag time played and the bag's span [s].
    """

    def __init__(self, node: Node, bag: BagReader, *, rate: float = 1.0, topics: Iterable[str] | None = None,
                 start_offset: float = 0.0, clock_hz: float = 0.0, loop: bool = False,
                 remap: dict[str, str] | None = None, progress: Callable[[float, float], None] | None = None):
        if not (rate > 0 and math.isfinite(rate)):
            raise ValueError(f"rate must be a finite number > 0, got {rate}")
        if not 0 <= start_offset <= MAX_SECONDS:
            raise ValueError(f"start offset must be a number in [0, {MAX_SECONDS:g}] s, got {start_offset}")
        if not (clock_hz == 0 or 0 < clock_hz <= MAX_CLOCK_HZ):
            raise ValueError(f"clock rate must be 0 (no /clock) or in (0, {MAX_CLOCK_HZ:g}] Hz, got {clock_hz}")
        self.node, self.bag, self.rate, self.loop = node, bag, rate, loop
        self.topics = sorted(topics) if topics else list(bag.topics)
        unknown = sorted(set(self.topics) - set(bag.topics))
        if unknown:
            raise ValueError(f"bag {bag.path} has no topic {', '.join(unknown)}; topics: {', '.join(bag.topics)}")
        remap = dict(remap or {})
        unknown = sorted(set(remap) - set(bag.topics))
        if unknown:
            raise ValueError(f"--remap names topics the bag does not have: {', '.join(unknown)}; "
                             f"topics: {', '.join(bag.topics)}")
        self.remap = {topic: remap.get(topic, topic) for topic in self.topics}
        self.progress, self._next_progress = progress, 0.0
        self.publishers = {}
        for topic in self.topics:
            info = bag.topics[topic]
            try:
                msg_class = message_class(info.type)
            except LookupError as exc:
                node.get_logger().warning(f"not playing {topic}: {exc}")
                continue
            self.publishers[topic] = node.create_publisher(msg_class, self.remap[topic],
                                                           playback_qos(info.offered_qos_profiles))
        self.start_ns = (bag.start_time_ns or 0) + int(start_offset * 1e9)
        self.clock_period = 1.0 / clock_hz if clock_hz > 0 else None
        self.clock_publisher = node.create_publisher(Clock, "/clock", QoSProfile(depth=10)) if clock_hz > 0 else None
        self.published = 0

    def wait_for_subscribers(self, timeout: float, stop: threading.Event | None = None) -> bool:
        """Wait until every publisher (and /clock) has a matched subscription, at most ``timeout`` s."""
        publishers = list(self.publishers.values()) + ([self.clock_publisher] if self.clock_publisher else [])
        deadline = time.monotonic() + timeout
        stop = stop or threading.Event()
        while not all(p.get_subscription_count() > 0 for p in publishers):
            if time.monotonic() >= deadline or stop.wait(0.02):
                return False
        return True

    def play(self, stop: threading.Event | None = None) -> int:
        """Publish until the bag ends (or ``stop`` is set); returns the number of messages published."""
        stop = stop or threading.Event()
        while True:
            self._play_once(stop)
            if not self.loop or stop.is_set():
                return self.published

    def wait_for_delivery(self, timeout: float) -> bool:
        """Wait until the reliable subscribers have acknowledged every message published, at most
        ``timeout`` s in all (True: all acknowledged): a context shut down right after the last
        publish drops what is still on its way (a test's subscriber missed the last of 20 messages)."""
        deadline = time.monotonic() + timeout
        publishers = list(self.publishers.values()) + ([self.clock_publisher] if self.clock_publisher else [])
        return all(p.wait_for_all_acked(Duration(nanoseconds=int(max(0.0, deadline - time.monotonic()) * 1e9)))
                   for p in publishers)

    def _play_once(self, stop: threading.Event) -> None:
        wall0 = time.monotonic()
        self._next_clock = wall0
        if not self.publishers:
            return
        for m in self.bag.messages(self.publishers, start_ns=self.start_ns):
            if not self._wait_until(wall0, wall0 + (m.log_time_ns - self.start_ns) * 1e-9 / self.rate, stop):
                return
            self.publishers[m.topic].publish(m.data)
            self.published += 1
            if self.progress is not None and time.monotonic() >= self._next_progress:
                self._next_progress = time.monotonic() + PROGRESS_PERIOD
                self.progress((m.log_time_ns - self.start_ns) * 1e-9, (self.bag.end_time_ns - self.start_ns) * 1e-9)

    def _wait_until(self, wall0: float, target: float, stop: threading.Event) -> bool:
        """Sleep until ``target`` (monotonic time), ticking /clock meanwhile; False when stopped."""
        while True:
            now = time.monotonic()
            if self.clock_publisher is not None:
                while self._next_clock <= min(now, target):
                    self._publish_clock(self.start_ns + int((self._next_clock - wall0) * self.rate * 1e9))
                    self._next_clock += self.clock_period
            if now >= target:
                return not stop.is_set()
            wake = min(target, self._next_clock) if self.clock_publisher is not None else target
            if stop.wait(min(WAIT_SLICE, max(0.0, wake - now))):
                return False

    def _publish_clock(self, t_ns: int) -> None:
        sec, nanosec = divmod(t_ns, 1_000_000_000)
        self.clock_publisher.publish(Clock(clock=Time(sec=sec, nanosec=nanosec)))
