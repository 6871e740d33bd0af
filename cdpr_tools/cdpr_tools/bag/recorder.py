"""BagRecorder node: subscribes to topics as they appear and writes them to a bag.

Like ``ros2 bag record``: serialized (raw) subscriptions, the QoS adapted to the publishers'
offers, those offers stored per topic, the receive time on the node's clock as log time (sim time
with ``use_sim_time``; also the publish time, since the EventsExecutor passes no message info).
Hidden topics are left out unless asked for. Follows the node convention of docs/tools.md, so the launcher can compose it.
"""
from __future__ import annotations

import re
from datetime import datetime

from rcl_interfaces.msg import ParameterDescriptor
from rclpy.exceptions import ParameterUninitializedException
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.parameter import Parameter

from cdpr_tools.bag.writer import BagWriter
from cdpr_tools.message_convert import message_class
from cdpr_control.nodes.runner import run_node
from cdpr_tools.ros_graph import adapted_qos, fully_qualified, topic_types

DEFAULT_QUEUE_DEPTH = 1000  # messages held per topic while the recorder is busy (1 s at 1 kHz)


def default_bag_name() -> str:
    """``bags/rosbag2_YYYY_MM_DD-HH_MM_SS``, rosbag2's default name under the project's bags/."""
    return datetime.now().strftime("bags/rosbag2_%Y_%m_%d-%H_%M_%S")


class BagRecorder(Node):
    """Parameters: ``output`` (bag path), ``topics`` (empty: all), ``exclude`` (regex),
    ``include_hidden_topics``, ``discovery_period`` [s], ``queue_depth``, ``compression``."""

    def __init__(self, **kwargs):
        super().__init__("bag_recorder", **kwargs)
        self.declare_parameter("output", "", ParameterDescriptor(
            description="bag directory (or .mcap file); empty: bags/rosbag2_<date>-<time>", read_only=True))
        self.declare_parameter("topics", Parameter.Type.STRING_ARRAY, ParameterDescriptor(
            description="topics to record; empty or unset: every topic", read_only=True))
        self.declare_parameter("exclude", "", ParameterDescriptor(
            description="regular expression of topics not to record", read_only=True))
        self.declare_parameter("include_hidden_topics", False, ParameterDescriptor(read_only=True))
        self.declare_parameter("discovery_period", 0.1, ParameterDescriptor(
            description="how often to look for new topics [s]", read_only=True))
        self.declare_parameter("queue_depth", DEFAULT_QUEUE_DEPTH, ParameterDescriptor(read_only=True))
        self.declare_parameter("compression", "none", ParameterDescriptor(
            description="chunk compression of the MCAP file: none, zstd or lz4 (as rosbag2's mcap storage)",
            read_only=True))
        output = self.get_parameter("output").value or default_bag_name()
        try:
            topics = self.get_parameter("topics").value or []
        except ParameterUninitializedException:  # declared without a value: record everything
            topics = []
        self.selected = {fully_qualified(t) for t in topics if t}
        exclude = self.get_parameter("exclude").value
        self.exclude = re.compile(exclude) if exclude else None
        self.include_hidden = self.get_parameter("include_hidden_topics").value
        self.depth = self.get_parameter("queue_depth").value
        self.writer = BagWriter(output, compression=self.get_parameter("compression").value)
        self._recording: dict[str, object] = {}  # topic -> subscription
        self._skipped: set[str] = set()
        # graph polling on the steady clock: with use_sim_time the node's clock waits for /clock
        self.create_timer(self.get_parameter("discovery_period").value, self.discover,
                          clock=Clock(clock_type=ClockType.STEADY_TIME))
        self.get_logger().info(f"recording to {self.writer.path}")

    def wanted(self, topic: str) -> bool:
        if self.selected and topic not in self.selected:
            return False
        return not (self.exclude and self.exclude.fullmatch(topic))

    def discover(self) -> None:
        """Subscribe to wanted topics that have publishers and no subscription yet."""
        for topic, types in topic_types(self, self.include_hidden).items():
            if topic in self._recording or topic in self._skipped or not self.wanted(topic):
                continue
            offers = self.get_publishers_info_by_topic(topic)
            if not offers:
                continue  # the offered QoS decides how to subscribe: wait for a publisher
            self._subscribe(topic, types[0], offers)

    def _subscribe(self, topic: str, type_name: str, offers) -> None:
        try:
            msg_class = message_class(type_name)
            self.writer.add_topic(topic, type_name, [o.qos_profile for o in offers],
                                  str(offers[0].topic_type_hash) if offers[0].topic_type_hash.version > 0 else None)
        except (LookupError, ValueError) as exc:
            self._skipped.add(topic)
            self.get_logger().warning(f"not recording {topic}: {exc}")
            return
        write, clock = self.writer.write, self.get_clock()

        def on_message(data: bytes) -> None:  # (the EventsExecutor cannot pass message info)
            write(topic, type_name, data, clock.now().nanoseconds)

        self._recording[topic] = self.create_subscription(
            msg_class, topic, on_message, adapted_qos(self, topic, self.depth), raw=True)
        self.get_logger().info(f"subscribed to {topic} [{type_name}]")

    @property
    def recorded_topics(self) -> list[str]:
        return sorted(self._recording)

    def destroy_node(self) -> None:
        """Stop subscribing, then close the bag (summary, metadata.yaml)."""
        for subscription in self._recording.values():
            self.destroy_subscription(subscription)
        self._recording.clear()
        self.writer.close()
        self.get_logger().info(f"bag {self.writer.path}: {self.writer.message_count} messages")
        super().destroy_node()


def main(args=None) -> None:
    run_node(BagRecorder, args)
