"""The ``cdpr`` command: one entry point for the project's tools.

Each sub-command lives in its own module and registers itself through ``add_parser(subparsers)``;
this file only assembles them, so ``cdpr --help`` lists what exists.
"""
from __future__ import annotations

import argparse
import importlib
import os
import signal
import sys

from cdpr_tools import progress

# sub-command modules of cdpr_tools, in the order `cdpr --help` lists them
COMMANDS = ("demo", "robot", "program", "hand", "topic", "param", "bag", "launch", "view", "plot", "identify", "analyze", "bench")


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
    try:
        args = build_parser().parse_args(argv)   # --help into a closed pipe is a closed pipe too
        progress.enable()  # long commands show how far they are (stderr)
        return _run(args)
    except KeyboardInterrupt:
        return 130
    except BrokenPipeError:
        return _closed_pipe()


def _run(args) -> int:
    try:
        code = int(args.run(args) or 0)
        sys.stdout.flush()               # a closed pipe shows here, not in the interpreter's exit
        return code
    except BrokenPipeError:              # an OSError, but no tool error: main ends quietly
        raise
    except Exception as exc:  # a tool error is a message, not a traceback
        if getattr(args, "debug", False):
            raise
        print(f"cdpr {args.command}: error: {exc}", file=sys.stderr)
        return 1


def _closed_pipe() -> int:
    """The reader of stdout left (``cdpr robot | head``): end quietly with the status of a process
    ended by SIGPIPE, as coreutils do. stdout goes to /dev/null so the exit's own flush is quiet too."""
    try:
        fd = sys.stdout.fileno()
    except (AttributeError, OSError, ValueError):   # not a file (a test's captured stdout): nothing to flush
        return 128 + signal.SIGPIPE
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, fd)
    os.close(devnull)
    return 128 + signal.SIGPIPE


if __name__ == "__main__":
    sys.exit(main())
