"""Client side of the graph daemon: where its socket is, starting it on first use, handing it a command.

Kept free of rclpy and of everything a command the daemon answers does not need, so that such a
command costs little more than the Python interpreter's start: the path of ``answer`` imports
only ``json``, ``socket``, ``zlib`` and ``contextlib`` beyond what the interpreter has loaded at
its start (``os``, ``sys``, ``pathlib``); starting, killing and stopping a daemon import the rest
when they run (``tests/tools/test_cli_daemon.py`` checks that a served command imports none of
rclpy, argparse, yaml, numpy, subprocess, hashlib, threading). One daemon serves one
graph: its socket's name holds the ROS domain, the discovery range and a digest of what else
decides what it sees or runs (RMW implementation, static peers, this package's location).
"""
from __future__ import annotations

import contextlib
import json
import os
import socket
import sys
import time
import zlib
from collections.abc import Iterator
from pathlib import Path

NO_DAEMON_ENV = "CDPR_NO_DAEMON"  # set to 1: every command discovers the graph itself
IDLE_TIMEOUT = 1800.0  # s without a command after which a daemon exits
START_TIMEOUT = 20.0  # s for a new daemon to answer (rclpy import and discovery start on a loaded machine)
ACCEPT_TIMEOUT = 5.0  # s for a running daemon to accept a command; longer, it hangs and is replaced
ALIVE_TIMEOUT = 10.0  # s between a working daemon's heartbeats; longer, it died during the command
STOP_TIMEOUT = 5.0  # s for a daemon to go after `cdpr daemon stop`
SERVER_MODULE = "cdpr_tools.daemon.server"
# (command, verb) the daemon may answer; it decides by the parsed arguments (e.g. `echo` only --once)
SERVED_VERBS = {"param": {"list", "get", "set", "describe", "dump"}, "topic": {"list", "info", "echo"},
                "node": {"list"}}


class DaemonUnavailable(RuntimeError):
    """The daemon cannot be reached or started; the command runs without it."""


def add_no_daemon(parser) -> None:
    """The ``--no-daemon`` option of a command the daemon can answer."""
    parser.add_argument("--no-daemon", action="store_true",
                        help=f"discover the graph in this command instead of asking the graph daemon "
                             f"(also {NO_DAEMON_ENV}=1)")


def disabled(argv: list[str]) -> bool:
    return "--no-daemon" in argv or os.environ.get(NO_DAEMON_ENV, "") not in ("", "0")


def socket_path() -> Path:
    """The socket of this environment's daemon, in a directory only this user can enter."""
    base = os.environ.get("XDG_RUNTIME_DIR")
    directory = Path(base) / "cdpr" if base else Path(f"/tmp/cdpr-{os.getuid()}")
    directory.mkdir(mode=0o700, parents=True, exist_ok=True)
    info = directory.stat()
    if info.st_uid != os.getuid() or info.st_mode & 0o077:
        raise DaemonUnavailable(f"{directory} belongs to someone else or is open to others")
    domain = os.environ.get("ROS_DOMAIN_ID", "") or "0"
    scope = os.environ.get("ROS_AUTOMATIC_DISCOVERY_RANGE", "") or "SUBNET"
    # crc32, not hashlib: hashlib loads OpenSSL (20 ms of a served command's start on a loaded machine)
    digest = "%08x" % zlib.crc32("\0".join((os.environ.get("RMW_IMPLEMENTATION", ""), os.environ.get("ROS_STATIC_PEERS", ""),
                                             str(Path(__file__).resolve().parent))).encode())
    return directory / f"daemon-domain{domain}-{scope.lower()}-{digest}.sock"


def log_path(path: Path) -> Path:
    return path.with_suffix(".log")


def pid_path(path: Path) -> Path:
    return path.with_suffix(".pid")


def answer(argv: list[str]) -> int | None:
    """Run command line ``argv`` in the daemon (started if need be): its exit status, having printed
    its output; None when the daemon does not answer this command and it is to run here."""
    if len(argv) < 2 or argv[1] not in SERVED_VERBS.get(argv[0], ()) or disabled(argv) or _asks_help(argv):
        return None
    try:
        return _run(argv)
    except (DaemonUnavailable, OSError, ValueError) as exc:  # ValueError: a reply that is no JSON
        print(f"cdpr: graph daemon: {exc}; answering without it", file=sys.stderr)
        return None


def _asks_help(argv: list[str]) -> bool:
    """Help needs no graph (nor a daemon started for it)."""
    return "-h" in argv or "--help" in argv


def _run(argv: list[str]) -> int | None:
    path = socket_path()
    try:
        return _ask(path, argv)
    except TimeoutError:  # it took the connection but not the command: hung
        _kill_hung(path)
    try:
        return _ask(path, argv)
    except TimeoutError:
        raise DaemonUnavailable("it accepts no commands") from None


def _ask(path: Path, argv: list[str]) -> int | None:
    """Hand ``argv`` to the daemon at ``path`` (started if none listens): as ``answer``;
    ``TimeoutError`` when the daemon does not accept it within ACCEPT_TIMEOUT."""
    with connect(path, start=True) as conn:
        reply = conn.request({"argv": argv}, ACCEPT_TIMEOUT)
        if not reply.get("accepted"):
            return None
        try:
            while "rc" not in reply:
                reply = conn.receive(ALIVE_TIMEOUT)
        except (TimeoutError, ConnectionError):
            # the command may have had its effect (a parameter set): not run again here
            print(f"cdpr: graph daemon stopped answering during the command (log: {log_path(path)})",
                  file=sys.stderr)
            return 1
    _write(reply["stdout"], reply["stderr"])
    return int(reply["rc"])


