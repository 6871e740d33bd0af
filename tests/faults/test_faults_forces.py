"""Forces that run away in the composed closed-loop graph (one process, lockstep, IPAnema 3 Mini,
default mismatched plant), issue 28's "Done when": the extreme gains of the issue set on the nodes
while ``cuboid_mini`` runs (forced through the stability check with ``allow_unstable``, as an
operator could), and the pushes of the issue (350 N; 900 N then 500 N). For each: the loop runs
on (no gap of 1 s of simulated time), no simulated cable force (the plant's) leaves
[0.5 f_min, 1.5 f_max] for more than 100 ms once the fault's cause is over (the gains' injection;
a push's end: a push beyond what the cables hold drives them out of the band while it lasts), and
a program that had such an excursion does not end ``done``. Times are the graph's simulated ones.
One launch serves the module; each test ends the hold it caused (``~/release_hold``).

The library-level twins of these cases (ControlLoop in one process, tests/control/test_force_watch.py)
measure the same figures faster; these show that the nodes do what the loop does.
"""
import numpy as np
import pytest

from required import import_or_skip  # noqa: E402  (a missing rclpy fails in CI)
rclpy = import_or_skip("rclpy")
from cdpr_msgs.msg import ProgramStatus  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from std_srvs.srv import Trigger  # noqa: E402

from cdpr_control import programs  # noqa: E402
from cdpr_test_nodes.fault_graph import FaultGraph  # noqa: E402
from cdpr_test_nodes.graph import wait_for  # noqa: E402

HANG_S = 120.0          # wall-clock guard against a hang, never a margin
MS = 1_000_000          # ns


@pytest.fixture(scope="module")
def graph():
    g = FaultGraph("composed", lockstep_timeout=0.02, state_timeout=5.0)
    try:
        yield g
    finally:
        g.close()


def set_parameters(graph, name: str, parameters: list) -> list:
    """Set ``parameters`` on node ``name`` (with ``allow_unstable`` first); -> the previous values."""
    node = graph.node(name)
    before = [Parameter(p.name, value=node.get_parameter(p.name).value) for p in parameters]
    result = node.set_parameters_atomically([Parameter("allow_unstable", value=True)])
    assert result.successful, result.reason
    result = node.set_parameters_atomically(parameters)
    assert result.successful, result.reason
    return before


def release_hold(graph) -> None:
    """End the force watch's hold and wait until the loop runs unheld with every force in its band."""
    client = graph.probe.create_client(Trigger, "/joint_command/release_hold")
    try:
        assert client.wait_for_service(timeout_sec=30.0)
        future = client.call_async(Trigger.Request())
        wait_for(future.done, timeout=HANG_S, what="the release_hold answer")
    finally:
        graph.probe.destroy_client(client)
    assert graph.node("joint_command").watch.fault is None
    graph.wait_running(periods=300, timeout=HANG_S)


def program_ended(running) -> object:
    running["thread"].join(HANG_S)
    assert "result" in running, running.get("error", "the program did not end")
    return running["result"]


def check_not_done(graph, result, since: int) -> None:
    """The program failed naming the force watch, /program_status says FAILED and never SUCCEEDED."""
    assert not result.success and "force watch" in result.message, result.message
    states = [m.state for m in graph.collector.messages("/program_status")
              if m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec >= since]
    assert ProgramStatus.FAILED in states and ProgramStatus.SUCCEEDED not in states, states


GAINS = {
    # issue 28: "OSPC K_p 7 during cuboid_mini" (x100 the shipped 0.07)
    "ospc_K_p_7": {"ospc": [Parameter("K_p", value=[7.0] * 6)]},
    # "CFC K_p 10 with T_i 1 ms and OSPC x100"
    "cfc_K_p_10_T_i_1ms_ospc_x100": {"cable_force_controller": [Parameter("K_p", value=10.0),
                                                                Parameter("T_i", value=1e-3)],
                                     "ospc": [Parameter("K_p", value=[7.0] * 6)]},
    # "T_i 1 ms alone"
    "cfc_T_i_1ms": {"cable_force_controller": [Parameter("T_i", value=1e-3)]},
}
INJECT_PERIODS = 300    # into cuboid_mini (its first move)
HELD_S = 1.0            # simulated time the hold is watched for after the program failed


