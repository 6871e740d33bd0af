"""``cdpr plot BAG``: pose error, cable forces and controller outputs of a recorded run as PNG."""
from __future__ import annotations

import json
from pathlib import Path


def add_parser(sub) -> None:
    p = sub.add_parser("plot", help="plot a recorded closed-loop run (pose error, cable forces, controllers)")
    p.add_argument("bag", help="bag directory or .mcap file recorded from the closed-loop graph")
    p.add_argument("-o", "--output", help="folder for the PNG files (default: beside the bag)")
    p.set_defaults(run=run)


def run(args) -> int:
    from cdpr_tools.run_report import plot_run, read_bag, summarize

    bag = Path(args.bag)
    if not bag.exists():
        raise FileNotFoundError(f"no bag at {bag}")
    data = read_bag(bag)
    out = Path(args.output) if args.output else bag.parent
    for path in plot_run(data, out, prefix=f"{bag.stem}_"):
        print(path)
    print(json.dumps(summarize(data), indent=2))
    return 0
