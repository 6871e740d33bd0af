"""The ``cdpr`` command: one entry point for the project's tools.

Each sub-command lives in its own module and registers itself through ``add_parser(subparsers)``;
this file only assembles them, so ``cdpr --help`` lists what exists.
"""
from __future__ import annotations

import argparse
import importlib
import os
import sys

from cdpr_tools import progress

# sub-command modules of cdpr_tools, in the order `cdpr --help` lists them
COMMANDS = ("demo", "robot", "program", "hand", "topic", "param", "bag", "launch", "view", "plot", "identify", "analyze", "validate", "bench")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="cdpr",
        description="Tools for the cdpr cable robot stack (ROS 2 Jazzy).",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name in COMMANDS:
        importlib.import_module(f"cdpr_tools.{name}_cmd").add_parser(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    # ROS 2 discovery stays on this machine unless the user says otherwise
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    args = build_parser().parse_args(argv)
    progress.enable()  # long commands show how far they are (stderr)
    try:
        return int(args.run(args) or 0)
    except KeyboardInterrupt:
        return 130
    except Exception as exc:  # a tool error is a message, not a traceback
        if getattr(args, "debug", False):
            raise
        print(f"cdpr {args.command}: error: {exc}", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
