"""``cdpr topic list|info|echo|hz|pub``: the topics of the running graph, as ``ros2 topic`` shows them.

``list``, ``info`` and ``echo --once`` run in the graph daemon (``cdpr daemon``), which knows the
graph already; ``--no-daemon`` or CDPR_NO_DAEMON=1 runs them here, where the command discovers the
graph itself: ``list`` prints once the graph has not changed for ``--spin-time`` seconds, the
others wait up to ``--timeout`` seconds for the topic they are given.
"""
from __future__ import annotations

import argparse
import math
import threading
import time
from typing import Callable

import yaml
from rclpy.qos import QoSProfile
from rclpy.serialization import deserialize_message
from rosgraph_msgs.msg import Clock

from cdpr_tools.daemon.client import add_no_daemon
from cdpr_tools.message_convert import dict_to_message, field_value, message_class, message_to_yaml
from cdpr_tools.ros_graph import (
    DISCOVERY_TIMEOUT,
    adapted_qos,
    find_topic,
    fully_qualified,
    graph_node,
    settle,
    spin_until,
    topic_types,
)

HZ_REPORT_PERIOD = 1.0  # s between `topic hz` reports


def add_parser(sub) -> None:
    p = sub.add_parser("topic", help="list, inspect, echo, measure and publish topics",
                       description=__doc__.replace("``", ""), formatter_class=argparse.RawDescriptionHelpFormatter)
    verbs = p.add_subparsers(dest="verb", metavar="VERB", required=True)

    ls = verbs.add_parser("list", help="list topics", description="List the topics of the graph.")
    ls.add_argument("-t", "--show-types", action="store_true", help="also show each topic's type")
    ls.add_argument("-c", "--count-topics", action="store_true", help="only print the number of topics")
    ls.add_argument("-v", "--verbose", action="store_true", help="publishers and subscribers per topic")
    ls.add_argument("--include-hidden-topics", action="store_true", help="also list hidden topics (/_...)")
    ls.add_argument("--spin-time", type=float, default=0.5, metavar="SEC",
                    help="without the daemon: list once the graph has not changed for SEC seconds (default 0.5)")
    add_no_daemon(ls)
    ls.set_defaults(run=run_list)

    info = verbs.add_parser("info", help="type and endpoints of a topic",
                            description="Print a topic's type and its publisher and subscription counts.")
    info.add_argument("topic")
    info.add_argument("-v", "--verbose", action="store_true", help="every endpoint with node, GID and QoS")
    _timeout(info)
    add_no_daemon(info)
    info.set_defaults(run=run_info)

    echo = verbs.add_parser("echo", help="print messages as YAML",
                            description="Print the messages of a topic. It waits up to --timeout seconds for a "
                                        "publisher and subscribes with its QoS (a latched, transient-local "
                                        "topic gives its last message); with --once or --count it fails when "
                                        "no message comes for --timeout seconds.")
    echo.add_argument("topic")
    echo.add_argument("type", nargs="?", help="message type (default: from the graph)")
    echo.add_argument("--once", action="store_true", help="print one message and exit")
    echo.add_argument("-n", "--count", type=int, metavar="N", help="print N messages and exit")
    echo.add_argument("--field", help="print only this field (dotted path, e.g. header.stamp)")
    echo.add_argument("--timeout", type=float, default=DISCOVERY_TIMEOUT, metavar="SEC",
                      help="wait up to SEC seconds for a publisher and, with --once or --count, for each "
                           f"message (default {DISCOVERY_TIMEOUT:g})")
    add_no_daemon(echo)
    echo.set_defaults(run=run_echo)

    hz = verbs.add_parser("hz", help="publishing rate of a topic",
                          description="Print the rate of a topic once a second (wall clock), and which clock "
                                      "it measured. When /clock has a publisher (a simulated graph), or with "
                                      "--use-sim-time, the rate is in simulated time: from the messages' "
                                      "header stamps, or for messages without a header from the /clock "
                                      "time at which they arrive.")
    hz.add_argument("topic")
    hz.add_argument("-w", "--window", type=int, default=10000, help="messages in the window (default 10000)")
    hz.add_argument("--duration", type=float, metavar="SEC", help="measure SEC wall-clock seconds, print once and exit")
    clock = hz.add_mutually_exclusive_group()
    clock.add_argument("--use-sim-time", action="store_true",
                       help="measure in simulated time (default when /clock has a publisher)")
    clock.add_argument("--wall-time", action="store_true",
                       help="measure in wall-clock time even when /clock is published")
    _timeout(hz)
    hz.set_defaults(run=run_hz)

    pub = verbs.add_parser("pub", help="publish a message",
                           description="Publish a message given as YAML, e.g. "
                                       "cdpr topic pub /chatter std_msgs/msg/String \"{data: hi}\". "
                                       "Time fields accept \"now\".")
    pub.add_argument("topic")
    pub.add_argument("type", help="message type, e.g. std_msgs/msg/String")
    pub.add_argument("values", nargs="?", default="{}", help="field values in YAML (default: all defaults)")
    pub.add_argument("-r", "--rate", type=float, default=1.0, help="publishing rate in Hz (default 1)")
    pub.add_argument("-1", "--once", action="store_true", help="publish one message and exit")
    pub.add_argument("-t", "--times", type=int, default=0, metavar="N", help="publish N messages and exit")
    pub.add_argument("-w", "--wait-matching-subscriptions", type=int, metavar="N",
                     help="first wait for N subscriptions (default 1 with --once/--times, else 0)")
    pub.add_argument("--keep-alive", type=float, default=0.1, metavar="SEC",
                     help="stay alive SEC seconds after the last message (default 0.1)")
    pub.set_defaults(run=run_pub)


