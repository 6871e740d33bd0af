"""bench_graph.py bounds the configurations that start node processes (issue 26: make bench hung in
the transport floor's processes configuration): one that does not finish within its bound is
killed with every process it started and reported, and the benchmark goes on. (No figures.)"""
import os
import pathlib
import subprocess
import sys
import time

import pytest

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[2] / "benchmarks"))
import bench_graph  # noqa: E402


def alive(pid: int) -> bool:
    try:
        state = pathlib.Path(f"/proc/{pid}/stat").read_text().rpartition(")")[2].split()[0]
    except OSError:
        return False
    return state != "Z"


def test_kill_tree_ends_the_children_in_sessions_of_their_own():
    # a parent, its child and a grandchild in a session of its own (as the launcher starts nodes)
    parent = subprocess.Popen(["sh", "-c", "sleep 60 & setsid sleep 60 & wait"], start_new_session=True)
    deadline = time.monotonic() + 10.0
    while len(bench_graph.descendants(parent.pid)) < 2:
        assert time.monotonic() < deadline, "the test's process tree did not start"
        time.sleep(0.02)
    below = bench_graph.descendants(parent.pid)
    bench_graph.kill_tree(parent.pid)
    parent.wait(10)
    deadline = time.monotonic() + 10.0
    while any(alive(pid) for pid in below):
        assert time.monotonic() < deadline, f"left running: {[p for p in below if alive(p)]}"
        time.sleep(0.02)


def test_a_configuration_past_its_bound_is_reported_not_waited_for(monkeypatch):
    # a graph of node processes cannot start looping within 1 s: its child is killed at the bound
    monkeypatch.setattr(bench_graph, "START_TIMEOUT_S", 1.0)
    monkeypatch.setattr(bench_graph, "WARMUP_S", 0.0)
    monkeypatch.setattr(bench_graph, "CHILD_MARGIN_S", 0.0)
    before = set(bench_graph.descendants(os.getpid()))
    t0 = time.monotonic()
    with pytest.raises(TimeoutError, match="did not finish within 3 s"):
        bench_graph.bounded_measure({"mode": "processes"}, 1.0)
    assert time.monotonic() - t0 < 30.0
    assert set(bench_graph.descendants(os.getpid())) <= before
