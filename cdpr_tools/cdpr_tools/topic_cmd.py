"""``cdpr topic list|info|echo|hz|pub``: the topics of the running graph, as ``ros2 topic`` shows them.

Every command discovers the graph itself (there is no daemon): ``list`` prints once the graph has
not changed for ``--spin-time`` seconds, the others wait up to ``--timeout`` seconds for the topic
they are given.
"""
from __future__ import annotations

import argparse
import math
import time

import yaml
from rclpy.qos import QoSProfile

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
                    help="list once the graph has not changed for SEC seconds (default 0.5)")
    ls.set_defaults(run=run_list)

    info = verbs.add_parser("info", help="type and endpoints of a topic",
                            description="Print a topic's type and its publisher and subscription counts.")
    info.add_argument("topic")
    info.add_argument("-v", "--verbose", action="store_true", help="every endpoint with node, GID and QoS")
    _timeout(info)
    info.set_defaults(run=run_info)

    echo = verbs.add_parser("echo", help="print messages as YAML", description="Print the messages of a topic.")
    echo.add_argument("topic")
    echo.add_argument("type", nargs="?", help="message type (default: from the graph)")
    echo.add_argument("--once", action="store_true", help="print one message and exit")
    echo.add_argument("-n", "--count", type=int, metavar="N", help="print N messages and exit")
    echo.add_argument("--field", help="print only this field (dotted path, e.g. header.stamp)")
    _timeout(echo)
    echo.set_defaults(run=run_echo)

    hz = verbs.add_parser("hz", help="publishing rate of a topic",
                          description="Print the rate of a topic from receive timestamps, once a second.")
    hz.add_argument("topic")
    hz.add_argument("-w", "--window", type=int, default=10000, help="messages in the window (default 10000)")
    hz.add_argument("--duration", type=float, metavar="SEC", help="measure SEC seconds, print once and exit")
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
        type_name = args.type or find_topic(node, topic, args.timeout)
        printed = [0]

        def on_message(msg) -> None:
            value = field_value(msg, args.field) if args.field else msg
            if hasattr(value, "get_fields_and_field_types"):
                text = message_to_yaml(value)
            else:
                text = yaml.safe_dump(value.tolist() if hasattr(value, "tolist") else value,
                                      default_flow_style=False)
            print(text.rstrip("\n").removesuffix("\n..."), "---", sep="\n", flush=True)
            printed[0] += 1

        node.create_subscription(message_class(type_name), topic, on_message, adapted_qos(node, topic))
        spin_until(node, lambda: limit is not None and printed[0] >= limit, None)
    return 0


def run_hz(args) -> int:
    with graph_node("hz") as node:
        topic = fully_qualified(args.topic)
        type_name = find_topic(node, topic, args.timeout, publishers=True)
        stamps: list[int] = []

        def on_message(_data, info) -> None:
            stamps.append(info["received_timestamp"])
            if len(stamps) > args.window + 1:
                del stamps[0]

        node.create_subscription(message_class(type_name), topic, on_message, adapted_qos(node, topic, 1000), raw=True)
        if args.duration is not None:
            spin_until(node, lambda: False, args.duration)
            print(format_rate(stamps))
            return 0
        while True:
            spin_until(node, lambda: False, HZ_REPORT_PERIOD)
            print(format_rate(stamps), flush=True)


def format_rate(stamps_ns: list[int]) -> str:
    """``ros2 topic hz``'s report of receive timestamps."""
    if len(stamps_ns) < 2:
        return "no new messages"
    periods = [(b - a) * 1e-9 for a, b in zip(stamps_ns, stamps_ns[1:])]
    mean = sum(periods) / len(periods)
    std = math.sqrt(sum((p - mean) ** 2 for p in periods) / len(periods))
    return (f"average rate: {1.0 / mean if mean > 0 else math.inf:.3f}\n"
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
