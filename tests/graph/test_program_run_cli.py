"""`cdpr program run` against a launched graph (closed_loop.yaml, IPAnema 3 Mini, composed, default
mismatched plant): a program from a .gcode file and a shipped one by name run to the end (issue 28:
a file's program went out as bytes into the goal's string field and the C conversion aborted the
client with exit 134). The client runs as a subprocess, so an abort is a failed test, not a dead
pytest; into a pipe its progress is a few plain lines, no carriage returns (issue 27)."""
import subprocess
import sys

import pytest

from cdpr_test_nodes.graph import subprocess_env
from cdpr_tools.demo_cmd import GRAPH
from cdpr_tools.launch import Launcher
from cdpr_tools.launch_file import load_launch_file

PROGRAM = "G21 G90\nG1 X20 F3000\nG1 X0\nM30\n"   # 20 mm out along x and back: about 1 s
CLIENT_TIMEOUT = 300.0                            # s of wall time, far beyond the runs on a loaded machine
# (the server's answer to the goal counts against --timeout: under load 17 the composed graph took
# more than the 5 s of --server-timeout's default to answer, and both tests failed)


@pytest.fixture(scope="module")
def graph():
    description = load_launch_file(GRAPH, {"robot": "ipanema3_mini"})
    with Launcher(description, mode="composed") as launch:   # stopped on leaving, also when a test fails
        yield launch


def program_run(program: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "cdpr_tools.cli", "program", "run", program,
                           "--timeout", str(CLIENT_TIMEOUT), "--server-timeout", str(CLIENT_TIMEOUT)],
                          env=subprocess_env(), capture_output=True, text=True, timeout=CLIENT_TIMEOUT + 60.0)


def check_done(run: subprocess.CompletedProcess, name: str) -> None:
    assert run.returncode == 0, run.stdout + run.stderr
    assert run.stdout.startswith(f"{name}: done after "), run.stdout
    assert "Traceback" not in run.stderr
    progress = [line for line in run.stderr.splitlines() if line.startswith(f"program {name!r}:")]
    assert "\r" not in run.stderr
    assert 1 <= len(progress) <= 11 and progress[-1].startswith(f"program {name!r}: 100.0 %"), run.stderr


def test_program_run_with_a_gcode_file(graph, tmp_path):
    path = tmp_path / "out_and_back.gcode"
    path.write_text(PROGRAM)
    check_done(program_run(str(path)), "out_and_back")
    assert graph.errors == []


def test_program_run_with_a_shipped_name(graph):
    check_done(program_run("rectangle"), "rectangle")
    assert graph.errors == []
