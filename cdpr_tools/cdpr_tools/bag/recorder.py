"""BagRecorder node: subscribes to topics as they appear and writes them to a bag.

Like ``ros2 bag record``: serialized (raw) subscriptions, the QoS adapted to the publishers'
offers, those offers stored per topic, the receive time on the node's clock as log time (sim time
with ``use_sim_time``; also the publish time, since the EventsExecutor passes no message info).
Hidden topics are left out unless asked for. Follows the node convention of docs/tools.md, so the launcher can compose it;
composed with the graph's nodes (one context), it gets their messages in-process, serialized once
for the bag (cdpr_control.nodes.intraprocess), and the nodes need not publish over DDS for it.
"""
from __future__ import annotations

from datetime import datetime

from rcl_interfaces.msg import ParameterDescriptor

from cdpr_tools.bag.writer import BagWriter
from cdpr_tools.message_convert import message_class
from cdpr_control.nodes.intraprocess import IntraProcessNode
from cdpr_control.nodes.runner import run_node
from cdpr_tools.ros_graph import TopicSelection, adapted_qos

DEFAULT_QUEUE_DEPTH = 1000  # messages held per topic while the recorder is busy (1 s at 1 kHz)
DISCOVERY_PERIOD = 0.1      # s between looks for new topics (default of ``discovery_period``)


def default_bag_name() -> str:
    """``bags/rosbag2_YYYY_MM_DD-HH_MM_SS``, rosbag2's default name under the project's bags/."""
    return datetime.now().strftime("bags/rosbag2_%Y_%m_%d-%H_%M_%S")


class BagRecorder(IntraProcessNode):
    """Parameters: ``output`` (bag path), ``topics`` (empty: all), ``exclude`` (regex),
    ``include_hidden_topics``, ``discovery_period`` [s], ``queue_depth``, ``compression``."""

    def __init__(self, **kwargs):
        super().__init__("bag_recorder", **kwargs)
        self.declare_parameter("output", "", ParameterDescriptor(
            description="bag directory (or .mcap file); empty: bags/rosbag2_<date>-<time>", read_only=True))
        self.declare_parameter("queue_depth", DEFAULT_QUEUE_DEPTH, ParameterDescriptor(read_only=True))
        self.declare_parameter("compression", "none", ParameterDescriptor(
            description="chunk compression of the MCAP file: none, zstd or lz4 (as rosbag2's mcap storage)",
            read_only=True))
        output = self.get_parameter("output").value or default_bag_name()
        self.depth = self.get_parameter("queue_depth").value
        self.writer = BagWriter(output, compression=self.get_parameter("compression").value)
        self._recording: dict[str, object] = {}  # topic -> subscription
        self.selection = TopicSelection(self, "record", DISCOVERY_PERIOD, self._subscribe)
        self.get_logger().info(f"recording to {self.writer.path}")

    def _subscribe(self, topic: str, type_name: str) -> bool | None:
        offers = self.get_publishers_info_by_topic(topic)
        if not offers:
            return None  # the publisher went again: the offered QoS decides how to subscribe
        try:
            msg_class = message_class(type_name)
            self.writer.add_topic(topic, type_name, [o.qos_profile for o in offers],
                                  str(offers[0].topic_type_hash) if offers[0].topic_type_hash.version > 0 else None)
        except (LookupError, ValueError) as exc:
            self.get_logger().warning(f"not recording {topic}: {exc}")
            return False
        write, clock = self.writer.write, self.get_clock()

        def on_message(data: bytes) -> None:  # (the EventsExecutor cannot pass message info)
            write(topic, type_name, data, clock.now().nanoseconds)

        self._recording[topic] = self.create_subscription(
            msg_class, topic, on_message, adapted_qos(self, topic, self.depth), raw=True)
        self.get_logger().info(f"subscribed to {topic} [{type_name}]")
        return True

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
