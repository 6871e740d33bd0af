"""``cdpr bag record|info|play``: rosbag2-compatible MCAP bags without ros2cli.

The bags are what ``ros2 bag record -s mcap`` writes (a directory with ``<name>_0.mcap`` and
metadata.yaml), so ``ros2 bag info/play``, Foxglove, ``rosbags`` and ``mcap_ros2`` read them, and
these commands read bags from ``ros2 bag`` in turn.
"""
from __future__ import annotations

import argparse
import re
import sys
import threading
from datetime import datetime, timezone

from rclpy.experimental import EventsExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter

from cdpr_control.analysis.arguments import non_negative, positive
from cdpr_tools.bag.player import DEFAULT_CLOCK_HZ, MAX_CLOCK_HZ, MAX_SECONDS, BagPlayer
from cdpr_tools.bag.reader import BagReader, CorruptBagError
from cdpr_tools.bag.recovery import RepairError, reindex
from cdpr_tools.bag.recorder import BagRecorder, default_bag_name
from cdpr_control.ros.runner import spin, stop_on_signals
from cdpr_tools.progress import Progress
from cdpr_tools.ros_graph import fully_qualified, new_context

# s: at the end of `bag play`, how long the reliable subscribers may take to acknowledge the last
# messages before the player's context goes (it would drop them)
DELIVERY_TIMEOUT = 5.0


def add_parser(sub) -> None:
    p = sub.add_parser("bag", help="record, inspect and play bags (rosbag2 MCAP layout)",
                       description=__doc__.replace("``", ""), formatter_class=argparse.RawDescriptionHelpFormatter)
    verbs = p.add_subparsers(dest="verb", metavar="VERB", required=True)

    r = verbs.add_parser("record", help="record topics to a bag until Ctrl-C",
                         description="Record topics to a bag directory until Ctrl-C (or --stop-after). "
                                     "Topics appearing later are picked up as they get publishers.")
    r.add_argument("topics", nargs="*", help="topics to record (default with -a: all)")
    r.add_argument("-a", "--all", action="store_true", help="record every topic (the default without TOPICS)")
    r.add_argument("-o", "--output", help="bag directory, or a path ending in .mcap for a single file "
                                          "(default: bags/rosbag2_<date>-<time>)")
    r.add_argument("-x", "--exclude", type=_regex, default="", help="regular expression of topics not to record")
    r.add_argument("--include-hidden-topics", action="store_true", help="also record hidden topics (/_...)")
    r.add_argument("--use-sim-time", action="store_true", help="log times from /clock instead of the wall clock")
    r.add_argument("--stop-after", type=_seconds, metavar="SEC", help="stop recording after SEC seconds")
    r.add_argument("--compression", choices=("none", "zstd", "lz4"), default="zstd",
                   help="compress each MCAP chunk (default zstd, in the writer process); every reader of "
                        "MCAP decompresses it")
    r.add_argument("-b", "--max-bag-size", type=_byte_count, default=0, metavar="BYTES",
                   help="split into files of about BYTES (rosbag2's numbered files, one metadata.yaml; 0: one file)")
    r.add_argument("-d", "--max-bag-duration", type=_seconds, default=0.0, metavar="SEC",
                   help="split into files of SEC seconds of log time (0: one file)")
    r.set_defaults(run=run_record)

    i = verbs.add_parser("info", help="print a bag's duration, topics, types and counts",
                         description="Print what a bag holds, as `ros2 bag info` does.")
    i.add_argument("bag", help="bag directory or .mcap file")
    i.set_defaults(run=run_info)

    y = verbs.add_parser("play", help="publish a bag's messages again",
                         description="Publish the messages of a bag with their recorded types, QoS and "
                                     "relative timing.")
    y.add_argument("bag", help="bag directory or .mcap file")
    y.add_argument("-r", "--rate", type=positive, default=1.0, help="playback speed factor (default 1.0)")
    y.add_argument("--clock", type=_clock_hz, nargs="?", const=DEFAULT_CLOCK_HZ, default=0.0, metavar="HZ",
                   help=f"publish /clock from the bag time at HZ (default {DEFAULT_CLOCK_HZ:g} Hz when given)")
    y.add_argument("--topics", nargs="+", metavar="TOPIC", help="play only these topics")
    y.add_argument("--start-offset", type=_seconds, default=0.0, metavar="SEC",
                   help="start SEC seconds into the bag")
    y.add_argument("-l", "--loop", action="store_true", help="play the bag again and again until Ctrl-C")
    y.add_argument("-d", "--delay", type=_seconds, default=0.0, metavar="SEC", help="wait SEC seconds before playing")
    y.add_argument("--wait-for-subscribers", type=_seconds, default=0.0, metavar="SEC",
                   help="wait up to SEC seconds until every topic has a subscriber")
    y.add_argument("--remap", nargs="+", type=_remap, default=[], metavar="FROM:=TO",
                   help="publish bag topic FROM on topic TO (as ros2 bag play --remap)")
    y.set_defaults(run=run_play)

    x = verbs.add_parser("reindex", help="rebuild the index and metadata.yaml of a bag cut off by a crash",
                         description="Make a bag whose recording was killed, or whose file is damaged, "
                                     "whole again, as `ros2 bag reindex` does: every intact chunk is kept "
                                     "(damaged ones are reported), the file gets its summary and index back "
                                     "(the original stays beside it as <file>.orig) and the bag directory a "
                                     "new metadata.yaml. Exits 1 when nothing could be read.")
    x.add_argument("bag", help="bag directory or .mcap file")
    x.set_defaults(run=run_reindex)