@pytest.mark.parametrize("case", list(GAINS))
def test_extreme_gains_during_cuboid_mini_end_in_a_hold_within_the_band_not_done(graph, case):
    start = graph.newest_command()
    running = graph.start_program(programs.read("cuboid_mini"), f"cuboid_{case}")
    graph.wait_program_state(ProgramStatus.RUNNING, timeout=HANG_S)
    graph.wait_running(periods=INJECT_PERIODS, timeout=HANG_S)
    assert graph.node("joint_command").watch.fault is None
    restore = {}
    try:
        for name, parameters in GAINS[case].items():
            restore[name] = set_parameters(graph, name, parameters)
        injected = graph.newest_command()
        result = program_ended(running)
        ended = graph.newest_command()
        graph.wait_stamp(ended + int(HELD_S * 1e9), timeout=HANG_S)   # the hold, the gains still set
        stamps, f = graph.forces(injected)
        print(f"\n{case} (mismatched plant): {result.message}; after the gains "
              f"{f.min():.1f}..{f.max():.1f} N, excursions {graph.excursions(injected)}")
        check_not_done(graph, result, start)
        assert graph.node("joint_command").watch.fault is not None         # latched
        graph.check_forces(since_stamp=injected)
        graph.check_commands(since_stamp=start)
    finally:
        for name, before in restore.items():
            assert graph.node(name).set_parameters_atomically(before).successful
            graph.node(name).set_parameters_atomically([Parameter("allow_unstable", value=False)])
        release_hold(graph)


AFTER_S = 1.5           # simulated time watched after a push's end
SETTLED_S = 1.0         # ... of which the last 0.5 s must have every force within [f_min, f_max]
CORNER = (-150.0, -100.0, -100.0)    # mm: cuboid_mini's first corner (where its program fails above)
# name -> (position [mm] pushed at, pushes: (force along x [N], duration [s], pause after it [s]),
# a program running through the pushes or None)
PUSHES = {
    "350_N_home_program": ((0.0, 0.0, 0.0), [(350.0, 0.5, 0.0)], "G21 G90\nG1 X20 F600\nG4 P600\nM30"),
    "900_N_then_500_N_home": ((0.0, 0.0, 0.0), [(900.0, 0.5, 0.5), (500.0, 0.5, 0.0)], None),
    "900_N_then_500_N_corner": (CORNER, [(900.0, 0.5, 0.5), (500.0, 0.5, 0.0)], None),
}


def pushed(graph, position, pushes: list, program: str | None = None) -> dict:
    """Move to ``position`` [mm], push the platform (``pushes`` in a row), optionally while
    ``program`` runs; watch until AFTER_S after the last push's end, then end the hold. -> {start,
    began, end, until (stamps [ns]: before the program, the first push, the last push's end, the
    end of the watch), result (the program's, or None), watch (the fault that held, or None)}."""
    x, y, z = position
    moved = graph.start_program(f"G21 G90\nG1 X{x:g} Y{y:g} Z{z:g} F6000\nM30", "to_the_push")
    assert program_ended(moved).success
    graph.wait_running(periods=1000, timeout=HANG_S)      # 1 s standing: a clean stretch for the watch
    start = graph.newest_command()
    running = None
    if program is not None:
        running = graph.start_program(program, "pushed")
        graph.wait_program_state(ProgramStatus.RUNNING, timeout=HANG_S)
        graph.wait_running(periods=100, timeout=HANG_S)
    try:
        for k, (force, duration, pause) in enumerate(pushes):
            at = graph.push(force, duration)
            began = at if k == 0 else began
            end = at + int(duration * 1e9)
            graph.wait_stamp(end + int(pause * 1e9), timeout=HANG_S)
        until = end + int(AFTER_S * 1e9)
        graph.wait_stamp(until, timeout=HANG_S)
        result = None if running is None else program_ended(running)
        watch = graph.node("joint_command").watch.fault
        stamps, f = graph.forces(end, until)
        late = f[stamps >= end + int(SETTLED_S * 1e9)]
        print(f"\npushes {pushes} at {position} mm (mismatched plant): after the end {f.min():.1f}..{f.max():.1f} N, "
              f"{SETTLED_S}-{AFTER_S} s after it {late.min():.2f}..{late.max():.2f} N; excursions (ms after the "
              f"end) {[((a - end) // MS, (b - end) // MS) for a, b in graph.excursions(end, until)]}; "
              f"held by {None if watch is None else watch.message}")
        return {"start": start, "began": began, "end": end, "until": until, "result": result, "watch": watch}
    finally:
        release_hold(graph)


