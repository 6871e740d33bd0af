"""The graph commands shown in README.md and docs/*.md run against the launched graph (issue 27).

tests/tools/test_documented_commands.py parses every documented `cdpr ...` line; this module runs
the concrete ones that talk to a graph and end by themselves (`param list|get|set|describe|dump`,
`node list`, `topic list|info`, `topic echo --once`) against graphs/closed_loop.yaml (IPAnema 3 Mini,
composed, default mismatched plant), as a user types them: `cdpr` in a process of its own, through
the graph daemon. A renamed node, parameter, value range or topic fails here. A stream (`topic echo`
without --once or --count, `topic hz`) is checked for what it names: the topic has a publisher
(`topic info`). A line the document shows failing (the next line of its block is the error) must
fail with that error (up to a "..." that stands for the rest). Commands that need a file of the reader's (`param load ... friction.yaml`,
`param dump -o`) or a robot stay parsed only.
"""
from __future__ import annotations

import shlex
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pytest

from cdpr_test_nodes.graph import kill_daemon, cdpr as run_cdpr, subprocess_env
from cdpr_tools.share import package_share
from test_documented_commands import DOCS, PLACEHOLDER, _is_reference, documented_commands

RUN = {("param", "list"), ("param", "get"), ("param", "set"), ("param", "describe"), ("param", "dump"),
       ("node", "list"), ("topic", "list"), ("topic", "info"), ("topic", "echo"), ("topic", "hz")}
COMPLETE = {("node", "list"), ("topic", "list")}  # need no argument: `cdpr node list` in prose runs too
STREAMS = {("topic", "echo"), ("topic", "hz")}  # without --once / --count they run until Ctrl-C
TIMEOUT = 30.0  # s a command may wait for a node or topic of the graph (discovery on a loaded machine)
NO_HANG = 120.0  # s after which a command hangs


def _error_shown_after(doc: str, line: int) -> str | None:
    """The error a document shows on the line after command ``line`` of a code block, if any."""
    lines = next(d for d in DOCS if d.name == doc).read_text(encoding="utf-8").splitlines()
    following = lines[line].strip() if line < len(lines) else ""
    return following if following.startswith("cdpr ") and ": error: " in following else None


def graph_commands() -> list[tuple[str, int, list[str], str | None]]:
    """(document, line, argv, documented error) of each concrete graph command, once per argv."""
    found, seen = [], set()
    for doc, line, command in documented_commands():
        if PLACEHOLDER.search(command):
            continue
        argv = shlex.split(command)[1:]
        if tuple(argv[:2]) not in RUN or (_is_reference(argv) and tuple(argv[:2]) not in COMPLETE) or "-o" in argv or "--output" in argv or tuple(argv) in seen:
            continue
        seen.add(tuple(argv))
        found.append((doc, line, argv, _error_shown_after(doc, line)))
    return found


COMMANDS = graph_commands()


def test_the_documents_show_graph_commands():
    verbs = {tuple(argv[:2]) for _, _, argv, _ in COMMANDS}
    assert {("param", "get"), ("param", "set"), ("node", "list"), ("topic", "echo")} <= verbs
    assert len(COMMANDS) >= 15


@pytest.fixture(scope="module")
def graph():
    """graphs/closed_loop.yaml in a process of its own (`cdpr launch`), and the environment of `cdpr`
    commands that use a graph daemon of this module's (stopped however the tests end)."""
    runtime = tempfile.mkdtemp(prefix="cdpr-docs-test-")  # short: Unix socket paths have 107 bytes
    env = {k: v for k, v in subprocess_env().items() if k != "CDPR_NO_DAEMON"}
    env["XDG_RUNTIME_DIR"] = runtime
    launch = subprocess.Popen([sys.executable, "-m", "cdpr_tools.cli", "launch",
                               str(package_share("cdpr_tools") / "graphs" / "closed_loop.yaml")],
                              env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    try:
        first = cdpr(env, "topic", "echo", "/joint_command/mode", "--once", "--timeout", "120")
        assert first.returncode == 0, first.stderr    # the graph runs, the daemon knows it
        yield env
    finally:
        cdpr(env, "daemon", "stop")
        for pid_file in Path(runtime).rglob("*.pid"):   # whatever the stop could not reach
            kill_daemon(int(pid_file.read_text()))
        shutil.rmtree(runtime, ignore_errors=True)
        launch.send_signal(signal.SIGINT)
        _, err = launch.communicate(timeout=NO_HANG)
    assert launch.returncode == 0, err[-2000:]



def cdpr(env: dict, *argv: str) -> subprocess.CompletedProcess:
    """`cdpr ARGV` in a process of its own; it must end within NO_HANG seconds."""
    return run_cdpr(env, *argv, timeout=NO_HANG)


def _runnable(argv: list[str], error: str | None) -> list[str]:
    """What runs for documented ``argv``: a stream becomes `topic info` of its topic; the rest gets a
    --timeout for discovery on a loaded machine (unless it gives one, or is shown failing: a node that
    is not there is waited for its default time only)."""
    if error is not None:
        return argv
    if tuple(argv[:2]) in STREAMS and not {"--once", "--count", "-n", "--duration"} & set(argv):
        return ["topic", "info", argv[2]]
    if argv[:2] == ["topic", "hz"]:
        return argv
    return argv if "--timeout" in argv or argv[:2] in (["node", "list"], ["topic", "list"]) else [*argv, "--timeout",
                                                                                              f"{TIMEOUT:g}"]


@pytest.mark.parametrize("doc, line, argv, error", COMMANDS, ids=[f"{d}:{n}" for d, n, _, _ in COMMANDS])
def test_documented_graph_command_runs(graph, doc, line, argv, error):
    runnable = _runnable(argv, error)
    start = time.monotonic()
    result = cdpr(graph, *runnable)
    where = f"{doc}:{line}: `cdpr {' '.join(runnable)}`"
    if error is not None:   # the document shows it failing: with its error (up to its "...", if it has one)
        assert result.returncode == 1, f"{where} was to fail with {error!r}: {result.stdout}"
        shown = error.split("...")[0] if "..." in error else error + "\n"
        assert result.stderr.startswith(shown), f"{where}: {result.stderr}"
        return
    assert result.returncode == 0, f"{where} exited {result.returncode} after {time.monotonic() - start:.1f} s: " \
                                   f"{result.stderr[-1000:]}"
    assert result.stdout, where
