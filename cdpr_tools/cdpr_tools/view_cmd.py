"""``cdpr view``: watch the running robot live in Foxglove (3D, plots, parameters).

Starts the Foxglove bridge (node ``foxglove_bridge``, Foxglove SDK) against the graph running on
this machine (``cdpr launch ...`` or ``cdpr demo`` in another terminal): every topic with its ROS 2
schema, and the nodes' parameters. In Foxglove: "Open connection", "Foxglove WebSocket", the URL
printed below; then import the shipped layout (Layout menu, "Import from file") for the 3D view of
``/visualization/markers``, cable forces, pose against set-point and the parameters. Ctrl-C stops.
"""
from __future__ import annotations

import argparse

from cdpr_tools.nodes.foxglove_bridge import DEFAULT_PORT
from cdpr_tools.share import package_share


def add_parser(sub) -> None:
    p = sub.add_parser("view", help="serve the live graph to Foxglove (WebSocket): 3D markers, plots, parameters",
                       description=__doc__.replace("``", ""), formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--host", default="127.0.0.1", help="address to listen on (0.0.0.0: every interface)")
    p.add_argument("--port", type=int, default=DEFAULT_PORT, help=f"WebSocket port (default {DEFAULT_PORT}; 0: any free)")
    p.add_argument("--topics", nargs="+", default=[], metavar="TOPIC", help="offer only these topics")
    p.add_argument("--exclude", default="", metavar="REGEX", help="do not offer topics matching REGEX")
    p.add_argument("--use-sim-time", action="store_true", help="log times from /clock (the simulation's time)")
    p.add_argument("--snapshot", metavar="PNG", help="instead: draw the markers on /visualization/markers "
                   "(matplotlib 3D, what Foxglove's 3D panel shows) to PNG and exit")
    p.add_argument("--timeout", type=float, default=30.0, help="with --snapshot: wait this long for markers [s]")
    p.set_defaults(run=run)


def layout_file():
    """The shipped Foxglove layout (share/cdpr_tools/layouts/cdpr.json)."""
    return package_share("cdpr_tools") / "layouts" / "cdpr.json"


def run(args) -> int:
    if args.snapshot:
        return snapshot(args.snapshot, args.timeout)
    from cdpr_control.ros.runner import run_node
    from cdpr_tools.nodes.foxglove_bridge import FoxgloveBridge

    ros_args = ["--ros-args", "-p", f"host:={args.host}", "-p", f"port:={args.port}",
                "-p", f"use_sim_time:={'true' if args.use_sim_time else 'false'}"]
    if args.topics:
        ros_args += ["-p", f"topics:=[{','.join(args.topics)}]"]
    if args.exclude:
        ros_args += ["-p", f"exclude:={args.exclude}"]
    print(f"[view] Foxglove layout: {layout_file()}", flush=True)
    print("[view] in Foxglove: Open connection > Foxglove WebSocket > the ws:// URL below; Ctrl-C stops", flush=True)
    run_node(FoxgloveBridge, ["cdpr view", *ros_args])
    return 0


def snapshot(path: str, timeout: float) -> int:
    """Draw the next marker array of the running graph to ``path``."""
    from visualization_msgs.msg import MarkerArray

    from cdpr_control.ros.qos import CONTROL
    from cdpr_tools.marker_plot import Scene, plot_markers
    from cdpr_tools.ros_graph import graph_node, spin_until

    scene = Scene()
    with graph_node("view") as node:  # until the static markers (sent once a second) came too
        node.create_subscription(MarkerArray, "/visualization/markers", scene.add, CONTROL)
        if not spin_until(node, lambda: {"frame", "cables"} <= scene.namespaces, timeout):
            raise TimeoutError(f"no complete /visualization/markers within {timeout:g} s (is a graph with "
                               "the visualization node running?)")
    print(f"[view] {plot_markers(scene, path)}")
    return 0