def _timeout(p) -> None:
    p.add_argument("--timeout", type=float, default=DISCOVERY_TIMEOUT, metavar="SEC",
                   help=f"wait up to SEC seconds for the topic to appear (default {DISCOVERY_TIMEOUT:g})")


def run_list(args) -> int:
    with graph_node("topic") as node:
        settle(node, args.spin_time)
        topics = topic_types(node, args.include_hidden_topics)
        if args.count_topics:
            print(len(topics))
        elif args.verbose:
            for title, count, noun in (("Published topics", node.count_publishers, "publisher"),
                                       ("Subscribed topics", node.count_subscribers, "subscriber")):
                print(f"{title}:")
                for name, types in sorted(topics.items()):
                    n = count(name)
                    if n:
                        print(f" * {name} [{', '.join(types)}] {n} {noun}{'s' if n > 1 else ''}")
                print()
        else:
            for name, types in sorted(topics.items()):
                print(f"{name} [{', '.join(types)}]" if args.show_types else name)
    return 0


def run_info(args) -> int:
    with graph_node("topic") as node:
        topic = fully_qualified(args.topic)
        type_name = find_topic(node, topic, args.timeout)
        if args.verbose:  # endpoint node names arrive a little after the endpoints
            spin_until(node, lambda: not any(e.node_name == "_NODE_NAME_UNKNOWN_" for e in
                                             node.get_publishers_info_by_topic(topic)
                                             + node.get_subscriptions_info_by_topic(topic)), args.timeout)
        publishers = node.get_publishers_info_by_topic(topic)
        subscriptions = node.get_subscriptions_info_by_topic(topic)
        print(f"Type: {type_name}")
        print(f"Publisher count: {len(publishers)}")
        if args.verbose:
            print()
            for endpoint in publishers:
                print(f"{endpoint}\n")
        print(f"Subscription count: {len(subscriptions)}")
        if args.verbose:
            print()
            for endpoint in subscriptions:
                print(f"{endpoint}\n")
    return 0


def run_echo(args) -> int:
    limit = 1 if args.once else args.count
    with graph_node("echo") as node:
        topic = fully_qualified(args.topic)
        # the publishers' QoS decides how to subscribe (a latched message reaches only a
        # transient-local subscription): wait for a publisher, not only for the topic's name
        found = find_topic(node, topic, args.timeout, publishers=True)
        received: list = []  # appended by the executor (the daemon's thread), taken here
        arrived = threading.Event()

        def on_message(msg) -> None:
            received.append(msg)
            arrived.set()

        subscription = node.create_subscription(message_class(args.type or found), topic, on_message,
                                                adapted_qos(node, topic))
        try:
            printed = 0
            while limit is None or printed < limit:
                if not spin_until(node, lambda: bool(received), None if limit is None else args.timeout, arrived):
                    raise TimeoutError(f"no message on {topic} within {args.timeout:g} s; "
                                       f"it has {node.count_publishers(topic)} publisher(s)")
                _print_message(received.pop(0), args.field)
                printed += 1
        finally:
            node.destroy_subscription(subscription)
    return 0


def _print_message(msg, field: str | None) -> None:
    value = field_value(msg, field) if field else msg
    if hasattr(value, "get_fields_and_field_types"):
        text = message_to_yaml(value)
    else:
        text = yaml.safe_dump(value.tolist() if hasattr(value, "tolist") else value, default_flow_style=False)
    print(text.rstrip("\n").removesuffix("\n..."), "---", sep="\n", flush=True)


