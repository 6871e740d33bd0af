"""``cdpr node list``: the nodes of the running graph, as ``ros2 node list`` shows them."""
from __future__ import annotations

from cdpr_tools.daemon.client import add_no_daemon
from cdpr_tools.ros_graph import DISCOVERY_TIMEOUT, graph_node, node_names, settle


def add_parser(sub) -> None:
    p = sub.add_parser("node", help="list the nodes of the graph", description=__doc__.replace("``", ""))
    verbs = p.add_subparsers(dest="verb", metavar="VERB", required=True)
    ls = verbs.add_parser("list", help="list nodes", description="List the fully qualified names of the nodes.")
    ls.add_argument("-a", "--all", action="store_true", help="also list hidden nodes (names starting with _)")
    ls.add_argument("-c", "--count-nodes", action="store_true", help="only print the number of nodes")
    ls.add_argument("--spin-time", type=float, default=0.5, metavar="SEC",
                    help="without the daemon: list once the graph has not changed for SEC seconds (default 0.5)")
    add_no_daemon(ls)
    ls.set_defaults(run=run_list)


def run_list(args) -> int:
    with graph_node("node") as node:
        settle(node, args.spin_time, DISCOVERY_TIMEOUT)
        names = node_names(node, include_hidden=args.all)
    for line in [len(names)] if args.count_nodes else names:
        print(line)
    return 0