class PushRuns:
    """Each case of PUSHES run once, when a test first asks for it (its cost in that test)."""

    def __init__(self, graph):
        self.graph, self.runs = graph, {}

    def __getitem__(self, case: str) -> dict:
        if case not in self.runs:
            self.runs[case] = pushed(self.graph, *PUSHES[case])
        return self.runs[case]


@pytest.fixture(scope="module")
def push_runs(graph) -> PushRuns:
    return PushRuns(graph)


def test_a_program_pushed_beyond_the_cables_fails_and_does_not_end_done(graph, push_runs):
    """Issue 28: a program through a cable-force excursion (a 350 N push, more than the eight 40 N
    cables hold) must not end ``done``: it fails naming the force watch."""
    run = push_runs["350_N_home_program"]
    assert graph.excursions(run["began"], run["until"]), "the push left every force in its band: no fault tried"
    check_not_done(graph, run["result"], run["start"])
    assert run["watch"] is not None


SLACK_LEFT = pytest.mark.xfail(strict=True, reason=(
    "open (issue 28): at cuboid_mini's corner (-150, -100, -100) mm, 900 N then 500 N leave the plant's cables "
    "settled and the platform tilted (1.6 deg); the hold's tension correction (control/joint_command.py, "
    "internal forces only) leaves cables at 0-5.5 N 1.0-1.5 s after the end (composed graph, mismatched plant)"))


@pytest.mark.parametrize("case", [c if "corner" not in c else pytest.param(c, marks=SLACK_LEFT) for c in PUSHES])
def test_after_a_push_the_loop_runs_and_the_cables_are_back_within_their_limits(graph, push_runs, case):
    """Issue 28: after a 350 N push forces stayed at 1.5-7.9 N (below f_min 5 N) 20 s later, after
    900 N then 500 N four cables at 0-0.07 N for 10 s. Now the loop runs on through the pushes (no
    gap of 1 s), every command is finite and within the rate limit, the watch held, and 1.0-1.5 s
    after the last push's end every cable is within [f_min, f_max]."""
    run = push_runs[case]
    assert run["watch"] is not None
    graph.check_commands(since_stamp=run["start"])
    stamps, f = graph.forces(run["began"], run["until"])
    assert len(stamps) > 1 and np.diff(stamps).max() <= 1_000 * MS
    late = f[stamps >= run["end"] + int(SETTLED_S * 1e9)]
    c = graph.robot.cable
    assert len(late) and np.all(late >= c.f_min) and np.all(late <= c.f_max), (late.min(), late.max())


@pytest.mark.xfail(strict=True, reason=(
    "open (issue 28, Done when): after a push's end the hold restores the tension over T_HOLD 0.25 s "
    "(control/joint_command.py): cables stay below 0.5 f_min for 300-355 ms after 350 N and 660-1500 ms after "
    "900 N then 500 N (composed graph, mismatched plant)"))
@pytest.mark.parametrize("case", list(PUSHES))
def test_after_a_push_no_cable_force_leaves_the_band_for_more_than_100_ms(graph, push_runs, case):
    """Issue 28, "Done when": no simulated cable force out of [0.5 f_min, 1.5 f_max] for more than
    100 ms from the push's end on (while a push beyond the cables lasts, they must leave it)."""
    run = push_runs[case]
    graph.check_forces(since_stamp=run["end"], until_stamp=run["until"])