def run_hz(args) -> int:
    with graph_node("hz") as node:
        topic = fully_qualified(args.topic)
        msg_class = message_class(find_topic(node, topic, args.timeout, publishers=True))
        clock, stamp_of = _hz_clock(node, args, msg_class)
        stamps: list[int] = []

        def on_message(data, info) -> None:
            stamp = stamp_of(data, info)
            if stamp is None:  # no /clock yet
                return
            stamps.append(stamp)
            if len(stamps) > args.window + 1:
                del stamps[0]

        node.create_subscription(msg_class, topic, on_message, adapted_qos(node, topic, 1000), raw=True)
        if args.duration is not None:
            spin_until(node, lambda: False, args.duration)
            print(format_rate(stamps, clock))
            return 0
        while True:
            spin_until(node, lambda: False, HZ_REPORT_PERIOD)
            print(format_rate(stamps, clock), flush=True)


def _hz_clock(node, args, msg_class) -> tuple[str, Callable[[bytes, dict], int | None]]:
    """The clock `topic hz` measures with: its name, and the time of a (raw) message in ns.

    Wall time: the receive timestamps. Simulated time (asked for, or /clock published now): the
    message's header stamp, which its publisher took from /clock; without a header, the latest
    /clock time when the message arrives (so periods are whole /clock periods).
    """
    if not (args.use_sim_time or (not args.wall_time and node.count_publishers("/clock") > 0)):
        return "wall time", lambda _data, info: info["received_timestamp"]
    if msg_class.get_fields_and_field_types().get("header") == "std_msgs/Header":
        def header_stamp(data: bytes, _info) -> int:
            stamp = deserialize_message(data, msg_class).header.stamp
            return stamp.sec * 1_000_000_000 + stamp.nanosec
        return "sim time, header stamps", header_stamp
    find_topic(node, "/clock", args.timeout, publishers=True)
    latest: list[int | None] = [None]

    def on_clock(msg: Clock) -> None:
        latest[0] = msg.clock.sec * 1_000_000_000 + msg.clock.nanosec

    node.create_subscription(Clock, "/clock", on_clock, adapted_qos(node, "/clock", 1))
    if not spin_until(node, lambda: latest[0] is not None, args.timeout):  # a paused clock counts nothing
        raise TimeoutError(f"/clock has a publisher but sent no time within {args.timeout:g} s; "
                           "--wall-time measures without it")
    return "sim time, /clock on arrival", lambda _data, _info: latest[0]


def format_rate(stamps_ns: list[int], clock: str) -> str:
    """``ros2 topic hz``'s report of message timestamps, naming the ``clock`` they are on."""
    if len(stamps_ns) < 2:
        return "no new messages"
    periods = [(b - a) * 1e-9 for a, b in zip(stamps_ns, stamps_ns[1:])]
    mean = sum(periods) / len(periods)
    std = math.sqrt(sum((p - mean) ** 2 for p in periods) / len(periods))
    return (f"average rate: {1.0 / mean if mean > 0 else math.inf:.3f} ({clock})\n"
            f"\tmin: {min(periods):.3f}s max: {max(periods):.3f}s std dev: {std:.5f}s window: {len(periods)}")
def run_pub(args) -> int:
    times = 1 if args.once else args.times
    wait = args.wait_matching_subscriptions
    wait = (1 if times else 0) if wait is None else wait
    values = yaml.safe_load(args.values) if args.values.strip() else {}
    if values is None:
        values = {}
    with graph_node("pub") as node:
        topic = fully_qualified(args.topic)
        msg_class = message_class(args.type)
        now = lambda: node.get_clock().now().to_msg()  # noqa: E731 ("now" stamps, fresh per message)
        dict_to_message(msg_class, values, now)  # fail on bad values before waiting for anyone
        publisher = node.create_publisher(msg_class, topic, QoSProfile(depth=10))
        if wait:
            print(f"waiting for {wait} matching subscription(s)...", flush=True)
            spin_until(node, lambda: publisher.get_subscription_count() >= wait, None)
        print("publisher: beginning loop", flush=True)
        count = 0
        period = 1.0 / args.rate if args.rate > 0 else 0.0
        next_time = time.monotonic()
        while not times or count < times:
            msg = dict_to_message(msg_class, values, now)
            publisher.publish(msg)
            count += 1
            print(f"publishing #{count}: {msg}", flush=True)
            if times and count >= times:
                break
            next_time += period
            spin_until(node, lambda: time.monotonic() >= next_time, None)
        spin_until(node, lambda: False, args.keep_alive)
    return 0
