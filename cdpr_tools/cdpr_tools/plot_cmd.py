"""``cdpr plot BAG``: pose error, cable forces and controller outputs of a recorded run as PNG."""
from __future__ import annotations

import json
from pathlib import Path


def add_parser(sub) -> None:
    p = sub.add_parser("plot", help="plot a recorded closed-loop run (pose error, cable forces, controllers)")
    p.add_argument("bag", help="bag directory or .mcap file recorded from the closed-loop graph")
    p.add_argument("-o", "--output", help="folder for the PNG files (default: beside the bag)")
    p.add_argument("--robot", help="robot name or file, named in the titles (a bag does not say which robot ran)")
    p.set_defaults(run=run)


def run(args) -> int:
    from cdpr_tools.bag import BagReader
    from cdpr_tools.identify.bag_data import controller
    from cdpr_tools.run_report import plot_run, read_bag, summarize

    bag = Path(args.bag)
    if not bag.exists():
        raise FileNotFoundError(f"no bag at {bag}")
    robot = None
    if args.robot:
        from cdpr_control.model.robot import load_robot

        robot = load_robot(args.robot)               # before the bag is read: a bad name fails at once
    data = read_bag(bag)
    title = ", ".join(([robot.name] if robot else []) + [controller(BagReader(bag)), f"bag {bag.name}"])
    out = Path(args.output) if args.output else bag.parent
    for path in plot_run(data, out, prefix=f"{bag.stem}_", title=title):
        print(path)
    print(json.dumps(summarize(data), indent=2))
    return 0
