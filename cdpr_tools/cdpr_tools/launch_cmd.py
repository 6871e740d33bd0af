"""``cdpr launch FILE|PACKAGE FILE [NAME:=VALUE ...]``: start a node graph from a ROS 2 YAML launch file.

The graph runs composed in one process (EventsExecutor, the default; messages between its nodes are
passed in-process and go over DDS only to subscribers outside it, ``--no-intra-process``: DDS for
all) or as one process per node (``--mode processes``), optionally recording every topic to a bag
(``--record``). Ctrl-C stops it cleanly. The file is in ROS 2's YAML launch format (the subset cdpr
launch reads is in docs/tools.md; anything else is an error naming the file and the entry).
"""
from __future__ import annotations

import argparse
import threading
from dataclasses import asdict
from pathlib import Path

import yaml

from cdpr_control.analysis.arguments import positive
from cdpr_tools.launch import MODES, STOP_TIMEOUT, Launcher, RecordSpec, select_nodes
from cdpr_tools.launch_file import find_launch_file, load_launch_file
from cdpr_control.ros.runner import stop_on_signals


def add_parser(sub) -> None:
    p = sub.add_parser("launch", help="start a node graph from a ROS 2 YAML launch file",
                       description=__doc__.replace("``", ""), formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("file", help="launch file (ROS 2 YAML launch format), or a package whose share holds the "
                   "file named next (as ros2 launch PACKAGE FILE)")
    p.add_argument("arguments", nargs="*", metavar="NAME:=VALUE", help="values for the file's arguments")
    p.add_argument("--mode", choices=MODES, help="composed (default): one process; processes: one per node")
    p.add_argument("--record", nargs="?", const="", metavar="BAG",
                   help="record every topic (to BAG, default bags/rosbag2_<date>-<time>)")
    p.add_argument("--record-compression", choices=("zstd", "lz4", "none"), default="zstd",
                   help="with --record: MCAP chunk compression (default zstd, in the writer process)")
    p.add_argument("--only", nargs="+", metavar="NODE", help="start only these nodes (name or module, regex); "
                   "the rest of the graph may run in another process or on another host")
    p.add_argument("--exclude", nargs="+", metavar="NODE", help="start every node but these")
    p.add_argument("--no-intra-process", dest="intra_process", action="store_false",
                   help="composed: deliver every message over DDS, as between processes (for comparison)")
    p.add_argument("--stop-timeout", type=positive, default=STOP_TIMEOUT, metavar="S",
                   help=f"seconds a process may take to exit after Ctrl-C before it gets SIGTERM (default {STOP_TIMEOUT:g}; "
                        "ros2 launch's sigterm_timeout)")
    p.add_argument("--show", action="store_true", help="print the resolved launch description, start nothing")
    p.set_defaults(run=run)


def parse_arguments(items: list[str]) -> dict[str, str]:
    values = {}
    for item in items:
        name, sep, value = item.partition(":=")
        if not sep or not name:
            raise ValueError(f"launch argument {item!r} is not NAME:=VALUE")
        values[name] = value
    return values


def _arguments_after_selection(args) -> None:
    """NAME:=VALUE items written after --only/--exclude (which take every word that follows) are
    launch arguments, as ros2 launch takes them anywhere: a node pattern never holds ':='. A
    selection left without a node is an error rather than the whole graph."""
    for option in ("only", "exclude"):
        items = getattr(args, option)
        if items and any(":=" in item for item in items):
            args.arguments += [item for item in items if ":=" in item]
            patterns = [item for item in items if ":=" not in item]
            if not patterns:
                raise ValueError(f"--{option} names no node (only launch arguments NAME:=VALUE followed it)")
            setattr(args, option, patterns)


def run(args) -> int:
    _arguments_after_selection(args)
    if not Path(args.file).is_file() and args.arguments and ":=" not in args.arguments[0]:
        args.file = str(find_launch_file(args.file, args.arguments.pop(0)))
    description = load_launch_file(args.file, parse_arguments(args.arguments))
    if args.only or args.exclude:
        description = select_nodes(description, args.only, args.exclude)
    if args.record is not None:
        record = description.record or RecordSpec()
        record.output = args.record or record.output
        record.compression = args.record_compression
        description.record = record
    mode = args.mode or description.mode
    if args.show:
        return show(description, mode)
    launcher = Launcher(description, mode, intra_process=args.intra_process, stop_timeout=args.stop_timeout)
    with stop_on_signals(threading.Event()) as stop:  # SIGINT and SIGTERM stop cleanly, also while stopping
        try:
            launcher.start()
            print(f"[launch] {len(description.nodes)} nodes started ({mode}) from {args.file}"
                  + (f", recording to {launcher.recorder.writer.path}" if launcher.recorder else "")
                  + "; Ctrl-C stops", flush=True)
            while not (launcher.wait(0.2) or stop.is_set()):
                pass
        finally:
            launcher.stop()
    if launcher.recorder is not None:
        print(f"[launch] bag {launcher.recorder.writer.path}: {launcher.recorder.writer.message_count} messages")
        if launcher.recorder.writer.failed:      # (disk full: the count above is what the bag holds)
            launcher.errors.append(f"recording: {launcher.recorder.writer.failed}")
    if launcher.errors:
        print("[launch] stopped with errors: " + "; ".join(launcher.errors))
        return 1
    print("[launch] stopped", flush=True)
    return 0


def show(description, mode: str) -> int:
    """The launch file as resolved (arguments substituted, paths made absolute)."""
    def compact(spec) -> dict:
        return {k: v for k, v in asdict(spec).items() if v not in (None, [], {}, False, "")}

    print(yaml.safe_dump({"mode": mode, "parameters": description.parameters,
                          "record": compact(description.record) if description.record else None,
                          "nodes": [compact(n) for n in description.nodes]}, sort_keys=False), end="")
    return 0