def _write(out: str, err: str) -> None:
    try:
        sys.stdout.write(out)
        sys.stdout.flush()
    except BrokenPipeError:  # `| head` has what it wanted; the exit status still tells
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
    sys.stderr.write(err)


class Connection:
    """One request and its newline-separated JSON replies over the daemon's socket."""

    def __init__(self, sock: socket.socket):
        self.sock = sock
        self.reader = sock.makefile("rb")

    def request(self, message: dict, timeout: float) -> dict:
        self.sock.sendall(json.dumps(message).encode() + b"\n")
        return self.receive(timeout)

    def receive(self, timeout: float) -> dict:
        self.sock.settimeout(timeout)
        try:
            line = self.reader.readline()
        except socket.timeout:
            raise TimeoutError from None
        if not line:
            raise ConnectionError("the daemon closed the connection")
        return json.loads(line)

    def close(self) -> None:
        self.reader.close()
        self.sock.close()


@contextlib.contextmanager
def connect(path: Path, start: bool = False) -> Iterator[Connection]:
    """A connection to the daemon at ``path``; with ``start``, a daemon is started when none listens
    (a socket file nobody listens on is a dead daemon's: replaced). ``DaemonUnavailable`` otherwise."""
    try:
        conn = _open(path)
    except (FileNotFoundError, ConnectionRefusedError):
        if not start:
            raise DaemonUnavailable("not running") from None
        conn = start_daemon(path)
    try:
        yield conn
    finally:
        conn.close()


def _open(path: Path) -> Connection:
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    try:
        sock.connect(str(path))
    except OSError:
        sock.close()
        raise
    return Connection(sock)


def start_daemon(path: Path, idle_timeout: float = IDLE_TIMEOUT) -> Connection:
    """Start a daemon at ``path`` unless one answers there already; a connection to it."""
    import subprocess
    from cdpr_tools.file_lock import locked
    with locked(path.with_suffix(".lock")):   # one command at a time starts it; the others wait, then connect
        with contextlib.suppress(FileNotFoundError, ConnectionRefusedError):
            return _open(path)  # another command started it meanwhile
        with contextlib.suppress(FileNotFoundError):
            path.unlink()  # a dead daemon's socket
        log = log_path(path)
        with open(log, "w") as out:
            process = subprocess.Popen(
                [sys.executable, "-m", SERVER_MODULE, str(path), "--idle-timeout", f"{idle_timeout:g}"],
                stdin=subprocess.DEVNULL, stdout=out, stderr=subprocess.STDOUT, start_new_session=True)
        deadline = time.monotonic() + START_TIMEOUT
        while time.monotonic() < deadline:
            with contextlib.suppress(FileNotFoundError, ConnectionRefusedError):
                return _open(path)
            if process.poll() is not None:
                raise DaemonUnavailable(f"it exited at start: {_last_line(log)} (log: {log})")
            time.sleep(0.02)
        raise DaemonUnavailable(f"it did not start within {START_TIMEOUT:g} s (log: {log})")


def _last_line(log: Path) -> str:
    lines = log.read_text(errors="replace").strip().splitlines()
    return lines[-1] if lines else "no output"


def daemon_pid(path: Path) -> int | None:
    """Pid of the daemon process of ``path``, if its pid file names a live daemon process."""
    try:
        pid = int(pid_path(path).read_text())
        cmdline = Path(f"/proc/{pid}/cmdline").read_bytes()
    except (OSError, ValueError):
        return None
    return pid if SERVER_MODULE.encode() in cmdline else None


def _kill_hung(path: Path) -> None:
    """A daemon that accepts connections but no commands is killed; the next command starts another."""
    import signal
    from cdpr_tools.file_lock import locked
    with locked(path.with_suffix(".lock")):   # one command at a time starts it; the others wait, then connect
        pid = daemon_pid(path)
        if pid is not None:
            os.kill(pid, signal.SIGKILL)
        with contextlib.suppress(FileNotFoundError):
            path.unlink()


def status(path: Path) -> dict:
    """The running daemon's status (``DaemonUnavailable`` if none answers)."""
    with connect(path) as conn:
        try:
            return conn.request({"op": "status"}, ACCEPT_TIMEOUT)["status"]
        except (TimeoutError, ConnectionError) as exc:
            raise DaemonUnavailable(f"it does not answer ({exc or 'timeout'})") from None


def stop(path: Path) -> bool:
    """Stop the running daemon and wait until its process is gone; False if none was running."""
    pid = daemon_pid(path)
    try:
        with connect(path) as conn:
            conn.request({"op": "stop"}, ACCEPT_TIMEOUT)
    except DaemonUnavailable:
        return False
    except (TimeoutError, ConnectionError):
        _kill_hung(path)
    deadline = time.monotonic() + STOP_TIMEOUT
    while pid is not None and _alive(pid) and time.monotonic() < deadline:
        time.sleep(0.02)
    if pid is not None and _alive(pid):
        _kill_hung(path)
    return True


def _alive(pid: int) -> bool:
    """The process runs (a zombie, which has exited but is not yet reaped, has an empty command line)."""
    try:
        return bool(Path(f"/proc/{pid}/cmdline").read_bytes())
    except OSError:
        return False