def _seconds(text: str) -> float:
    """A duration [s]: finite, >= 0 and at most MAX_SECONDS (argparse type; beyond it a bag's
    nanosecond times and a thread's wait overflow)."""
    value = non_negative(text)
    if value > MAX_SECONDS:
        raise argparse.ArgumentTypeError(f"must be at most {MAX_SECONDS:g} s (31 years), got {text!r}")
    return value


def _clock_hz(text: str) -> float:
    """A /clock rate [Hz] in (0, MAX_CLOCK_HZ] (argparse type)."""
    value = positive(text)
    if value > MAX_CLOCK_HZ:
        raise argparse.ArgumentTypeError(f"must be at most {MAX_CLOCK_HZ:g} Hz, got {text!r}")
    return value


def _regex(text: str) -> str:
    """A Python regular expression (argparse type)."""
    try:
        re.compile(text)
    except re.error as exc:
        raise argparse.ArgumentTypeError(f"not a regular expression: {text!r} ({exc})") from None
    return text


def _byte_count(text: str) -> int:
    """A whole number of bytes >= 0 (argparse type)."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a whole number of bytes: {text!r}") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be >= 0, got {text!r}")
    return value


def run_record(args) -> int:
    if args.all and args.topics:
        raise ValueError("give either -a/--all or topics, not both")
    output = args.output or default_bag_name()
    overrides = [Parameter("output", value=output),
                 Parameter("exclude", value=args.exclude),
                 Parameter("include_hidden_topics", value=args.include_hidden_topics),
                 Parameter("use_sim_time", value=args.use_sim_time),
                 Parameter("compression", value=args.compression),
                 Parameter("max_bag_size", value=int(args.max_bag_size)),
                 Parameter("max_bag_duration", value=float(args.max_bag_duration))]
    if args.topics:
        overrides.append(Parameter("topics", value=list(args.topics)))
    context = new_context()
    recorder = None
    stop = threading.Event()
    try:
        with stop_on_signals(stop):
            try:
                recorder = BagRecorder(context=context, parameter_overrides=overrides)
            except OSError as exc:              # the bag cannot be created there: a usage error
                print(f"cdpr bag record: error: cannot create the bag {output}: {exc.strerror or exc}",
                      file=sys.stderr)
                return 2
            executor = EventsExecutor(context=context)
            executor.add_node(recorder)
            if args.stop_after is not None:
                timer = threading.Timer(args.stop_after, stop.set)
                timer.daemon = True
                timer.start()
            print(f"recording to {recorder.writer.path} (Ctrl-C to stop)", flush=True)
            spin(executor, stop)
    finally:
        stop.set()
        if recorder is not None:
            recorder.destroy_node()          # closes the bag: the count is then what the file holds
            print(f"bag {recorder.writer.path}: {recorder.writer.message_count} messages on "
                  f"{len(recorder.writer.topics)} topics")
        context.try_shutdown()
    if recorder.writer.failed:
        print(f"cdpr bag record: error: {recorder.writer.failed}", file=sys.stderr)
        return 1
    return 0


def run_info(args) -> int:
    bag = BagReader(args.bag)
    print(format_info(bag))
    _warn(bag)
    return 0


def run_reindex(args) -> int:
    try:
        report = reindex(args.bag)
    except RepairError as exc:
        for line in exc.report:             # what was repaired nevertheless (other files of the bag)
            print(line)
        print(f"cdpr bag reindex: error: {exc}", file=sys.stderr)
        return 1
    for line in report:
        print(line)
    return 0


def _warn(bag: BagReader) -> None:
    for problem in bag.problems:
        print(f"warning: {problem}", file=sys.stderr)


def format_info(bag: BagReader) -> str:
    """The summary `ros2 bag info` prints."""
    size = sum(f.stat().st_size for f in bag.files)
    lines = [
        f"Files:             {', '.join(f.name for f in bag.files)}",
        f"Bag size:          {_size(size)}",
        "Storage id:        mcap",
        f"ROS Distro:        {bag.metadata.get('ros_distro', 'unknown')}",
        f"Duration:          {bag.duration_ns / 1e9:.9f}s",
        f"Start:             {_stamp(bag.start_time_ns)}",
        f"End:               {_stamp(bag.end_time_ns)}",
        f"Messages:          {bag.message_count}",
    ]
    topics = [f"Topic: {t.name} | Type: {t.type} | Count: {t.message_count} | "
              f"Serialization Format: {t.serialization_format}" for t in bag.topics.values()]
    lines.append("Topic information: " + ("\n" + " " * 19).join(topics or ["(none)"]))
    return "\n".join(lines)


def _size(n: int) -> str:
    for unit in ("B", "KiB", "MiB", "GiB"):
        if n < 1024 or unit == "GiB":
            return f"{n:.1f} {unit}" if unit != "B" else f"{n} B"
        n /= 1024


def _stamp(ns: int | None) -> str:
    if ns is None:
        return "(no messages)"
    wall = datetime.fromtimestamp(ns / 1e9, tz=timezone.utc)
    sec, nsec = divmod(ns, 1_000_000_000)
    return f"{wall:%b %d %Y %H:%M:%S}.{nsec:09d} ({sec}.{nsec:09d})"


def _play_progress():
    """bag play's progress on stderr (about once a second): bag time played of the bag's span."""
    shown = Progress("bag play")

    def update(done_s: float, total_s: float) -> None:
        shown.update(done_s / total_s if total_s > 0 else 1.0, f"{done_s:.1f} of {total_s:.1f} s of the bag")
    return update


def _remap(text: str) -> tuple[str, str]:
    """FROM:=TO (topic names, made fully qualified) for --remap."""
    source, sep, target = text.partition(":=")
    if not sep or not source.strip() or not target.strip():
        raise argparse.ArgumentTypeError(f"{text!r} is not FROM:=TO (e.g. /winch/state:=/replay/winch/state)")
    return fully_qualified(source.strip()), fully_qualified(target.strip())


def run_play(args) -> int:
    bag = BagReader(args.bag)
    context = new_context()
    stop = threading.Event()
    try:
        with stop_on_signals(stop):
            node = Node("bag_player", context=context, start_parameter_services=False)
            player = BagPlayer(node, bag, rate=args.rate, topics=args.topics, start_offset=args.start_offset,
                               clock_hz=args.clock, loop=args.loop, remap=dict(args.remap),
                               progress=_play_progress())
            if args.wait_for_subscribers > 0 and not player.wait_for_subscribers(args.wait_for_subscribers, stop):
                print("not every topic has a subscriber; playing anyway", flush=True)
            if args.delay > 0:
                stop.wait(args.delay)
            print(f"playing {bag.path}: {len(player.publishers)} topics, {bag.duration_ns / 1e9:.3f} s "
                  f"at rate {args.rate:g}" + (f", /clock at {args.clock:g} Hz" if args.clock else ""), flush=True)
            _warn(bag)
            try:
                count = player.play(stop)
            except CorruptBagError as exc:
                print(f"published {player.published} of {bag.message_count} messages, then: {exc}", file=sys.stderr)
                return 1
            if not stop.is_set() and not player.wait_for_delivery(DELIVERY_TIMEOUT):
                print(f"warning: not every subscriber acknowledged the last messages within {DELIVERY_TIMEOUT:g} s",
                      file=sys.stderr)
        print(f"published {count} messages" + (" (stopped)" if stop.is_set() else ""))
        if bag.damage:                         # (each was warned about before playing; again at the end)
            counted, unknown = bag.lost_messages
            print(f"error: {len(bag.damage)} damaged part(s) of {bag.path} were skipped: {counted} messages lost"
                  + (f", and an unknown number in {unknown} part(s)" if unknown else ""), file=sys.stderr)
            for damage in bag.damage:
                print(f"  {damage}", file=sys.stderr)
            return 1
    finally:
        context.try_shutdown()
    return 0
