"""BagRecorder node: subscribes to topics as they appear and writes them to a bag.

Like ``ros2 bag record``: the QoS adapted to the publishers' offers, those offers stored per topic,
the receive time on the node's clock as log time (sim time with ``use_sim_time``; also the publish
time, since the EventsExecutor passes no message info). Hidden topics are left out unless asked
for. Follows the node convention of docs/tools.md, so the launcher can compose it.

Composed with the graph's nodes (one context), the recorder gets their messages in-process
(cdpr_control.ros.intraprocess), on the thread that runs the control loop, and the nodes need
not publish over DDS for it. So it does as little as it can there: a topic with a publisher in the
process is subscribed to as objects, payloads where the publisher publishes them
(cdpr_control.ros.adapted: no ROS message is built for the bag) and messages otherwise, each encoded
once by the generated encoder of its type (:mod:`.encode`, which reads the message's slots, which a
payload has too; a few us where rclpy's serialization takes 3-11), and the bytes are queued for the
writer child process (:mod:`.writer_process`), which writes the bag on the other core. Topics
published elsewhere only are subscribed to serialized (``raw``), as ``ros2 bag record`` does.
"""
from __future__ import annotations

from datetime import datetime

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
from rclpy.clock import Clock, ClockType

from cdpr_tools.bag.encode import encoder, serialize
from cdpr_tools.bag.writer_process import BagWriterProcess
from cdpr_tools.message_convert import message_class
from cdpr_control.ros.adapted import as_message
from cdpr_control.ros.intraprocess import IntraProcess, IntraProcessNode
from cdpr_control.ros.runner import run_node
from cdpr_tools.ros_graph import TopicSelection, adapted_qos

