"""``cdpr daemon start|stop|status``: the graph daemon that answers ``param``, ``topic`` and ``node`` commands.

The first of those commands starts it (one per ROS_DOMAIN_ID and discovery range, as ``ros2
daemon``); it exits after its idle timeout. ``--no-daemon`` on a command, or CDPR_NO_DAEMON=1,
does without it.
"""
from __future__ import annotations

import argparse

from cdpr_tools.daemon import client


def add_parser(sub) -> None:
    p = sub.add_parser("daemon", help="start, stop or query the graph daemon",
                       description=__doc__.replace("``", ""), formatter_class=argparse.RawDescriptionHelpFormatter)
    verbs = p.add_subparsers(dest="verb", metavar="VERB", required=True)
    start = verbs.add_parser("start", help="start the daemon unless it runs")
    start.add_argument("--idle-timeout", type=float, default=client.IDLE_TIMEOUT, metavar="SEC",
                       help=f"exit after SEC seconds without a command (default {client.IDLE_TIMEOUT:g})")
    start.set_defaults(run=run_start)
    verbs.add_parser("stop", help="stop the daemon").set_defaults(run=run_stop)
    verbs.add_parser("status", help="whether the daemon runs, and what it has served").set_defaults(run=run_status)


def run_start(args) -> int:
    if args.idle_timeout <= 0:
        raise ValueError(f"--idle-timeout must be > 0 s, got {args.idle_timeout:g}")
    path = client.socket_path()
    was_running = client.daemon_pid(path) is not None
    client.start_daemon(path, args.idle_timeout).close()
    print("The daemon is already running" if was_running else "The daemon has been started")
    return 0


def run_stop(args) -> int:
    print("The daemon has been stopped" if client.stop(client.socket_path()) else "The daemon is not running")
    return 0


def run_status(args) -> int:
    """Prints the status; exit status 0 when the daemon runs, 1 when not."""
    path = client.socket_path()
    try:
        s = client.status(path)
    except client.DaemonUnavailable as exc:
        print(f"The daemon is not running ({path}: {exc})" if client.daemon_pid(path) else "The daemon is not running")
        return 1
    print(f"The daemon is running: pid {s['pid']}, up {s['uptime']:.1f} s, served {s['served']} commands "
          f"({s['running']} running), {s['nodes']} nodes known\n"
          f"  domain {s['domain']}, discovery range {s['discovery_range'] or 'default'}, idle timeout "
          f"{s['idle_timeout']:g} s\n  socket {s['socket']}")
    return 0
