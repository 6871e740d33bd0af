"""The graph daemon's process: a hidden rclpy node that keeps discovery warm and runs commands.

``python -m cdpr_tools.daemon.server SOCKET`` (started by ``client.start_daemon``) listens on the
Unix domain socket SOCKET. A connection sends one JSON line: ``{"argv": [...]}`` (a ``cdpr``
command line), ``{"op": "status"}`` or ``{"op": "stop"}``. For a command it answers
``{"accepted": false}`` when the caller is to run it itself (a verb it does not serve, a parse
error or help), else ``{"accepted": true}``, ``{"alive": true}`` every ``HEARTBEAT`` seconds while
the command runs, and ``{"rc", "stdout", "stderr"}``. Commands run concurrently, each in the
connection's thread, through the same code as on the command line: ``ros_graph.graph_node``
hands them this node, which the main thread spins, and what they print goes to their own buffers.
The daemon exits after ``--idle-timeout`` seconds without a command, on ``stop`` and on SIGTERM.
"""
from __future__ import annotations

import argparse
import contextlib
import importlib
import io
import json
import os
import signal
import socketserver
import sys
import threading
import time
from pathlib import Path
from typing import Iterator

from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node

from cdpr_tools import cli
from cdpr_tools.daemon.client import SERVED_VERBS, pid_path
from cdpr_tools.ros_graph import SharedNode, new_context, node_names, settle_shared, share_node

HEARTBEAT = 2.0  # s between "alive" lines while a command runs
SETTLE_QUIET = 0.5  # s the graph stays unchanged before the first discovery counts as settled
SPIN_TIMEOUT = 0.1  # s, the main loop's wake-up to look at the idle time and stop requests


class ThreadOutput(io.TextIOBase):
    """``sys.stdout`` / ``sys.stderr`` of the daemon: what a command's thread prints goes to the
    buffer of that command (``captured``), anything else to the daemon's log."""

    def __init__(self, log):
        super().__init__()
        self.log = log
        self.local = threading.local()

    def _stream(self):
        return getattr(self.local, "buffer", None) or self.log

    def writable(self) -> bool:
        return True

    def write(self, text: str) -> int:
        return self._stream().write(text)

    def flush(self) -> None:
        self._stream().flush()

    @contextlib.contextmanager
    def captured(self) -> Iterator[io.StringIO]:
        self.local.buffer = io.StringIO()
        try:
            yield self.local.buffer
        finally:
            del self.local.buffer


def _run_command(args: argparse.Namespace) -> int:
    """``cli.run``, and a command's ``sys.exit`` as its exit status (it must not end the daemon)."""
    try:
        return cli.run(args)
    except SystemExit as exc:
        return exc.code if isinstance(exc.code, int) else 1


def served(args: argparse.Namespace) -> bool:
    """Whether the daemon runs parsed command ``args`` (what writes files or streams runs in the caller)."""
    if args.verb not in SERVED_VERBS.get(args.command, ()) or getattr(args, "no_daemon", False):
        return False
    if args.command == "param" and args.verb == "dump":
        return not args.output  # a path relative to the caller's directory
    if args.command == "topic" and args.verb == "echo":
        return args.once  # one answer; a stream of messages prints as it comes, in the caller
    return True


