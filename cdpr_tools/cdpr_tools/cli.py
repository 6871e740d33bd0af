"""The ``cdpr`` command: one entry point for the project's tools.

Each sub-command lives in its own module and registers itself through ``add_parser(subparsers)``;
this file only assembles them, so ``cdpr --help`` lists what exists. A command line naming a
command imports only that command's module; one the graph daemon answers (``cdpr_tools.daemon``)
is handed to it before anything else is imported here (argparse and the rest load only for a
command that runs in this process).
"""
from __future__ import annotations

import os
import sys

from cdpr_tools.daemon import client as daemon_client

# sub-command modules of cdpr_tools, in the order `cdpr --help` lists them
COMMANDS = ("demo", "robot", "program", "hand", "topic", "param", "node", "bag", "launch", "view", "plot", "identify",
            "analyze", "validate", "bench", "daemon")


def build_parser(argv: list[str] | None = None) -> argparse.ArgumentParser:
    """The parser of every command, or, when ``argv`` starts with a command, of that one only
    (importing every command's module costs about a second; `cdpr param get` needs one)."""
    import argparse
    import importlib
    parser = argparse.ArgumentParser(
        prog="cdpr",
        description="Tools for the cdpr cable robot stack (ROS 2 Jazzy).",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    names = argv[:1] if argv and argv[0] in COMMANDS else COMMANDS
    for name in names:
        importlib.import_module(f"cdpr_tools.{name}_cmd").add_parser(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    # ROS 2 discovery stays on this machine unless the user says otherwise
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    argv = sys.argv[1:] if argv is None else list(argv)
    try:
        answered = daemon_client.answer(argv)
        if answered is not None:
            return answered
        args = build_parser(argv).parse_args(argv)   # --help into a closed pipe is a closed pipe too
        from cdpr_tools import progress
        progress.enable()  # long commands show how far they are (stderr)
        return run(args)
    except KeyboardInterrupt:
        return 130
    except BrokenPipeError:
        return _closed_pipe()


def run(args: argparse.Namespace) -> int:
    """Run parsed command ``args``: its exit status; an error is a message, not a traceback (the
    graph daemon runs commands through this too)."""
    try:
        code = int(args.run(args) or 0)
        sys.stdout.flush()               # a closed pipe shows here, not in the interpreter's exit
        return code
    except KeyboardInterrupt:
        return 130
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
    import signal
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