DEFAULT_QUEUE_DEPTH = 1000  # messages held per topic while the recorder is busy (1 s at 1 kHz)
DISCOVERY_PERIOD = 0.1      # s between looks for new topics (default of ``discovery_period``)
SEND_PERIOD = 0.1           # s: the longest a message waits in the queue for the writer process


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
        self.declare_parameter("compression", "zstd", ParameterDescriptor(
            description="chunk compression of the MCAP file: zstd (default: the main job's bag to 29 % of its "
                        "uncompressed size, compressed in the writer process), lz4 or none (as rosbag2's mcap storage)",
            read_only=True))
        self.declare_parameter("max_bag_size", 0, ParameterDescriptor(
            description="split the bag into files of about this many bytes (0: one file), as ros2 bag record",
            read_only=True, integer_range=[IntegerRange(from_value=0, to_value=2**62, step=1)]))
        self.declare_parameter("max_bag_duration", 0.0, ParameterDescriptor(
            description="split the bag into files of this many seconds of log time (0: one file)", read_only=True,
            floating_point_range=[FloatingPointRange(from_value=0.0, to_value=1e9, step=0.0)]))
        output = self.get_parameter("output").value or default_bag_name()
        self.depth = self.get_parameter("queue_depth").value
        self.writer = BagWriterProcess(output, compression=self.get_parameter("compression").value,
                                       max_bag_size=self.get_parameter("max_bag_size").value,
                                       max_bag_duration=self.get_parameter("max_bag_duration").value)
        self._recording: dict[str, object] = {}  # topic -> subscription
        self._from_dds: dict[str, object] = {}   # topic -> on_message, for topics only DDS brings (take_waiting)
        self._failure_logged = False
        self.selection = TopicSelection(self, "record", DISCOVERY_PERIOD, self._subscribe)
        # (steady clock: with use_sim_time the node's clock stands while the graph does)
        self.create_timer(SEND_PERIOD, self._send, clock=Clock(clock_type=ClockType.STEADY_TIME))
        self.get_logger().info(f"recording to {self.writer.path}")

    def _subscribe(self, topic: str, type_name: str) -> bool | None:
        offers = self.get_publishers_info_by_topic(topic)
        if not offers:
            return None  # the publisher went again: the offered QoS decides how to subscribe
        try:
            msg_class = message_class(type_name)
            index = self.writer.add_topic(
                topic, type_name, [o.qos_profile for o in offers],
                str(offers[0].topic_type_hash) if offers[0].topic_type_hash.version > 0 else None)
        except (LookupError, ValueError) as exc:
            self.get_logger().warning(f"not recording {topic}: {exc}")
            return False
        # what BagWriterProcess.put does, inlined (these run on the loop's thread, 20 times a period);
        # in-process messages are taken inside their publish (a tap: intraprocess.py), not queued
        queue, batch, send = self.writer.queue, self.writer.batch, self.writer.send
        append, now = queue.append, self.get_clock().handle.get_now   # (Clock.now() builds a Time: 2 us)
        encode = encoder(type_name)
        if encode is not None and self._published_here(topic):
            def on_message(msg) -> None:  # the publisher's payload or message (or rclpy's, from another process)
                try:
                    data = encode(msg)
                except Exception:  # noqa: BLE001 - a value the encoder cannot pack: rclpy decides
                    data = serialize(as_message(msg), type_name)
                append((index, now().nanoseconds, data, True))
                if len(queue) >= batch:
                    send()
            raw = False
        else:
            def on_message(data: bytes) -> None:  # (the EventsExecutor cannot pass message info)
                append((index, now().nanoseconds, data, False))
                if len(queue) >= batch:
                    send()
            raw = True
        self._recording[topic] = self.create_subscription(
            msg_class, topic, on_message, adapted_qos(self, topic, self.depth), raw=raw, tap=True, adapted=not raw)
        if raw:
            self._from_dds[topic] = on_message
        self.get_logger().info(f"subscribed to {topic} [{type_name}]")
        return True

    def _published_here(self, topic: str) -> bool:
        """Whether a node of this process publishes ``topic`` (then its messages come as objects)."""
        registry = IntraProcess.of(self.context)
        entry = registry.topics.get(topic) if registry.enabled else None
        return bool(entry and entry.publishers)

    def _send(self) -> None:
        self.writer.send()
        if self.writer.failed and not self._failure_logged:
            self._failure_logged = True
            self.get_logger().error(self.writer.failed)

    @property
    def recorded_topics(self) -> list[str]:
        return sorted(self._recording)

    def take_waiting(self) -> int:
        """Record the messages DDS holds for this recorder that no executor took (count returned).

        Call it once nothing spins the recorder any more: on a loaded machine its thread may lag the
        publishers by many messages when a launch stops, and they would be lost with the
        subscriptions. Each subscription's history holds up to ``queue_depth`` of them, in order.
        Only topics that no node of this process published when the recorder subscribed and none
        publishes now: a local publisher's messages are recorded inside its publish, and their DDS
        copies would be recorded twice. They go straight to the recorder's callback, not through the
        in-process queue, which may hold deliveries to nodes destroyed meanwhile."""
        registry = IntraProcess.of(self.context)
        count = 0
        for topic, on_message in self._from_dds.items():
            entry = registry.topics.get(topic)
            if entry is not None and entry.publishers:
                continue
            subscription = self._recording[topic]
            with subscription.handle:
                while (taken := subscription.handle.take_message(subscription.msg_type, True)) is not None:
                    on_message(taken[0])
                    count += 1
        return count

    def destroy_node(self) -> None:
        """Record what is still waiting, stop subscribing, then close the bag (summary,
        metadata.yaml) and wait for the writer. Call it once nothing spins the recorder."""
        self.take_waiting()
        for subscription in self._recording.values():
            self.destroy_subscription(subscription)
        self._recording.clear()
        self._from_dds.clear()
        self.writer.close()
        self.get_logger().info(f"bag {self.writer.path}: {self.writer.message_count} messages")
        super().destroy_node()


def main(args=None) -> None:
    run_node(BagRecorder, args)