class GraphDaemon:
    """The node, its executor (spun by the main thread) and the socket server (a thread per command)."""

    def __init__(self, path: Path, idle_timeout: float):
        self.path, self.idle_timeout = path, idle_timeout
        for command in SERVED_VERBS:  # imported now, so that no command waits for it (ACCEPT_TIMEOUT)
            importlib.import_module(f"cdpr_tools.{command}_cmd")
        self.context = new_context()
        self.node = Node(f"_cdpr_daemon_{os.getpid()}", context=self.context, start_parameter_services=False)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        share_node(SharedNode(self.node))
        self.stdout, self.stderr = ThreadOutput(sys.stdout), ThreadOutput(sys.stderr)
        sys.stdout, sys.stderr = self.stdout, self.stderr
        self.started = time.time()
        self.lock = threading.Lock()
        self.served = 0  # commands run here (tests check that the daemon, not the caller, answered)
        self.running = 0
        self.last_command = time.monotonic()
        self.stopping = threading.Event()

    def serve(self) -> None:
        daemon = self

        class Handler(socketserver.StreamRequestHandler):
            def handle(self) -> None:
                daemon.handle(self.rfile, self.wfile)

        server = socketserver.ThreadingUnixStreamServer(str(self.path), Handler)
        server.daemon_threads = True
        self.path.chmod(0o600)
        inode = self.path.stat().st_ino
        pid_path(self.path).write_text(str(os.getpid()))
        threading.Thread(target=server.serve_forever, daemon=True).start()
        threading.Thread(target=settle_shared, args=(SETTLE_QUIET,), daemon=True).start()
        print(f"cdpr graph daemon {os.getpid()} on {self.path}", flush=True)
        try:
            while not self.stopping.is_set() and not self._idle():
                self.executor.spin_once(timeout_sec=SPIN_TIMEOUT)
        finally:
            server.shutdown()
            server.server_close()
            self._remove(inode)
            self.executor.shutdown()
            self.node.destroy_node()
            self.context.try_shutdown()

    def _idle(self) -> bool:
        with self.lock:
            return not self.running and time.monotonic() - self.last_command > self.idle_timeout

    def _remove(self, inode: int) -> None:
        """Remove the socket and pid file, unless a newer daemon has replaced them already."""
        with contextlib.suppress(FileNotFoundError):
            if self.path.stat().st_ino == inode:
                self.path.unlink()
                pid_path(self.path).unlink(missing_ok=True)

    def handle(self, rfile, wfile) -> None:
        send_lock = threading.Lock()

        def send(message: dict) -> None:
            with send_lock:
                wfile.write(json.dumps(message).encode() + b"\n")
                wfile.flush()

        try:
            request = json.loads(rfile.readline() or b"{}")
            if request.get("op") == "status":
                send({"status": self.status()})
            elif request.get("op") == "stop":
                send({"stopping": True})
                self.stopping.set()
            elif isinstance(request.get("argv"), list):
                self.command([str(a) for a in request["argv"]], send)
        except (BrokenPipeError, ConnectionResetError):
            pass  # the caller went away (Ctrl-C); its command ran to its own end

    def command(self, argv: list[str], send) -> None:
        args = self._parse(argv)
        if args is None or not served(args):
            send({"accepted": False})
            return
        with self.lock:
            self.running += 1
            self.last_command = time.monotonic()
        send({"accepted": True})
        done = threading.Event()
        threading.Thread(target=self._heartbeat, args=(send, done), daemon=True).start()
        try:
            with self.stdout.captured() as out, self.stderr.captured() as err:
                rc = _run_command(args)
            with self.lock:
                self.served += 1
        finally:
            done.set()
            with self.lock:
                self.running -= 1
                self.last_command = time.monotonic()
        send({"rc": rc, "stdout": out.getvalue(), "stderr": err.getvalue()})

    def _parse(self, argv: list[str]) -> argparse.Namespace | None:
        """Parsed ``argv``, or None for what argparse answers itself (errors, help): the caller does."""
        with self.stdout.captured(), self.stderr.captured():
            try:
                return cli.build_parser(argv).parse_args(argv)
            except SystemExit:
                return None

    @staticmethod
    def _heartbeat(send, done: threading.Event) -> None:
        while not done.wait(HEARTBEAT):
            with contextlib.suppress(OSError):
                send({"alive": True})

    def status(self) -> dict:
        with self.lock:
            served, running = self.served, self.running
        return {"pid": os.getpid(), "uptime": round(time.time() - self.started, 3), "served": served,
                "running": running, "socket": str(self.path), "idle_timeout": self.idle_timeout,
                "domain": os.environ.get("ROS_DOMAIN_ID", "") or "0",
                "discovery_range": os.environ.get("ROS_AUTOMATIC_DISCOVERY_RANGE", ""),
                "nodes": len(node_names(self.node)), "python": sys.executable}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m cdpr_tools.daemon.server", description=__doc__)
    parser.add_argument("socket", type=Path)
    parser.add_argument("--idle-timeout", type=float, required=True, metavar="SEC")
    args = parser.parse_args(argv)
    daemon = GraphDaemon(args.socket, args.idle_timeout)
    signal.signal(signal.SIGTERM, lambda *_: daemon.stopping.set())
    daemon.serve()
    return 0


if __name__ == "__main__":
    sys.exit(main())
